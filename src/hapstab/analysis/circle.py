"""The paper's method: the circle criterion (Theorem 2.1) applied to the inverse
transfer function G^{-1}(z) of the HVE (eq. 14/15) and of the PEB teleoperator
(eq. 24/30), for each approximation of Z{v/s}.

With a passive operator (and environment), the loop is stable if G^{-1}(z) is
positive real (the paper's argument via Lemma 1). Z{v/s} is approximated by

============  ==================  ==========================
name          X(z) = X_h / V_h     the paper
============  ==================  ==========================
forward       T / (z - 1)          used for (13), (18), (29), (34)
backward      T z / (z - 1)
tustin        (T/2)(z + 1)/(z - 1)
============  ==================  ==========================

Forward difference is the paper's worst case, and it is special: its condition
(iii) is *identical* to the exact sampled-data passivity condition of Colgate and
Schenkel (see :mod:`hapstab.passivity`), so its K_max never exceeds the exact
stability limit with passive terminations. Backward difference and Tustin are
not bounds: at n = 0 they accept every K (Re{z/(z-1)} = 1/2 and
Re{(z+1)/(z-1)} = 0 on the circle), although the loop goes unstable.

References
----------
The paper, Section 3 (eq. 14-18) and Section 4 (eq. 24-34).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hapstab.analysis.positive_real import (
    PositiveRealResult,
    RationalMatrix,
    circle_criterion,
    positive_real,
)
from hapstab.analysis.sweeps import psd_limit, refine_minimum, theta_grid
from hapstab.errors import AnalysisError
from hapstab.models.controllers import SpringDamper, spring_damper
from hapstab.models.loops import HapticLoop, TeleoperationLoop, whole_delay
from hapstab.results import CriticalStiffnessResult

__all__ = ["APPROXIMATIONS", "loop_inverse", "port_scaling", "circle_test",
           "critical_stiffness_circle"]

APPROXIMATIONS = ("forward", "backward", "tustin")


def _approx(approximation: Any) -> str:
    a = str(approximation).strip().lower() if approximation is not None else "forward"
    if a not in APPROXIMATIONS:
        raise AnalysisError(f"approximation = {approximation!r}: unknown; allowed: "
                            + ", ".join(APPROXIMATIONS))
    return a


def _x_poly(a: str, T: float) -> tuple[np.ndarray, np.ndarray]:
    """X(z) = X_h(z)/V_h(z) as (num, den) in z (Section 3)."""
    num = {"forward": [T], "backward": [T, 0.0], "tustin": [T / 2, T / 2]}[a]
    return np.array(num), np.array([1.0, -1.0])


def _x_y(a: str, theta: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """X(e^{jw}) and Y = X (z-1)/(T z) (the B-term factor), without cancellation:
    z - 1 = 2j sin(w/2) e^{jw/2}, never cos(w) - 1."""
    s = np.sin(theta / 2)
    if a == "forward":
        return T * np.exp(-0.5j * theta) / (2j * s), np.exp(-1j * theta)
    if a == "backward":
        return T * np.exp(0.5j * theta) / (2j * s), np.ones_like(theta, dtype=complex)
    return -0.5j * T * np.cos(theta / 2) / s + 0j, (1.0 + np.exp(-1j * theta)) / 2


def _check_kind(loop: Any) -> None:
    if not isinstance(loop, (HapticLoop, TeleoperationLoop)):
        raise AnalysisError(f"loop = {loop!r}: must be a HapticLoop or a TeleoperationLoop")


def port_scaling(loop: HapticLoop | TeleoperationLoop, scaling: str | None = "auto"
                 ) -> tuple[float, ...]:
    """Diagonal port weights D used as D G^{-1}(z) (PEB only).

    With C_m != C_s the residue (25) at z = 1, ``T [[K_m, -K_m], [-K_s, K_s]]``,
    is not Hermitian and G^{-1} is never PR for K > 0. Weighting the master port
    by K_s/K_m makes it Hermitian; stability still follows, because D times a
    diagonal passive termination is passive (the multiplier K of Theorem 2.1
    plays the same role). Equal controllers give D = I, the paper's test.

    Parameters
    ----------
    scaling : {"auto", None}
        ``None``: the paper's literal test (no weighting).
    """
    if isinstance(loop, HapticLoop):
        return (1.0,)
    if scaling not in ("auto", None, "none"):
        raise AnalysisError(f"scaling = {scaling!r}: allowed: 'auto' or None")
    km, ks = _stiffness(loop.master_controller), _stiffness(loop.slave_controller)
    if scaling == "auto" and km > 0 and ks > 0 and km != ks:
        return (ks / km, 1.0)
    return (1.0, 1.0)


def _stiffness(c: Any) -> float:
    return c.stiffness if isinstance(c, SpringDamper) else 0.0


def _h_poly(c: Any, T: float) -> tuple[np.ndarray, np.ndarray]:
    num, den = c.transfer(T)
    return np.asarray(num, float), np.asarray(den, float)


def loop_inverse(loop: HapticLoop | TeleoperationLoop, approximation: str = "forward",
                 scaling: str | None = "auto") -> RationalMatrix:
    """G^{-1}(z): force to velocity inverse of the loop without its terminations.

    HVE, eq. (15) generalised: ``b + z^{-n} H(z) X(z)``. PEB, eq. (24)/(30)
    generalised: ``diag(b_m, b_s) + H(z) X(z)`` with H of eq. (21), any
    C_m, C_s (also :class:`~hapstab.models.DiscreteController`), any n, and the
    port weighting of :func:`port_scaling`.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
    approximation : {"forward", "backward", "tustin"}
    scaling : {"auto", None}

    Returns
    -------
    RationalMatrix
    """
    _check_kind(loop)
    a, T, n = _approx(approximation), loop.period, whole_delay(loop, "the circle criterion")
    xn, xd = _x_poly(a, T)
    zn = np.concatenate([[1.0], np.zeros(n)])  # z^n: the delay z^{-n} moves to the denominator

    def term(c: Any, delayed: bool, sign: float, weight: float) -> tuple[np.ndarray, np.ndarray]:
        hn, hd = _h_poly(c, T)
        num = sign * weight * np.polymul(hn, xn)
        den = np.polymul(hd, xd)
        return num, (np.polymul(den, zn) if delayed else den)

    def plus(b: float, nd: tuple[np.ndarray, np.ndarray], weight: float) -> tuple[np.ndarray, np.ndarray]:
        num, den = nd
        return np.polyadd(weight * b * den, num), den

    if isinstance(loop, HapticLoop):
        num, den = plus(loop.device.damping, term(loop.controller, True, 1.0, 1.0), 1.0)
        return RationalMatrix([[num]], [[den]])
    s1, s2 = port_scaling(loop, scaling)
    cm, cs = loop.master_controller, loop.slave_controller
    g11 = plus(loop.master.damping, term(cm, False, 1.0, s1), s1)
    g22 = plus(loop.slave.damping, term(cs, False, 1.0, s2), s2)
    g12, g21 = term(cm, True, -1.0, s1), term(cs, True, -1.0, s2)
    return RationalMatrix([[g11[0], g12[0]], [g21[0], g22[0]]],
                          [[g11[1], g12[1]], [g21[1], g22[1]]])


def circle_test(loop: HapticLoop | TeleoperationLoop, approximation: str = "forward",
                sector: Any = None, scaling: str | None = "auto") -> PositiveRealResult:
    """The circle-criterion test at the loop's own stiffness.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
    approximation : {"forward", "backward", "tustin"}
    sector : float, sequence of float or None
        Sector [0, k_i] of the termination(s) (operator plus device mass as a
        memoryless nonlinearity, Theorem 2.1): tests ``K^{-1} + G(z)``. ``None``
        (default) is the passive limit: G^{-1}(z) PR (equivalently G(z) PR).
    scaling : {"auto", None}
        Port weighting for PEB, see :func:`port_scaling`.

    Returns
    -------
    PositiveRealResult
        Verdict, failing condition of Definition 1, margin and worst frequency.
    """
    Ginv = loop_inverse(loop, approximation, scaling)
    if sector is None:
        return positive_real(Ginv, loop.period)
    if isinstance(loop, TeleoperationLoop):
        # inverting the 2x2 G^-1 leaves uncancelled factors at z = 1, which root-finding
        # splits into spurious poles off the circle: refuse rather than answer wrongly
        raise AnalysisError("sector: a finite sector is supported for the HVE only; for PEB use the "
                            "passive limit (no sector)")
    return circle_criterion(Ginv.inverse(), sector, loop.period)


# ----------------------------------------------------------------- K_max, fast path
def _hermitian_parts(loop: HapticLoop | TeleoperationLoop, a: str, D: tuple[float, ...],
                     theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hermitian parts of G^{-1} = A + K C at K = 0 (A) and per unit master K (C)."""
    T, n = loop.period, whole_delay(loop, "the circle criterion")
    X, Y = _x_y(a, theta, T)
    d = np.exp(-1j * n * theta)
    if isinstance(loop, HapticLoop):
        B = spring_damper(loop.controller).damping
        return 2 * (loop.device.damping + B * np.real(d * Y)), 2 * np.real(d * X)
    cm = spring_damper(loop.master_controller, "master_controller")
    cs = spring_damper(loop.slave_controller, "slave_controller")
    r = cs.stiffness / cm.stiffness if cm.stiffness > 0 else 1.0  # as with_stiffness keeps it
    s1, s2 = D
    N = theta.size
    A = np.zeros((N, 2, 2), complex)
    C = np.zeros((N, 2, 2), complex)
    A[:, 0, 0] = s1 * (loop.master.damping + cm.damping * Y)
    A[:, 1, 1] = s2 * (loop.slave.damping + cs.damping * Y)
    A[:, 0, 1], A[:, 1, 0] = -s1 * d * cm.damping * Y, -s2 * d * cs.damping * Y
    C[:, 0, 0], C[:, 1, 1] = s1 * X, s2 * r * X
    C[:, 0, 1], C[:, 1, 0] = -s1 * d * X, -s2 * r * d * X
    herm = lambda M: M + np.conj(np.swapaxes(M, 1, 2))  # noqa: E731
    return herm(A), herm(C)


