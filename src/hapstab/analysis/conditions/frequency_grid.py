"""Frequency sweeps on the unit circle: a dense grid, local refinement of every
promising minimum, and the largest K keeping an affine Hermitian matrix
``A(w) + K C(w)`` positive semidefinite.

Shared by the positive-real test (:mod:`~hapstab.analysis.conditions.positive_real`),
the circle criterion (:mod:`~hapstab.analysis.conditions.circle`) and sampled-data
passivity (:mod:`~hapstab.analysis.conditions.passivity`). Angles ``theta`` are in
rad/sample (theta = w T).
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from hapstab.tolerances import DIVISOR_FLOOR

__all__ = ["theta_grid", "refine_minimum", "refine_minimum_rows", "affine_kmax_rows",
           "psd_limit", "min_eig"]

_GOLD = (3.0 - np.sqrt(5.0)) / 2.0  # 0.381966...: golden-section step


def theta_grid(oscillations: int, points_per_oscillation: int = 48, minimum: int = 512,
               extra: np.ndarray | None = None) -> np.ndarray:
    """Sorted angles in (0, pi], dense enough to resolve ``oscillations`` periods.

    The first point is tiny but positive: the limit w -> 0 matters (it is where
    eq. (13), (18), (29) and (34) bind) and is approached as ``O(theta^2)``, so a
    first point of 1e-7/(oscillations+1) puts the limit within ~1e-14 relative.

    Parameters
    ----------
    oscillations : int
        Number of oscillations of the swept function over [0, pi] (about the
        degree of the trigonometric polynomials involved, e.g. n + 2).
    points_per_oscillation, minimum : int
        Grid density.
    extra : array, optional
        Additional angles (e.g. clustered near poles and zeros close to the circle).
    """
    N = max(minimum, points_per_oscillation * (int(oscillations) + 1))
    _check_grid_cost(N)
    th0 = 1e-7 / (int(oscillations) + 1)  # the w -> 0 limit to ~1e-14 (see above)
    th = np.linspace(0.0, np.pi, N)
    th[0] = th0
    if extra is not None and len(extra):
        e = np.asarray(extra, dtype=float)
        th = np.concatenate([th, e[(e > 0) & (e <= np.pi)]])
    return np.unique(th)


#: Peak bytes an analysis over the grid holds per angle (its frequency responses, the
#: margins): measured 400 (PEB passivity, 480,144 angles, 0.30 GB peak) and 125 (HVE,
#: 2.4e6 angles, 0.40 GB); taken as 450, above both, plus 0.1 GB for the process.
GRID_BYTES_PER_ANGLE = 450.0
#: Seconds per angle of one pass over the grid (PEB passivity: 0.87 s at 480,144 angles,
#: 1.8e-6), taken as 2e-6; a K scan over the grid costs far more and checks its own.
GRID_SECONDS_PER_ANGLE = 2e-6


def _check_grid_cost(angles: int) -> None:
    """Refuse, before it is built, a grid (it grows with the delay) whose analysis is
    over the budget (see the constants above)."""
    from hapstab.budget import Cost, check
    check(Cost(f"a frequency grid of {angles} angles", 1e8 + GRID_BYTES_PER_ANGLE * angles,
               GRID_SECONDS_PER_ANGLE * angles))


def refine_minimum(f: Callable[[np.ndarray], np.ndarray], theta: np.ndarray,
                   values: np.ndarray, n_best: int = 8, iters: int = 48,
                   # above f's rounding (~1e-13 relative) and the first point's offset
                   # from the w -> 0 limit (~1e-14), far below the 1e-6 aimed at
                   zero_rtol: float = 1e-10) -> tuple[float, float]:
    """Global minimum of ``f`` on [theta[0], theta[-1]] from its grid values.

    Every grid local minimum among the ``n_best`` lowest is refined by a
    golden-section search inside its two neighbouring grid cells (vectorised over
    the candidates). 48 golden steps shrink a cell by 0.618^48 ~ 1e-10, far below
    what a 1e-6 relative accuracy in the minimum value needs (the error is
    quadratic in the angle at a smooth interior minimum).

    zero_rtol : float
        How close (relative) the first grid value must be to the minimum for the
        minimum to be reported as the limit w -> 0.

    Returns
    -------
    (theta_min, f_min) : tuple of float
        ``theta_min = 0`` when the minimum is the limit at the grid's first
        point (see :func:`theta_grid`).
    """
    t, v = refine_minimum_rows(lambda rows, t: f(t), theta, np.asarray(values)[None, :],
                               n_best, iters, zero_rtol)
    return float(t[0]), float(v[0])


def refine_minimum_rows(f: Callable[[np.ndarray, np.ndarray], np.ndarray], theta: np.ndarray,
                        values: np.ndarray, n_best: int = 8, iters: int = 48,
                        zero_rtol: float = 1e-10,     # refine_minimum's (its reason there)
                        ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`refine_minimum` of many functions on one grid at once: ``values[r]`` is
    row r's grid, ``f(rows, t)`` row ``rows[i]``'s value at ``t[i]``; every row's
    golden sections run in one vectorised search (each row's steps are the ones
    :func:`refine_minimum` takes for it alone).

    Returns
    -------
    (theta_min, f_min) : tuple of arrays, one entry per row
    """
    v = np.where(np.isnan(values), np.inf, values)
    R, N = v.shape
    best_t, best_v = np.full(R, np.nan), np.full(R, np.inf)
    if N == 0:
        return best_t, best_v
    inf = np.full((R, 1), np.inf)
    left, right = np.hstack([inf, v[:, :-1]]), np.hstack([v[:, 1:], inf])
    is_min = (v <= left) & (v <= right) & np.isfinite(v)
    ib = np.argmin(v, axis=1)
    best_t, best_v = theta[ib].astype(float), v[np.arange(R), ib].astype(float)
    picks = []
    for r in range(R):           # each row's n_best lowest local minima, in its own order
        cand = np.flatnonzero(is_min[r])
        picks.append(cand[np.argsort(v[r, cand])[:n_best]])
    rows = np.repeat(np.arange(R), [p.size for p in picks])
    if rows.size:
        cand = np.concatenate(picks)
        a = theta[np.maximum(cand - 1, 0)].astype(float)
        b = theta[np.minimum(cand + 1, N - 1)].astype(float)
        c, d = a + _GOLD * (b - a), b - _GOLD * (b - a)
        fc, fd = _clean(f(rows, c)), _clean(f(rows, d))
        for _ in range(iters):
            m = fc < fd  # the minimum lies in [a, d]
            c_old, d_old, fc_old, fd_old = c, d, fc, fd
            b = np.where(m, d_old, b)
            a = np.where(m, a, c_old)
            c = np.where(m, a + _GOLD * (b - a), d_old)
            d = np.where(m, c_old, b - _GOLD * (b - a))
            fn = _clean(f(rows, np.where(m, c, d)))
            fc = np.where(m, fn, fd_old)
            fd = np.where(m, fc_old, fn)
        for t, val in ((c, fc), (d, fd)):
            # per row its first lowest candidate (np.argmin's pick within the row)
            order = np.lexsort((np.arange(rows.size), val, rows))
            first = order[np.r_[True, rows[order][1:] != rows[order][:-1]]]
            at = rows[first]
            better = val[first] < best_v[at]
            best_t[at[better]], best_v[at[better]] = t[first][better], val[first][better]
    # the first grid point stands for the limit w -> 0 (see theta_grid); when it is as
    # low as the refined minimum (to rounding), the worst case is that limit
    zero = np.isfinite(v[:, 0]) & (v[:, 0] <= best_v + zero_rtol * np.abs(best_v))
    best_t = np.where(zero, 0.0, best_t)
    best_v = np.where(zero, np.minimum(best_v, v[:, 0]), best_v)
    return best_t, best_v


