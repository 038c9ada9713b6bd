"""The Z-width of a haptic device (Colgate and Brown 1994): the virtual walls (K, B)
it renders passively, the ones it renders stably, and the impedance a wall actually
displays over frequency.

* **Passive**: for each virtual damping B the largest K for which the device side is
  passive (Colgate-Schenkel, :func:`~hapstab.analysis.conditions.passivity.critical_stiffness_passivity`):
  exact for any delay and for a filtered velocity estimate. Passivity is what holds
  against *any* passive operator, so it is the Z-width in Colgate and Brown's sense.
  With encoder quantisation Delta and Coulomb friction f_c, Abbott and Okamura's
  condition adds K <= 2 f_c / Delta (where its assumptions hold: B = 0, no delay;
  :mod:`hapstab.analysis.nonlinear.nonlinear_passivity`).
* **Stable**: for each B the exact K_max with the loop's own operator
  (:func:`~hapstab.analysis.design.regions.kmax_over_B`), the end of the stable interval that
  starts at 0. A wall between the two lines is stable with this operator and not
  guaranteed with another.
* **Displayed impedance** of the wall at one (K, B): the force the hold applies at the
  frequency of a sinusoidal motion, per unit position, is (first harmonic, aliases
  left out)

      F/X = H(e^{jwT}) e^{-jnwT} (1 - e^{-jwT}) / (jwT),

  whose real part is the stiffness the operator feels and imaginary part over w the
  damping (at low frequency K and B - K (n + 1/2) T: the delay and the hold take
  damping away).

References
----------
J. E. Colgate and J. M. Brown, "Factors affecting the Z-width of a haptic display",
IEEE ICRA 1994; J. E. Colgate and G. G. Schenkel, J. Robotic Systems 14(1), 1997 (the
paper's eq. 1); J. J. Abbott and A. M. Okamura, "Effects of position quantization and
sampling rate on virtual-wall passivity", IEEE Trans. Robotics 21(5), 2005.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from hapstab.analysis.conditions.passivity import critical_stiffness_passivity
from hapstab.analysis.design.kb_plane import check_equal_gains, with_gains
from hapstab.analysis.design.regions import kmax_over_B
from hapstab.analysis.nonlinear.nonlinear_passivity import abbott_okamura
from hapstab.errors import AnalysisError, ArgumentTypeError, check_real
from hapstab.models.loops import HapticLoop, headline, whole_delay
from hapstab.results import Result, jsonable, write_csv

__all__ = ["ZWidthResult", "zwidth", "displayed_impedance"]


def displayed_impedance(loop: HapticLoop, frequencies_hz: Any) -> tuple[np.ndarray, np.ndarray]:
    """The stiffness and damping a virtual wall displays at each frequency.

    Parameters
    ----------
    loop : HapticLoop
        Its controller (any H(z), at the loop's own K) and whole-sample delay.
    frequencies_hz : array of float
        In (0, Nyquist].

    Returns
    -------
    stiffness : array
        Re(F/X) in N/m.
    damping : array
        Im(F/X)/w in N*s/m.

    Raises
    ------
    AnalysisError
        A fractional delay, or a frequency outside (0, 1/(2T)].

    References
    ----------
    Colgate and Brown 1994 (the displayed impedance); the module docstring.
    """
    T, n = loop.period, whole_delay(loop, "the displayed impedance")
    f = np.asarray(frequencies_hz, float)
    if f.size == 0 or not np.all((f > 0) & (f <= 0.5 / T * (1 + 1e-12))):  # Nyquist, rounded
        raise AnalysisError(f"frequencies = {f.min() if f.size else '[]'}..: must be in "
                            f"(0, {0.5 / T:g}] Hz (up to the Nyquist frequency)")
    w = 2 * np.pi * f
    z = np.exp(1j * w * T)
    num, den = loop.controller.transfer(T)
    # (1 - e^{-jwT})/(jwT) = e^{-jwT/2} sin(wT/2)/(wT/2): no cancellation at small wT
    hold = np.exp(-0.5j * w * T) * np.sinc(w * T / (2 * np.pi))
    fx = np.polyval(num, z) / np.polyval(den, z) * z ** (-n) * hold
    return fx.real, fx.imag / w


@dataclass(frozen=True)
class ZWidthResult(Result):
    """Passive and stable virtual walls over B, and the displayed impedance at one wall.

    Attributes
    ----------
    B_rows : array
        Virtual dampings in N*s/m.
    K_passive : array
        Largest passive K at each B (N/m; 0: not passive for any K).
    K_stable : array
        Exact K_max at each B with the loop's operator (N/m).
    K_quantised : float or None
        Abbott and Okamura's passive limit with friction and quantisation at B = 0
        (N/m), when a resolution was given.
    nonlinear_reason : str
        How ``K_quantised`` was found, or why it was not.
    frequencies_hz, displayed_stiffness, displayed_damping : arrays
        The displayed impedance at (``K_at``, ``B_at``): N/m and N*s/m.
    K_at, B_at : float
        The wall whose impedance is shown.
    K_passive_B0, K_stable_B0 : float
        The largest passive K and the exact K_max at B = 0 exactly (not the nearest row).
    K_window : (float, float)
        The stiffness range drawn, N/m.
    period : float
        T in s.
    headline : str
        The loop in words.
    """

    B_rows: np.ndarray = field(repr=False)
    K_passive: np.ndarray = field(repr=False)
    K_stable: np.ndarray = field(repr=False)
    K_quantised: float | None
    nonlinear_reason: str
    frequencies_hz: np.ndarray = field(repr=False)
    displayed_stiffness: np.ndarray = field(repr=False)
    displayed_damping: np.ndarray = field(repr=False)
    K_at: float
    B_at: float
    K_window: tuple[float, float]
    period: float
    headline: str
    K_passive_B0: float = float("nan")
    K_stable_B0: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return jsonable({
            "loop": self.headline, "period_s": self.period,
            "rows": {"virtual_damping_N_s_per_m": self.B_rows,
                     "passive_up_to_N_per_m": self.K_passive,
                     "stable_up_to_N_per_m": self.K_stable},
            "passive_up_to_at_B0_N_per_m": self.K_passive_B0,
            "stable_up_to_at_B0_N_per_m": self.K_stable_B0,
            "quantised_passive_up_to_N_per_m": self.K_quantised,
            "nonlinear_reason": self.nonlinear_reason,
            "displayed": {"stiffness_N_per_m": self.K_at, "virtual_damping_N_s_per_m": self.B_at,
                          "frequency_Hz": self.frequencies_hz,
                          "displayed_stiffness_N_per_m": self.displayed_stiffness,
                          "displayed_damping_N_s_per_m": self.displayed_damping}})

    def to_csv(self, path: Any) -> None:
        """Write the rows: virtual_damping, passive_up_to, stable_up_to.

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        write_csv(path, ["virtual_damping_N_s_per_m", "passive_up_to_N_per_m",
                         "stable_up_to_N_per_m"],
                  ([repr(float(b)), repr(float(p)), repr(float(s))]
                   for b, p, s in zip(self.B_rows, self.K_passive, self.K_stable, strict=True)))

    def plot(self, ax: Any = None) -> Any:
        """The (K, B) plane with the passive and stable walls, and the displayed
        impedance over frequency (two panels).

        Parameters
        ----------
        ax : pair of matplotlib Axes, optional
            Where to draw; a new figure when omitted.

        Returns
        -------
        array of two matplotlib Axes
        """
        from hapstab.plotting.zwidth import plot_zwidth
        return plot_zwidth(self, ax)


def _rows(loop: HapticLoop, Bs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K_passive, K_stable) at each B."""
    stable = np.array([s.kmax for s in kmax_over_B(loop, Bs)])
    passive = np.array([critical_stiffness_passivity(with_gains(loop, 1.0, float(B)))
                        .critical_stiffness for B in Bs])
    return passive, stable


def _quantised(loop: HapticLoop, coulomb_friction_N: Any, resolution_m: Any
               ) -> tuple[float | None, str]:
    """Abbott and Okamura's limit at B = 0, or why it does not apply."""
    if resolution_m is None:
        return None, "no encoder resolution given: the linear limits only"
    wall = cast(HapticLoop, with_gains(loop, 1.0, 0.0))
    try:
        r = abbott_okamura(wall, coulomb_friction_N=coulomb_friction_N, resolution_m=resolution_m)
    except AnalysisError as e:
        return None, f"Abbott-Okamura does not apply: {e}"
    return r.critical_stiffness, r.reason


def zwidth(loop: HapticLoop, K: tuple[float, float], B: tuple[float, float],
           resolution: int = 60, *, at: tuple[float, float] | None = None,
           frequencies_hz: Any = None, coulomb_friction_N: float | None = None,
           resolution_m: float | None = None) -> ZWidthResult:
    """The Z-width of a haptic device: passive and stable virtual walls, and the
    impedance one of them displays (see the module docstring).

    Parameters
    ----------
    loop : HapticLoop
        The device, its operator, T, the delay and the controller form (SpringDamper or
        FilteredSpringDamper; its own K and B are replaced).
    K : (float, float)
        The stiffness window of the plot in N/m.
    B : (float, float)
        The virtual dampings scanned, in N*s/m.
    resolution : int
        Rows in B (2..2000).
    at : (K, B), optional
        The wall whose displayed impedance is computed; default the loop's own, or, when
        that is no wall (K = B = 0: a flat zero), the passive limit at B = 0.
    frequencies_hz : array, optional
        Default 200 points from 0.1 Hz to Nyquist, logarithmic.
    coulomb_friction_N, resolution_m : float, optional
        For Abbott and Okamura's limit at B = 0 (friction default: the device's).

    Returns
    -------
    ZWidthResult

    Raises
    ------
    AnalysisError
        Not an HVE, unequal or non-spring-damper controllers, bad windows.

    References
    ----------
    Colgate and Brown 1994; Colgate and Schenkel 1997; Abbott and Okamura 2005.
    """
    if getattr(loop, "kind", None) != "hve":
        raise AnalysisError("zwidth: the Z-width is a device's (an hve loop)")
    check_equal_gains(loop)
    if isinstance(resolution, bool) or not isinstance(resolution, int) or not 2 <= resolution <= 2000:
        raise ArgumentTypeError(f"resolution = {resolution!r}: must be a whole number in [2, 2000]")
    (k0, k1), (b0, b1) = (tuple(check_real(n, v) for v in w) for n, w in (("K", K), ("B", B)))
    if not (0 <= k0 < k1 and b0 < b1):
        raise AnalysisError(f"K = {K}, B = {B}: need 0 <= K_lo < K_hi and B_lo < B_hi")
    Bs = np.linspace(b0, b1, resolution)
    passive, stable = _rows(loop, Bs)
    kq, why = _quantised(loop, coulomb_friction_N, resolution_m)
    (p0,), (s0,) = _rows(loop, np.array([0.0]))
    c = loop.controller
    K_at, B_at = ((getattr(c, "stiffness", 0.0), getattr(c, "damping", 0.0)) if at is None
                  else (check_real("at K", at[0]), check_real("at B", at[1])))
    if at is None and K_at == 0 and B_at == 0 and 0 < p0 < math.inf:
        K_at = float(p0)
    T = loop.period
    f = np.geomspace(min(0.1, 0.05 / T), 0.5 / T, 200) if frequencies_hz is None else frequencies_hz
    ks, bs = displayed_impedance(cast(HapticLoop, with_gains(loop, K_at, B_at)), f)
    return ZWidthResult(Bs, passive, stable, kq, why, np.asarray(f, float), ks, bs,
                        float(K_at), float(B_at), (k0, k1), T, headline(loop),
                        float(p0), float(s0))
