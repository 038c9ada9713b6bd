"""The paper's procedure for K_max: the largest K whose simulated free response
stays bounded (Section 5, the stars of Fig. 5 / Fig. 6).

References
----------
The paper, Fig. 2a, Fig. 3 and Section 5.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hapstab import budget
from hapstab.engine.structure import structure_of
from hapstab.engine.system import SampledSystem, build
from hapstab.errors import AnalysisError, ArgumentTypeError, check_real
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.results import CriticalStiffnessResult
from hapstab.simulation.growth import SNAPSHOTS_PER_STATE, BoundednessVerdict, assess
from hapstab.simulation.propagate import propagate_linear

__all__ = ['critical_stiffness_simulation']


def _stiffness_scale(loop: HapticLoop | TeleoperationLoop) -> float:
    """m/T^2 of the lightest port: the stiffness that moves a mass by its own
    sample-scale motion, the natural unit of K."""
    st = structure_of(loop)
    m = min(pt.device.mass + pt.termination.mass for pt in st.ports)
    return m / loop.period ** 2


#: The downward scan of :func:`critical_stiffness_simulation` stops at this many m/T^2:
#: the exact analysis resolves K from 1e-6 of its own scale (about 2 m/T^2), and a
#: stiffness this small moves the poles by less than the 2000-sample growth fit sees.
_K_FLOOR = 1e-10


#: Simulated runs of one K_max search, for its cost: 16 to 20 on the paper's loops (a
#: scan by the factor 4, then bisection to rtol = 1e-4), rounded up.
SEARCH_RUNS = 25


def search_cost(loop: HapticLoop | TeleoperationLoop, points: int = 1, n_samples: int = 2000
                ) -> budget.Cost:
    """The cost of ``points`` K_max searches by simulation (see
    :func:`critical_stiffness_simulation`) on loops of ``loop``'s size.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (its order sets the cost of each run).
    points : int
        How many searches (periods times delays).
    n_samples : int
        Samples per run before the long-delay rule lengthens it.

    Returns
    -------
    Cost
    """
    N = build(loop).order
    M = max(n_samples, 2 * SNAPSHOTS_PER_STATE * N)
    one = budget.simulation_cost(M, N, 0, runs=SEARCH_RUNS)
    # a run also holds the block propagator (64 N x N) and the fit's N x window matrices
    one = budget.Cost(one.what, one.memory_bytes + 8.0 * N * N * 80, one.seconds)
    return budget.Cost(f"{points} K_max search(es) by simulation ({SEARCH_RUNS} runs of {M} "
                       f"samples of a {N}-state loop each)", one.memory_bytes,
                       points * one.seconds)


def critical_stiffness_simulation(loop: HapticLoop | TeleoperationLoop, *,
                                  # rtol: 0.01 %, far finer than the paper's figures show,
                                  # in ~14 runs from a bracket of ratio 4
                                  n_samples: int = 2000, window: int = 500, rtol: float = 1e-4,
                                  seed: int = 0, ratio: float = 4.0) -> CriticalStiffnessResult:
    """The paper's procedure: the largest K for which the simulated loop stays bounded.

    K is raised from ``1e-6 m/T^2`` by factors of ``ratio`` until the simulated
    free response (from a seeded random initial state, which excites every mode)
    is unbounded, then the last bounded / first unbounded pair is bisected in
    log K to relative width ``rtol``. If the loop is unbounded already at the
    start (e.g. a negative virtual damping B that nearly cancels the device
    damping b leaves K_max ~ (b + B)/(T/2 + t_d), arbitrarily small), K is
    lowered by ``ratio`` down to ``1e-10 m/T^2`` before K_max = 0 is reported. Each verdict
    is :func:`hapstab.simulation.growth.assess` on ``n_samples`` samples (observed explosion, else the
    fitted growth rate).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controller(s); K is varied as in :meth:`hapstab.HapticLoop.with_stiffness`.
    n_samples : int
        Samples per simulated run.
    window : int
        Final samples the growth rate is fitted on.
    rtol : float
        Relative width of the final bracket.
    seed : int
        Seed of the initial state.
    ratio : float
        Step of the upward scan (> 1); like the paper, a stable island between two
        scan points could be missed.

    Returns
    -------
    CriticalStiffnessResult
        ``method="simulation"``; ``details`` has the number of runs, the horizon
        and the verdicts at the final bracket.

    Raises
    ------
    AnalysisError
        If a controller is not a spring-damper.

    References
    ----------
    The paper, Section 5 and the stars of Fig. 5 / Fig. 6.
    """
    sysm = build(loop)
    n_samples, window, rtol, ratio = _check_options(sysm, n_samples, window, rtol, ratio)
    budget.check(search_cost(loop, 1, n_samples))
    # a fit needs several snapshots per state entry (growth.SNAPSHOTS_PER_RANK): long
    # delays get a longer window and run
    window = max(window, SNAPSHOTS_PER_STATE * sysm.order)
    n_samples = max(n_samples, 2 * window)
    T, Ks = loop.period, _stiffness_scale(loop)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ArgumentTypeError(f"seed = {seed!r:.40}: must be a whole number >= 0")
    run = _Runs(sysm, np.random.default_rng(seed).standard_normal(sysm.order), n_samples,
                window, T)
    lo, v_lo, hi, v_hi = _bracket(run, Ks, ratio)
    details: dict[str, Any] = {"runs": run.count, "horizon_samples": n_samples}
    if v_lo is None:
        assert v_hi is not None
        return CriticalStiffnessResult(
            0.0, "simulation", (), f"unbounded already at K = {hi:.4g} N/m: {v_hi.reason}", T,
            loop.delay_in_samples, details=details)
    if v_hi is None:
        return CriticalStiffnessResult(
            math.inf, "simulation", ((0.0, math.inf),),
            f"bounded for every K tried up to {lo:.4g} N/m", T, loop.delay_in_samples,
            details=details)
    while hi / lo - 1 > rtol:
        mid = math.sqrt(lo * hi)
        v = run(mid)
        if v.bounded:
            lo, v_lo = mid, v
        else:
            hi, v_hi = mid, v
    reason = (f"largest K whose simulated free response ({n_samples} samples) stays bounded; "
              f"at K = {lo:.6g}: {v_lo.reason}; at K = {hi:.6g}: {v_hi.reason}")
    details.update(runs=run.count, bracket=[lo, hi],
                   confidence=min((v_lo.confidence, v_hi.confidence),
                                  key=["low", "medium", "high"].index))
    return CriticalStiffnessResult(lo, "simulation", ((0.0, lo),), reason, T,
                                   loop.delay_in_samples, details=details)


def _check_options(sysm: SampledSystem, n_samples: Any, window: Any, rtol: float,
                   ratio: float) -> tuple[int, int, float, float]:
    """The options of :func:`critical_stiffness_simulation`, checked, as Python numbers
    (a numpy int8 window or float32 ratio would carry its own width into the search)."""
    if not sysm.varies_with_K:
        raise AnalysisError("method = 'simulation': needs SpringDamper controller(s) to vary K")
    if isinstance(n_samples, bool) or not (isinstance(n_samples, (int, np.integer))
                                           and n_samples >= 64):
        raise AnalysisError(f"n_samples = {n_samples!r}: must be a whole number >= 64")
    if isinstance(window, bool) or not (isinstance(window, (int, np.integer))
                                        and 16 <= window <= n_samples):
        raise AnalysisError(f"window = {window!r}: must be a whole number in [16, n_samples]")
    rtol, ratio = check_real("rtol", rtol), check_real("ratio", ratio)
    if not 1e-12 <= rtol < 0.1:   # below ~1e-12 the bracket's ends are neighbouring doubles
        raise AnalysisError(f"rtol = {rtol}: must be in [1e-12, 0.1)")
    if not ratio > 1:
        raise AnalysisError(f"ratio = {ratio}: must be > 1")
    return int(n_samples), int(window), rtol, ratio


class _Runs:
    """The verdict on the free response from one seeded state, at any K; counts runs."""

    def __init__(self, sysm: SampledSystem, s0: np.ndarray, n_samples: int, window: int,
                 T: float) -> None:
        self.sysm, self.s0, self.n, self.window, self.T = sysm, s0, n_samples, window, T
        self.Bz = np.zeros((sysm.order, 1))
        self.count = 0

    def __call__(self, K: float) -> BoundednessVerdict:
        self.count += 1
        S = propagate_linear(self.sysm.closed_loop(K)[0], self.Bz, self.s0, None, self.n,
                             block=128)
        v = assess(S, None, self.T, window=self.window)
        if v.verdict == "undecided":     # cannot happen with the window sized above
            raise AnalysisError(f"simulation at K = {K:.6g} N/m cannot decide: {v.reason}")
        return v


def _bracket(run: _Runs, Ks: float, ratio: float
             ) -> tuple[float, BoundednessVerdict | None, float, BoundednessVerdict | None]:
    """The last bounded and first unbounded K of a geometric scan from 1e-6 Ks:
    (lo, v_lo, hi, v_hi); v_lo None if unbounded down to the floor, v_hi None if
    bounded up to 1e4 Ks."""
    lo = 1e-6 * Ks  # below K_max of usual devices (~2bT/m of Ks); lower ones: scan down
    v_lo = run(lo)
    if not v_lo.bounded:
        # a negative virtual damping that nearly cancels the device's leaves K_max far
        # below the usual start: scan down before concluding that no K is stable
        hi, v_hi = lo, v_lo
        while not v_lo.bounded and lo > _K_FLOOR * Ks:
            hi, v_hi = lo, v_lo
            lo /= ratio
            v_lo = run(lo)
        if not v_lo.bounded:
            return lo, None, lo, v_lo
        return lo, v_lo, hi, v_hi
    K = lo
    while K < 1e4 * Ks:
        K *= ratio
        v = run(K)
        if not v.bounded:
            return lo, v_lo, K, v
        lo, v_lo = K, v
    return lo, v_lo, math.inf, None