def affine_kmax_rows(parts: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]],
                     dampings: np.ndarray, oscillations: int, tol_scale: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Per virtual damping B, min over w of the PSD limit of ``A0 + B A1 + K C``
    (:func:`psd_limit`): the K_max of a test whose matrix is affine in K and B (the
    K-B plane's rows, h = K + B g), every row on one grid and one golden search.

    Parameters
    ----------
    parts : callable
        ``parts(theta) -> (A0, A1, C)``, each ``(N,)`` or ``(N, p, p)``.
    dampings : array
        The rows' B.
    oscillations : int
        For :func:`theta_grid`.
    tol_scale : float
        The PSD slack per angle relative to A's largest entry (the single test's).

    Returns
    -------
    (K_max, theta) : arrays, one entry per row
    """
    Bs = np.asarray(dampings, float)

    def limit(A0: np.ndarray, A1: np.ndarray, C: np.ndarray, B: np.ndarray) -> np.ndarray:
        """psd_limit of A0 + B A1 + K C (``B``: one value per angle)."""
        A = A0 + B.reshape(-1, *([1] * (A0.ndim - 1))) * A1
        tol = tol_scale * np.abs(A).reshape(A.shape[0], -1).max(axis=1)
        return psd_limit(A, C, tol)

    def k_of(rows: np.ndarray, t: np.ndarray, first: int = 0) -> np.ndarray:
        return limit(*parts(t), Bs[rows + first])

    th = theta_grid(oscillations)
    grid = parts(th)              # once; each row's grid is the same matrices with its B
    # rows in chunks of ~ROW_VALUES grid values (the search holds ~5 such arrays): a
    # long delay's 1e5 angles times 200 rows would hold 1e8 (each row's answer is its own)
    per = max(1, ROW_VALUES // th.size)
    K, t_min = np.empty(Bs.size), np.empty(Bs.size)
    for r0 in range(0, Bs.size, per):
        sl = slice(r0, r0 + per)
        vals = np.array([limit(*grid, np.full(th.size, B)) for B in Bs[sl]]).reshape(-1, th.size)
        t_min[sl], K[sl] = refine_minimum_rows(functools.partial(k_of, first=r0), th, vals)
    return K, t_min


#: Grid values (rows x angles) :func:`affine_kmax_rows` holds at once: 2e6 doubles, ~16 MB
#: per array.
ROW_VALUES = 2_000_000


def _clean(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return np.where(np.isnan(x), np.inf, x)


def min_eig(H: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue of a stack of Hermitian matrices ``(N, m, m)``, or of
    real scalars ``(N,)``."""
    H = np.asarray(H)
    if H.ndim == 1:
        return H.real.astype(float)
    if H.shape[-1] == 1:
        return H[..., 0, 0].real.astype(float)
    if H.shape[-1] == 2:  # closed form: exact for Hermitian 2x2 and cheaper than eigvalsh
        a, d = H[..., 0, 0].real, H[..., 1, 1].real
        off = np.abs(H[..., 0, 1])
        return (a + d) / 2 - np.hypot((a - d) / 2, off)
    return np.linalg.eigvalsh(H)[..., 0]