def _affine_kmax(loop: HapticLoop | TeleoperationLoop, parts: Any, oscillations: int
                 ) -> tuple[float, float]:
    """min over w of the PSD limit of A(w) + K C(w): (K_max, worst angle)."""
    def k_of(t: np.ndarray) -> np.ndarray:
        A, C = parts(t)
        tol = 1e-12 * np.abs(A).reshape(t.size, -1).max(axis=1)  # rounding slack on A >= 0
        return psd_limit(A, C, tol)

    th = theta_grid(oscillations)
    return refine_minimum(k_of, th, k_of(th))[::-1]


def _check_stiffness_loop(loop: Any) -> None:
    _check_kind(loop)
    ctrls = ([loop.controller] if isinstance(loop, HapticLoop)
             else [loop.master_controller, loop.slave_controller])
    if not all(isinstance(c, SpringDamper) for c in ctrls):
        raise AnalysisError("critical stiffness: needs SpringDamper controller(s) "
                            "(a DiscreteController has no stiffness to vary)")


def critical_stiffness_circle(loop: HapticLoop | TeleoperationLoop, approximation: str = "forward",
                              sector: Any = None, scaling: str | None = "auto"
                              ) -> CriticalStiffnessResult:
    """Largest K for which the circle criterion proves stability (G^{-1} PR).

    G^{-1} is affine in K, and the set of K where an affine Hermitian matrix is
    PSD is an interval, so K_max = min over w of the PSD limit at w (scalar:
    a ratio; 2x2: the first positive root of det(A + K C), a quadratic). The
    minimum over w is found on a dense grid and refined by golden section.
    Conditions (i)-(ii) hold for every K >= 0 here (poles at z = 0 and a simple
    pole at z = 1 with residue K T times a PSD matrix), except for PEB with
    C_m != C_s and ``scaling=None`` (non-Hermitian residue: K_max = 0).
    Any sign of the virtual damping B: G^-1 is affine in B too, and negative B
    only lowers the Hermitian part; with ``B <= 0`` the forward-difference limit is
    eq. (18) (HVE) resp. (34) (PEB, b_m = b_s) exactly, and 0 when the device
    damping does not cover |B| (the reason says so).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        SpringDamper controller(s); for PEB, K is the master's and K_s/K_m is kept.
    approximation : {"forward", "backward", "tustin"}
        Forward (default) is the paper's worst case and the only one that is a
        stability bound (see the module notes).
    sector : float, sequence of float or None
        Finite sector bound(s) k_i of Theorem 2.1: K_max of ``K^{-1} + G`` PR,
        found by bracketing and bisection of :func:`circle_test` (bisection to
        1e-6 relative; the PR test of G = (G^{-1})^{-1} itself resolves about
        1e-4 relative, because Re G vanishes like w^2 as w -> 0). Never below
        the passive limit. ``None``: passive limit (fast, exact up to rounding).
    scaling : {"auto", None}
        PEB port weighting, see :func:`port_scaling`.

    Returns
    -------
    CriticalStiffnessResult
        ``crossing_frequency_hz`` is the frequency at which PR is first lost.

    References
    ----------
    The paper, Theorem 2.1, Definition 1, eq. (15) and (30).
    """
    _check_stiffness_loop(loop)
    a = _approx(approximation)
    T, n = loop.period, whole_delay(loop, "the circle criterion")
    D = port_scaling(loop, scaling)
    if sector is not None:
        return _sector_kmax(loop, a, sector, scaling)
    km_ks = False
    if isinstance(loop, TeleoperationLoop):
        km = spring_damper(loop.master_controller, "master_controller").stiffness
        ks = spring_damper(loop.slave_controller, "slave_controller").stiffness
        km_ks = km != ks and D == (1.0, 1.0) and km > 0
    if km_ks:
        K, th = 0.0, 0.0
        why = "residue (25) at z = 1 is not Hermitian for K_m != K_s (no port scaling)"
    else:
        K, th = _affine_kmax(loop, lambda t: _hermitian_parts(loop, a, D, t), n + 2)
        if K == 0:   # condition (iii) fails at K = 0: the virtual damping (e.g. B < -b) wins
            why = ("G^-1(z) is not PR for any K >= 0: condition (iii) fails already at K = 0 "
                   f"(at w = {th / T:.6g} rad/s; the virtual damping takes more than the device "
                   "damping provides)")
        elif math.isfinite(K):
            why = (f"G^-1(z) is PR for K <= K_max; at K_max, condition (iii) binds at "
                   f"w = {th / T:.6g} rad/s")
        else:
            why = "G^-1(z) is PR for every K >= 0"
    eq = "(15)" if isinstance(loop, HapticLoop) else "(30)"
    reason = f"circle criterion (Theorem 2.1), {a} approximation, G^-1 of eq. {eq}: {why}"
    if a != "forward":
        reason += " (not a stability bound: only forward difference is)"
    f_hz = th / (2 * math.pi * T) if math.isfinite(K) else float("nan")
    return CriticalStiffnessResult(
        float(K), "circle", ((0.0, float(K)),) if K > 0 else (), reason, T, n, f_hz,
        {"approximation": a, "worst_frequency_rad_s": th / T if math.isfinite(K) else float("nan"),
         "port_scaling": list(D), "sector": None})


