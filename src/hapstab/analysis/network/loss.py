"""Mean-square K_max of a loop whose network drops packets.

The loop with losses is a Markov jump linear system (:mod:`.jump`); at stiffness K it
is mean-square stable iff rho(K), the spectral radius of its second-moment operator
(:mod:`.moments`), is below 1. K_max is the end of the stable interval that starts at
K -> 0+: a scan of K finds the first computed rho >= 1 and bisection closes in on it.

What this is and is not: the *criterion* is exact (necessary and sufficient for
mean-square stability of the model, Costa et al. 2005, Theorem 3.9); its *evaluation*
is floating point (rho from LAPACK / ARPACK, its error the rounding times the
eigenvalue's condition number, reported as the margin ``1 - rho`` at the answer), and
the scan checks K at grid points: an unstable window narrower than the scan's step
below the answer would be missed. So the answer is *not* a certificate in the sense
of the exact core; the result says so (``certified = False``). With no loss
(P = 0) the exact core's certified K_max is returned.

References
----------
O. L. V. Costa, M. D. Fragoso and R. P. Marques, *Discrete-Time Markov Jump Linear
Systems*, Springer 2005, Theorem 3.9.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from hapstab.analysis.network.jump import JumpSystem, lossy_system
from hapstab.analysis.network.moments import (
    pencil_dimension,
    second_moment_radius,
    unit_crossings,
)
from hapstab.analysis.network.result import LossCurveResult, LossStiffnessResult
from hapstab.errors import check_reals
from hapstab.models.loops import require_loop

__all__ = ["loss_critical_stiffness", "kmax_against_loss", "SCAN", "BISECTION_RTOL"]

#: Largest companion pencil solved by QZ (about 20 s at 3000 on the project's machine,
#: O(d^3)); above it the scan with ARPACK (O(M N^3) per step of its iteration).
MAX_PENCIL = 3000
#: The scan of K, in units of the loss-free K_max (or of m / T^2 when that is infinite):
#: geometric up to 0.05, then steps of 1/32 up to 4, then geometric up to 1000.
SCAN = np.concatenate([np.geomspace(1e-6, 0.05, 12, endpoint=False),
                       np.arange(0.05, 4.0, 1.0 / 32.0), np.geomspace(4.0, 1e3, 25)])
#: The bracket reported around the first root K* of det(I - T(K)) = 0: [K*(1 - s),
#: K*(1 + s)]. rho - 1 is then about s K* rho'(K*) ~ 1e-11 on either side, three orders
#: above its rounding (~1e-14), so both sides are checked with room to spare.
ROOT_STEP = 1e-8
#: Points below the first root where rho is checked < 1 as well (evenly spaced).
CHECKS = 8
#: Bisection stops when the bracket is this narrow (relative): far below the 1e-6 the
#: answer is tested to, and above the rounding of rho near a simple crossing.
BISECTION_RTOL = 1e-10


def _loss_free(loop) -> float:
    from hapstab.analysis.methods import critical_stiffness

    return float(critical_stiffness(loop).critical_stiffness)


def _scale(loop, k0: float) -> float:
    """The scan's unit: the loss-free K_max, or m / T^2 (the lightest port) when that is
    0 or infinite."""
    if math.isfinite(k0) and k0 > 0:
        return k0
    from hapstab.engine.structure import structure_of

    st = structure_of(loop)
    m = min(pt.device.mass + pt.termination.mass for pt in st.ports)
    return float(m) / float(loop.period) ** 2


def _radius(js: JumpSystem, K: float, deadline: float) -> float:
    """rho(T) at K, once the search is within its time budget (a budgeted stop: each
    radius of a large operator costs ARPACK's iteration, O(M N^3) a step, and no count of
    them is known before the search)."""
    if time.monotonic() > deadline:
        from hapstab.budget import BudgetError

        raise BudgetError(f"packet loss: the mean-square search of a {js.order}-state loop "
                          f"with {js.modes} modes ran past its time budget; run it anyway "
                          "with --yes (Python: hapstab.budget.unlimited())")
    return second_moment_radius(js.at(K), js.transition)


def _scan(js: JumpSystem, scale: float, deadline: float = math.inf) -> tuple:
    """(K_lo, K_hi, rho(K_lo), rho(K_hi)) bracketing the first computed rho >= 1 on the
    :data:`SCAN` grid (then bisection), and the scan (K, rho). K_lo = 0 when the scan's
    first K is already unstable; K_hi = inf when the scan ends stable. For operators too
    large for :func:`unit_crossings` (ARPACK on the operator's action)."""
    Ks, rhos = [], []
    lo, r_lo = 0.0, float("nan")
    for g in SCAN:
        K = float(g * scale)
        r = _radius(js, K, deadline)
        Ks.append(K)
        rhos.append(r)
        if r >= 1.0:
            break
        lo, r_lo = K, r
    else:
        return lo, math.inf, r_lo, math.nan, np.array(Ks), np.array(rhos), "scan"
    hi, r_hi = Ks[-1], rhos[-1]
    while lo > 0.0 and hi - lo > BISECTION_RTOL * hi:
        mid = 0.5 * (lo + hi)
        r = _radius(js, mid, deadline)
        if r < 1.0:
            lo, r_lo = mid, r
        else:
            hi, r_hi = mid, r
    return lo, hi, r_lo, r_hi, np.array(Ks), np.array(rhos), "scan"


def _roots(js: JumpSystem, scale: float, deadline: float = math.inf) -> tuple:
    """The same bracket from the first real root of det(I - T(K)) = 0
    (:func:`unit_crossings`): rho is checked below 1 as K -> 0+, at ``CHECKS`` points
    below the root and on both sides of it (``ROOT_STEP``); a check that fails falls
    back to :func:`_scan`."""
    roots = unit_crossings(js.A0, js.A1, js.transition)
    # a floor against division by zero / rounding, far below the answer's own accuracy
    roots = roots[roots > 1e-12 * scale]
    # a floor against division by zero / rounding, far below the answer's own accuracy
    K0 = min(1e-6 * scale, 0.5 * roots[0]) if roots.size else 1e-6 * scale
    r0 = _radius(js, K0, deadline)
    if r0 >= 1.0:
        return 0.0, K0, math.nan, r0, np.array([K0]), np.array([r0]), "roots"
    if not roots.size:
        return _scan(js, scale, deadline)
    lo, hi = roots[0] * (1.0 - ROOT_STEP), roots[0] * (1.0 + ROOT_STEP)
    # a guard against a real root taken for complex (an ill-conditioned crossing): rho
    # must also be below 1 at CHECKS points below the first root
    below = roots[0] * np.arange(1, CHECKS + 1) / (CHECKS + 1)
    r_below = [_radius(js, float(K), deadline) for K in below]
    r_lo, r_hi = _radius(js, lo, deadline), _radius(js, hi, deadline)
    if not (r_lo < 1.0 and max(r_below) < 1.0):
        return _scan(js, scale, deadline)
    return (float(lo), float(hi), r_lo, r_hi, np.array([K0, *below, lo, hi]),
            np.array([r0, *r_below, r_lo, r_hi]), "roots")


def loss_critical_stiffness(loop, loss: float, burst: float | None = None
                            ) -> LossStiffnessResult:
    """Mean-square K_max of ``loop`` when each networked packet is lost with
    probability ``loss`` (independently, or in bursts).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controllers, whole-sample delays. The HVE's position channel and
        each of PEB's directions are networked (:mod:`hapstab.analysis.network.jump`).
    loss : float
        P in [0, 1), the long-run fraction of packets lost on each networked term.
    burst : float, optional
        Mean burst length L >= 1 (samples) of a Gilbert-Elliott chain per term;
        ``None``: independent losses.

    Returns
    -------
    LossStiffnessResult
        ``critical_stiffness``: the largest K found with every scanned K in (0, K]
        mean-square stable (the stable end of the bisection); ``upper_bound``: the
        unstable end. For P = 0 the exact core's certified K_max.

    Raises
    ------
    BudgetError
        The search ran past the time budget (:func:`hapstab.budget.seconds_allowed`;
        ``--yes`` / :func:`hapstab.budget.unlimited` lift it): its cost is not known in
        advance.

    References
    ----------
    Costa, Fragoso and Marques 2005, Theorem 3.9 (mean-square stability iff the
    second-moment operator's spectral radius is < 1); the model of issue 30.
    """
    require_loop(loop)
    t0 = time.perf_counter()
    js = lossy_system(loop, loss, burst)
    k0 = _loss_free(loop)
    d = loop.to_dict()
    common = dict(loss=float(loss), burst=burst, loss_free_critical_stiffness=k0,
                  period=js.period, terms=js.terms, modes=js.modes, order=js.order,
                  loop_dict=d)
    if float(loss) == 0.0:
        return LossStiffnessResult(critical_stiffness=k0, upper_bound=k0, rho_at=math.nan,
                                   rho_above=math.nan, certified=True, scan_K=np.zeros(0),
                                   scan_rho=np.zeros(0), seconds=time.perf_counter() - t0,
                                   **common)
    small = pencil_dimension(js.order, js.modes, js.independent) <= MAX_PENCIL
    from hapstab.budget import seconds_allowed

    deadline = t0 + seconds_allowed()
    lo, hi, r_lo, r_hi, Ks, rhos, how = (_roots if small else _scan)(js, _scale(loop, k0),
                                                                     deadline)
    return LossStiffnessResult(critical_stiffness=lo, upper_bound=hi, rho_at=r_lo,
                               rho_above=r_hi, certified=False, scan_K=Ks, scan_rho=rhos,
                               seconds=time.perf_counter() - t0,
                               search=how, **common)


def kmax_against_loss(loop, losses: Sequence[float] | np.ndarray, burst: float | None = None
                      ) -> LossCurveResult:
    """Mean-square K_max at each loss rate (:func:`loss_critical_stiffness`).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        As for :func:`loss_critical_stiffness`.
    losses : array of float
        Loss rates P in [0, 1).
    burst : float, optional
        Mean burst length (samples); ``None``: independent losses.

    Returns
    -------
    LossCurveResult
    """
    P = check_reals("losses", losses)
    rows = [loss_critical_stiffness(loop, float(p), burst) for p in P]
    return LossCurveResult(tuple(rows))