def psd_limit(A: np.ndarray, C: np.ndarray, tol: np.ndarray | float = 0.0) -> np.ndarray:
    """Largest K >= 0 with ``A + K' C`` PSD for every K' in [0, K], per angle.

    The set of K for which an affine Hermitian matrix is PSD is an interval
    (the PSD cone is convex), so this is its upper end when A itself is PSD,
    and 0 when it is not (``min_eig(A) < -tol``).

    Parameters
    ----------
    A, C : array
        Hermitian parts at K = 0 and per unit K, shape ``(N,)`` (scalar) or
        ``(N, 2, 2)``.
    tol : float or array
        Slack on ``min_eig(A)`` allowed for rounding.

    Returns
    -------
    (N,) array of float, possibly ``inf``.
    """
    A, C = np.asarray(A), np.asarray(C)
    if A.ndim == 1 or A.shape[-1] == 1:
        a, c = min_eig(A), min_eig(C)
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(c < 0, np.maximum(a, 0.0) / -c, np.inf)
        return np.where(a < -tol, 0.0, k)
    if A.shape[-1] != 2:
        raise ValueError("psd_limit: only scalar or 2x2 Hermitian stacks")
    a11, a22, a12 = A[..., 0, 0].real, A[..., 1, 1].real, A[..., 0, 1]
    c11, c22, c12 = C[..., 0, 0].real, C[..., 1, 1].real, C[..., 0, 1]
    # det(A + K C) = q0 + q1 K + q2 K^2; PSD is lost where it first reaches 0
    q0 = a11 * a22 - np.abs(a12) ** 2
    q1 = a11 * c22 + a22 * c11 - 2.0 * np.real(a12 * np.conj(c12))
    q2 = c11 * c22 - np.abs(c12) ** 2
    # det C that is 0 to rounding (~500 eps of its scale, as for q0 below) is 0: else a
    # singular C (e.g. K T [[1, 1], [1, 1]]) puts a root at K ~ 1e16 where there is none
    q2 = np.where(np.abs(q2) <= 1e-13 * (np.abs(c11) + np.abs(c22)) ** 2, 0.0, q2)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        disc = q1 * q1 - 4.0 * q0 * q2
        sq = np.sqrt(np.maximum(disc, 0.0))
        q = -0.5 * (q1 + np.where(q1 >= 0, sq, -sq))  # no cancellation (Numerical Recipes 5.6)
        r1 = np.where(q2 != 0, q / q2, np.inf)
        r2 = np.where(q != 0, q0 / q, np.inf)
        r1 = np.where((disc >= 0) & (r1 > 0), r1, np.inf)
        r2 = np.where((disc >= 0) & (r2 > 0), r2, np.inf)
        k = np.minimum(r1, r2)
        # singular A (q0 ~ 0): PSD survives K > 0 only if the determinant grows
        scale = np.maximum(np.abs(a11) + np.abs(a22), DIVISOR_FLOOR) ** 2
        sing = np.abs(q0) <= 1e-13 * scale  # det is 0 to rounding: ~500 eps of its scale
        # and q1 > 0 beyond its rounding (the same ~500 eps of its own scale)
        grows = ((q1 > 1e-13 * np.sqrt(scale) * (np.abs(c11) + np.abs(c22)))
                 | ((q1 >= 0) & (q2 >= 0) & (c11 + c22 >= 0)))
        k = np.where(sing, np.where(grows, np.where(q2 < 0, -q1 / q2, np.inf), 0.0), k)
        # when det stays positive the trace cannot change sign: k stays inf
    return np.where(min_eig(A) < -tol, 0.0, k)