def _sector_kmax(loop: Any, a: str, sector: Any, scaling: str | None) -> CriticalStiffnessResult:
    """K_max of K^{-1} + G(z) PR by bracketing then bisection (relative 1e-6),
    starting from the passive limit (PR of G implies PR of K^{-1} + G) and assuming
    the PR set in K is an interval, as it is for the passive limit."""
    try:
        ks = np.atleast_1d(np.asarray(sector, dtype=float))
    except (TypeError, ValueError):
        raise AnalysisError(f"sector = {sector!r}: must be a number k > 0 or one per port") from None
    for k in ks:
        if not k > 0:  # NaN fails too
            raise AnalysisError(f"sector = {sector!r}: every k_i must be > 0 (inf: passive limit)")
    base = critical_stiffness_circle(loop, a, None, scaling).critical_stiffness
    if math.isinf(base):
        lo, hi = base, base
    else:
        def ok(K: float) -> bool:
            return circle_test(loop.with_stiffness(K), a, sector, scaling).positive_real

        damp = (loop.device.damping if isinstance(loop, HapticLoop)
                else max(loop.master.damping, loop.slave.damping))
        lo = base * (1 - 1e-7) if base > 0 else 0.0  # PR of G implies PR of K^-1 + G
        if lo > 0 and not ok(lo):
            raise AnalysisError("sector: the circle test fails already at the passive limit's "
                                f"K = {lo:.6g} N/m, which PR of G guarantees; no finite-sector "
                                "result can be trusted here")
        step = base if base > 0 else max(damp, 1e-6) / loop.period * 1e-6
        hi = lo + step
        while ok(hi):
            lo, step = hi, step * 2
            hi = lo + step
            if hi > 1e12 * max(1.0, base):
                lo = hi = float("inf")
                break
        while math.isfinite(hi) and hi - lo > 1e-6 * hi:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    K = lo
    res = circle_test(loop.with_stiffness(hi), a, sector, scaling) if math.isfinite(hi) else None
    reason = (f"circle criterion (Theorem 2.1) with sector [0, {', '.join(f'{k:g}' for k in ks)}], "
              f"{a} approximation: K^-1 + G(z) is PR for K <= K_max")
    f_hz = res.worst_frequency_hz if res is not None else float("nan")
    return CriticalStiffnessResult(
        float(K), "circle", ((0.0, float(K)),) if K > 0 else (), reason, loop.period,
        whole_delay(loop, "the circle criterion"), f_hz,
        {"approximation": a, "worst_frequency_rad_s": f_hz * 2 * math.pi,
         "port_scaling": list(port_scaling(loop, scaling)), "sector": ks.tolist()})
