"""Each port's polynomials in y = z - 1 for the characteristic function of
:mod:`hapstab.engine.frequency`: the exact zero-order-hold discretisation (matrix
exponential), d(y) = det(yI - (Phi - I)) from the continuous poles, and the
numerators by Leverrier's recursion, with bounds on their rounding; batched over
items that each have their own port matrices and period.

References
----------
K. J. Astrom and B. Wittenmark, *Computer-Controlled Systems*, 3rd ed., sec. 2.3
(ZOH sampling) and 7.7 (modified z-transform); N. J. Higham, SIAM J. Matrix Anal.
Appl. 26 (2005) 1179-1193 (the matrix exponential).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hapstab.engine.zoh import THETA13, expm_batched
from hapstab.tolerances import DIVISOR_FLOOR

__all__ = ["PortPoly", "COEF_REL", "port_polynomials"]

#: Relative error assumed for the discretised coefficients (matrix exponential and
#: Leverrier recursion on matrices of order <= 8: a few tens of unit round-offs).
COEF_REL = 64 * np.finfo(float).eps


@dataclass
class PortPoly:
    """Polynomials in y = z - 1 (ascending) of one port, one row per item."""

    d: np.ndarray          # (L, q+1)  det(yI - (Phi - I))
    dhat: np.ndarray       # (L, q)    d / y (free ports only, else empty)
    N: np.ndarray          # (L, q)    C adj(yI - E) Gamma
    Nt: dict[float, np.ndarray]   # fraction f -> (L, q+1): z^-1 Nt / d is the f-delayed measurement
    D: dict[float, np.ndarray]    # fraction f -> (L, q): (Nt - (1 + y) N) / y
    err: dict[str, np.ndarray]    # coefficient error bounds, same shapes
    R: np.ndarray | None = None   # (L, q) c adj(yI - E) Gamma: the termination's force
    mz_M: np.ndarray | None = None   # (L,) termination mass / port mass




def _zoh(A: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, S) with Phi = e^{AT}, S = int_0^T e^{As} ds, batched over T and over A
    (one matrix, or one per item: (L, n, n))."""
    n = A.shape[-1]
    M = np.zeros((*A.shape[:-2], 2 * n, 2 * n))
    M[..., :n, :n], M[..., :n, n:] = A, np.eye(n)
    E = expm_batched(T[:, None, None] * (M if M.ndim == 3 else M[None]))
    return E[:, :n, :n], E[:, :n, n:]


