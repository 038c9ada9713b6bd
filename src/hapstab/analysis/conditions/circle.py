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
Schenkel (see :mod:`hapstab.analysis.conditions.passivity`), so its K_max never exceeds the exact
stability limit with passive terminations. Backward difference and Tustin are
not bounds: at n = 0 they accept every K (Re{z/(z-1)} = 1/2 and
Re{(z+1)/(z-1)} = 0 on the circle), although the loop goes unstable.

A finite sector (Theorem 2.1 with K = diag(k_i)) tests ``K^{-1} + G(z)`` with
G = (G^{-1})^{-1} (:func:`loop_transfer`: for two ports the factor z - 1 of
det G^{-1}'s numerator is divided out analytically). The theorem's feedback is
*memoryless*: a termination f_i = -phi_i(v_i) with 0 <= v phi(v) <= k_i v^2, e.g. a
damper c_i <= k_i. The device mass is not memoryless, so the finite-sector K_max is
a bound only when the devices' masses are negligible (m_i << b_i T: the velocity
settles within a sample and the forward-difference model is the exact loop). With
the paper's masses it is not (PEB, n = 1, k = 0.1: 14.31 N/m against an exact
10.004 N/m with nothing attached); backward difference and Tustin are not bounds
even then. The passive limit (no sector) is the bound for any passive termination.

References
----------
The paper, Section 3 (eq. 14-18) and Section 4 (eq. 24-34).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hapstab import budget
from hapstab.analysis.conditions.closed_forms import G_INVERSE
from hapstab.analysis.conditions.device_terms import (
    APPROXIMATIONS,
    approximation_name,
    integrator_polynomial,
    integrator_response,
    stiffness_side,
    whole_delay_side,
)
from hapstab.analysis.conditions.frequency_grid import affine_kmax_rows
from hapstab.analysis.conditions.positive_real import (
    PositiveRealResult,
    RationalMatrix,
    circle_criterion,
    positive_real,
)
from hapstab.engine.device_side import DeviceSide, device_side
from hapstab.engine.structure import structure_of
from hapstab.engine.system import build
from hapstab.errors import AnalysisError, ModelError
from hapstab.models.loops import HapticLoop, TeleoperationLoop, require_loop, whole_delay
from hapstab.results import CriticalStiffnessResult
from hapstab.tolerances import PSD_SLACK

__all__ = ["APPROXIMATIONS", "loop_inverse", "loop_transfer", "port_scaling", "circle_test",
           "critical_stiffness_circle", "kmax_parts"]

def port_scaling(loop: HapticLoop | TeleoperationLoop, scaling: str | None = "auto"
                 ) -> tuple[float, ...]:
    """Diagonal port weights D used as D G^{-1}(z).

    With C_m != C_s the residue (25) at z = 1, ``T [[K_m, -K_m], [-K_s, K_s]]``,
    is not Hermitian and G^{-1} is never PR for K > 0 (nor with position/force
    scaling, ``T [[alpha beta K_m, -beta K_m], [-alpha K_s, K_s]]``). Weighting the
    master by K_s/K_m (times alpha/beta with scaling;
    :meth:`~hapstab.engine.device_side.DeviceSide.port_weights`) makes it Hermitian;
    stability still follows,
    because D times a diagonal passive termination is passive (the multiplier K of
    Theorem 2.1 plays the same role). Equal controllers give D = I, the paper's test.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop.
    scaling : {"auto", None}
        ``None``: the paper's literal test (no weighting).

    Returns
    -------
    tuple of float
        One weight per port (a haptic loop: ``(1.0,)``).
    """
    return device_side(loop, "port scaling").port_weights(scaling)


