"""Boundedness verdict and growth-rate estimate from a simulated trajectory.

The paper decides stability by watching the simulated outputs for boundedness
(Section 5). Near the stability boundary the critical mode of the paper's loops
grows or decays at only ~0.003 1/s per 1 % of K (the net damping b - KT/2 is
what crosses zero), so watching alone would need horizons of hours. Here the
verdict combines what is *observed* (non-finite or exploding state) with a
growth rate *estimated from the trajectory* by dynamic mode decomposition with
control (DMDc): a least-squares linear model of the sample-to-sample map is fitted
to the snapshots and its dominant eigenvalue gives the rate. The fit uses the
trajectory only (never the model's matrices); its residual and its agreement on
the two halves of the window say how sure the verdict is.

Differences ``s[k+1] - s[k]`` are fitted rather than states, so constant offsets
(a step force, a wall's rest position, a rigid-body mode at z = 1) do not count
as growth.

A forced trajectory is not fitted: :func:`combine` judges a linear run on its
free responses (from the initial state, and from an impulse where each force
enters). Nonlinear runs are judged by :mod:`~hapstab.simulation.behaviour`.

References
----------
The paper, Section 5 (boundedness of the simulated outputs); J. L. Proctor,
S. L. Brunton, J. N. Kutz, "Dynamic mode decomposition with control", SIAM J.
Appl. Dyn. Syst. 15(1), 2016.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.results import Result, jsonable
from hapstab.tolerances import DIVISOR_FLOOR

__all__ = ["BoundednessVerdict", "assess", "combine", "dmd_rate"]

#: |state| beyond this (relative to the initial scale) is "observed unbounded".
EXPLODE = 1e12

#: The default window holds at least this many snapshots per state entry (long
#: delays): comfortably above SNAPSHOTS_PER_RANK, which a fit needs to be trusted.
SNAPSHOTS_PER_STATE = 4

#: singular values below this (relative) are rounding, not modes
SVD_RTOL = 1e-9


#: What a verdict was read from, in words (``basis``).
_BASIS = {"bound": "proved by a bound of the model", "rate estimate": "from the decay rate",
          "observed": "observed", "trajectory": "from the trajectory"}


@dataclass(frozen=True)
class BoundednessVerdict(Result):
    """Is the simulated loop bounded, how fast does it grow, and how sure is that.

    Attributes
    ----------
    verdict : {"bounded", "unbounded", "marginal", "undecided"}
        ``marginal``: the fitted dominant mode neither grows nor decays within the
        fit's resolution (a pole on the unit circle: sustained oscillation, or drift
        such as a constant force pushing masses nothing ties to ground).
    growth_rate : float
        Estimated asymptotic rate sigma in 1/s (amplitude ~ exp(sigma t));
        < 0 decays, > 0 grows; ``-inf`` if nothing moves.
    growth_rate_uncertainty : float
        Disagreement of the estimate between the two halves of the window, 1/s.
    confidence : {"high", "medium", "low"}
        ``high``: observed explosion, or a clean linear fit (residual < 1e-6) whose
        rate is > 5 uncertainties from 0; ``medium``: > 1 uncertainty and residual
        < 1e-2; ``low`` otherwise (near the boundary, or nonlinear switching).
    basis : {"observed", "rate estimate"}
    observed_growth : float
        max |ds| over the last tenth of the run / max over the first tenth.
    fit_residual : float
        Relative residual of the linear fit (0 for an exactly linear loop, up to
        rounding).
    reason : str
    behaviour : {"at rest", "settles", "grows", "marginal", "limit cycle", "drifts", "undecided"}
        What the motion does, in words that fit the loop: a linear run ``settles``,
        ``grows`` or is ``marginal``; a nonlinear run settles, oscillates in a
        ``limit cycle`` (``amplitude_m``, ``period_s``), ``grows``, ``drifts`` or is
        ``undecided`` (then ``duration_hint_s`` says how long a run would tell).
    amplitude_m, period_s : float or None
        Limit cycle: half the peak-to-peak position of the port that moves most,
        and the mean time between its upward crossings of its mean.
    duration_hint_s : float or None
        A run length that would decide, when this one is too short to.
    judged_on : str
        What the verdict was read from (e.g. "free response and input channel").
    """

    verdict: str
    growth_rate: float
    growth_rate_uncertainty: float
    confidence: str
    basis: str
    observed_growth: float
    fit_residual: float
    reason: str
    behaviour: str = ""
    amplitude_m: float | None = None
    period_s: float | None = None
    duration_hint_s: float | None = None
    judged_on: str = "trajectory"

    def __post_init__(self) -> None:
        if not self.behaviour:
            b = {"bounded": "settles", "unbounded": "grows"}.get(self.verdict, self.verdict)
            if self.verdict == "bounded" and self.growth_rate == -math.inf:
                b = "at rest"
            object.__setattr__(self, "behaviour", b)

    @property
    def bounded(self) -> bool:
        return self.verdict == "bounded"

    def words(self) -> str:
        """The verdict in words one can quote: ``bounded: settles (high confidence, from
        the decay rate)``; a bounded run whose pattern is not clear yet says so instead of
        ``bounded: undecided``, a run too short to tell instead of ``undecided: undecided``."""
        basis = _BASIS.get(self.basis, self.basis)
        if self.behaviour == "undecided":
            what = ("bounded, its pattern not yet settled" if self.verdict == "bounded"
                    else "undecided: the run is too short to tell")
        elif self.behaviour == self.verdict:
            what = self.verdict
        else:
            what = f"{self.verdict}: {self.behaviour}"
        return f"{what} ({self.confidence} confidence, {basis})"

    def rate_words(self) -> str:
        """The growth rate in words: ``-0.325 1/s``, or ``none: nothing moves`` at rest
        (not ``-inf 1/s``)."""
        if self.growth_rate == -math.inf:
            return "none: nothing moves"
        return f"{self.growth_rate:.3g} 1/s"

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"verdict": self.verdict, "behaviour": self.behaviour,
                         "growth_rate_per_s": self.growth_rate,
                         "growth_rate_uncertainty_per_s": self.growth_rate_uncertainty,
                         "confidence": self.confidence, "basis": self.basis,
                         "judged_on": self.judged_on,
                         "limit_cycle_amplitude_m": self.amplitude_m,
                         "limit_cycle_period_s": self.period_s,
                         "duration_hint_s": self.duration_hint_s,
                         "observed_growth": self.observed_growth,
                         "fit_residual": self.fit_residual, "reason": self.reason})


#: Above this the snapshots are divided by their largest entry first: below it their
#: squares (<= 1e200) and sums over any run (<= 1e8 entries) stay far below 1.8e308.
SQUARES_SAFE = 1e100


def dmd_rate(D: np.ndarray, U: np.ndarray | None = None,
             with_rank: bool = False) -> tuple[float, ...]:
    """Largest |eigenvalue| of the linear map fitted to snapshots, and the fit residual.

    Parameters
    ----------
    D : (M, N) array
        Snapshots d[0..M-1] (here: state differences).
    U : (M, p) array, optional
        Inputs u[k] acting between d[k] and d[k+1] (DMDc).
    with_rank : bool
        Also return the numerical rank of the regression (snapshots and inputs).

    Returns
    -------
    rho : float
        max |lambda| of the fitted map restricted to the excited subspace
        (0 if the snapshots are all zero).
    residual : float
        ||X2 - G Omega|| / ||X2||.
    rank : int
        Only with ``with_rank``.
    """
    big = np.abs(D).max() if D.size else 0.0
    if math.isfinite(big) and big > SQUARES_SAFE:    # (a 1e308 state: D * D overflowed)
        D = D / big                                  # the rate does not depend on the scale
    X1, X2 = D[:-1].T, D[1:].T
    scale = np.sqrt(np.mean(D * D, axis=0))          # similarity scaling: same eigenvalues
    keep = scale > 0
    if not keep.any() or X1.shape[1] < 2:
        return (0.0, 0.0, 0) if with_rank else (0.0, 0.0)
    X1, X2, scale = X1[keep] / scale[keep, None], X2[keep] / scale[keep, None], scale[keep]
    n = X1.shape[0]
    Om = X1
    if U is not None and U.size and np.any(U[:-1]):
        us = np.sqrt(np.mean(U[:-1] ** 2, axis=0))
        us[us == 0] = 1.0
        Om = np.vstack([X1, (U[:-1] / us).T])
    Uo, So, Vo = np.linalg.svd(Om, full_matrices=False)
    r = int(np.sum(So > SVD_RTOL * So[0])) if So.size and So[0] > 0 else 0
    if r == 0:
        return (0.0, 0.0, 0) if with_rank else (0.0, 0.0)
    G = X2 @ Vo[:r].T @ np.diag(1.0 / So[:r]) @ Uo[:, :r].T   # [A_hat, B_hat]
    resid = float(np.linalg.norm(X2 - G @ Om) / max(np.linalg.norm(X2), DIVISOR_FLOOR))
    A_hat = G[:, :n]
    # restrict to the subspace the output snapshots actually span
    U2, S2, _ = np.linalg.svd(X2, full_matrices=False)
    r2 = int(np.sum(S2 > SVD_RTOL * S2[0])) if S2.size and S2[0] > 0 else 0
    if r2 == 0:
        return (0.0, resid, r) if with_rank else (0.0, resid)
    Q = U2[:, :r2]
    ev = np.linalg.eigvals(Q.T @ A_hat @ Q)
    rho = float(np.abs(ev).max())
    return (rho, resid, r) if with_rank else (rho, resid)


def assess(states: np.ndarray, forces: np.ndarray | None, period: float,
           window: int | None = None, differences: bool = True) -> BoundednessVerdict:
    """Verdict on a trajectory at the sampling instants.

    Parameters
    ----------
    states : (M+1, N) array
        The closed-loop state at each sampling instant.
    forces : (M, p) array or None
        Exogenous forces held over each sample (``s[k+1] = A s[k] + G f[k]``).
    period : float
        T in s.
    window : int, optional
        Number of final snapshots the rate is fitted on (default: the last half,
        at most 1024: a linear fit needs a few times the state dimension).
    differences : bool
        Fit the differences ``s[k+1] - s[k]`` (default: a constant offset, such as
        a rigid-body position, is not growth) or the states themselves (a mode at
        z = 1 counts as marginal: a constant force would make it drift).

    Returns
    -------
    BoundednessVerdict

    Notes
    -----
    A forced trajectory can hide its own dynamics: in a sinusoidal steady state
    the input is a linear function of the state, and the fit cannot tell the
    loop from the input. :func:`~hapstab.simulation.run.simulate` therefore judges a
    linear run on its free responses (see :func:`combine`), not on the forced
    trajectory.
    """
    S = np.asarray(states, float)
    if not np.all(np.isfinite(S)):
        return BoundednessVerdict("unbounded", math.inf, 0.0, "high", "observed", math.inf, 0.0,
                                  "the state overflowed (non-finite): observed unbounded")
    D = np.diff(S, axis=0) if differences else S[1:]
    M = D.shape[0]
    if M < 8:
        raise ValueError(f"trajectory of {M} samples: at least 8 are needed for a verdict")
    mag = np.abs(D).max(axis=1)
    tenth = max(1, M // 10)
    first, last = mag[:tenth].max(), mag[-tenth:].max()
    obs = last / first if first > 0 else (math.inf if last > 0 else 1.0)
    s0 = max(np.abs(S[0]).max(), first, DIVISOR_FLOOR)
    with np.errstate(over="ignore"):        # a state of 1e308 at the start: inf, not exploded
        explode = EXPLODE * s0
    if np.abs(S).max() > explode:
        return BoundednessVerdict("unbounded", math.inf, 0.0, "high", "observed", obs, 0.0,
                                  f"the state grew beyond {EXPLODE:.0e} times its initial size")
    # the last half, at most 1024 snapshots, or 4 per state entry when the state is
    # larger (long delays): a fit needs several snapshots per unknown
    W = min(M, window or min(max(M // 2, 16), max(1024, SNAPSHOTS_PER_STATE * S.shape[1])))
    Dw = D[-W:]
    Uw = _input_snapshots(forces, M, differences)
    Uw = None if Uw is None else Uw[-W:]
    if not np.any(Dw):
        what = "constant" if differences else "zero"
        return BoundednessVerdict("bounded", -math.inf, 0.0, "high", "observed", obs, 0.0,
                                  f"the state is {what} over the last part of the run")
    return _fitted_verdict(Dw, Uw, period, obs)


#: A fit is trusted only with at least this many snapshots per fitted dimension:
#: with fewer, least squares matches any data exactly (residual ~1e-15) and its
#: eigenvalues are noise (a 68-sample run of a loop with 100 delay states was
#: "unbounded, high" at 13.7 1/s while it decays).
SNAPSHOTS_PER_RANK = 3


def _input_snapshots(forces: np.ndarray | None, M: int, differences: bool) -> np.ndarray | None:
    """The input acting between snapshot k and k+1, row k (DMDc pairs U[k] with D[k]).

    With differences, d[k+1] = A d[k] + G (f[k+1] - f[k]); with states,
    s[k+2] = A s[k+1] + G f[k+1]: either way row k holds what enters at k+1.
    """
    if forces is None or not np.size(forces):
        return None
    F = np.asarray(forces, float).reshape(M, -1)
    U = np.zeros_like(F)
    U[:-1] = np.diff(F, axis=0) if differences else F[1:]
    return U


def _fitted_verdict(Dw: np.ndarray, Uw: np.ndarray | None, period: float,
                    obs: float) -> BoundednessVerdict:
    """The DMD(c) rate of the window, its uncertainty from the two halves, the verdict."""
    W = Dw.shape[0]
    rho, resid, rank = dmd_rate(Dw, Uw, with_rank=True)
    half = W // 2
    rates = []
    for sl in (slice(0, half), slice(half, W)):
        r_, _ = dmd_rate(Dw[sl], None if Uw is None else Uw[sl])
        rates.append(math.log(r_) / period if r_ > 0 else -math.inf)
    rate = math.log(rho) / period if rho > 0 else -math.inf
    finite = [r for r in rates if math.isfinite(r)]
    unc = max((abs(r - rate) for r in finite), default=0.0) if math.isfinite(rate) else 0.0
    # |lambda| is not resolved better than rounding (1e-12) nor than the fit itself:
    # a relative residual r leaves |lambda| uncertain by about r
    unc = max(unc, max(1e-12, resid) / period)
    short = W < SNAPSHOTS_PER_RANK * (rank + 1)
    if short:
        conf = "low"
    elif not math.isfinite(rate):
        conf = "high"
    elif resid < 1e-6 and abs(rate) > 5 * unc:  # linear to ~6 digits, the rate 5 x clear
        conf = "high"
    elif resid < 1e-2 and abs(rate) > unc:      # linear to ~2 digits, the rate clear
        conf = "medium"
    else:
        conf = "low"
    verdict = "unbounded" if rate > 0 else "bounded"
    what = "grows" if rate > 0 else "decays"
    if math.isfinite(rate) and abs(rate) <= unc:
        verdict, what = "marginal", "neither grows nor decays (a pole on the unit circle)"
    reason = (f"fitted dominant mode {what}: rate {rate:.4g} 1/s (+-{unc:.2g}), linear-fit "
              f"residual {resid:.1e}; observed change over the run x{obs:.3g}")
    hint = None
    if short:
        verdict = "undecided"
        need = 2 * SNAPSHOTS_PER_RANK * (rank + 1) * period      # the window is half the run
        reason += (f"; but {W} snapshots are too few for a fit of rank {rank}: run at least "
                   f"{need:.3g} s")
        hint = need
    return BoundednessVerdict(verdict, rate, unc, conf, "rate estimate", obs, resid, reason,
                              duration_hint_s=hint)


_CONF = ("low", "medium", "high")


def combine(parts: list[tuple[str, BoundednessVerdict]]) -> BoundednessVerdict:
    """One verdict for a linear run from the verdicts of its free responses.

    A linear run is the sum of the free response from its initial state and the
    responses to its inputs; a bounded input gives a bounded response exactly when
    the loop's response to an impulse where it enters decays. So the run is judged
    on those homogeneous responses, never on the forced trajectory (whose steady
    state a fit would mistake for the loop's own dynamics).

    Parameters
    ----------
    parts : list of (what, verdict)
        E.g. ``("free response from the initial state", v)``.

    Returns
    -------
    BoundednessVerdict
        The verdict of the fastest-growing part; ``confidence`` is that part's if
        it grows, else the lowest of the parts that move.
    """
    moving = [(w, v) for w, v in parts if v.growth_rate > -math.inf or v.verdict != "bounded"]
    judged = "; ".join(w for w, _ in parts)
    if not moving:
        return BoundednessVerdict("bounded", -math.inf, 0.0, "high", "observed", 1.0, 0.0,
                                  "nothing moves: the loop stays at rest", "at rest",
                                  judged_on=judged)
    _what, top = max(moving, key=lambda wv: wv[1].growth_rate)
    conf = top.confidence if top.verdict != "bounded" else min(
        (v.confidence for _, v in moving), key=_CONF.index)
    reason = "; ".join(f"{w}: {v.reason}" for w, v in moving)
    if top.verdict == "bounded":
        reason = "every motion decays, so the run stays bounded: " + reason
    hints = [v.duration_hint_s for _, v in moving if v.duration_hint_s]
    return BoundednessVerdict(top.verdict, top.growth_rate, top.growth_rate_uncertainty, conf,
                              top.basis, top.observed_growth, max(v.fit_residual for _, v in moving),
                              reason, judged_on=judged, duration_hint_s=max(hints, default=None))
