"""The result of :func:`hapstab.jitter`: the bracket [stable_up_to, unstable_from] on K
under a time-varying delay, with the destabilising pattern."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.results import Result, jsonable, write_csv

__all__ = ["JitterResult"]


@dataclass(frozen=True)
class JitterResult(Result):
    """K under a time-varying delay: a bracket, the gap between its ends reported.

    Parameters
    ----------
    stable_up_to : float
        N/m. At every K scanned in (0, stable_up_to] the small-gain jitter margin held:
        stable for every delay sequence in the range (sufficient condition, floating
        point; 0 if it held nowhere).
    unstable_from : float
        N/m. The smallest K found at which ``pattern``, repeated, grows (its growth rate
        per sample >= 1 + RATE_MARGIN); or, if no enumerated pattern grows below the
        constant-delay worst case, that worst case (the exact core's certified K_max of
        the constant delay ``pattern``: unstable just above it).
    pattern : tuple of tuple of int
        The destabilising delays, one tuple (a delay per networked term) per sample of a
        period.
    pattern_rate : float
        rho(A_{d_p} ... A_{d_1})^(1/p) at unstable_from (1.0 for the constant worst case,
        which is on the boundary there).
    pattern_is_constant : bool
        The pattern is the constant worst delay (no shorter answer was found).
    small_gain : float
        N ||M||_inf at stable_up_to (< 1), nan if no K passed.
    constant_worst : float
        min over constant delays d in [lo, hi] of the certified K_max(d), N/m.
    constant_worst_delay : int
        Its delay (for PEB the round trip), samples.
    nominal_kmax : float
        Certified K_max at the nominal delay lo (round trip 2 lo for PEB), N/m.
    delay_samples : (int, int)
        (lo, hi).
    range_s : (float, float) or None
        The transport delays in s, when given so.
    period : float
        T in s.
    terms : tuple of str
        The networked terms, each with its own delay.
    patterns_checked, max_length : int
        Patterns enumerated and their longest length.
    order : int
        State dimension of the switched system.
    scan_K, scan_rate : arrays
        K (N/m) and the largest pattern growth rate there (the pattern search).
    gain_K, gain : arrays
        K (N/m) and N ||M||_inf there (the small-gain search; inf: nominal unstable).
    seconds : float
        Wall time.
    loop_dict : dict
        The loop analysed.
    """

    stable_up_to: float
    unstable_from: float
    pattern: tuple[tuple[int, ...], ...]
    pattern_rate: float
    pattern_is_constant: bool
    small_gain: float
    constant_worst: float
    constant_worst_delay: int
    nominal_kmax: float
    delay_samples: tuple[int, int]
    range_s: tuple[float, float] | None
    period: float
    terms: tuple[str, ...]
    patterns_checked: int
    max_length: int
    order: int
    scan_K: np.ndarray = field(repr=False, compare=False)
    scan_rate: np.ndarray = field(repr=False, compare=False)
    gain_K: np.ndarray = field(repr=False, compare=False)
    gain: np.ndarray = field(repr=False, compare=False)
    seconds: float = 0.0
    loop_dict: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def gap(self) -> float:
        """unstable_from - stable_up_to, N/m: where the answer is not known."""
        return self.unstable_from - self.stable_up_to

    @property
    def relative_gap(self) -> float:
        """gap / unstable_from."""
        return self.gap / self.unstable_from if self.unstable_from > 0 else math.nan

    def pattern_text(self) -> str:
        """The pattern as delays per sample, ``5 6 7 5`` (PEB: ``(1,2) (2,3)``)."""
        one = all(len(d) == 1 for d in self.pattern)
        return " ".join(str(d[0]) if one else "(" + ",".join(map(str, d)) + ")"
                        for d in self.pattern)

    @property
    def reason(self) -> str:
        """The answer in words, with what each end rests on."""
        lo, hi = self.delay_samples
        span = (f"a transport delay in [{self.range_s[0] * 1e3:g}, {self.range_s[1] * 1e3:g}] "
                f"ms, i.e. {lo}..{hi} whole samples at a receiver acting at the sampling "
                "instants" if self.range_s else f"a delay of {lo}..{hi} samples")
        low = (f"stable for every delay sequence for K up to {self.stable_up_to:.6g} N/m "
               f"(small-gain jitter margin, Kao & Lincoln 2004: {self.small_gain:.6f} < 1 "
               "there; sufficient, floating point)" if self.stable_up_to > 0 else
               "the small-gain jitter margin holds at no K scanned (no guaranteed range)")
        if self.pattern_is_constant:
            high = (f"unstable just above {self.unstable_from:.6g} N/m with the constant delay "
                    f"{self.pattern_text()} (exact core; no enumerated pattern of length <= "
                    f"{self.max_length} grows below it)")
        else:
            high = (f"unstable from {self.unstable_from:.6g} N/m: the periodic delay pattern "
                    f"{self.pattern_text()} grows by {self.pattern_rate:.10g} per sample "
                    f"(constant-delay worst case {self.constant_worst:.6g} N/m)")
        return (f"with {span} changing from sample to sample (the newest arrived sample is "
                f"used): {low}; {high}. Not known in between: gap {self.gap:.4g} N/m "
                f"({100 * self.relative_gap:.3g} % of unstable_from)")

    def to_dict(self) -> dict[str, Any]:
        return jsonable({
            "stable_up_to_N_per_m": self.stable_up_to,
            "unstable_from_N_per_m": self.unstable_from, "gap_N_per_m": self.gap,
            "relative_gap": self.relative_gap, "method": "jitter-bracket",
            "pattern_samples": [list(d) for d in self.pattern],
            "pattern_growth_per_sample": self.pattern_rate,
            "pattern_is_constant": self.pattern_is_constant,
            "small_gain_at_stable_up_to": self.small_gain,
            "constant_delay_worst_N_per_m": self.constant_worst,
            "constant_delay_worst_samples": float(self.constant_worst_delay),
            "nominal_critical_stiffness": self.nominal_kmax,
            "delay_range_samples": list(self.delay_samples),
            "delay_range_s": list(self.range_s) if self.range_s else None,
            "period_s": self.period, "networked_terms": list(self.terms),
            "patterns_checked": self.patterns_checked, "max_pattern_length": self.max_length,
            "state_dimension": self.order, "certified": False, "seconds": self.seconds,
            "reason": self.reason})

    def to_csv(self, path: Any) -> None:
        """Write the two searches: search (``pattern`` or ``small-gain``),
        stiffness_N_per_m, value (the largest pattern growth rate per sample; N ||M||_inf).

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write.
        """
        rows = [["pattern", repr(float(k)), repr(float(r))]
                for k, r in zip(self.scan_K, self.scan_rate, strict=True)]
        rows += [["small-gain", repr(float(k)), repr(float(g))]
                 for k, g in zip(self.gain_K, self.gain, strict=True)]
        write_csv(path, ["search", "stiffness_N_per_m", "value"], rows)

    def plot(self, ax: Any = None) -> Any:
        """Both searches against K: the worst pattern's growth rate, the small-gain number,
        1, and the bracket shaded.

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
        o = np.argsort(self.scan_K)
        ax.semilogx(self.scan_K[o], self.scan_rate[o], "o-", ms=3,
                    label="largest pattern growth per sample")
        g = np.argsort(self.gain_K)
        ax.semilogx(self.gain_K[g], np.minimum(self.gain[g], 2.0), "s-", ms=3,
                    label="small-gain number N ||M|| (< 1: stable)")
        ax.axhline(1.0, color="k", lw=0.8)
        if self.unstable_from > self.stable_up_to > 0:
            ax.axvspan(self.stable_up_to, self.unstable_from, color="C1", alpha=0.2,
                       label="not known")
        ax.axvline(self.unstable_from, color="C3", ls="--",
                   label=f"unstable from {self.unstable_from:.4g} N/m")
        ax.set_xlabel("K (N/m)")
        ax.set_ylabel("growth rate / gain")
        ax.legend(loc="best", fontsize="small")
        return ax
