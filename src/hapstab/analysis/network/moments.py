"""Mean-square stability of a Markov jump linear system: the second-moment operator.

For ``x[k+1] = A_{theta_k} x[k]`` with theta a Markov chain (``p_ij`` = P(j at k+1 | i
at k)), the second moments ``Q_j[k] = E[x[k] x[k]^T 1{theta_k = j}]`` obey

    Q_j[k+1] = sum_i p_ij A_i Q_i[k] A_i^T            (the operator T),

and the system is mean-square stable (E|x[k]|^2 -> 0 from every initial state and
initial mode distribution) iff the spectral radius of T is below 1 (Costa, Fragoso and
Marques 2005, Theorem 3.9). With independent losses (p_ij = pi_j) the moments of all
modes add to ``Q = sum_i pi_i A_i Q A_i^T`` and the condition is
``rho(sum_i pi_i A_i (x) A_i) < 1`` (Kronecker product), of dimension N^2 instead of
M N^2.

T is never formed as a matrix when it is large: it acts on the M matrices Q_i as M
products ``A_i Q_i A_i^T`` (2 M N^3 operations, memory M N^2), and its dominant
eigenvalue comes from ARPACK's implicitly restarted Arnoldi iteration on that action.
T maps the cone of positive semidefinite tuples into itself, so rho(T) is itself an
eigenvalue with a positive semidefinite eigenvector (Krein-Rutman; Costa et al. 2005,
Proposition 3.6 and Lemma A.8).

References
----------
O. L. V. Costa, M. D. Fragoso and R. P. Marques, *Discrete-Time Markov Jump Linear
Systems*, Springer 2005, ch. 3 (eq. (3.8), Theorem 3.9).
R. B. Lehoucq, D. C. Sorensen and C. Yang, *ARPACK Users' Guide*, SIAM 1998.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import linalg as spla

from hapstab.errors import AnalysisError

__all__ = ["second_moment_radius", "second_moment_step", "DENSE_DIMENSION"]

#: Up to this dimension of the operator (N^2 or M N^2) it is formed and all its
#: eigenvalues taken by LAPACK (about 10 ms at 400, 1 s at 1500); above, ARPACK on its
#: action.
DENSE_DIMENSION = 1500


def second_moment_step(A: np.ndarray, transition: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """One step of the operator: ``Q'_j = sum_i p_ij A_i Q_i A_i^T``.

    Parameters
    ----------
    A : (M, N, N) array
        The mode matrices.
    transition : (M, M) array
        The chain, ``transition[i, j]`` = P(j next | i now).
    Q : (M, N, N) array
        The moments of each mode.

    Returns
    -------
    (M, N, N) array
    """
    S = A @ Q @ np.swapaxes(A, 1, 2)
    return np.einsum("ij,inm->jnm", transition, S)


def _dense(A: np.ndarray, transition: np.ndarray, independent: bool) -> np.ndarray:
    M, N = A.shape[0], A.shape[1]
    if independent:
        pi = transition[0]
        return sum(pi[i] * np.kron(A[i], A[i]) for i in range(M))
    D = np.zeros((M * N * N, M * N * N))
    for i in range(M):
        kr = np.kron(A[i], A[i])
        for j in range(M):
            D[j * N * N:(j + 1) * N * N, i * N * N:(i + 1) * N * N] = transition[i, j] * kr
    return D


def second_moment_radius(A: np.ndarray, transition: np.ndarray) -> float:
    """Spectral radius of the second-moment operator T of the jump system.

    Parameters
    ----------
    A : (M, N, N) array
        The mode matrices at one stiffness.
    transition : (M, M) array
        The Markov chain of the modes.

    Returns
    -------
    float
        rho(T): below 1 iff the system is mean-square stable. Computed in double
        precision (LAPACK or ARPACK), not enclosed: its error is of the order of the
        rounding times the eigenvalue's condition number.

    Raises
    ------
    AnalysisError
        If ARPACK does not converge (the dominant eigenvalue is then not known).
    """
    M, N = A.shape[0], A.shape[1]
    independent = bool(np.all(transition == transition[:1]))
    dim = N * N if independent else M * N * N
    if dim <= DENSE_DIMENSION:
        return float(np.abs(np.linalg.eigvals(_dense(A, transition, independent))).max())
    At = np.swapaxes(A, 1, 2)
    if independent:
        pi = transition[0]

        def mv(x: np.ndarray) -> np.ndarray:
            X = np.real_if_close(x).reshape(N, N)
            return np.einsum("i,inm->nm", pi, A @ X @ At).ravel()
    else:
        def mv(x: np.ndarray) -> np.ndarray:
            return second_moment_step(A, transition, x.reshape(M, N, N)).ravel()
    op = spla.LinearOperator((dim, dim), matvec=mv, dtype=float)
    v0 = np.tile(np.eye(N).ravel(), 1 if independent else M)   # inside the PSD cone
    for k, ncv in ((2, 40), (6, 120)):       # a wider Krylov space when eigenvalues crowd
        try:
            # a floor against division by zero / rounding, far below the answer's own accuracy
            w = spla.eigs(op, k=k, which="LM", v0=v0, tol=1e-13, maxiter=20 * dim,
                          ncv=min(dim - 1, ncv), return_eigenvectors=False)
            return float(np.abs(w).max())
        except spla.ArpackNoConvergence:
            continue
    raise AnalysisError(f"packet loss: ARPACK did not converge on the {dim}-dimensional "
                        "second-moment operator; the mean-square radius is not known")


def _symmetric_basis(N: int) -> tuple[np.ndarray, np.ndarray]:
    """Duplication D (N^2 x S) and elimination L (S x N^2), S = N(N+1)/2: vec X = D svec X
    for symmetric X, L D = I. T maps symmetric matrices to symmetric ones and its
    Perron eigenvector is symmetric, so L T D keeps every eigenvalue that matters."""
    iu, ju = np.triu_indices(N)
    S = iu.size
    D = np.zeros((N * N, S))
    L = np.zeros((S, N * N))
    s = np.arange(S)
    D[iu * N + ju, s] = 1.0
    D[ju * N + iu, s] = 1.0
    L[s, iu * N + ju] = np.where(iu == ju, 1.0, 0.5)
    L[s, ju * N + iu] += np.where(iu == ju, 0.0, 0.5)
    return D, L


def operator_coefficients(A0: np.ndarray, A1: np.ndarray, transition: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(T0, T1, T2) with T(K) = T0 + K T1 + K^2 T2 on symmetric matrices (per mode, the
    modes' blocks ``p_ij`` apart; one block for independent losses).

    Parameters
    ----------
    A0, A1 : (M, N, N) arrays
        Mode i is ``A0[i] + K A1[i]``; ``(A0 + K A1) (x) (A0 + K A1)`` expands into
        ``A0 (x) A0 + K (A0 (x) A1 + A1 (x) A0) + K^2 A1 (x) A1``.
    transition : (M, M) array
        The chain.

    Returns
    -------
    tuple of three (D, D) arrays
    """
    M, N = A0.shape[0], A0.shape[1]
    D, L = _symmetric_basis(N)
    S = D.shape[1]
    independent = bool(np.all(transition == transition[:1]))
    blocks = 1 if independent else M
    out = [np.zeros((blocks * S, blocks * S)) for _ in range(3)]
    for i in range(M):
        parts = (np.kron(A0[i], A0[i]), np.kron(A0[i], A1[i]) + np.kron(A1[i], A0[i]),
                 np.kron(A1[i], A1[i]))
        red = [L @ P @ D for P in parts]
        for j in range(blocks):
            w = transition[0, i] if independent else transition[i, j]
            ci = 0 if independent else i
            for T, R in zip(out, red, strict=True):
                T[j * S:(j + 1) * S, ci * S:(ci + 1) * S] += w * R
    return out[0], out[1], out[2]