def _leverrier(E: np.ndarray, G: np.ndarray, d_desc: np.ndarray, kappa: np.ndarray,
               T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Leverrier on vectors: adj(yI - E) Gamma = sum_k y^(q-1-k) v_k; returns V (L, q, q),
    row k = v_k, and magnitudes that bound its error.

    E and Gamma come from the matrix exponential, accurate normwise rather than per entry
    (a stiff port's position entries carry the rounding of its larger velocity terms),
    here in the state's natural units, positions and T times velocities (w = [1, T, ...]),
    times ``kappa`` = 1 + the number of squarings (each squaring rounds again); each step
    then adds |E| |v| + |d_k| |Gamma|. Measured against 60 digits this holds up to walls
    whose resonance is below about a third of the sampling rate; at 1e6 N/m with T = 0.5
    to 2 ms it is still up to 40 times short (a bound normwise across units holds there,
    but made the exact core run out of memory on extreme loops)."""
    q = E.shape[1]
    w = np.ones((T.size, q))
    w[:, 1:] = T[:, None]
    Es = np.abs(E) * w[:, :, None] / w[:, None, :]            # diag(w) |E| diag(1/w)
    Gs = np.abs(G) * w
    e_norm, g_norm = kappa * Es.max(axis=(1, 2)), kappa * Gs.max(axis=1)
    g_mag = Gs + g_norm[:, None]
    v, mag = G.copy(), g_mag
    vs, mags = [v], [mag]
    for k in range(1, q):
        v = np.einsum("lij,lj->li", E, v) + d_desc[:, k:k + 1] * G
        mag = (np.einsum("lij,lj->li", Es, mag) + e_norm[:, None] * mag.sum(axis=1, keepdims=True)
               + np.abs(d_desc[:, k:k + 1]) * g_mag)
        vs.append(v)
        mags.append(mag)
    return np.stack(vs, axis=1), np.stack(mags, axis=1) / w[:, None, :]


def port_polynomials(A: np.ndarray, Bv: np.ndarray, free: bool, T: np.ndarray,
               fractions: Sequence[float], force: tuple[np.ndarray, np.ndarray] | None = None,
               mz_M: float | np.ndarray = 0.0) -> PortPoly:
    """Polynomials of one port (state [x, v, rest...], position = state 0) at each
    period of ``T``; ``A`` (q, q) and ``Bv`` (q, 1) are one port's or, stacked (L, q, q)
    and (L, q, 1), one per item (then ``force``'s rows and ``mz_M`` too). With
    ``force`` = (c, |c|-bound), the row of the termination's force
    (``Ft = -c s + (m_z/M) u_old``) and the magnitudes it was summed from, also the
    numerator of its force at kT^-. Each item's numbers are computed by the same
    operations whatever else is in the batch."""
    L, q = T.size, A.shape[-1]
    A = np.broadcast_to(A, (L, q, q))
    Bv = np.broadcast_to(Bv, (L, q, 1))
    _Phi, S = _zoh(A, T)
    E = A @ S                                        # Phi - I, accurate for small T
    G = S @ Bv                                       # (L, q, 1)
    # d(y) = prod (y - expm1(lambda T)): a free port's lambda = 0 is structural
    lam = np.linalg.eigvals(A[:, 1:, 1:]) if free else np.linalg.eigvals(A)
    delta = np.expm1(T[:, None] * lam)
    if free:
        delta = np.concatenate([np.zeros((L, 1)), delta], axis=1)
    d_desc = np.ones((L, 1), complex)
    for i in range(q):
        d_desc = np.concatenate([d_desc, np.zeros((L, 1))], axis=1)
        d_desc[:, 1:] -= delta[:, i:i + 1] * d_desc[:, :-1]
    d_desc = d_desc.real
    if free:
        d_desc[:, -1] = 0.0                           # exactly: a root at y = 0
    # one rounding per squaring of the scaling-and-squaring exponential (its count as
    # engine.zoh.expm_batched takes it; the augmented matrix's norm is at least A T's)
    norm = np.maximum(T * np.abs(A).sum(axis=1).max(axis=1), DIVISOR_FLOOR)   # (log2 of 0 guarded)
    squarings = np.maximum(0.0, np.ceil(np.log2(norm / THETA13)))
    V, Vmag = _leverrier(E, G[:, :, 0], d_desc, 1.0 + squarings, T)
    N = V[:, ::-1, 0]                                 # ascending: coefficient of y^(q-1-k)
    d = d_desc[:, ::-1].copy()
    # magnitudes that rounding acts on: coefficients of prod (y + |delta_i|)
    mag = np.ones((L, 1))
    for i in range(q):
        mag = np.concatenate([mag, np.zeros((L, 1))], axis=1)
        mag[:, 1:] += np.abs(delta[:, i:i + 1]) * mag[:, :-1]
    scale_d = mag[:, ::-1]
    err = {"d": COEF_REL * scale_d, "N": COEF_REL * (np.abs(N) + Vmag[:, ::-1, 0])}
    dhat = d[:, 1:] if free else np.zeros((L, 0))
    err["dhat"] = err["d"][:, 1:] if free else np.zeros((L, 0))
    Nt, D = {}, {}
    for f in fractions:
        Phf, Sf = _zoh(A, (1.0 - f) * T)
        Gf = (Sf @ Bv)[:, 0, 0]                       # C Gamma_{1-f}
        c_phi = Phf[:, 0, :]                          # C Phi_{1-f}
        part = np.einsum("li,lki->lk", c_phi, V)[:, ::-1]        # ascending, degree q-1
        nt = Gf[:, None] * d
        nt[:, :q] += part
        Nt[f] = nt
        onepy_N = np.zeros((L, q + 1))
        onepy_N[:, :q] += N
        onepy_N[:, 1:] += N
        diff = nt - onepy_N
        D[f] = diff[:, 1:]                            # the constant term is 0 exactly
        err[f"Nt{f}"] = COEF_REL * (np.abs(nt) + np.abs(Gf)[:, None] * scale_d
                                    + np.pad(np.abs(part), ((0, 0), (0, 1))))
        err[f"D{f}"] = (err[f"Nt{f}"] + COEF_REL * np.abs(onepy_N))[:, 1:]
    R = None
    if force is not None:
        c, c_mag = (np.broadcast_to(x, (L, q)) for x in force)
        R = np.einsum("lki,li->lk", V, c)[:, ::-1]             # ascending, degree q-1
        if free:
            R[:, 0] = 0.0          # exactly: c[0] = 0 and adj(-E) Gamma is along e_0
        err["R"] = COEF_REL * (np.abs(R) + np.einsum("lki,li->lk", Vmag, c_mag)[:, ::-1])
    return PortPoly(d, dhat, N, Nt, D, err, R,
                    np.broadcast_to(np.asarray(mz_M, float), (L,)).copy() if force is not None
                    else None)


