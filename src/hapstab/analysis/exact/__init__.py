"""The certified exact core: every crossing of the unit circle found with a proof
(:mod:`~hapstab.analysis.exact.crossings`), and the verdicts and K_max built on it
(:mod:`~hapstab.analysis.exact.core`)."""

from hapstab.analysis.exact.core import (
    exact_critical_stiffness,
    exact_kmax_batch,
    stability,
)
from hapstab.analysis.exact.many import critical_stiffness_many

__all__ = ["stability", "exact_critical_stiffness", "exact_kmax_batch", "critical_stiffness_many"]
