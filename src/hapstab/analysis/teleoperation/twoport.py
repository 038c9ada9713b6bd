"""Absolute stability of the sampled-data teleoperator as a two-port (Llewellyn).

The paper's two-port is the device side of the loop, ``P(z) = G^{-1}(z) = diag(b) +
Hc(z) X(z)`` (eq. 30 generalised; :func:`hapstab.analysis.conditions.circle.loop_inverse`), between
the port velocities (through the approximation X of the hold) and the forces; the
terminations (operator with the master's mass, environment with the slave's) close it.
The circle criterion asks P to be passive. Llewellyn's criterion asks less: that the
two-port be stable with *every* pair of passive terminations,

* Re p11 >= 0 and Re p22 >= 0,
* eta = (2 Re p11 Re p22 - Re(p12 p21)) / |p12 p21| >= 1,

on the whole unit circle, with p_ij analytic outside it and any pole on it simple with
a residue k such that k / z0 is real and >= 0 for p11 and p22 (Adams & Hannaford's form).
For spring-damper controllers and the forward, backward or Tustin approximation, P's poles are
z = 0 (delays, 1/z) and z = 1, simple, with residue T Hc(1) = T [[ab K_m, -b K_m], [-a K_s, K_s]]
(a, b: position and force scaling, 1 without):
the conditions on it hold for every K >= 0.

Where p12 = p21 (equal controllers, or proportional ones B_m/K_m = B_s/K_s after the port
scaling) Llewellyn's inequality is the passivity one: the paper's PEB gets the circle
criterion's K_max exactly. It allows more where the channels differ.

Numerics: near w = 0, |p12 p21| ~ 1/w^2 and eta -> 1, so ``eta - 1`` from eta itself is
rounding. hapstab evaluates the equivalent ``Re p11 Re p22 >= (Re sqrt(p12) sqrt(p21))^2``
(since |w| + Re w = 2 (Re sqrt w)^2 for w = p12 p21), which has no cancellation, and
reports the margin ``min(Re p11, Re p22, sqrt(Re p11 Re p22) - |Re sqrt(p12 p21)|)`` in
N*s/m: >= 0 exactly where the conditions hold (plus a rounding slack,
:data:`~hapstab.analysis.teleoperation.llewellyn_scan.SLACK`).

Bounded impedance: a designer who knows that every operator (environment) has at least
b_h_min (b_e_min) of damping asks for stability only with terminations b_min + Z', Z'
passive; that is Llewellyn's test on P + diag(b_h_min, b_e_min) (``operator_damping_min``,
``environment_damping_min``; Haddadi & Hashtrudi-Zaad 2010 bound the terminations in the
same spirit).

References
----------
F. B. Llewellyn, "Some fundamental properties of transmission systems", Proc. IRE 40,
1952; R. J. Adams and B. Hannaford, "Stable haptic interaction with virtual
environments", IEEE Trans. Robot. Autom. 15(3), 1999; K. Hashtrudi-Zaad and S. E.
Salcudean, "Analysis of control architectures for teleoperation systems with impedance/
admittance master and slave manipulators", Int. J. Robotics Research 20(6), 2001; the
paper, eq. (30) and Theorem 2.1; A. Haddadi and K. Hashtrudi-Zaad, "Bounded-impedance
absolute stability of bilateral teleoperation control systems", IEEE Trans. Haptics 3(1),
2010.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.analysis.conditions.device_terms import (
    approximation_name,
    integrator_response,
    stiffness_side,
)
from hapstab.analysis.conditions.frequency_grid import (
    refine_minimum_rows,
    theta_grid,
)
from hapstab.analysis.teleoperation.llewellyn_scan import (
    SCAN_START,
    below,
    first_failure,
    margin_of,
)
from hapstab.engine.device_side import DeviceSide
from hapstab.engine.structure import own_stiffness, structure_of
from hapstab.errors import AnalysisError, check_real
from hapstab.models.loops import TeleoperationLoop, require_loop
from hapstab.results import CriticalStiffnessResult, Result, jsonable, write_csv

__all__ = ["llewellyn_margin", "critical_stiffness_llewellyn", "llewellyn_test", "TwoPortResult"]


def _side(loop: Any, approximation: Any, bounds: tuple[Any, Any] = (0.0, 0.0)
          ) -> tuple[DeviceSide, str]:
    """The device side with the terminations' least damping moved into it (bounded
    impedance, :func:`_damping_bounds`), and the approximation's name."""
    require_loop(loop)
    if len(loop.port_names) != 2:                # a two-port: master and slave
        raise AnalysisError("method = 'llewellyn': a two-port criterion, for a "
                            "TeleoperationLoop (peb) or a FourChannelLoop (4ch); for the HVE "
                            "use 'circle' or 'passivity'")
    # any whole delays: the conditions see the delays only through p12 p21, i.e. the
    # round trip (and so does the loop with any terminations)
    side = stiffness_side(loop, "Llewellyn's test", forces=True, equal_delays=False)
    side.check_forces("Llewellyn's test")
    extra = _damping_bounds(*bounds)
    if any(extra) and side.forces:     # after the force feedback (DeviceSide.with_forces)
        side = dataclasses.replace(side, extra_damping=np.array(extra, float))
    elif any(extra):
        side = dataclasses.replace(side, damping=side.damping + np.array(extra, float))
    return side, approximation_name(approximation)   # forward, backward or tustin


