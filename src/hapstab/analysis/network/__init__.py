"""Networks as they are (issue 30): packet loss, exact in the mean-square sense
(:mod:`~hapstab.analysis.network.loss`, on the Markov jump linear system of
:mod:`~hapstab.analysis.network.jump`) and an unknown constant delay in a range at a
sample-synchronous receiver (:mod:`~hapstab.analysis.network.delay_range`) or acting
between the samples, proved over the continuum
(:mod:`~hapstab.analysis.network.frac_range`), and a delay varying from sample to
sample, bracketed (:mod:`~hapstab.analysis.network.jitter`)."""

from hapstab.analysis.network.delay_range import delay_range_critical_stiffness
from hapstab.analysis.network.frac_result import fractional_range_critical_stiffness
from hapstab.analysis.network.jitter import jitter
from hapstab.analysis.network.loss import kmax_against_loss, loss_critical_stiffness

__all__ = ["loss_critical_stiffness", "kmax_against_loss", "delay_range_critical_stiffness",
           "fractional_range_critical_stiffness", "jitter"]