#: A root K of det(I - T(K)) = 0 is taken as real when |Im K| <= this times |K|: the QZ
#: algorithm's backward error (about 1e-16 times the pencil's norm) moves a simple real
#: root off the axis by that times its condition number; 1e-7 leaves room for condition
#: numbers up to about 1e8 (a double root splits by sqrt(eps) ~ 1e-8 too).
REAL_ROOT = 1e-7


def unit_crossings(A0: np.ndarray, A1: np.ndarray, transition: np.ndarray) -> np.ndarray:
    """Every real K > 0 at which 1 is an eigenvalue of the second-moment operator T(K).

    rho(T(K)) is an eigenvalue of T(K) (T is positive), so rho can reach 1 only at one of
    these K: with rho < 1 as K -> 0+, the first of them is the mean-square K_max, with
    no scan of K that could step over a window. They are the real eigenvalues of the
    quadratic eigenvalue problem (I - T0 - K T1 - K^2 T2) v = 0, solved as the companion
    pencil [[0, I], [I - T0, -T1]] w = K [[I, 0], [0, T2]] w (QZ, LAPACK).

    Parameters
    ----------
    A0, A1 : (M, N, N) arrays
        The modes, ``A0[i] + K A1[i]``.
    transition : (M, M) array
        The chain.

    Returns
    -------
    array
        The real positive roots, ascending (double precision, not enclosed).
    """
    from scipy import linalg as sla

    T0, T1, T2 = operator_coefficients(A0, A1, transition)
    d = T0.shape[0]
    eye, zero = np.eye(d), np.zeros((d, d))
    lhs = np.block([[zero, eye], [eye - T0, -T1]])
    rhs = np.block([[eye, zero], [zero, T2]])
    alpha, beta = sla.eig(lhs, rhs, right=False, homogeneous_eigvals=True)
    # a floor against division by zero / rounding, far below the answer's own accuracy
    finite = np.abs(beta) > 1e-14 * np.abs(alpha)
    K = alpha[finite] / beta[finite]
    real = K[(np.abs(K.imag) <= REAL_ROOT * np.abs(K)) & (K.real > 0)].real
    return np.sort(real)


def pencil_dimension(order: int, modes: int, independent: bool) -> int:
    """Size of the companion pencil :func:`unit_crossings` solves (2 (M) N(N+1)/2).

    Parameters
    ----------
    order : int
        N, the jump system's state dimension.
    modes : int
        M.
    independent : bool
        Independent losses (one block).

    Returns
    -------
    int
    """
    return 2 * (1 if independent else modes) * order * (order + 1) // 2