def _damping_bounds(operator_min: Any, environment_min: Any) -> tuple[float, float]:
    """The least damping (N*s/m) known of the operator and of the environment.

    Bounded impedance: a termination Z = b_min + Z' with Z' passive is a passive Z' on
    the two-port whose p11 (or p22) gained b_min, so Llewellyn's conditions are tested
    on P + diag(b_h_min, b_e_min). Only the real parts of p11 and p22 enter them, so a
    termination's least mass or stiffness (imaginary at s = j w) would change nothing;
    its least damping is what a designer who knows the operator roughly can use.
    """
    return (check_real("operator_damping_min", operator_min, nonnegative=True),
            check_real("environment_damping_min", environment_min, nonnegative=True))


def _parts(side: DeviceSide, a: str, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P = A + K C at each angle: (A, C), each (N, 2, 2)."""
    X = integrator_response(a, theta, side.period_s)[:, None, None]
    A = np.diag(side.damping)[None] + X * side.controller_matrix(theta, "B")
    C = X * side.controller_matrix(theta, "K")
    return side.with_forces(A, theta), side.with_forces(C, theta, "K")


def _margin(A: np.ndarray, C: np.ndarray, K: float) -> np.ndarray:
    """Llewellyn's margin at each angle for stiffness K (see the module notes)."""
    return margin_of(A + K * C)


#: Stiffnesses tried at once in each round of the search for K_max: the bracket shrinks
#: by SECTIONS + 1 per round (one vectorised golden search for all of them) instead of 2
#: per bisection step: ~10 rounds to 1e-9 relative instead of ~30 golden searches.
SECTIONS = 8
#: ... but each K also costs its margin on the whole grid (paper PEB: 0.2 ms at 1,104
#: angles, 1.7 ms at 9,744, 11 ms at 96,144, against ~16 ms for a golden search): fewer
#: at once on larger grids, SECTION_ANGLES / angles of them (one, plain bisection, from
#: 80,000 angles: measured 4.4 s against 6.5 s with eight at n = 1000).
SECTION_ANGLES = 80_000


def _worst(side: DeviceSide, a: str, th: np.ndarray, A: np.ndarray, C: np.ndarray,
           Ks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(angle, margin) of the smallest margin at each K of ``Ks``: each K's margins on
    the grid (``A + K C``) refined by golden section between grid points, all K in one
    vectorised search (:func:`~hapstab.analysis.conditions.frequency_grid.refine_minimum_rows`)."""
    def f(rows: np.ndarray, t: np.ndarray) -> np.ndarray:
        At, Ct = _parts(side, a, t)
        return margin_of(At + Ks[rows][:, None, None] * Ct)
    return refine_minimum_rows(f, th, np.array([_margin(A, C, K) for K in Ks]))


def _last_passing(side: DeviceSide, a: str, th: np.ndarray, A: np.ndarray, C: np.ndarray,
                  lo: float, hi: float, zero: float, tol: float) -> tuple[float, float]:
    """Shrink [lo, hi] (margin >= -tol at lo, not at hi) to 1e-9 relative around the
    first K where the refined margin fails, :data:`SECTIONS` stiffnesses a round (fewer
    on large grids, :data:`SECTION_ANGLES`)."""
    sections = max(1, min(SECTIONS, SECTION_ANGLES // th.size))
    steps = np.arange(1, sections + 1) / (sections + 1)
    while hi - lo > 1e-9 * hi and hi > zero:     # to 1e-9 relative: far below any design use
        Ks = lo + (hi - lo) * steps
        bad = np.flatnonzero(_worst(side, a, th, A, C, Ks)[1] < -tol)
        if not bad.size:
            lo = float(Ks[-1])
        else:
            lo, hi = (float(Ks[bad[0] - 1]) if bad[0] else lo), float(Ks[bad[0]])
    return lo, hi


def llewellyn_margin(loop: TeleoperationLoop, approximation: str = "forward",
                     theta: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Llewellyn's margin of the two-port at the loop's own K, on the unit circle.

    Parameters
    ----------
    loop : TeleoperationLoop
        Spring-damper controllers, whole-sample delays.
    approximation : {"forward", "backward", "tustin"}
        X(z) as in the circle criterion.
    theta : array, optional
        Angles in (0, pi] (default: a grid dense enough for the delay).

    Returns
    -------
    (theta, margin) : arrays
        ``margin >= 0`` where Re p11 >= 0, Re p22 >= 0 and eta >= 1 (N*s/m; it includes
        the rounding slack
        :data:`~hapstab.analysis.teleoperation.llewellyn_scan.SLACK`).
    """
    side, a = _side(loop, approximation)
    th = theta_grid(side.oscillations) if theta is None else np.asarray(theta, float)
    A, C = _parts(side, a, th)
    K = own_stiffness(structure_of(loop))   # the loop's K
    return th, _margin(A, C, K)


def critical_stiffness_llewellyn(loop: TeleoperationLoop, approximation: str = "forward",
                                 operator_damping_min: float = 0.0,
                                 environment_damping_min: float = 0.0
                                 ) -> CriticalStiffnessResult:
    """Largest K for which the two-port is absolutely stable (Llewellyn) for every K in
    (0, K]: a geometric scan of K, the first K whose margin is negative on the unit circle
    (minimum over angles refined by golden section), then the bracket shrunk to 1e-9
    relative around the first failure, :data:`SECTIONS` stiffnesses a round.

    Parameters
    ----------
    loop : TeleoperationLoop
        Spring-damper controllers (K is the master's; K_s/K_m kept), whole-sample delays.
    approximation : {"forward", "backward", "tustin"}
        X(z) as in the circle criterion.
    operator_damping_min, environment_damping_min : float
        Bounded impedance: the least damping (N*s/m, >= 0) every operator and every
        environment is known to have; default 0, Llewellyn's "every passive termination".
        Haddadi and Hashtrudi-Zaad 2010 (bounded-impedance absolute stability).

    Returns
    -------
    CriticalStiffnessResult
        ``method="llewellyn"``; details: the approximation and the damping bounds.
    """
    bounds = _damping_bounds(operator_damping_min, environment_damping_min)
    side, a = _side(loop, approximation, bounds)
    T, n = side.period_s, int(loop.delay_in_samples)   # (the forward delay)
    th = theta_grid(side.oscillations)
    _check_scan_cost(th.size)
    A, C = _parts(side, a, th)

    def worst(K: float) -> tuple[float, float]:
        t, m = _worst(side, a, th, A, C, np.array([K]))
        return float(t[0]), float(m[0])

    tol = 0.0        # (the margin carries its own rounding slack, SLACK)
    if worst(0.0)[1] < -tol:
        why = ("the force feedback (through the devices' masses) and the virtual damping take "
               "more than the damping gives" if side.forces else
               "the virtual damping takes more than the device damping gives")
        return _result(0.0, a, T, n, worst(0.0)[0], f"not absolutely stable at K = 0: {why}",
                       bounds, side)
    K_hi = first_failure(A, C, tol)
    if K_hi is None:
        return _result(math.inf, a, T, n, None, "absolutely stable for every K up to 1e12 N/m",
                       bounds, side)
    lo, hi = below(K_hi), K_hi
    while lo > 0 and worst(lo)[1] < -tol:   # the grid passed lo; the refined minimum must too
        lo, hi = below(lo), lo
    # 1e-12 of the loop's stiffness scale b/T is zero (a margin exactly 0 at K = 0 ends
    # there, up to the slack); without any damping (b = 0: an undamped pair, B = 0, every
    # margin 0 at K = 0) 1e-12 of the scan's first K, else the bisection went on to the
    # denormals (~1,100 refined minima: minutes)
    zero = 1e-12 * max(float(np.max(side.damping)) / T, SCAN_START)
    lo, hi = _last_passing(side, a, th, A, C, lo, hi, zero, tol)
    if hi <= zero:
        return _result(0.0, a, T, n, worst(hi)[0], "not absolutely stable for any K > 0",
                       bounds, side)
    th_w = worst(hi)[0]
    return _result(lo, a, T, n, th_w, f"Llewellyn's conditions fail beyond K_max, first at "
                                      f"w = {th_w / T:.6g} rad/s", bounds, side)


#: Seconds per angle of the grid of one Llewellyn K_max (the K scan, its refinement and
#: bisection): 21 s at 192,144 angles (PEB, 2000 samples) and 87 s at 960,144 (10,000),
#: measured on a loaded 2-core machine (1.1e-4 and 0.9e-4): taken as 1.2e-4. Since the
#: screened scan (session 13, quiet): 1.8 s at 19,344 angles (n = 200, 9.3e-5: the
#: refinement's share) and 9.2 s at 192,144 (4.8e-5); the bound is kept for loaded machines.
SCAN_SECONDS_PER_ANGLE = 1.2e-4


def _check_scan_cost(angles: int) -> None:
    """Refuse, before any work, a scan whose angle grid (it grows with the delay) is
    over the time budget (:data:`SCAN_SECONDS_PER_ANGLE`)."""
    from hapstab.budget import Cost, check
    # memory: the grid's parts (a few complex arrays per angle) and a 2e6-element chunk
    check(Cost(f"Llewellyn's K_max: a scan over {angles} angles", 256.0 * angles + 1.3e8,
               SCAN_SECONDS_PER_ANGLE * angles))


#: What the test is worth with force channels (README, "Lawrence's 4-channel architecture").
FORCE_CAVEAT = ("; with measured forces this two-port ignores their sampling (a stiff "
                "termination's force is sampled like a virtual wall's), so it is NOT a stability "
                "bound in general: a seeded campaign found loops unstable below it with C_3, C_5 "
                "or C_6 (none with C_2 alone); C_5 and C_6 only scale a row of the two-port, "
                "which Llewellyn's conditions do not see; confirm with the exact analysis")


def _two_port_name(side: DeviceSide) -> str:
    """Which two-port the test ran on (with force channels, not eq. 30's)."""
    if side.forces:
        return ("two-port (I - G_f)^-1 (G^-1 + jw M) - jw M (measured forces fed back through "
                "G_f, the devices' masses M at s = jw)")
    return "two-port G^-1 (eq. 30)"


def _result(K: float, a: str, T: float, n: int, theta: float | None,
            why: str, bounds: tuple[float, float], side: DeviceSide) -> CriticalStiffnessResult:
    f_hz = theta / (2 * math.pi * T) if theta is not None else float("nan")
    return CriticalStiffnessResult(
        float(K), "llewellyn", ((0.0, float(K)),) if K > 0 else (),
        f"Llewellyn's absolute stability of the {_two_port_name(side)}, {a} approximation"
        f"{_terminations(bounds)}: {why}{FORCE_CAVEAT if side.forces else ''}", T, n, f_hz,
        {"approximation": a, "operator_damping_min": bounds[0],
         "environment_damping_min": bounds[1]})


def _terminations(bounds: tuple[float, float]) -> str:
    """How the terminations are bounded, for the reason ("" for every passive pair)."""
    if not any(bounds):
        return ""
    return (f", terminations with damping of at least {bounds[0]:g} (operator) and "
            f"{bounds[1]:g} N*s/m (environment)")


@dataclass(frozen=True)
class TwoPortResult(Result):
    """Llewellyn's test of the two-port at one stiffness, over the unit circle.

    Attributes
    ----------
    absolutely_stable : bool
        Whether Re p11 >= 0, Re p22 >= 0 and eta >= 1 at every angle.
    margin : float
        Smallest margin over the angles, N*s/m (see the module notes).
    worst_frequency_rad_s, worst_frequency_hz : float
        Where it is smallest.
    eta_min : float
        Smallest eta = (2 Re p11 Re p22 - Re p12 p21) / |p12 p21| away from w -> 0 (where
        it tends to 1), on the angles above 1e-3 rad/sample.
    frequency_rad_s, margins, eta : arrays
        The curves (for the plot and the CSV).
    stiffness, period : float
        K (N/m) and T (s).
    approximation : str
        X(z).
    reason : str
        The verdict in words.
    damping_bounds : (float, float)
        The least operator and environment damping assumed (N*s/m; 0: every passive pair).
    """

    absolutely_stable: bool
    margin: float
    worst_frequency_rad_s: float
    worst_frequency_hz: float
    eta_min: float
    frequency_rad_s: np.ndarray = field(repr=False)
    margins: np.ndarray = field(repr=False)
    eta: np.ndarray = field(repr=False)
    stiffness: float
    period: float
    approximation: str
    reason: str
    damping_bounds: tuple[float, float] = (0.0, 0.0)

    @property
    def verdict(self) -> str:
        return "absolutely stable" if self.absolutely_stable else "not absolutely stable"

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"verdict": self.verdict, "absolutely_stable": self.absolutely_stable,
                         "margin": self.margin, "worst_frequency_rad_s": self.worst_frequency_rad_s,
                         "worst_frequency_hz": self.worst_frequency_hz, "eta_min": self.eta_min,
                         "stiffness": self.stiffness, "period_s": self.period,
                         "approximation": self.approximation, "reason": self.reason,
                         "operator_damping_min": self.damping_bounds[0],
                         "environment_damping_min": self.damping_bounds[1]})

    def to_csv(self, path: Any) -> None:
        """One row per angle: frequency_rad_s, margin_N_s_per_m, eta.

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        write_csv(path, ["frequency_rad_s", "margin_N_s_per_m", "eta"],
                  zip(self.frequency_rad_s, self.margins, self.eta, strict=True))

    def plot(self, ax: Any = None) -> Any:
        from hapstab.plotting import plot_twoport
        return plot_twoport(self, ax)


def llewellyn_test(loop: TeleoperationLoop, approximation: str = "forward",
                   operator_damping_min: float = 0.0,
                   environment_damping_min: float = 0.0) -> TwoPortResult:
    """Llewellyn's absolute stability of the two-port at the loop's own K.

    Parameters
    ----------
    loop : TeleoperationLoop
        Spring-damper controllers (K is the master's), whole-sample delays.
    approximation : {"forward", "backward", "tustin"}
        X(z) as in the circle criterion.
    operator_damping_min, environment_damping_min : float
        Bounded impedance: the least damping (N*s/m) of every operator and environment
        (see :func:`critical_stiffness_llewellyn`); default 0, every passive pair.

    Returns
    -------
    TwoPortResult

    References
    ----------
    Llewellyn 1952; Adams and Hannaford 1999 (see the module docstring); A. Haddadi and
    K. Hashtrudi-Zaad, "Bounded-impedance absolute stability of bilateral teleoperation
    control systems", IEEE Trans. Haptics 3(1), 2010.
    """
    bounds = _damping_bounds(operator_damping_min, environment_damping_min)
    side, a = _side(loop, approximation, bounds)
    T = side.period_s
    K = own_stiffness(structure_of(loop))
    th = theta_grid(side.oscillations)
    A, C = _parts(side, a, th)

    margins = _margin(A, C, K)
    th_w, m = (float(x[0]) for x in _worst(side, a, th, A, C, np.array([K])))
    P = A + K * C
    w = P[:, 0, 1] * P[:, 1, 0]
    with np.errstate(all="ignore"):
        eta = (2 * P[:, 0, 0].real * P[:, 1, 1].real - w.real) / np.abs(w)
    # eta -> 1 as w -> 0 is rounding there: its minimum is read above 1e-3 rad/sample
    away = th > 1e-3
    eta_min = float(np.nanmin(eta[away])) if away.any() else float("nan")
    ok = bool(m >= 0)
    why = (f"Llewellyn's conditions hold at every frequency (margin {m:.6g} N*s/m)" if ok else
           f"Llewellyn's conditions fail at w = {th_w / T:.6g} rad/s (margin {m:.6g} N*s/m): "
           "some pair of passive terminations makes the loop unstable")
    return TwoPortResult(ok, float(m), th_w / T, th_w / (2 * math.pi * T), eta_min, th / T,
                         margins, eta, float(K), T, a,
                         f"{_two_port_name(side)}, {a} approximation{_terminations(bounds)}: "
                         f"{why}{FORCE_CAVEAT if side.forces else ''}", bounds)
