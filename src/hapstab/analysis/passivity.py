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

with H of eq. (21) and the port weights D of :func:`hapstab.circle.port_scaling`
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

from hapstab.analysis.circle import port_scaling
from hapstab.analysis.sweeps import min_eig, psd_limit, refine_minimum, theta_grid
from hapstab.errors import AnalysisError
from hapstab.models.controllers import SpringDamper, spring_damper
from hapstab.models.loops import HapticLoop, TeleoperationLoop, whole_delay
from hapstab.results import CriticalStiffnessResult, Result, jsonable
from hapstab.tolerances import ROOT_ON_CIRCLE

__all__ = ["PassivityResult", "sampled_passivity", "critical_stiffness_passivity"]


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
    """

    passive: bool
    margin: float
    worst_frequency_rad_s: float
    worst_frequency_hz: float
    failed_condition: str | None
    reason: str
    period: float

    @property
    def verdict(self) -> str:
        return "passive" if self.passive else "not passive"

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"verdict": self.verdict, "passive": self.passive, "margin": self.margin,
                         "worst_frequency_rad_s": self.worst_frequency_rad_s,
                         "worst_frequency_hz": self.worst_frequency_hz,
                         "failed_condition": self.failed_condition, "reason": self.reason,
                         "period_s": self.period})


def _h_of(c: Any, theta: np.ndarray, T: float, unit: str | None = None) -> np.ndarray:
    """H(e^{j theta}); ``unit="K"``/``"B"`` gives the SpringDamper's K- or B-part."""
    if isinstance(c, SpringDamper):
        one_minus = 2j * np.sin(theta / 2) * np.exp(-0.5j * theta)  # 1 - e^{-j theta}
        k = 1.0 if unit == "K" else (0.0 if unit == "B" else c.stiffness)
        B = 0.0 if unit == "K" else c.damping
        return k + B * one_minus / T
    num, den = c.transfer(T)
    poles = np.roots(den) if len(den) > 1 else np.zeros(0)
    if np.any(np.abs(poles) >= 1.0 - ROOT_ON_CIRCLE):     # on the circle to np.roots' accuracy
        raise AnalysisError("passivity: the controller H(z) has a pole on or outside the unit "
                            "circle; the Colgate-Schenkel test needs a stable H(z)")
    z = np.exp(1j * theta)
    return np.polyval(num, z) / np.polyval(den, z)


def _parts(loop: HapticLoop | TeleoperationLoop, theta: np.ndarray, scaling: str | None,
           unit: str | None) -> tuple[np.ndarray, np.ndarray]:
    """(damping matrix D diag(b), sampled part W = -(T/2) Herm{...}/(1 - cos)) with the
    controllers' full H (unit None), K-part per unit master K ("K") or B-part ("B")."""
    T, n = loop.period, whole_delay(loop, "sampled-data passivity")
    f = 1j * np.exp(-0.5j * theta) / np.sin(theta / 2)  # (1 - e^{-jw})/(1 - cos w)
    d = np.exp(-1j * n * theta)
    if isinstance(loop, HapticLoop):
        h = d * _h_of(loop.controller, theta, T, unit)
        return np.full(theta.size, loop.device.damping), -(T / 2) * np.real(f * h)
    D = port_scaling(loop, scaling)
    cm, cs = loop.master_controller, loop.slave_controller
    hm, hs = _h_of(cm, theta, T, unit), _h_of(cs, theta, T, unit)
    if unit == "K" and isinstance(cm, SpringDamper):  # per unit master K, K_s/K_m kept
        ks = spring_damper(cs, "slave_controller").stiffness
        hs = hs * (ks / cm.stiffness if cm.stiffness > 0 else 1.0)
    H = np.zeros((theta.size, 2, 2), complex)
    H[:, 0, 0], H[:, 0, 1] = D[0] * hm, -D[0] * d * hm
    H[:, 1, 0], H[:, 1, 1] = -D[1] * d * hs, D[1] * hs
    X = f[:, None, None] * H
    W = -(T / 2) * (X + np.conj(np.swapaxes(X, 1, 2))) / 2
    Db = np.zeros((theta.size, 2, 2), complex)
    Db[:, 0, 0], Db[:, 1, 1] = D[0] * loop.master.damping, D[1] * loop.slave.damping
    return Db, W


