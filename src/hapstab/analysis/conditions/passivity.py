"""Exact passivity of the sampled-data device + virtual environment (Colgate and
Schenkel 1997), and its multiport form for PEB teleoperation.

A device with viscous damping b, coupled to a discrete H(z) (with n samples of
delay) through a sampler and a zero-order hold, is passive if and only if

    b >= (T/2) Re{(1 - e^{-jwT}) H(e^{jwT}) e^{-jnwT}} / (1 - cos wT)

for every w in (0, pi/T]. With passive operator and environment impedances,
passivity implies stability, so the passivity K_max never exceeds the exact one.
(1 - e^{-jwT})/(1 - cos wT) is evaluated as j e^{-jwT/2}/sin(wT/2): no
cancellation as w -> 0.

For PEB the same energy argument (the ZOH force u_k does work u_k^T(x_{k+1} - x_k)
over a sample, the damper dissipates at least (x_{k+1} - x_k)^T b (x_{k+1} - x_k)/T)
gives the matrix condition

    D diag(b_m, b_s) - (T/2) Herm{(1 - e^{-jwT}) D H(e^{jwT})} / (1 - cos wT) >= 0

with H of eq. (21) and the port weights D of :func:`hapstab.analysis.conditions.circle.port_scaling`
(D = I for C_m = C_s); this is sufficient for stability with passive
terminations. It coincides with the forward-difference circle criterion: the
paper's "worst-case approximation" is exactly sampled-data passivity.

References
----------
J. E. Colgate and G. G. Schenkel, "Passivity of a class of sampled-data
systems: application to haptic interfaces", J. Robotic Systems 14(1), 1997
(the paper's [4]; eq. (1)); A. Jazayeri and M. Tavakoli, IEEE Trans. Haptics
6(3), 2012 (the paper's [9]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.analysis.conditions.frequency_grid import (
    affine_kmax_rows,
    min_eig,
    refine_minimum,
    theta_grid,
)
from hapstab.engine.device_side import DeviceSide, device_side
from hapstab.errors import AnalysisError
from hapstab.models.controllers import has_stiffness
from hapstab.models.loops import HapticLoop, TeleoperationLoop, require_loop, whole_delay
from hapstab.results import CriticalStiffnessResult, Result, jsonable
from hapstab.tolerances import DIVISOR_FLOOR, PSD_SLACK, ROOT_ON_CIRCLE

__all__ = ["kmax_parts", "PassivityResult", "sampled_passivity", "critical_stiffness_passivity"]


@dataclass(frozen=True)
class PassivityResult(Result):
    """Verdict of the exact sampled-data passivity test.

    Attributes
    ----------
    passive : bool
    margin : float
        min over w of the smallest eigenvalue of the passivity matrix, in N*s/m:
        how much damping is to spare (negative: missing).
    worst_frequency_rad_s, worst_frequency_hz : float
        Where the margin is smallest.
    failed_condition : str or None
        ``"colgate-schenkel"`` when not passive.
    reason : str
        The verdict in words.
    period : float
        Sampling period T in s (converts rad/sample to rad/s).
    curve_frequency_hz : numpy.ndarray or None
        With ``curve_points``: frequencies in Hz from (almost) 0 to the Nyquist frequency
        1/(2T), evenly spaced (the first is the w -> 0 limit, see
        :func:`hapstab.analysis.conditions.frequency_grid.theta_grid`); None otherwise.
    curve_margin : numpy.ndarray or None
        The margin at each of them (the smallest eigenvalue of the passivity matrix,
        N*s/m): the curve whose minimum over all w is ``margin``; None otherwise.
    """

    passive: bool
    margin: float
    worst_frequency_rad_s: float
    worst_frequency_hz: float
    failed_condition: str | None
    reason: str
    period: float
    curve_frequency_hz: np.ndarray | None = None
    curve_margin: np.ndarray | None = None

    @property
    def verdict(self) -> str:
        return "passive" if self.passive else "not passive"

    def to_dict(self) -> dict[str, Any]:
        d = {"verdict": self.verdict, "passive": self.passive, "margin": self.margin,
             "worst_frequency_rad_s": self.worst_frequency_rad_s,
             "worst_frequency_hz": self.worst_frequency_hz,
             "failed_condition": self.failed_condition, "reason": self.reason,
             "period_s": self.period}
        if self.curve_frequency_hz is not None and self.curve_margin is not None:
            d["margin_curve"] = {"frequency_hz": self.curve_frequency_hz,
                                 "margin": self.curve_margin}
        return jsonable(d)


def _side(loop: Any) -> DeviceSide:
    """The device side, after refusing what the test is not derived for: a delay that
    is not n whole samples both ways, or a controller pole on or outside the circle."""
    require_loop(loop)
    whole_delay(loop, "sampled-data passivity")
    side = device_side(loop, "sampled-data passivity")
    for ch in side.channels:
        if ch.controller.admits("eq23"):        # eq. (23): its one pole is z = 0
            continue
        den = ch.controller.transfer(side.period_s)[1]
        poles = np.roots(den) if len(den) > 1 else np.zeros(0)
        if np.any(np.abs(poles) >= 1.0 - ROOT_ON_CIRCLE):     # on the circle to np.roots' accuracy
            raise AnalysisError("passivity: the controller H(z) has a pole on or outside the unit "
                                "circle; the Colgate-Schenkel test needs a stable H(z)")
    return side


def _parts(side: DeviceSide, theta: np.ndarray, D: tuple[float, ...], part: str | None
           ) -> tuple[np.ndarray, np.ndarray]:
    """(damping matrix D diag(b), sampled part W = -(T/2) Herm{f D Hc}) with
    f = (1 - e^{-jw})/(1 - cos w) and the controllers' whole H (``part`` None),
    their part per unit K ("K") or at K = 0 ("B")."""
    f = 1j * np.exp(-0.5j * theta) / np.sin(theta / 2)  # (1 - e^{-jw})/(1 - cos w)
    w = np.asarray(D)[None, :, None]
    X = f[:, None, None] * w * side.controller_matrix(theta, part)
    W = -(side.period_s / 2) * (X + np.conj(np.swapaxes(X, 1, 2))) / 2
    Db = np.broadcast_to(np.diag(np.asarray(D) * side.damping), W.shape).astype(complex)
    return Db, W


def sampled_passivity(loop: HapticLoop | TeleoperationLoop, scaling: str | None = "auto",
                      curve_points: int = 0) -> PassivityResult:
    """Exact sampled-data passivity of the device(s) + discrete controller(s).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Any controller (SpringDamper or a stable DiscreteController). The
        terminations do not enter: passivity is a property of the device side.
    scaling : {"auto", None}
        PEB port weighting (see :func:`hapstab.analysis.conditions.circle.port_scaling`).
    curve_points : int
        Also return the margin over frequency at this many evenly spaced frequencies from
        the w -> 0 limit to the Nyquist frequency (0: none; at most
        :data:`MAX_CURVE_POINTS`). Its minimum is ``margin`` up to the grid's spacing: the
        reported minimum is refined between grid points.

    Returns
    -------
    PassivityResult

    Raises
    ------
    AnalysisError
        If H(z) has a pole on or outside the unit circle, or ``curve_points`` is not a
        whole number in 0...:data:`MAX_CURVE_POINTS`.

    References
    ----------
    Colgate and Schenkel 1997; the paper, eq. (1).
    """
    points = _curve_points(curve_points)
    side = _side(loop)
    T, D = side.period_s, side.port_weights(scaling)

    def margin(t: np.ndarray) -> np.ndarray:
        Db, W = _parts(side, t, D, None)
        return min_eig(Db + W)

    th = theta_grid(side.oscillations)
    t_min, m = refine_minimum(margin, th, margin(th))
    scale = float(np.max(np.abs(_parts(side, th, D, None)[1]))) + DIVISOR_FLOOR
    ok = m >= -PSD_SLACK * scale  # rounding slack relative to the sampled part's size
    where = f"w = {t_min / T:.6g} rad/s ({t_min / (2 * math.pi * T):.6g} Hz)"
    reason = (f"passive (Colgate-Schenkel): damping to spare {m:.6g} N*s/m, least at {where}" if ok
              else f"not passive (Colgate-Schenkel): {-m:.6g} N*s/m of damping missing at {where}")
    curve = None
    if points:                     # evenly spaced, the first at the w -> 0 limit (theta_grid's)
        curve = np.linspace(0.0, np.pi, points)
        curve[0] = theta_grid(side.oscillations)[0]
    return PassivityResult(bool(ok), float(m), t_min / T, t_min / (2 * math.pi * T),
                           None if ok else "colgate-schenkel", reason, T,
                           None if curve is None else curve / (2 * math.pi * T),
                           None if curve is None else margin(curve))


#: The most points a margin curve may have (a curve for a page or a plot needs ~1000).
MAX_CURVE_POINTS = 100_000


def _curve_points(points: Any) -> int:
    """``curve_points`` checked: a whole number in 0...MAX_CURVE_POINTS (1 is refused: a
    curve needs both ends)."""
    if isinstance(points, bool) or not isinstance(points, (int, np.integer)) \
            or not (points == 0 or 2 <= points <= MAX_CURVE_POINTS):
        raise AnalysisError(f"curve_points = {points!r:.40}: must be 0 (no curve) or a whole "
                            f"number of points from 2 to {MAX_CURVE_POINTS}")
    return int(points)


def critical_stiffness_passivity(loop: HapticLoop | TeleoperationLoop,
                                 approximation: str | None = None,
                                 scaling: str | None = "auto") -> CriticalStiffnessResult:
    """Largest K for which the sampled-data device + controller is passive.

    The passivity matrix is affine in K, so K_max is the minimum over w of its
    PSD limit (see :func:`~hapstab.analysis.conditions.frequency_grid.psd_limit`), on a
    dense grid refined by golden section. At n = 0 this is exactly eq. (1):
    ``K_max = 2(b - |B|)/T``, for either sign of B. Negative virtual damping is handled like any other: for
    B <= 0 the limit binds at w -> 0 and equals eq. (18), ``(b + B)/(T/2 + t_d)``;
    when the device damping does not cover it (e.g. ``B < -b``) K_max = 0 and the
    reason says how much damping is missing at K = 0.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Controllers with a stiffness (SpringDamper, FilteredSpringDamper,
        AffineController: the passivity matrix is affine in K for each); for PEB, K
        is the master's, K_s/K_m kept.
    approximation : None
        Not applicable (passivity is exact); given only to reject it clearly.
    scaling : {"auto", None}
        PEB port weighting.

    Returns
    -------
    CriticalStiffnessResult
        ``method = "passivity"``; ``crossing_frequency_hz`` is where passivity
        is first lost.

    Raises
    ------
    AnalysisError
        Approximation given, or a controller that is not a SpringDamper.
    """
    if approximation is not None:
        raise AnalysisError(f"approximation = {approximation!r}: applies to method 'circle' only; "
                            "'passivity' is exact")
    side = _stiffness_side(loop)
    T, D = side.period_s, side.port_weights(scaling)
    # the loop's own K_max: one row of the batched minimum at its own B (B = 1 times the
    # controllers' part; PSD_SLACK: the rounding slack on A >= 0, relative to |A|)
    Ks, ts = affine_kmax_rows(_affine_parts(side, D), np.ones(1), side.oscillations, PSD_SLACK)
    t_min, K = float(ts[0]), float(Ks[0])
    fin = math.isfinite(K)
    head = ("sampled-data passivity (Colgate-Schenkel 1997"
            + (", multiport" if side.ports > 1 else "") + "): ")
    if K > 0:
        reason = head + "passive for K <= K_max" + (f"; binds at w = {t_min / T:.6g} rad/s" if fin
                                                    else " = inf")
    else:  # already at K = 0 the damping does not cover the virtual damping (e.g. B < -b)
        th = theta_grid(side.oscillations)
        Db, WB = _parts(side, th, D, "B")
        m0 = min_eig(Db + WB)
        i = int(np.argmin(m0))
        reason = head + (f"not passive for any K >= 0: at K = 0, {-m0[i]:.6g} N*s/m of damping is "
                         f"already missing at w = {th[i] / T:.6g} rad/s (the virtual damping "
                         "takes more than the device damping provides)")
    return CriticalStiffnessResult(
        float(K), "passivity", ((0.0, float(K)),) if K > 0 else (), reason, T,
        whole_delay(loop, "sampled-data passivity"),
        t_min / (2 * math.pi * T) if fin else float("nan"),
        {"worst_frequency_rad_s": t_min / T if fin else float("nan"),
         "port_scaling": list(D)})


def _stiffness_side(loop: Any) -> DeviceSide:
    """:func:`_side`, refusing also controllers without a stiffness to vary."""
    side = _side(loop)
    if not all(has_stiffness(ch.controller) for ch in side.channels):
        raise AnalysisError("critical stiffness: needs SpringDamper controller(s) (or "
                            "FilteredSpringDamper / AffineController: a stiffness to vary)")
    if side.ratios is None:
        raise AnalysisError("controllers: the master's stiffness is 0 and the slave's is not, so "
                            "K_s/K_m is undefined; give the master a stiffness > 0 to vary K")
    return side


def _affine_parts(side: DeviceSide, D: tuple[float, ...]) -> Any:
    """theta -> (D diag(b), the sampled part at K = 0, the sampled part per unit K): the
    passivity matrix at K is the first two plus K times the third."""
    def parts(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        Db, WB = _parts(side, t, D, "B")
        return Db, WB, _parts(side, t, D, "K")[1]
    return parts


def kmax_parts(loop: HapticLoop | TeleoperationLoop, scaling: str | None = "auto") -> Any:
    """What :func:`critical_stiffness_passivity` minimises over, for batched callers
    (the K-B region's rows): ``(parts, oscillations)``, ``parts(theta) -> (fixed,
    controller, per_K)`` with the passivity matrix ``fixed + controller + K per_K``
    (the controller's part at K = 0 is linear in its virtual damping), and the grid's
    oscillations (:func:`~hapstab.analysis.conditions.frequency_grid.theta_grid`).

    Raises
    ------
    AnalysisError
        Where :func:`critical_stiffness_passivity` refuses the loop.
    """
    side = _stiffness_side(loop)
    return _affine_parts(side, side.port_weights(scaling)), side.oscillations
