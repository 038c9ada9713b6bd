"""K_max for a constant delay known only to lie in a range, with a receiver that acts at
the sampling instants.

The model (sample-synchronous receiver): the position sampled at kT is sent at kT,
arrives after a constant transport delay tau in [tau_lo, tau_hi], and the controller,
which runs at the sampling instants, uses it from the first instant at or after its
arrival, (k + ceil(tau / T)) T. The loop is then exactly the paper's loop with the whole
delay n = ceil(tau / T), and the delays of the range are the finitely many
n in {ceil(tau_lo / T), ..., ceil(tau_hi / T)}: the minimum of the exact core's certified
K_max over them is the certified minimum over the whole continuum of tau, with no
sampling of the range (every tau of the range is one of these n).

For PEB each direction's delay lies in the range independently; with whole delays only
the round trip n_f + n_b enters the characteristic function (the return difference's
determinant is (1 + C_m G_m)(1 + C_s G_s) - C_m C_s G_m G_s z^-(n_f + n_b), the delays
appearing only in the cross term), so the round trips 2 n_lo ... 2 n_hi are analysed.

A delay that acts *between* the sampling instants (the engine's fractional delay,
e.g. a sensor sampled off the controller's clock; what ``kmax --delay-range`` in seconds
answers) is proved over its continuum by
:func:`~hapstab.analysis.network.frac_result.fractional_range_critical_stiffness`
(:mod:`~hapstab.analysis.network.frac_range`): the HVE, and the PEB with the same one-way
delay both ways; different ranges in each direction would make the two fractions a 2-D
family that is not covered (refused, by name).

References
----------
The paper, Fig. 2a and eq. (20); the exact core (:func:`hapstab.critical_stiffness`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.errors import AnalysisError, ModelError, check_real
from hapstab.models.delays import whole_delays
from hapstab.models.loops import require_loop
from hapstab.results import Result, jsonable, write_csv

__all__ = ["DelayRangeResult", "delay_range_critical_stiffness", "whole_delays"]


@dataclass(frozen=True)
class DelayRangeResult(Result):
    """Certified minimum of K_max over a range of constant delays.

    Parameters
    ----------
    critical_stiffness : float
        min over the range of the exact core's certified K_max, N/m: the loop is stable
        for every K in (0, critical_stiffness] at every delay of the range.
    worst_delay_samples : int
        The delay (samples; for PEB the round trip) that gives it.
    delays_samples : tuple of int
        Every delay analysed (one-way for the HVE; round trips n_f + n_b for PEB).
    kmax : tuple of float
        The certified K_max at each, N/m.
    range_s : (float, float) or None
        The transport delay range in s, if given in seconds.
    period : float
        T in s.
    round_trip : bool
        Delays are round trips (a two-port loop).
    loop_dict : dict
        The loop analysed.
    """

    critical_stiffness: float
    worst_delay_samples: int
    delays_samples: tuple[int, ...]
    kmax: tuple[float, ...]
    range_s: tuple[float, float] | None
    period: float
    round_trip: bool
    loop_dict: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def reason(self) -> str:
        """The answer in words."""
        what = "round trip" if self.round_trip else "delay"
        span = (f"a transport delay in [{self.range_s[0] * 1e3:g}, {self.range_s[1] * 1e3:g}] ms "
                f"(acting as {self.delays_samples[0]}..{self.delays_samples[-1]} whole samples "
                "at a receiver that runs at the sampling instants)" if self.range_s else
                f"whole-sample {what}s {self.delays_samples[0]}..{self.delays_samples[-1]}")
        return (f"stable for K in (0, {self.critical_stiffness:.10g}] N/m at every delay of "
                f"{span}; the worst is a {what} of {self.worst_delay_samples} samples "
                f"(certified K_max at each of the {len(self.delays_samples)} delays, exact core)")

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"critical_stiffness": self.critical_stiffness, "method": "exact",
                         "worst_delay_samples": float(self.worst_delay_samples),
                         "delays_samples": [float(d) for d in self.delays_samples],
                         "kmax_per_delay": list(self.kmax),
                         "delay_range_s": list(self.range_s) if self.range_s else None,
                         "round_trip": self.round_trip, "period_s": self.period,
                         "certified": True, "reason": self.reason})

    def to_csv(self, path: Any) -> None:
        """Write delay_samples, critical_stiffness_N_per_m (one row per delay).

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write.
        """
        write_csv(path, ["delay_samples", "critical_stiffness_N_per_m"],
                  [[str(d), repr(k)] for d, k in zip(self.delays_samples, self.kmax,
                                                     strict=True)])

    def plot(self, ax: Any = None) -> Any:
        """K_max at each delay of the range, the minimum marked.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw.

        Returns
        -------
        matplotlib Axes
        """
        from hapstab.plotting import axes_or_new

        ax = axes_or_new(ax)
        ax.plot(self.delays_samples, self.kmax, "o-", label="certified K_max")
        ax.plot([self.worst_delay_samples], [self.critical_stiffness], "r*", ms=12,
                label="worst delay")
        ax.set_xlabel("round trip (samples)" if self.round_trip else "delay (samples)")
        ax.set_ylabel("K_max (N/m)")
        ax.legend(loc="best")
        return ax


def delay_range_critical_stiffness(loop: Any, lo: float, hi: float, *, seconds: bool = True
                                   ) -> DelayRangeResult:
    """Certified minimum of K_max over every constant delay of a range.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (its own delay is replaced); spring-damper controllers.
    lo, hi : float
        The range: transport delays in s (``seconds=True``; the sample-synchronous
        receiver of the module docstring; a delay acting between the samples:
        :func:`~hapstab.analysis.network.frac_result.fractional_range_critical_stiffness`),
        or whole samples (``seconds=False``).
    seconds : bool
        Whether ``lo`` and ``hi`` are seconds.

    Returns
    -------
    DelayRangeResult
    """
    from hapstab.analysis.methods import critical_stiffness

    require_loop(loop)
    if getattr(loop, "force_gains", None) is not None:
        raise AnalysisError("delay range: modelled for hve and peb (the 4-channel loop's "
                            "delays do not enter only as a round trip)")
    if seconds:
        n_lo, n_hi = whole_delays(lo, hi, loop.period)
    else:
        n_lo, n_hi = (int(check_real("delay range start", lo, nonnegative=True)),
                      int(check_real("delay range end", hi, nonnegative=True)))
        if n_lo != lo or n_hi != hi or n_hi < n_lo:
            raise ModelError(f"delay range = {lo!r}:{hi!r}: whole samples, start <= end")
    two = len(loop.controllers) == 2
    ds = list(range(2 * n_lo, 2 * n_hi + 1)) if two else list(range(n_lo, n_hi + 1))
    _check_cost(ds, 2 if two else 1)
    ks = []
    for d in ds:
        at = (loop.replace(delay_samples=d // 2, delay_backward_samples=d - d // 2,
                           fractional_delay=0.0, fractional_delay_backward=None)
              if two else loop.with_whole_delay(d))
        ks.append(float(critical_stiffness(at).critical_stiffness))
    i = int(np.argmin(ks))
    return DelayRangeResult(ks[i], ds[i], tuple(ds), tuple(ks),
                            (float(lo), float(hi)) if seconds else None, loop.period, two,
                            loop.to_dict())


def _check_cost(ds: list[int], ports: int) -> None:
    """Refuse, before any work, a range whose K_max at every delay is over the budget
    (:func:`hapstab.budget.exact_search_cost` at the longest delay, plus
    :data:`hapstab.budget.POINT_SECONDS` per delay)."""
    from hapstab.budget import POINT_SECONDS, Cost, check, exact_search_cost
    one = exact_search_cost(ds[-1], ports)
    check(Cost(f"delay range: K_max at {len(ds)} delays up to {ds[-1]} samples",
               one.memory_bytes, len(ds) * (one.seconds + POINT_SECONDS)))