def loop_inverse(loop: HapticLoop | TeleoperationLoop, approximation: str = "forward",
                 scaling: str | None = "auto") -> RationalMatrix:
    """G^{-1}(z): force to velocity inverse of the loop without its terminations.

    ``G^{-1}(z) = D (diag(b) + Hc(z) X(z))`` with Hc the engine's controller matrix
    (:class:`~hapstab.engine.device_side.DeviceSide`): for the HVE eq. (15)
    generalised, ``b + z^{-n} H(z) X(z)``; for PEB eq. (24)/(30) generalised, with
    any C_m, C_s (also :class:`~hapstab.models.DiscreteController`), any n, and the
    port weighting D of :func:`port_scaling`.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (delays a whole number of samples).
    approximation : {"forward", "backward", "tustin"}
        X(z), the approximation of Z{v/s}.
    scaling : {"auto", None}
        Port weighting (see :func:`port_scaling`).

    Returns
    -------
    RationalMatrix
    """
    side = whole_delay_side(loop)
    xn, xd = integrator_polynomial(approximation_name(approximation), side.period_s)
    D = side.port_weights(scaling)
    hn, hd = side.controller_polynomials()
    nums: list[list[np.ndarray]] = []
    dens: list[list[np.ndarray]] = []
    for i in range(side.ports):
        nums.append([])
        dens.append([])
        for j in range(side.ports):
            num, den = D[i] * np.polymul(hn[i][j], xn), np.polymul(hd[i][j], xd)
            if i == j:
                num = np.polyadd(D[i] * side.damping[i] * den, num)
            nums[i].append(num)
            dens[i].append(den)
    return RationalMatrix(nums, dens)


def _zpow(k: int) -> np.ndarray:
    return np.concatenate([[1.0], np.zeros(k)])


def loop_transfer(loop: HapticLoop | TeleoperationLoop, approximation: str = "forward",
                  scaling: str | None = "auto") -> RationalMatrix:
    """G(z) = (D G^{-1}(z))^{-1}: velocity per force of the loop without its terminations.

    For the HVE simply ``1 / G^{-1}``. For two ports it is built as
    ``adj(M) diag(c_j / D_j) / q`` from ``G^{-1} = diag(D_i / ((z - 1) c_i)) M(z)``,
    ``c_i = hd_i z^N_i`` (controller denominator times the row's longest delay), so that
    M is polynomial, ``M = (z - 1) diag(b_i c_i) + diag(hn_i xn) S(z)`` with
    ``S_ij = s_ij z^(N_i - n_ij)``. A position-error loop has det S(1) = 0 (S(1) =
    [[1, -1], [-1, 1]]): det M = (z - 1) q(z) with

        q = (z - 1) a_1 a_2 + a_1 h_2 S_22 + a_2 h_1 S_11 + h_1 h_2 det S(z) / (z - 1)

    (a_i = b_i c_i, h_i = hn_i xn), so the factor (z - 1) that G^{-1}'s pole at z = 1
    leaves in both ``diag((z - 1) c_j)`` and the determinant is divided out analytically,
    not by root-finding; det S(z) / (z - 1) divides a polynomial of a few signed
    coefficients (e.g. ``z^2n - 1``), exactly for unit signs. The powers of z the delays
    and the controllers leave in both are exact zero coefficients and cancel exactly.
    (Inverting G^{-1} elementwise instead left (z - 1)^k in both, which root-finding
    split into spurious poles at |z| ~ 1 + 1e-4.)

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (delays a whole number of samples).
    approximation : {"forward", "backward", "tustin"}
        X(z), the approximation of Z{v/s}.
    scaling : {"auto", None}
        Port weighting D (see :func:`port_scaling`).

    Returns
    -------
    RationalMatrix
        Its poles are the zeros of det G^{-1}(z): the loop's own poles with massless
        devices and nothing attached (for forward difference exactly those of the
        sampled-data loop in that limit).
    """
    a = approximation_name(approximation)
    side = whole_delay_side(loop)
    if side.ports == 1:
        return loop_inverse(loop, a, scaling).inverse()
    if side.ports != 2:
        raise AnalysisError(f"loop_transfer: {side.ports} ports; implemented for one and two")
    return _two_port_transfer(side, a, side.port_weights(scaling))


#: det S(1) of the channels' signs counts as 0 below this relative to its two products:
#: signs (or scale factors) multiplied in pairs carry a few round-offs, far below this
_SINGULAR_SIGNS = 1e-12


