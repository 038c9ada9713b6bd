"""The small-gain jitter margin: a sufficient condition for stability under every delay
sequence in [lo, hi].

**The theorem used** (the discrete-time jitter margin of Kao & Lincoln 2004, in the
form of Cervin, Lincoln et al. 2004, Sec. 3). Write the delayed measurement as the
nominal one plus the jitter: ``y_t[k] = v_t[k] + r_t[k]`` with ``v_t[k] = x_t[k - lo]``
and ``r_t[k] = v_t[k - delta_k] - v_t[k]``, delta_k = d_k - lo in {0, ..., N},
N = hi - lo. With ``w_t = (1 - z^-1) v_t``, ``r_t[k] = -sum_{i < delta_k} w_t[k - i]``,
so by Cauchy-Schwarz ``|r_t[k]|^2 <= N sum_{i < N} |w_t[k - i]|^2`` and, summing over k,

    ||r_t||_2 <= N ||w_t||_2      for *every* sequence delta_k in {0, ..., N}

(no assumption on how delta_k varies: the bound covers arbitrary switching, a superset
of the admissible sequences). The loop is the nominal loop (every delay lo, a linear
time-invariant system from r to w, ``M(z) = C (zI - A_lo)^-1 B``) closed by this
operator, causal and of l2 gain <= N. By the small-gain theorem, if

1. the nominal loop is stable (rho(A_lo(K)) < 1; the exact core's K_max at delay lo
   says on which K), and
2. ``N ||D M D^-1||_inf < 1`` for some constant positive diagonal D (D = 1 for the HVE,
   whose M is scalar: ``N |e^{jw} - 1| |G C / (1 + G C e^{-j w lo})| < 1`` for every
   w, G C the loop gain without delay; for PEB each direction's jitter operator is its
   own, so a constant D commutes with them),

the loop is l2-stable under every delay sequence: every signal of the loop is square
summable, and the state tends to 0, from any initial state.

**Evaluation.** ||D M D^-1||_inf by a frequency grid (log-spaced near w = 0, linear
up to pi, and the angles of A_lo's eigenvalues), then the level-set test of Bruinsma &
Steinbuch adapted to discrete time: at a level g above the largest singular value
found, the symplectic pencil ``[[A, B B^T / g^2], [0, I]] - z [[I, 0], [C^T C, A^T]]``
has an eigenvalue on the unit circle exactly where g is a singular value of M; where
it has none, ||M||_inf < g. Floating point (LAPACK's QZ), not enclosed.

References
----------
C.-Y. Kao and B. Lincoln, "Simple stability criteria for systems with time-varying
delays", Automatica 40(8), 2004, pp. 1429-1434.
A. Cervin, B. Lincoln, J. Eker, K.-E. Arzen and G. Buttazzo, "The jitter margin and its
application in the design of real-time control systems", RTCSA 2004.
N. A. Bruinsma and M. Steinbuch, "A fast algorithm to compute the H-infinity norm of a
transfer function matrix", Systems & Control Letters 14(4), 1990.
"""

from __future__ import annotations

import numpy as np
from scipy import linalg as sla
from scipy.optimize import minimize_scalar

__all__ = ["hinf_norm", "small_gain"]

#: The level tested above the largest gain found: 1 + 1e-6 (the grid's value is refined
#: by the level-set test to this relative width; far above the rounding of the gain, far
#: below any margin a user reads).
HINF_REL = 1e-6
#: An eigenvalue of the pencil within 1e-6 of |z| = 1 counts as on it: QZ does not keep
#: the symplectic pairing (z, 1/conj(z)), so an eigenvalue on the circle comes back
#: perturbed by about the rounding times its condition; a false "on" only adds
#: frequencies to evaluate, never a wrong bound.
UNIT_TOL = 1e-6


def _responses(A: np.ndarray, B: np.ndarray, C: np.ndarray, w: np.ndarray) -> np.ndarray:
    """C (e^{jw} I - A)^-1 B at each w, (W, m, m) (dense solves)."""
    z = np.exp(1j * w)
    n = A.shape[0]
    return C @ np.linalg.solve(z[:, None, None] * np.eye(n) - A, B.astype(complex))


def _sigma(G: np.ndarray) -> np.ndarray:
    """The largest singular value of each G[i] (1 x 1 and 2 x 2 in closed form:
    sigma^2 = (|G|_F^2 + sqrt(|G|_F^4 - 4 |det G|^2)) / 2)."""
    if G.shape[-1] == 1:
        return np.abs(G[:, 0, 0])
    if G.shape[-1] == 2:
        f = (np.abs(G) ** 2).sum(axis=(1, 2))
        det = np.abs(G[:, 0, 0] * G[:, 1, 1] - G[:, 0, 1] * G[:, 1, 0])
        return np.sqrt((f + np.sqrt(np.maximum(f * f - 4 * det * det, 0.0))) / 2)
    return np.linalg.svd(G, compute_uv=False)[:, 0]


