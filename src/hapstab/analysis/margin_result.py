"""The result objects of :mod:`hapstab.analysis.margins`: the margins at K and the
Nyquist / Bode view of the exact sampled loop."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.results import Result, jsonable, write_csv

__all__ = ["MarginResult", "FrequencyView"]


@dataclass(frozen=True)
class FrequencyView(Result):
    """The stiffness loop L(e^{j 2 pi f T}) of the exact sampled loop at K (see
    :mod:`hapstab.analysis.margins`): closed-loop poles on the unit circle where L = -1.

    Attributes
    ----------
    frequency_hz : (F,) array
        Frequencies from ~1e-4 of the Nyquist frequency up to 1 / (2T).
    loop : (F,) complex array
        L at each frequency (dimensionless).
    ports : int
        1: ``L = -K G``; 2: ``L = det(I - K G) - 1``.
    stiffness : float
        K in N/m.
    period : float
        T in s.
    open_loop_outside : int
        P, the poles of the loop at K = 0 outside the unit circle.
    open_loop_on_circle : int
        Poles of the loop at K = 0 on the unit circle (to 1e-9; a free mass's z = 1).
    """

    frequency_hz: np.ndarray
    loop: np.ndarray
    ports: int
    stiffness: float
    period: float
    open_loop_outside: int
    open_loop_on_circle: int

    @property
    def circle_bound(self) -> bool:
        """Whether the circle criterion's line Re L = -1 applies (one port, P = 0)."""
        return self.ports == 1 and self.open_loop_outside == 0

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"frequency_hz": self.frequency_hz, "loop_re": self.loop.real,
                         "loop_im": self.loop.imag, "ports": self.ports,
                         "stiffness_N_per_m": self.stiffness, "period_s": self.period,
                         "open_loop_outside": self.open_loop_outside,
                         "open_loop_on_circle": self.open_loop_on_circle})

    def to_csv(self, path: Any) -> None:
        """Write frequency_hz, loop_re, loop_im, magnitude_db, phase_deg per frequency."""
        # a floor against division by zero / rounding, far below the answer's own accuracy
        mag = 20 * np.log10(np.maximum(np.abs(self.loop), 1e-300))
        write_csv(path, ["frequency_hz", "loop_re", "loop_im", "magnitude_db", "phase_deg"],
                  zip(self.frequency_hz, self.loop.real, self.loop.imag, mag,
                      np.degrees(np.angle(self.loop)), strict=True))

    def plot(self, ax: Any = None, kind: str = "both") -> Any:
        """Nyquist (``kind="nyquist"``), Bode (``"bode"``: magnitude and phase) or all three
        panels (``"both"``, default); ``ax`` one axes or a sequence of 2 / 3."""
        from hapstab.plotting.margins import plot_frequency_view

        return plot_frequency_view(self, ax=ax, kind=kind)