def _two_port_transfer(side: DeviceSide, a: str, D: tuple[float, ...]) -> RationalMatrix:
    """:func:`loop_transfer` for two ports (see there for the construction)."""
    pm, pa = np.polymul, np.polyadd
    T = side.period_s
    if len(side.channels) != 2:
        raise AnalysisError("circle criterion with a finite sector: derived for one controller "
                            "per port (PEB); this loop has several (C_1 or C_4 apart from C_s, "
                            "C_m); use sector=None or the exact analysis")
    xn, z1 = integrator_polynomial(a, T)
    c: list[np.ndarray] = [np.ones(1), np.ones(1)]
    be: list[np.ndarray] = [np.zeros(1), np.zeros(1)]
    S: list[list[np.ndarray]] = [[np.zeros(1), np.zeros(1)], [np.zeros(1), np.zeros(1)]]
    for ch in side.channels:
        i = ch.port
        hn, hd = (np.asarray(v, float) for v in ch.controller.transfer(T))
        N = max(int(d) for _, _, d in ch.terms)
        for j, s, d in ch.terms:
            S[i][j] = pa(S[i][j], s * _zpow(N - int(d)))
        c[i], be[i] = pm(hd, _zpow(N)), pm(hn, xn)
    al = [side.damping[i] * c[i] for i in (0, 1)]
    M = [[pa(pm(z1, al[i]) if i == j else np.zeros(1), pm(be[i], S[i][j])) for j in (0, 1)]
         for i in (0, 1)]
    d1, d2 = pm(S[0][0], S[1][1]), pm(S[0][1], S[1][0])
    top: np.ndarray = np.ones(1)
    if abs(d1.sum() - d2.sum()) <= _SINGULAR_SIGNS * (np.abs(d1).sum() + np.abs(d2).sum()):
        sigma = np.polydiv(np.polysub(d1, d2), z1)[0]  # partial sums of a few signs: exact
        q: np.ndarray = pa(pa(pm(z1, pm(al[0], al[1])), pm(pm(be[0], be[1]), sigma)),
               pa(pm(pm(al[0], be[1]), S[1][1]), pm(pm(al[1], be[0]), S[0][0])))
    else:   # det S(1) != 0: det M has no factor z - 1, which stays in the numerators
        q = np.polysub(pm(M[0][0], M[1][1]), pm(M[0][1], M[1][0]))
        top = z1
    adj = [[M[1][1], -M[0][1]], [-M[1][0], M[0][0]]]
    nums = [[pm(pm(adj[i][j], c[j]), top) / D[j] for j in (0, 1)] for i in (0, 1)]
    try:
        return RationalMatrix(nums, [[q, q], [q, q]])
    except ModelError as e:   # G^-1(inf) singular, e.g. no device damping with forward
        raise AnalysisError(f"G(z) = (G^-1(z))^-1 is not proper ({e}): G^-1 is singular at "
                            "z = inf (e.g. devices without damping); Theorem 2.1 needs a "
                            "proper G") from None


def _weighted_sector(sector: Any, D: tuple[float, ...]) -> Any:
    """The sector of D phi: the weighted loop D G^-1 sees each termination's force times
    D_i, so a termination in [0, k_i] is a nonlinearity in [0, D_i k_i] there."""
    if all(d == 1.0 for d in D):
        return sector
    try:
        ks = np.broadcast_to(np.asarray(sector, dtype=float), (len(D),))
    except (TypeError, ValueError):
        return sector  # circle_criterion names the error
    return [float(d * k) for d, k in zip(D, ks, strict=True)]


def circle_test(loop: HapticLoop | TeleoperationLoop, approximation: str = "forward",
                sector: Any = None, scaling: str | None = "auto", *,
                max_memory: float | None = None,
                max_seconds: float | None = None) -> PositiveRealResult:
    """The circle-criterion test at the loop's own stiffness.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
    approximation : {"forward", "backward", "tustin"}
    sector : float, sequence of float or None
        Sector [0, k_i] of each termination as a memoryless map from the port's
        velocity to force (Theorem 2.1; e.g. a damper c_i <= k_i, on a device of
        negligible mass, see the module notes): tests ``K^{-1} + G(z)``, with the
        port weights D as ``(D K)^{-1} + G D^{-1}`` (the weighted loop sees D_i phi_i).
        ``None`` (default) is the passive limit: G^{-1}(z) PR (equivalently G(z) PR).
    scaling : {"auto", None}
        Port weighting for PEB, see :func:`port_scaling`.
    max_memory, max_seconds : float, optional
        Budget in bytes and seconds (default :mod:`hapstab.budget`'s): the test finds
        the roots of polynomials about as long as the loop's delay, each a dense
        eigenvalue problem; estimated first.

    Returns
    -------
    PositiveRealResult
        Verdict, failing condition of Definition 1, margin and worst frequency.
    """
    require_loop(loop)
    sysm = build(loop)
    N = sysm.order
    # measured: 8 s (no sector) and 27 s (a sector) at N = 2004, 1.7 and 5.6 eigenvalue
    # problems of that size: charged as 2 and 6; PEB with a sector (the roots of det G^-1
    # once, of four numerators, and the sweep) 30 s at N = 2004 (n = 1000): charged as 7
    problems = 2 if sector is None else (6 if sysm.n_ports == 1 else 7)
    budget.check(budget.Cost(f"circle_test: roots of a {N}-state loop's polynomials",
                             64.0 * N * N, problems * budget.eig_seconds(N)),
                 max_memory, max_seconds)
    if sector is None:
        return positive_real(loop_inverse(loop, approximation, scaling), loop.period)
    G = loop_transfer(loop, approximation, scaling)
    return circle_criterion(G, _weighted_sector(sector, port_scaling(loop, scaling)), loop.period)