def _check(loop: Any) -> None:
    if not isinstance(loop, (HapticLoop, TeleoperationLoop)):
        raise AnalysisError(f"loop = {loop!r}: must be a HapticLoop or a TeleoperationLoop")


def sampled_passivity(loop: HapticLoop | TeleoperationLoop, scaling: str | None = "auto"
                      ) -> PassivityResult:
    """Exact sampled-data passivity of the device(s) + discrete controller(s).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Any controller (SpringDamper or a stable DiscreteController). The
        terminations do not enter: passivity is a property of the device side.
    scaling : {"auto", None}
        PEB port weighting (see :func:`hapstab.circle.port_scaling`).

    Returns
    -------
    PassivityResult

    Raises
    ------
    AnalysisError
        If H(z) has a pole on or outside the unit circle.

    References
    ----------
    Colgate and Schenkel 1997; the paper, eq. (1).
    """
    _check(loop)
    T = loop.period

    def margin(t: np.ndarray) -> np.ndarray:
        Db, W = _parts(loop, t, scaling, None)
        return min_eig(Db + W)

    th = theta_grid(whole_delay(loop, "sampled-data passivity") + 2)
    t_min, m = refine_minimum(margin, th, margin(th))
    scale = float(np.max(np.abs(_parts(loop, th, scaling, None)[1]))) + 1e-300
    ok = m >= -1e-12 * scale  # rounding slack relative to the sampled part's size
    where = f"w = {t_min / T:.6g} rad/s ({t_min / (2 * math.pi * T):.6g} Hz)"
    reason = (f"passive (Colgate-Schenkel): damping to spare {m:.6g} N*s/m, least at {where}" if ok
              else f"not passive (Colgate-Schenkel): {-m:.6g} N*s/m of damping missing at {where}")
    return PassivityResult(bool(ok), float(m), t_min / T, t_min / (2 * math.pi * T),
                           None if ok else "colgate-schenkel", reason, T)


def critical_stiffness_passivity(loop: HapticLoop | TeleoperationLoop,
                                 approximation: str | None = None,
                                 scaling: str | None = "auto") -> CriticalStiffnessResult:
    """Largest K for which the sampled-data device + controller is passive.

    The passivity matrix is affine in K, so K_max is the minimum over w of its
    PSD limit (see :func:`hapstab.frequency.psd_limit`), on a dense grid refined
    by golden section. At n = 0 this is exactly eq. (1): ``K_max = 2(b - |B|)/T``,
    for either sign of B. Negative virtual damping is handled like any other: for
    B <= 0 the limit binds at w -> 0 and equals eq. (18), ``(b + B)/(T/2 + t_d)``;
    when the device damping does not cover it (e.g. ``B < -b``) K_max = 0 and the
    reason says how much damping is missing at K = 0.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        SpringDamper controller(s); for PEB, K is the master's, K_s/K_m kept.
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
    _check(loop)
    if approximation is not None:
        raise AnalysisError(f"approximation = {approximation!r}: applies to method 'circle' only; "
                            "'passivity' is exact")
    ctrls = loop.controllers
    if not all(isinstance(c, SpringDamper) for c in ctrls):
        raise AnalysisError("critical stiffness: needs SpringDamper controller(s)")
    T = loop.period

    def k_of(t: np.ndarray) -> np.ndarray:
        Db, WB = _parts(loop, t, scaling, "B")
        _, WK = _parts(loop, t, scaling, "K")
        A = Db + WB
        tol = 1e-12 * np.abs(A).reshape(t.size, -1).max(axis=1)  # rounding slack on A >= 0
        return psd_limit(A, WK, tol)

    th = theta_grid(whole_delay(loop, "sampled-data passivity") + 2)
    t_min, K = refine_minimum(k_of, th, k_of(th))
    fin = math.isfinite(K)
    head = ("sampled-data passivity (Colgate-Schenkel 1997"
            + (", multiport" if loop.kind == "peb" else "") + "): ")
    if K > 0:
        reason = head + "passive for K <= K_max" + (f"; binds at w = {t_min / T:.6g} rad/s" if fin
                                                    else " = inf")
    else:  # already at K = 0 the damping does not cover the virtual damping (e.g. B < -b)
        Db, WB = _parts(loop, th, scaling, "B")
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
         "port_scaling": list(port_scaling(loop, scaling))})
