"""Exact zero-order-hold discretisation of each port (matrix exponential, batched).
"""

from __future__ import annotations

import numpy as np

from hapstab.engine.structure import Port
from hapstab.errors import ModelError
from hapstab.tolerances import DIVISOR_FLOOR

__all__ = ['discretize', 'port_matrices', 'expm_batched', 'THETA13']


def port_matrices(port: Port) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous (A, B, Cf) of one port, state ``[x, v, xi_r...]``.

    ``B`` is the input of the net applied force (exogenous minus actuator);
    ``Cf`` gives the termination's force from the state (without its mass term).
    The termination ``Z = m_z s + d_z + k_z/s + Z_r(s)`` acts on the device's own
    position and velocity, so no redundant integrator appears.

    Parameters
    ----------
    port : Port
        The device and its termination.

    Returns
    -------
    A : (q, q) array
    B : (q, 1) array
        Input of the net force in N (state in m, m/s, ...).
    Cf : (1, q) array
        The termination's force in N.
    """
    dev, z = port.device, port.termination
    M = dev.mass + z.mass
    Ar, Br, Cr = z.state_space()
    nr = Ar.shape[0]
    A = np.zeros((2 + nr, 2 + nr))
    A[0, 1] = 1.0
    A[1, 0] = -z.stiffness / M
    A[1, 1] = -(dev.damping + z.damping) / M
    A[1, 2:] = -Cr[0] / M
    A[2:, 2:] = Ar
    A[2:, 1] = Br[:, 0]
    B = np.zeros((2 + nr, 1))
    B[1, 0] = 1.0 / M
    Cf = np.zeros((1, 2 + nr))
    Cf[0, 0], Cf[0, 1], Cf[0, 2:] = z.stiffness, z.damping, Cr[0]
    with np.errstate(all="ignore"):
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
            raise ModelError(f"{port.name} mass = {M:g} kg, {port.name} damping = "
                             f"{dev.damping + z.damping:g} N*s/m, stiffness {z.stiffness:g} N/m: "
                             "the port's dynamics (b/m, k/m, 1/m) overflow double precision")
    return A, B, Cf


# Pade (13, 13) coefficients of exp (Higham 2005, Table 2.3) and the norm bound theta_13
_PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
           129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0,
           40840800.0, 960960.0, 16380.0, 182.0, 1.0)


#: theta_13 (Higham 2005, Table 2.3): the 1-norm up to which the Pade (13, 13)
#: approximant of exp is accurate to double precision; larger matrices are scaled by
#: 2^-s below it and squared s times.
THETA13 = 5.371920351148152


def expm_batched(M: np.ndarray) -> np.ndarray:
    """exp of each matrix of a stack (P, n, n): scaling and squaring with the (13, 13)
    Pade approximant (N. J. Higham, SIAM J. Matrix Anal. Appl. 26 (2005) 1179-1193),
    vectorised over the stack (scipy's expm loops over it in Python).

    Parameters
    ----------
    M : (P, n, n) array
        The matrices (dimensionless: A T for a sampled system).

    Returns
    -------
    (P, n, n) array
        e^M for each.
    """
    M = np.asarray(M, float)
    n = M.shape[-1]
    norm = np.abs(M).sum(axis=-2).max(axis=-1)                   # 1-norm per matrix
    with np.errstate(divide="ignore"):
        s = np.maximum(0, np.ceil(np.log2(np.maximum(norm, DIVISOR_FLOOR) / THETA13))).astype(int)
    X = M / (2.0 ** s)[:, None, None]
    b = _PADE13
    Id = np.broadcast_to(np.eye(n), X.shape)
    X2 = X @ X
    X4 = X2 @ X2
    X6 = X4 @ X2
    U = X @ (X6 @ (b[13] * X6 + b[11] * X4 + b[9] * X2) + b[7] * X6 + b[5] * X4 + b[3] * X2
             + b[1] * Id)
    V = X6 @ (b[12] * X6 + b[10] * X4 + b[8] * X2) + b[6] * X6 + b[4] * X4 + b[2] * X2 + b[0] * Id
    R = np.linalg.solve(V - U, V + U)
    for k in range(int(s.max()) if s.size else 0):
        sq = s > k
        R[sq] = R[sq] @ R[sq]
    return R


def discretize(A: np.ndarray, B: np.ndarray, periods: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation for each period (batched matrix exponential).

    Returns Ad (P, n, n) and Bd (P, n, m): ``Ad = e^{AT}``, ``Bd = int_0^T e^{At} dt B``.

    Parameters
    ----------
    A : (n, n) array
        Continuous state matrix (1/s).
    B : (n, m) array
        Continuous input matrix.
    periods : (P,) array
        Sampling periods T in s.

    Returns
    -------
    Ad : (P, n, n) array
    Bd : (P, n, m) array
    """
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    E = expm_batched(np.asarray(periods, float)[:, None, None] * M[None])
    return E[:, :n, :n], E[:, :n, n:]