# ----------------------------------------------------------------- K_max, fast path
def _circle_parts(side: DeviceSide, a: str, D: tuple[float, ...]) -> Any:
    """theta -> the Hermitian part of D G^-1 as (fixed, the controllers' part at K = 0,
    the part per unit K): D G^-1's at K is their sum with K times the last."""
    w = np.asarray(D)[None, :, None]
    fixed = _herm(w * np.diag(side.damping)[None])

    def parts(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        X = integrator_response(a, theta, side.period_s)[:, None, None]
        return (np.broadcast_to(fixed, (theta.size, side.ports, side.ports)),
                _herm(w * X * side.controller_matrix(theta, "B")),
                _herm(w * X * side.controller_matrix(theta, "K")))
    return parts


def _herm(M: np.ndarray) -> np.ndarray:
    return M + np.conj(np.swapaxes(M, 1, 2))


def _unhermitian_residue(side: DeviceSide, D: tuple[float, ...]) -> bool:
    """PEB with K_m != K_s and no port scaling: the residue (25) at z = 1 is not
    Hermitian, and K_max is 0 by it."""
    return len(set(side.ratios or ())) > 1 and set(D) == {1.0}


def kmax_parts(loop: HapticLoop | TeleoperationLoop, approximation: str = "forward",
               scaling: str | None = "auto") -> Any:
    """What :func:`critical_stiffness_circle` (no sector) minimises over, for batched
    callers (the K-B region's rows): ``(parts, oscillations)``, ``parts(theta) ->
    (fixed, controller, per_K)``, the Hermitian part of D G^-1 being ``fixed +
    controller + K per_K`` (the controller's part at K = 0 is linear in its virtual
    damping), and the grid's oscillations.

    Raises
    ------
    AnalysisError
        Where :func:`critical_stiffness_circle` refuses the loop, and for unequal
        unscaled PEB controllers (whose K_max is 0 by the residue, not this minimum).
    """
    side = stiffness_side(loop)
    a = approximation_name(approximation)
    whole_delay(loop, "the circle criterion")
    D = side.port_weights(scaling)
    if _unhermitian_residue(side, D):
        raise AnalysisError("circle: the residue at z = 1 is not Hermitian (K_m != K_s, "
                            "no port scaling)")
    return _circle_parts(side, a, D), side.oscillations


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
        the passive limit, nor above the limit of the loop with nothing attached
        (c_i = 0 is in every sector). A stability bound only for devices of
        negligible mass (see the module notes). ``None``: passive limit (fast,
        exact up to rounding).
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
    side = stiffness_side(loop)
    a = approximation_name(approximation)
    T, n = side.period_s, whole_delay(loop, "the circle criterion")
    D = side.port_weights(scaling)
    if sector is not None:
        return _sector_kmax(loop, a, sector, scaling)
    if _unhermitian_residue(side, D):
        K, th = 0.0, 0.0
        why = "residue (25) at z = 1 is not Hermitian for K_m != K_s (no port scaling)"
    else:
        # the loop's own K_max: one row of the batched minimum, at its own B (B = 1 times
        # the controllers' part)
        Ks, ths = affine_kmax_rows(_circle_parts(side, a, D), np.ones(1), side.oscillations,
                                   PSD_SLACK)
        K, th = float(Ks[0]), float(ths[0])
        if K == 0:   # condition (iii) fails at K = 0: the virtual damping (e.g. B < -b) wins
            why = ("G^-1(z) is not PR for any K >= 0: condition (iii) fails already at K = 0 "
                   f"(at w = {th / T:.6g} rad/s; the virtual damping takes more than the device "
                   "damping provides)")
        elif math.isfinite(K):
            why = (f"G^-1(z) is PR for K <= K_max; at K_max, condition (iii) binds at "
                   f"w = {th / T:.6g} rad/s")
        else:
            why = "G^-1(z) is PR for every K >= 0"
    eq = "of eq. " + G_INVERSE[loop.kind] if loop.kind in G_INVERSE else "of the loop"
    reason = f"circle criterion (Theorem 2.1), {a} approximation, G^-1 {eq}: {why}"
    if a != "forward":
        reason += " (not a stability bound: only forward difference is)"
    f_hz = th / (2 * math.pi * T) if math.isfinite(K) else float("nan")
    return CriticalStiffnessResult(
        float(K), "circle", ((0.0, float(K)),) if K > 0 else (), reason, T, n, f_hz,
        {"approximation": a, "worst_frequency_rad_s": th / T if math.isfinite(K) else float("nan"),
         "port_scaling": list(D), "sector": None})


def _inertia_note(loop: Any) -> str:
    """What the finite-sector K_max is worth for this loop: a bound only for memoryless
    terminations on devices of negligible mass (module notes), so say m / (b T)."""
    side = device_side(loop, "the circle criterion")
    masses = [d.mass for d in _devices(loop)]
    ratio = max(m / (b * loop.period) if b > 0 else math.inf
                for m, b in zip(masses, side.damping, strict=True))
    # m = b T: the device's velocity settles in one sample, far from memoryless
    if ratio >= 1:
        return (f"NOT a stability bound for this loop: its devices have m/(bT) = {ratio:.3g} "
                "(the theorem needs memoryless terminations, devices of negligible mass)")
    return (f"a stability bound only for memoryless terminations in the sector on devices "
            f"of negligible mass (m/(bT) << 1; here {ratio:.3g})")


def _devices(loop: Any) -> list[Any]:
    return [pt.device for pt in structure_of(loop).ports]


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

        damp = float(np.max(device_side(loop, "the circle criterion").damping))
        # PR of G implies PR of K^-1 + G; 1e-7 below the passive limit keeps lo inside it
        # despite its rounding (~1e-12), at a tenth of the bisection's resolution (1e-6)
        lo = base * (1 - 1e-7) if base > 0 else 0.0
        if lo > 0 and not ok(lo):
            raise AnalysisError("sector: the circle test fails already at the passive limit's "
                                f"K = {lo:.6g} N/m, which PR of G guarantees; no finite-sector "
                                "result can be trusted here")
        # no passive limit to start from: a first step of 1e-6 (the bisection's resolution)
        # of b/T, the scale of K_max at n = 0 (2 b / T), with b = 1e-6 N*s/m if it is 0
        step = base if base > 0 else max(damp, 1e-6) / loop.period * 1e-6
        hi = lo + step
        while ok(hi):
            lo, step = hi, step * 2
            hi = lo + step
            if hi > 1e12 * max(1.0, base):
                lo = hi = float("inf")
                break
        # to 1e-6 relative: below what the PR test itself resolves (~1e-4, see above),
        # so the bisection adds no error of its own
        while math.isfinite(hi) and hi - lo > 1e-6 * hi:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    K = lo
    res = circle_test(loop.with_stiffness(hi), a, sector, scaling) if math.isfinite(hi) else None
    reason = (f"circle criterion (Theorem 2.1) with sector [0, {', '.join(f'{k:g}' for k in ks)}], "
              f"{a} approximation: K^-1 + G(z) is PR for K <= K_max; {_inertia_note(loop)}")
    f_hz = res.worst_frequency_hz if res is not None else float("nan")
    return CriticalStiffnessResult(
        float(K), "circle", ((0.0, float(K)),) if K > 0 else (), reason, loop.period,
        whole_delay(loop, "the circle criterion"), f_hz,
        {"approximation": a, "worst_frequency_rad_s": f_hz * 2 * math.pi,
         "port_scaling": list(port_scaling(loop, scaling)), "sector": ks.tolist()})
