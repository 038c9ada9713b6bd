"""A 40-digit referee for the poles near the unit circle of a brute-force closed loop
A(K) = A0 + K A1 (no hapstab code).

numpy's eigenvalues of the float matrices are accurate to ~1e-11 on these loops: a pole
nearer the circle than that is not theirs to place. Each eigenvalue within ``near`` of
the circle is refined by Rayleigh-quotient inverse iteration on the same closed loop
built in mpmath (``digits`` digits, every double of the loop taken as exact: the
builders' ``digits`` argument), started from numpy's value: solve (A - mu I) y = x,
mu <- mu + (y^H x) / (y^H y), x <- y / |y|, until mu moves less than 10^-(digits - 10).
The refinement is trusted only when it converged, stayed near its start and the refined
eigenvalues are distinct (two starts that fell to one eigenvalue would lose another);
otherwise the referee abstains (None).

References
----------
G. H. Golub and C. F. Van Loan, *Matrix Computations*, 4th ed., sec. 7.6.1 (inverse
iteration) and 8.2.3 (Rayleigh quotient iteration).
"""

from __future__ import annotations

import mpmath
import numpy as np

#: Digits of the refinement (the issue's referee: 40 significant digits, and 10 to spare)
DIGITS = 50


def refined_moduli(A0, A1, A0x, A1x, K: float, near: float = 1e-6, digits: int = DIGITS):
    """|lambda| of every eigenvalue of A0 + K A1, those within ``near`` of the unit circle
    refined on the exact matrices ``A0x + K A1x`` (object arrays of mpf, built at
    ``digits``); None if a refinement is not trusted (module docstring).

    Returns
    -------
    list of mpf or float, or None
    """
    lam = np.linalg.eigvals(np.asarray(A0, float) + K * np.asarray(A1, float))
    out: list = []
    refined: list = []
    with mpmath.workdps(digits):
        A = mpmath.matrix((A0x + mpmath.mpf(K) * A1x).tolist())
        for z in lam:
            if abs(abs(z) - 1.0) >= near:
                out.append(abs(z))
                continue
            mu = _rayleigh(A, complex(z), digits)
            if mu is None or abs(complex(mu) - z) > 1e-6:
                return None
            if any(abs(mu - r) < mpmath.mpf(10) ** (-(digits // 2)) for r in refined):
                return None
            refined.append(mu)
            out.append(abs(mu))
    return out


def _rayleigh(A, mu0: complex, digits: int):
    n = A.rows
    mu = mpmath.mpc(mu0)
    x = mpmath.matrix([mpmath.mpc(1, 0.1 * i) for i in range(n)])
    x = x / mpmath.norm(x)
    tol = mpmath.mpf(10) ** (-(digits - 10))
    for _ in range(60):
        try:
            y = mpmath.lu_solve(A - mu * mpmath.eye(n), x)
        except ZeroDivisionError:     # mu is an eigenvalue to the working precision
            return mu
        yy = sum(abs(v) ** 2 for v in y)
        step = sum(mpmath.conj(y[i]) * x[i] for i in range(n)) / yy
        mu += step
        x = y / mpmath.sqrt(yy)
        if abs(step) < tol * max(1, abs(mu)):
            return mu
    return None


def count_outside(moduli, decided: float):
    """(poles outside the circle, whether every |lambda| is at least ``decided`` from 1)."""
    return sum(1 for r in moduli if r > 1), all(abs(r - 1) >= decided for r in moduli)
