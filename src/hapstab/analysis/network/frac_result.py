"""The answer for a range of constant delays that act between the sampling instants
(:mod:`~hapstab.analysis.network.frac_range`; the HVE, and the PEB with the same
one-way delay both ways): a proved enclosure of min K_max, the worst
delay, and the segments it was proved on."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from hapstab.analysis.network.frac_range import Segment
from hapstab.errors import AnalysisError
from hapstab.results import Result, jsonable, write_csv

__all__ = ["FractionalRangeResult", "REPORT_RTOL"]

#: A lower end within this (relative) of the base point K_0 proves nothing above it
#: (the branch and bound's boxes at K_0 itself report K_0; rounding of its doubles)
BASE_ROUNDING = 1e-6
#: The relative gap between the proved ends above which the answer is reported
#: *uncertain* (the acceptance's 1e-6, with margin for the float worst point)
REPORT_RTOL = 1e-7


@dataclass(frozen=True)
class FractionalRangeResult(Result):
    """Certified minimum of K_max over every constant delay tau in [tau_lo, tau_hi],
    the delay acting between the sampling instants (e[k] = x(kT - tau)).

    Parameters
    ----------
    critical_stiffness : float
        The proved lower end, N/m: every delay of the range is stable for K in
        [K_0, critical_stiffness) (the exact core's base point K_0).
    upper_bound : float
        The proved upper end, N/m: at the worst delay a pole is on the unit circle at
        some K <= upper_bound, so min K_max over the range lies in
        [critical_stiffness, upper_bound].
    kmax_at_worst : float
        The exact core's K_max at the worst delay, N/m (beside the proof).
    worst_delay_samples : float
        The worst delay found, n + f samples.
    range_samples : (float, float)
        The range in samples.
    period : float
        T in s.
    segments : tuple of Segment
        Each whole part of the range with its proved ends.
    loop_dict : dict
        The loop analysed.
    directions : int
        1 for the HVE; 2 for the PEB, the one-way delay the same both ways.
    """

    critical_stiffness: float
    upper_bound: float
    kmax_at_worst: float
    worst_delay_samples: float
    range_samples: tuple[float, float]
    period: float
    segments: tuple[Segment, ...]
    loop_dict: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)
    directions: int = 1

    @property
    def _what(self) -> str:
        """The delay the range is of, in words."""
        return ("constant delay" if self.directions == 1
                else "constant one-way delay (the same both ways)")

    @property
    def gap(self) -> float:
        """upper_bound - critical_stiffness, N/m."""
        return self.upper_bound - self.critical_stiffness

    @property
    def certified(self) -> bool:
        """The enclosure is closed to :data:`REPORT_RTOL` (else the lower end is safe but
        the gap is *uncertain*)."""
        return (math.isfinite(self.upper_bound)
                and self.gap <= REPORT_RTOL * abs(self.upper_bound))

    @property
    def worst_delay_s(self) -> float:
        return self.worst_delay_samples * self.period

    @property
    def reason(self) -> str:
        """The answer in words."""
        lo, hi = (v * self.period * 1e3 for v in self.range_samples)
        if self.critical_stiffness == 0.0:
            where = (f"a pole reaches |z| = 1 by K = {self.upper_bound:.4g} N/m"
                     if math.isfinite(self.upper_bound) else "K_max is near 0")
            return (f"no K > 0 is proved stable at every {self._what} of [{lo:g}, {hi:g}] ms "
                    f"acting between the samples: at {self.worst_delay_s * 1e3:.6g} ms {where} "
                    "(uncertain below it)")
        head = (f"stable for K in (0, {self.critical_stiffness:.10g}] N/m at every {self._what} "
                f"of [{lo:g}, {hi:g}] ms, acting between the samples (proved over the "
                f"continuum: {len(self.segments)} segment(s), branch and bound on the modified "
                "z-transform)")
        if self.certified:
            return (f"{head}; the worst delay is {self.worst_delay_s * 1e3:.6g} ms, where a pole "
                    f"reaches |z| = 1 by K = {self.upper_bound:.10g} N/m")
        return (f"{head}; uncertain above it: the minimum lies in [{self.critical_stiffness:.10g}, "
                f"{self.upper_bound:.10g}] N/m (gap {self.gap:.3g} N/m not closed within the "
                "budget), the worst delay found "
                f"{self.worst_delay_s * 1e3:.6g} ms")

    def to_dict(self) -> dict[str, Any]:
        return jsonable({
            "critical_stiffness": self.critical_stiffness, "method": "exact",
            "upper_bound_N_per_m": self.upper_bound, "kmax_at_worst_delay": self.kmax_at_worst,
            "gap_N_per_m": self.gap, "worst_delay_samples": self.worst_delay_samples,
            "worst_delay_s": self.worst_delay_s,
            "delay_range_s": [v * self.period for v in self.range_samples],
            "delay_range_samples": list(self.range_samples), "fractional": True,
            "round_trip": False, "same_delay_both_ways": self.directions == 2,
            "period_s": self.period, "certified": self.certified,
            "segments": [{"whole_samples": s.whole, "fractions": [s.f_lo, s.f_hi],
                          "lower_N_per_m": s.lower, "upper_N_per_m": s.upper,
                          "worst_fraction": s.worst_fraction, "boxes": s.boxes}
                         for s in self.segments],
            "reason": self.reason})

    def to_csv(self, path: Any) -> None:
        """Write one row per segment: whole_samples, f_lo, f_hi, lower, upper (N/m),
        worst_fraction.

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write.
        """
        write_csv(path, ["whole_samples", "f_lo", "f_hi", "lower_N_per_m", "upper_N_per_m",
                         "worst_fraction"],
                  [[str(s.whole), repr(s.f_lo), repr(s.f_hi), repr(s.lower), repr(s.upper),
                    repr(s.worst_fraction)] for s in self.segments])

    def plot(self, ax: Any = None) -> Any:
        """Each segment's proved lower end and upper end at its worst fraction, against
        the delay in samples; the range's minimum marked.

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
        for i, s in enumerate(self.segments):
            ax.hlines(s.lower, s.whole + s.f_lo, s.whole + s.f_hi, colors="C0",
                      label="proved lower end" if i == 0 else None)
            if math.isfinite(s.upper):
                ax.plot([s.whole + s.worst_fraction], [s.upper], "C1o",
                        label="proved crossing" if i == 0 else None)
        ax.plot([self.worst_delay_samples], [self.critical_stiffness], "r*", ms=12,
                label="worst delay")
        ax.set_xlabel("delay (samples)")
        ax.set_ylabel("K (N/m)")
        ax.legend(loc="best")
        return ax


def fractional_range_critical_stiffness(loop: Any, lo_s: float, hi_s: float, *,
                                        max_boxes: int | None = None,
                                        backward_s: tuple[float, float] | None = None
                                        ) -> FractionalRangeResult:
    """Certified minimum of K_max over every constant delay tau in [lo_s, hi_s] seconds
    acting between the sampling instants (:mod:`~hapstab.analysis.network.frac_range`):
    the HVE's delay, or the PEB's one-way delay, the same tau in both directions (a
    symmetric link, what ``--delay-s`` means for the PEB).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (its delay is replaced): spring-damper controllers, terminations
        without internal states (and, for the PEB, no rigid-body mode).
    lo_s, hi_s : float
        The range, s (0 <= lo_s <= hi_s).
    backward_s : (float, float), optional
        The PEB's slave -> master range, s: only the forward range itself (or None) is
        allowed; a different one is refused by name (each direction's delay would then
        be a 2-D family, not covered).
    max_boxes : int, optional
        Boxes per segment and proof (default
        :data:`~hapstab.analysis.network.frac_range.MAX_BOXES`); a gap left open is
        reported *uncertain*.

    Returns
    -------
    FractionalRangeResult

    Raises
    ------
    ModelError
        A range with its end below its start, or longer than the delay limit.
    AnalysisError
        A loop outside the model (the 4-channel teleoperator, a filtered damper, an
        operator with states, a rigid-body mode), or different ranges in each direction.
    """
    from hapstab.analysis.network.frac_range import MAX_BOXES, fraction_range_minimum
    from hapstab.models.delays import whole_delays
    from hapstab.models.loops import require_loop
    require_loop(loop)
    _refuse_asymmetric(loop, (lo_s, hi_s), backward_s)
    whole_delays(lo_s, hi_s, loop.period)            # validates the range and its length
    lo, hi = lo_s / loop.period, hi_s / loop.period
    segs, lower, upper, k0 = fraction_range_minimum(loop, lo, hi,
                                                    max_boxes=max_boxes or MAX_BOXES)
    worst = min(segs, key=lambda s: s.upper)
    # the bound holds on [K_0, lower): the double below it is a closed end; a bound no
    # higher than K_0 (to rounding) proves nothing: 0, as the exact core says for a loop
    # it cannot prove stable above its base point
    safe = math.nextafter(lower, -math.inf) if lower > k0 * (1 + BASE_ROUNDING) else 0.0
    core = next((s.kmax_at_worst for s in segs if not math.isnan(s.kmax_at_worst)), math.nan)
    return FractionalRangeResult(safe, upper, core, worst.whole + worst.worst_fraction,
                                 (lo, hi), loop.period, tuple(segs), loop.to_dict(),
                                 len(loop.port_names))


def _refuse_asymmetric(loop: Any, forward: tuple[float, float],
                       backward: tuple[float, float] | None) -> None:
    """Refuse, by name, a range this proof does not cover: a backward range other than the
    forward one (or any, for a one-port loop), and the 4-channel teleoperator."""
    if getattr(loop, "force_gains", None) is not None:
        raise AnalysisError("delay range between the samples: modelled for hve and peb (the "
                            "4-channel loop's force channels are not in the model)")
    same = backward is not None and tuple(map(float, backward)) == tuple(map(float, forward))
    if backward is None or (same and len(loop.port_names) == 2):
        return
    if len(loop.port_names) != 2:
        raise AnalysisError(f"backward_s = {backward!r}: a one-port loop has one delay; "
                            "leave it out")
    raise AnalysisError(
        f"backward_s = {backward!r} with the forward range {forward!r}: different ranges in "
        "each direction make the two fractions a 2-D family, not covered; allowed: the same "
        "range both ways (leave backward_s out), or whole samples per direction "
        "(delay_range_critical_stiffness(loop, lo, hi, seconds=False))")
