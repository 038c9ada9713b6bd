"""A device's mass, damping and Coulomb friction from a recorded run.

A log holds, at each sampling instant t_k = t_0 + k T, the force the controller
commanded (held until the next sample) and the position the encoder read. The
parameters ``theta = (m, b, f_c, x_0, v_0)`` are estimated by output-error nonlinear
least squares on the exact sampled model (:mod:`hapstab.analysis.identification.identify_model`: the
zero-order hold solved in closed form, Coulomb friction's stick-slip events located
exactly), with the encoder's quantisation in the measurement.

Noise model
-----------
``y_k = Q(x(t_k) + e_k)``: the commanded force is applied exactly, ``e_k`` is white
sensor noise, ``Q`` the encoder (``floor``: ``Delta floor(x / Delta)``, whose error has
mean ``-Delta / 2``; ``nearest``: mean 0). The reading plus that mean,
``x(t_k) + eps_k``, is fitted; ``eps_k`` (noise plus quantisation error, variance
``sigma^2 + Delta^2 / 12`` while the device moves by more than a step between samples:
Widrow's model) is treated as independent with one unknown variance ``s^2``.

Confidence intervals
--------------------
Wald intervals of nonlinear least squares: ``theta_hat +- t_{1-alpha/2, N-p} se``,
``se`` the larger of ``sqrt(diag(s^2 (J^T J)^{-1}))`` (``s^2 = RSS / (N - p)``) and the
Newey-West sandwich's (errors correlated from sample to sample: an encoder reading of a
slowly moving device), J the Jacobian of the model's positions at the estimate (central
differences). They are asymptotic: they
cover the truth at about the nominal rate when the errors are as above and the
estimates far from their bounds (b, f_c >= 0); a lower end below 0 is cut at 0.
Friction is kept (``friction="auto"``) when its interval excludes 0.

References
----------
L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, Sec. 7.3
(output-error models) and Sec. 9.3 (eq. 9.17: the covariance of the estimate);
G. A. F. Seber and C. J. Wild, *Nonlinear Regression*, 1989, Sec. 5.1 (eq. 5.4,
the t-based intervals); B. Widrow and I. Kollar, *Quantization Noise*, 2008, Ch. 4; W. K. Newey and K. D.
West, "A simple, positive semi-definite, heteroskedasticity and autocorrelation
consistent covariance matrix", *Econometrica* 55(3), 1987 (eq. 2, Bartlett weights);
D. W. K. Andrews, *Econometrica* 59(3), 1991 (bandwidths).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hapstab.analysis.identification.identify_log import read_log
from hapstab.analysis.identification.identify_model import predict
from hapstab.analysis.identification.identify_result import IdentificationResult
from hapstab.errors import AnalysisError, ModelError, check_real
from hapstab.models.parts import quantize

__all__ = ["identify", "FRICTION_CHOICES"]

#: What ``friction`` may be: estimate it and keep it when the data shows it, always, never.
FRICTION_CHOICES = ("auto", "yes", "no")
#: Largest condition number of the column-scaled J^T J: beyond it the data cannot tell the
#: parameters apart (their intervals would rest on the last digits of J, whose central
#: differences carry ~1e-10 relative error).
_CONDITION = 1e10


#: The identification's time per sample of its log (s), for the time budget.
SECONDS_PER_SAMPLE = 1e-3


def identify(log: Any, *, resolution_m: float | None = None, quantizer: str = "floor",
             friction: str | bool = "auto", confidence: float = 0.95,
             columns: tuple[str, str, str] | None = None) -> IdentificationResult:
    """Estimate a device's m, b (and f_c) from a recorded run, with confidence intervals.

    Parameters
    ----------
    log : str, os.PathLike, dict or (N, 3) array
        A CSV file with a header (time in s, commanded force in N, measured position in
        m; see :func:`~hapstab.analysis.identification.identify_log.read_log`), a dict of three arrays
        (``time_s``, ``force_N``, ``position_m``) or an array of those three columns.
    resolution_m : float, optional
        The encoder's step Delta in m (default: no quantisation).
    quantizer : {"floor", "nearest"}
        How the encoder reads (as in :func:`hapstab.simulate`).
    friction : {"auto", "yes", "no"} or bool
        Estimate Coulomb friction and keep it when its interval excludes 0 (auto), always
        (yes / True), or never (no / False).
    confidence : float
        The intervals' level, 0.5 ... 0.9999.
    columns : tuple of str, optional
        The CSV's time, force and position column names, when they are not recognised.

    Returns
    -------
    IdentificationResult

    Raises
    ------
    ModelError
        A malformed log (NaN, non-uniform time, too short, a period or values outside the
        models' range) or option.
    BudgetError
        A log whose fit would take longer than the time budget (about
        :data:`SECONDS_PER_SAMPLE` a sample; ``--yes`` / :func:`hapstab.budget.unlimited`).
    AnalysisError
        Data that cannot identify the parameters (no excitation; parameters the run
        cannot tell apart), with the reason.

    References
    ----------
    Ljung (1999), Sec. 7.3 and eq. (9.17); Seber and Wild (1989), eq. (5.4).
    """
    level = check_real("confidence", confidence)
    if not 0.5 <= level <= 0.9999:
        raise ModelError(f"confidence = {confidence!r}: allowed 0.5 ... 0.9999")
    fr = _friction_choice(friction)
    t, F, y, T, source = read_log(log, columns)
    from hapstab import budget
    # the fit's simulations of the log: ~0.7-0.8 ms a sample (measured, 20,000 and
    # 100,000 samples on this 2-core machine: 13 and 83 s), rounded up
    budget.check(budget.Cost(f"identification from a log of {t.size} samples",
                             0.0, SECONDS_PER_SAMPLE * t.size))
    res = None if resolution_m is None else check_real("resolution_m", resolution_m,
                                                       positive=True)
    if quantizer not in ("floor", "nearest"):
        raise ModelError(f"quantizer = {quantizer!r}: allowed: floor, nearest")
    _excited(F, y, res)
    target = y + (res / 2 if res and quantizer == "floor" else 0.0)
    fit = _fit(F, target, T, level, fr != "no")
    if fr == "auto" and fit["friction"] and not fit["low"][2] > 0:
        fit = _fit(F, target, T, level, False, fc_upper=fit["high"][2])
    return IdentificationResult(
        time_s=t, force_N=F, position_m=y, fitted_m=fit["x"], period_s=T,
        estimate=tuple(fit["theta"]), low=tuple(fit["low"]), high=tuple(fit["high"]),
        std_error=tuple(fit["se"]), residual_std_m=fit["s"], confidence=level,
        resolution_m=res, quantizer=quantizer, friction=fr, friction_upper_N=fit["fc_upper"],
        friction_fitted=fit["friction"], source=source,
        whiteness=_lag1(target - fit["x"]), check=_readback(fit, F, T, res, quantizer, y))


def _friction_choice(friction: Any) -> str:
    if friction is True or friction is False:
        return "yes" if friction else "no"
    if not isinstance(friction, str) or friction not in FRICTION_CHOICES:
        raise ModelError(f"friction = {friction!r}: allowed: auto, yes, no (or True, False)")
    return friction


def _excited(F: np.ndarray, y: np.ndarray, res: float | None) -> None:
    """Refuse a run that cannot identify m and b: no force, or no motion to speak of."""
    if not np.any(F[:-1] != F[0]) and F[0] == 0:
        raise AnalysisError("force: zero over the whole log: no excitation (the motion then "
                            "shows no mass); record a run with a varying commanded force")
    if np.ptp(F[:-1]) == 0:
        raise AnalysisError(f"force: constant ({F[0]:g} N) over the whole log: too little "
                            "excitation to tell mass from damping reliably; use a varying "
                            "force (chirp, steps, noise)")
    steps = np.ptp(y) / res if res else math.inf
    if steps < 20 or np.ptp(y) == 0:
        raise AnalysisError(f"position: travels {np.ptp(y):.3g} m ({steps:.3g} encoder steps) "
                            "over the log: too little motion to identify the device (need "
                            ">= 20 steps); apply a larger force")


def _initial(F: np.ndarray, y: np.ndarray, T: float, friction: bool) -> list[np.ndarray]:
    """Starts of the search, best first: the linear least squares in (x0, v0, 1/m, f_c/m)
    at the best a = b/m of a log-spaced scan (variable projection), for the friction-free
    device and, with friction, from a few friction levels, each refined three times on
    the slide / stick pattern of the model it gives (a stuck sample feels no net force)."""
    N = y.size
    t = np.arange(N) * T
    grid = np.concatenate([[0.0], np.geomspace(0.01 / (N * T), 0.5 / T, 60)])

    def solve(a: float, sgn: np.ndarray | None) -> tuple[float, np.ndarray]:
        moving = F if sgn is None else np.where(np.isnan(sgn), 0.0, F)
        cols = [np.ones(N), t if a == 0 else -np.expm1(-a * t) / a,
                predict(1.0, a, 0.0, 0.0, 0.0, moving, T)]
        if sgn is not None:
            cols.append(-predict(1.0, a, 0.0, 0.0, 0.0, np.nan_to_num(sgn), T))
        D = np.column_stack(cols)
        c = np.linalg.lstsq(D, y, rcond=None)[0]
        return float(np.sum((D @ c - y) ** 2)), c

    def best(sgn: np.ndarray | None) -> tuple[float, np.ndarray]:
        a = min(grid, key=lambda g: solve(g, sgn)[0])
        cost, c = solve(a, sgn)
        m = 1 / c[2] if c[2] > 0 else 1.0
        fc = max(c[3] * m, 0.0) if sgn is not None else 0.0
        return cost, np.array([m, a * m, fc, c[0], c[1]])

    cost, th = best(None)
    starts = [(cost, th)]
    if friction:
        for share in (0.02, 0.1, 0.3):
            cand = th.copy()
            cand[2] = share * float(np.abs(F).max())
            for _ in range(3):
                cost, cand = best(_pattern(cand, F, T))
            starts.append((cost, cand))
    return [s for _, s in sorted(starts, key=lambda cs: cs[0])]


def _pattern(th: np.ndarray, F: np.ndarray, T: float) -> np.ndarray:
    """Each sample's direction of sliding in the model ``th`` (+-1, 0 at rest) and NaN
    where it sticks the whole sample."""
    dx = np.diff(predict(th[0], th[1], th[2], th[3], th[4], F, T), append=np.nan)
    out = np.sign(dx)
    out[dx == 0] = np.nan
    return out


def _fit(F: np.ndarray, y: np.ndarray, T: float, level: float, friction: bool,
         fc_upper: float | None = None) -> dict[str, Any]:
    """The least-squares estimate, its Jacobian's covariance and the intervals."""
    from scipy.stats import t as student

    idx = [0, 1, 2, 3, 4] if friction else [0, 1, 3, 4]
    starts = _initial(F, y, T, friction)

    def full(p: np.ndarray) -> np.ndarray:
        th = np.zeros(5)
        th[idx] = p
        return th

    # least-squares stops and floors: far below the stated intervals
    big = np.full(y.size, 1e6 * max(float(np.ptp(y)), 1e-12))

    def resid(p: np.ndarray) -> np.ndarray:
        # a trial step of the unbounded search may leave the physical region (m <= 0,
        # b < 0): a huge residual makes it reject the step
        m, b, fc, x0, v0 = (float(v) for v in full(p))
        if not m > 0:
            return big
        try:
            with np.errstate(all="ignore"):
                r = predict(m, b, fc, x0, v0, F, T) - y
        except (OverflowError, ValueError, ZeroDivisionError):
            return big
        return r if np.all(np.isfinite(r)) else big

    scale = _scales(starts[0], y, T, F)[idx]
    p = _search(resid, [s[idx] for s in starts], scale,
                # least-squares stops and floors: far below the stated intervals
                np.array([1e-9, 0.0, 0.0, -np.inf, -np.inf])[idx])
    J = _jacobian(resid, p, scale)
    N, k = y.size, len(idx)
    r = resid(p)
    s2 = float(r @ r) / (N - k)
    se = np.sqrt(np.diag(_covariance(J, s2, idx, r, N / (N - k))))
    q = float(student.ppf(0.5 + level / 2, N - k))
    th, ses = full(p), full(se)
    low, high = th - q * ses, th + q * ses
    low[1:3] = np.maximum(low[1:3], 0.0)
    return {"theta": th, "se": ses, "low": low, "high": high, "s": math.sqrt(s2),
            "x": r + y, "friction": friction,
            "fc_upper": fc_upper if not friction else None}


def _search(resid: Any, starts: list[np.ndarray], scale: np.ndarray,
            lo: np.ndarray) -> np.ndarray:
    """The least-squares minimum found from the starts (the lowest of their local minima).

    Levenberg-Marquardt (MINPACK) converges in a few Jacobians from a good start; the
    bounded trust region (slower, ~50 Jacobians) only where it leaves m > 0, b, f_c >= 0.
    With friction the sum of squares has local minima (other stick-slip patterns), hence
    several starts."""
    from scipy.optimize import least_squares

    best, cost = starts[0], math.inf
    for p0 in starts:
        sol = least_squares(resid, p0, x_scale=scale, method="lm",
                            # least-squares stops and floors: far below the stated intervals
                            xtol=1e-10, ftol=1e-10, gtol=1e-10)
        if np.any(sol.x < lo):
            # least-squares stops and floors: far below the stated intervals
            p1 = np.maximum(sol.x, lo + scale * 1e-6 * (lo > -np.inf))
            sol = least_squares(resid, p1, bounds=(lo, np.inf), x_scale=scale, method="trf",
                                # least-squares stops and floors: far below the stated intervals
                                xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=200)
        if sol.cost < cost:
            best, cost = sol.x, sol.cost
    return np.asarray(best)


def _scales(th0: np.ndarray, y: np.ndarray, T: float, F: np.ndarray) -> np.ndarray:
    """A typical size of each parameter (the search's and the differences' scale)."""
    N = y.size
    # least-squares stops and floors: far below the stated intervals
    m = max(th0[0], 1e-6)
    # least-squares stops and floors: far below the stated intervals
    travel = max(float(np.ptp(y)), 1e-12)
    return np.array([m, max(th0[1], m / (N * T)),
                     max(th0[2], 1e-2 * float(np.sqrt(np.mean(F ** 2)))),
                     max(abs(th0[3]), travel), travel / (N * T)])


def _jacobian(resid: Any, p: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Central differences of the model's positions, step 1e-6 of each parameter's scale
    (truncation ~1e-12 relative, rounding ~eps / 1e-6 ~ 1e-10: below any interval's
    digits); one-sided forward at a bound (b or f_c at 0)."""
    cols = []
    for j in range(p.size):
        # least-squares stops and floors: far below the stated intervals
        h = 1e-6 * scale[j]
        up, dn = p.copy(), p.copy()
        up[j] += h
        if j in (1, 2) and p[j] - h < 0:
            cols.append((resid(up) - resid(p)) / h)
            continue
        dn[j] -= h
        cols.append((resid(up) - resid(dn)) / (2 * h))
    return np.column_stack(cols)


def _covariance(J: np.ndarray, s2: float, idx: list[int], r: np.ndarray,
                dof: float) -> np.ndarray:
    """The estimate's covariance: the larger of ``s^2 (J^T J)^{-1}`` and the Newey-West
    sandwich (serially correlated errors), per parameter; refusing a Jacobian whose
    columns the data cannot tell apart.

    Quantisation errors are not independent when the device moves less than an encoder
    step between samples (Widrow's condition fails: a reading stays in one step for
    several samples, its error drifts slowly). The heteroskedasticity and autocorrelation
    consistent sandwich ``A^{-1} S A^{-1}`` (``A = J^T J``; ``S`` the Bartlett-weighted
    sum of ``J_k^T r_k r_{k+l} J_{k+l}`` over lags ``|l| <= L``) covers that; ``dof``
    (``N / (N - p)``) is its small-sample factor. Without it the 95 % intervals held b
    only 86 % of the time on noise-free, slowly moving logs (Newey and West 1987;
    Andrews 1991)."""
    names = ["mass", "damping", "friction", "initial position", "initial velocity"]
    d = np.linalg.norm(J, axis=0)
    if np.any(d == 0):
        j = int(np.flatnonzero(d == 0)[0])
        raise AnalysisError(f"log: the positions do not depend on the {names[idx[j]]}: it "
                            "cannot be identified from this run; excite the device more")
    Js = J / d
    cond = np.linalg.cond(Js.T @ Js)
    if not cond < _CONDITION:
        raise AnalysisError(f"log: the run cannot tell the parameters apart (condition "
                            f"number {cond:.3g} > {_CONDITION:.0e}); use a richer force "
                            "(several amplitudes and frequencies, reversals)")
    inv = np.linalg.inv(Js.T @ Js)
    sandwich = inv @ _long_run(Js * r[:, None], _bandwidth(r)) @ inv * dof
    white = s2 * inv
    out = white.copy()
    np.fill_diagonal(out, np.maximum(np.diag(white), np.diag(sandwich)))
    return out / np.outer(d, d)


def _bandwidth(r: np.ndarray) -> int:
    """Lags of the sandwich: Newey and West's ``4 (N / 100)^{2/9}``, widened to the lag
    where the residuals' autocorrelation first falls below ``2 / sqrt(N)`` (the white
    noise band; quantisation errors of a slow device stay correlated longer), at most
    ``N / 10`` lags."""
    N = r.size
    base = int(4 * (N / 100) ** (2 / 9))
    c = r - r.mean()
    den = float(c @ c)
    if den <= 0:
        return base
    limit = max(base, N // 10)
    for lag in range(1, limit + 1):
        if abs(float(c[lag:] @ c[:-lag]) / den) < 2 / math.sqrt(N):
            return max(base, 2 * lag)
    return limit


def _long_run(g: np.ndarray, L: int) -> np.ndarray:
    """Bartlett-weighted long-run covariance ``sum_{|l| <= L} (1 - |l| / (L + 1))
    sum_k g_k^T g_{k+l}`` of the score rows ``g_k = J_k r_k``."""
    S = g.T @ g
    for lag in range(1, L + 1):
        G = g[lag:].T @ g[:-lag]
        S = S + (1 - lag / (L + 1)) * (G + G.T)
    return S


def _lag1(r: np.ndarray) -> float:
    """Lag-1 autocorrelation of the residuals (near 0 for the white errors assumed)."""
    r = r - r.mean()
    den = float(r @ r)
    return float(r[1:] @ r[:-1]) / den if den > 0 else 0.0


def _readback(fit: dict[str, Any], F: np.ndarray, T: float, res: float | None,
              quantizer: str, y: np.ndarray) -> float:
    """Share of samples whose reading the fitted model, quantised, reproduces within one
    encoder step (a plain check of the fit, independent of the noise model)."""
    if not res:
        return math.nan
    q = quantize(fit["x"], res, quantizer)
    # least-squares stops and floors: far below the stated intervals
    return float(np.mean(np.abs(q - y) <= res * (1 + 1e-9)))