def _fmt(x: float | None, unit: str, digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "not found"
    if math.isinf(x):
        return "unbounded"
    return f"{x:.{digits}g} {unit}".strip()


@dataclass(frozen=True)
class MarginResult(Result):
    """How far the loop's delay, stiffness and virtual damping can move from their values
    with the loop still stable (see :mod:`hapstab.analysis.margins` for what each rests
    on). A bound that the search did not reach is ``None`` (JSON ``null``) and said in
    ``reason``.

    Attributes
    ----------
    verdict : str
        The loop's own verdict at K (:func:`hapstab.stability`).
    stiffness, period, delay_s : float
        K (N/m), T (s), the loop's delay t_d (s; teleoperation: master -> slave).
    delay_margin_samples : float
        Largest extra delay / T with the loop stable for every extra delay in [0, it].
    delay_unstable_samples : float or None
        The first extra delay found not stable (the bracket's other end).
    delay_searched_samples : float
        How far the delay search went.
    stiffness_interval : (float, float) or None
        The stable interval (K_lo, K_hi] containing K, N/m (exact, safe ends).
    damping : float
        The loop's virtual damping B, N*s/m.
    damping_interval : (float or None, float or None)
        B_lo, B_hi in N*s/m (None: not found not stable within the search).
    view : FrequencyView or None
        The Nyquist / Bode view (None when K cannot be varied or K = 0).
    reason : str
        What each margin is and anything not computed.
    note : str
        A note on the whole run (the friction-free model), said once.
    """

    verdict: str
    stiffness: float
    period: float
    delay_s: float
    delay_margin_samples: float
    delay_unstable_samples: float | None
    delay_searched_samples: float
    stiffness_interval: tuple[float, float] | None
    damping: float
    damping_interval: tuple[float | None, float | None]
    view: FrequencyView | None = field(repr=False, default=None)
    reason: str = ""
    note: str = ""

    @property
    def delay_margin_s(self) -> float:
        """The delay margin in seconds."""
        return self.delay_margin_samples * self.period

    @property
    def stiffness_margin(self) -> float | None:
        """K_hi / K: the factor by which K can grow (the gain margin in K)."""
        iv = self.stiffness_interval
        return None if iv is None or self.stiffness <= 0 else iv[1] / self.stiffness

    def to_dict(self) -> dict[str, Any]:
        iv = self.stiffness_interval
        lo, hi = self.damping_interval
        unst = self.delay_unstable_samples
        return jsonable({
            "verdict": self.verdict, "stiffness_N_per_m": self.stiffness,
            "period_s": self.period, "delay_s": self.delay_s,
            "delay_margin_s": self.delay_margin_s,
            "delay_margin_samples": self.delay_margin_samples,
            "delay_unstable_s": None if unst is None else unst * self.period,
            "delay_searched_s": self.delay_searched_samples * self.period,
            "stiffness_min_N_per_m": None if iv is None else iv[0],
            "stiffness_max_N_per_m": None if iv is None else iv[1],
            "stiffness_margin_N_per_m": None if iv is None else iv[1] - self.stiffness,
            "stiffness_margin_ratio": self.stiffness_margin,
            "damping_N_s_per_m": self.damping, "damping_min_N_s_per_m": lo,
            "damping_max_N_s_per_m": hi, "reason": self.reason,
            **({"friction_note": self.note} if self.note else {})})

    def rows(self) -> list[tuple[str, str]]:
        """The margins as (name, value with unit) pairs, rounded to 4 digits (a grid and
        bisection bracket is finer; the certified K_max is given to 6)."""
        iv = self.stiffness_interval
        lo, hi = self.damping_interval
        unst = self.delay_unstable_samples
        d = (f"{_fmt(self.delay_margin_s * 1e3, 'ms')} ({self.delay_margin_samples:.4g} "
             "samples)" + ("" if unst is not None else
                           f", no loss up to +{self.delay_searched_samples:g} samples"))
        return [("verdict at K", self.verdict), ("stiffness K", _fmt(self.stiffness, "N/m", 6)),
                ("delay margin", d),
                ("stiffness range", "n/a" if iv is None else
                 f"({iv[0]:.6g}, {iv[1]:.6g}] N/m" + (
                     f", K can grow x{self.stiffness_margin:.4g}" if self.stiffness_margin
                     else "")),
                ("damping range", f"[{_fmt(lo, '')}, {_fmt(hi, '')}] N*s/m around B = "
                                  f"{self.damping:.4g} N*s/m")]

    def to_csv(self, path: Any) -> None:
        """Write the margins as name, value rows (the keys of :meth:`to_dict`)."""
        write_csv(path, ["name", "value"],
                  ((k, v) for k, v in self.to_dict().items() if not isinstance(v, dict)))

    def plot(self, ax: Any = None) -> Any:
        """The Nyquist and Bode views (:meth:`FrequencyView.plot`), titled with the
        margins; an empty axes saying why when there is no view."""
        from hapstab.plotting.margins import plot_margins

        return plot_margins(self, ax=ax)
