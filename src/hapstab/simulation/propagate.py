"""The exact linear recurrence ``s[k+1] = A s[k] + B f[k]``, many samples per
matrix product (block recurrence).

References
----------
The paper, Fig. 2a, Fig. 3 and Section 5.
"""

from __future__ import annotations

import numpy as np

__all__ = ['propagate_linear']


def propagate_linear(A: np.ndarray, B: np.ndarray, s0: np.ndarray, F: np.ndarray | None,
                     n_samples: int, block: int = 64) -> np.ndarray:
    """The exact recurrence ``s[k+1] = A s[k] + B f[k]``, ``block`` samples per product.

    Parameters
    ----------
    A : (N, N) array
        One-sample state transition.
    B : (N, p) array
        Input matrix of the held forces.
    s0 : (N,) array
        Initial state.
    F : (M, p) array or None
        Held inputs (None: free response).
    n_samples : int
        M.
    block : int
        Samples per block; powers A^1..A^block are formed once.

    Returns
    -------
    (M+1, N) array of states; rows after an overflow are inf/nan.
    """
    N = A.shape[0]
    m = max(1, min(block, n_samples))
    pw = np.empty((m, N, N))
    pw[0] = A
    for j in range(1, m):
        pw[j] = A @ pw[j - 1]
    Pw = pw.reshape(m * N, N)
    forced = F is not None and np.any(F)
    if forced:
        p = B.shape[1]
        H = np.empty((m, N, p))                      # H[j] = A^j B
        H[0] = B
        H[1:] = pw[:-1] @ B
        Toe: np.ndarray = np.zeros((m, N, m, p))
        for i in range(m):
            Toe[i:, :, i, :] = H[:m - i]             # s[k+1+j] gets A^(j-i) B f[k+i]
        Toe = Toe.reshape(m * N, m * p)
        nb = -(-n_samples // m)
        Fp = np.zeros((nb * m, p))
        Fp[:n_samples] = F
        Fb = Fp.reshape(nb, m * p)
    S = np.empty((n_samples + 1, N))
    S[0] = s0
    s = np.asarray(s0, float)
    with np.errstate(over="ignore", invalid="ignore"):
        # the forced part of every block at once; only the free part is sequential
        Fc = (Fb @ Toe.T).reshape(-1, m, N) if forced else None
        k = b = 0
        while k < n_samples:
            blk = (Pw @ s).reshape(m, N)
            if Fc is not None:                       # forced
                blk += Fc[b]
            take = min(m, n_samples - k)
            S[k + 1:k + 1 + take] = blk[:take]
            s = blk[take - 1]
            k += take
            b += 1
            if not np.isfinite(s).all():
                S[k + 1:] = np.inf
                break
    return S