def _gains(A: np.ndarray, B: np.ndarray, C: np.ndarray, w: np.ndarray) -> np.ndarray:
    """sigma_max(C (e^{jw} I - A)^-1 B) at each w."""
    return _sigma(_responses(A, B, C, w))


def _grid(A: np.ndarray) -> np.ndarray:
    ang = np.abs(np.angle(np.linalg.eigvals(A)))
    # from 1e-7 rad/sample (a 0.016 mHz oscillation at 1 kHz; M has a zero at w = 0, so
    # nothing below it can peak), 400 log-spaced to 0.1 and 600 linear to pi, and each
    # eigenvalue's angle with its neighbours 0.1 % either side (the resonances)
    return np.unique(np.concatenate([np.geomspace(1e-7, 1e-1, 400), np.linspace(0.0, np.pi, 600),
                                     ang, np.clip(ang * (1 + np.array([[-1e-3], [1e-3]])), 0,
                                                  np.pi).ravel()]))


def _on_circle(A: np.ndarray, B: np.ndarray, C: np.ndarray, g: float) -> np.ndarray:
    """Angles in [0, pi] where g is a singular value of M (the pencil's unit-circle
    eigenvalues)."""
    n = A.shape[0]
    I0, Z = np.eye(n), np.zeros((n, n))
    F = np.block([[A, B @ B.T / g ** 2], [Z, I0]])
    E = np.block([[I0, Z], [C.T @ C, A.T]])
    with np.errstate(divide="ignore", invalid="ignore"):
        z = sla.eigvals(F, E)
    z = z[np.isfinite(z)]
    return np.sort(np.abs(np.angle(z[np.abs(np.abs(z) - 1.0) <= UNIT_TOL])))


def hinf_norm(A: np.ndarray, B: np.ndarray, C: np.ndarray, iterations: int = 30) -> float:
    """An upper end of ||C (zI - A)^-1 B||_inf (A stable): the grid's largest gain,
    raised by the level-set test until the pencil has no unit-circle eigenvalue.

    Parameters
    ----------
    A, B, C : arrays
        (n, n), (n, m), (m, n).
    iterations : int
        Level-set rounds; inf if the test never clears (it has not, in any loop tried).

    Returns
    -------
    float
    """
    w = _grid(A)
    s = _gains(A, B, C, w)
    best = float(s.max())
    if best == 0.0:
        return 0.0
    for _ in range(iterations):
        g = best * (1.0 + HINF_REL)
        ang = _on_circle(A, B, C, g)
        if ang.size == 0:
            return g
        probe = np.concatenate([ang, (ang[:-1] + ang[1:]) / 2])
        top = float(_gains(A, B, C, probe).max())
        for a in ang:                           # local maximum around each crossing
            # 0.1 % of the angle either side (1e-9 rad: a floor for a = 0)
            span = max(1e-9, 1e-3 * a)
            r = minimize_scalar(lambda t: -_gains(A, B, C, np.array([t]))[0],
                                bounds=(max(0.0, a - span), min(np.pi, a + span)),
                                # to 1e-12 rad: far narrower than any resonance
                                method="bounded", options={"xatol": 1e-12})
            top = max(top, -float(r.fun))
        if top <= g:            # every crossing spurious (a QZ eigenvalue near the circle)
            return g
        best = top
    return float("inf")


def small_gain(A: np.ndarray, B: np.ndarray, C: np.ndarray, N: int) -> tuple[float, float]:
    """N min_D ||D M D^-1||_inf (< 1: the jitter margin holds) and the D used.

    Parameters
    ----------
    A, B, C : arrays
        The nominal loop and the jitter's input and output (:class:`.JitterModes`).
    N : int
        hi - lo, samples.

    Returns
    -------
    (float, float)
        The small-gain number and the scaling d of the second term (1 for one term).
    """
    if N == 0:
        return 0.0, 1.0
    if B.shape[1] == 1:
        return N * hinf_norm(A, B, C), 1.0
    G = _responses(A, B, C, _grid(A))

    def peak(logd: float) -> float:          # D M D^-1 on the grid: M_ij d_i / d_j
        D = np.array([1.0, np.exp(logd)])
        return float(_sigma(G * (D[:, None] / D[None, :])).max())

    r = minimize_scalar(peak, bounds=(-12.0, 12.0), method="bounded", options={"xatol": 1e-3})
    cands = [0.0, float(r.x)]
    logd = min(cands, key=peak)
    D = np.array([1.0, np.exp(logd)])
    return N * hinf_norm(A, B / D, D[:, None] * C), float(D[1])
