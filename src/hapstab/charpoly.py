"""The characteristic polynomial of ``A(K) = A0 + K B1 C1`` and the frequencies at
which one of its roots can sit on the unit circle for real K (see
:mod:`hapstab.crossings` for how they are used)."""

from __future__ import annotations

import numpy as np

__all__ = ["chi_coefficients", "crossing_polys", "unit_circle_angles", "rough_mu",
           "positive_real_roots", "deflate", "poly_mul_rows"]

def chi_coefficients(A0: np.ndarray, A1: np.ndarray, Ks: np.ndarray, r: int,
                      eig0: np.ndarray, B1: np.ndarray, C1: np.ndarray) -> np.ndarray:
    """Coefficients (ascending in z) of chi's K'-polynomial, K' = K/Ks.

    a(z) = chi(z, 0) is the product of (z - lambda) over the eigenvalues of A0
    (backward stable: exact for a matrix within rounding of A0). For r = 1,
    chi = a(z) - K C1 adj(zI - A0) B1, and adj(zI - A0) = sum_k z^(N-1-k) B_k with
    B_0 = I, B_k = A0 B_(k-1) + a_k I (Faddeev-LeVerrier), applied to B1: N mat-vecs.
    For r = 2 the z-coefficients at K = Ks, 2 Ks come from eigenvalues likewise and
    Lagrange interpolation in K' = 0, 1, 2 gives the K'-coefficients.

    Returns (P, r+1, N+1) real: chi(z, K) = sum_l (K/Ks)^l sum_m c[l, m] z^m.
    """
    P, N, _ = A0.shape

    def poly(ev: np.ndarray) -> np.ndarray:            # descending coefficients of prod (z - ev)
        d = np.zeros((P, N + 1), complex)
        d[:, 0] = 1.0
        for i in range(N):
            d[:, 1:i + 2] = d[:, 1:i + 2] - ev[:, i:i + 1] * d[:, 0:i + 1]
        return d.real

    a = poly(eig0)
    if r == 1:
        b = np.zeros((P, N + 1))
        v = B1[:, :, 0].copy()
        c = C1[:, 0, :]
        for k in range(N):
            b[:, 1 + k] = -np.einsum("pn,pn->p", c, v)
            v = np.einsum("pij,pj->pi", A0, v) + a[:, k + 1:k + 2] * B1[:, :, 0]
        return np.stack([a[:, ::-1], (Ks[:, None] * b)[:, ::-1]], axis=1)
    vals = np.stack([a] + [poly(np.linalg.eigvals(A0 + (l * Ks)[:, None, None] * A1))
                           for l in range(1, r + 1)], axis=1)[:, :, ::-1]
    V = np.vander(np.arange(r + 1, dtype=float), r + 1, increasing=True)  # rows: l^0..l^r
    return np.einsum("kl,plm->pkm", np.linalg.inv(V), vals)


def poly_mul_rows(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Row-wise polynomial product (ascending coefficients), batched."""
    out = np.zeros((x.shape[0], x.shape[1] + y.shape[1] - 1))
    for i in range(x.shape[1]):
        out[:, i:i + y.shape[1]] += x[:, i:i + 1] * y
    return out


def crossing_polys(c: np.ndarray) -> np.ndarray:
    """Rows of ascending coefficients of the polynomials whose unit-circle roots are
    all frequencies where chi(e^{j theta}, K) = 0 for some real K; c is (P, r+1, N+1).

    r = 1: a b~ - a~ b (x~ the reversal): exactly anti-palindromic by construction.
    r = 2: the resultant in K of chi(z, K) and its reversal; made exactly
    (anti-)palindromic, which keeps simple unit-circle roots on the circle.
    """
    rev = lambda x: x[:, ::-1]  # noqa: E731
    if c.shape[1] == 2:
        a, b = c[:, 0], c[:, 1]
        q = poly_mul_rows(a, rev(b))
        return q - rev(q)
    a, b, cc = c[:, 0], c[:, 1], c[:, 2]
    x1 = poly_mul_rows(cc, rev(a)) - poly_mul_rows(rev(cc), a)
    x2 = poly_mul_rows(cc, rev(b)) - poly_mul_rows(rev(cc), b)
    x3 = poly_mul_rows(b, rev(a)) - poly_mul_rows(rev(b), a)
    q = poly_mul_rows(x1, x1) - poly_mul_rows(x2, x3)
    pal = np.abs(q + rev(q)).sum(axis=1) > np.abs(q - rev(q)).sum(axis=1)
    return np.where(pal[:, None], 0.5 * (q + rev(q)), 0.5 * (q - rev(q)))


def unit_circle_angles(Q: np.ndarray, tol: float = 2e-3) -> list[np.ndarray]:
    """Angles in (0, pi) of the unit-circle roots of each row of Q, (anti-)palindromic
    polynomials of degree 2M (ascending coefficients).

    With x = cos(theta), ``z^-M q(z)`` is ``q_M + 2 sum_k q_{M+k} T_k(x)``
    (palindromic) or ``2j sin(theta) sum_k q_{M+k} U_{k-1}(x)`` (anti-palindromic),
    a Chebyshev series of half the degree whose real roots in (-1, 1) are the
    wanted angles; roots come from colleague matrices, batched over equal degrees.
    """
    P, L = Q.shape
    M = (L - 1) // 2
    hi = Q[:, M + 1:]
    anti = np.abs(Q + Q[:, ::-1]).sum(axis=1) <= np.abs(Q - Q[:, ::-1]).sum(axis=1)
    # U_n = 2 (T_n + T_{n-2} + ...) (- T_0 if n even): reverse cumulative sums
    tu = np.zeros((P, max(M, 1)))
    for par in (0, 1):
        tu[:, par::2] = 2 * np.cumsum(hi[:, par::2][:, ::-1], axis=1)[:, ::-1]
    tu[:, 0] -= hi[:, 0::2].sum(axis=1)
    tt = np.concatenate([Q[:, M:M + 1], 2 * hi], axis=1)
    tu = np.concatenate([tu, np.zeros((P, tt.shape[1] - tu.shape[1]))], axis=1)
    t = np.where(anti[:, None], tu, tt)
    scale = np.abs(t).max(axis=1, keepdims=True)
    big = np.abs(t) > 1e-13 * np.where(scale > 0, scale, 1.0)
    deg = np.where(big.any(axis=1), t.shape[1] - 1 - np.argmax(big[:, ::-1], axis=1), 0)
    out: list[np.ndarray] = [np.zeros(0)] * P
    for n in np.unique(deg):
        if n < 1:
            continue
        idx = np.flatnonzero(deg == n)
        c = t[idx, :n + 1]
        if n == 1:
            x = (-c[:, 0] / c[:, 1])[:, None].astype(complex)
        else:   # colleague matrix, as numpy.polynomial.chebyshev.chebcompanion
            mat = np.zeros((len(idx), n, n))
            scl = np.array([1.0] + [np.sqrt(0.5)] * (n - 1))
            off = np.full(n - 1, 0.5)
            off[0] = np.sqrt(0.5)
            mat[:, np.arange(n - 1), np.arange(1, n)] = off
            mat[:, np.arange(1, n), np.arange(n - 1)] = off
            mat[:, :, -1] -= (c[:, :-1] / c[:, -1:]) * (scl / scl[-1]) * 0.5
            x = np.linalg.eigvals(mat)
        th = np.arccos(np.clip(x.real, -1.0, 1.0))
        # a root at |z| = e^{-eps} maps to Im x ~ eps sin(theta)
        keep = (np.abs(x.imag) <= tol * np.maximum(np.sin(th), 1e-6)) & (np.abs(x.real) < 1.0)
        keep &= (th > 1e-9) & (th < np.pi - 1e-9)
        for j, i in enumerate(idx):
            out[i] = np.sort(th[j][keep[j]])
    return out


def rough_mu(c: np.ndarray, Ks: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """1/K at candidate angles from chi's coefficients (cheap, for filtering only):
    the root K' of sum_l c[l](z) K'^l = 0 nearest the real axis."""
    z = np.exp(1j * theta)
    zp = z[:, None] ** np.arange(c.shape[-1])[None, :]
    v = np.einsum("plm,pm->pl", c, zp)                     # (n, r+1)
    with np.errstate(all="ignore"):
        if v.shape[1] == 2:
            k = -v[:, 0] / v[:, 1]
        else:
            a, b, cc = v[:, 0], v[:, 1], v[:, 2]
            sq = np.sqrt(b * b - 4 * a * cc)
            k1, k2 = (-b + sq) / (2 * cc), (-b - sq) / (2 * cc)
            rel = lambda k: np.abs(k.imag) / np.abs(k)  # noqa: E731
            k = np.where(rel(k1) <= rel(k2), k1, k2)
        mu = 1.0 / (k * Ks)
    return np.where(np.isfinite(mu), mu, 0.0)


def positive_real_roots(vals: np.ndarray) -> list[np.ndarray]:
    """Positive real roots in K' of each row's polynomial sum_l vals[l] K'^l, degree <= 2,
    vectorised (the cancellation-free form of the quadratic formula)."""
    v = np.zeros((vals.shape[0], 3))
    v[:, :vals.shape[1]] = vals
    c0, c1, c2 = v[:, 0], v[:, 1], v[:, 2]
    with np.errstate(all="ignore"):
        scale = np.abs(v).max(axis=1)
        quad = np.abs(c2) > 1e-13 * scale
        disc = c1 * c1 - 4 * c2 * c0
        sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
        qq = -0.5 * (c1 + np.copysign(sq, c1))
        r1 = np.where(quad, qq / c2, -c0 / c1)
        r2 = np.where(quad, c0 / qq, np.nan)
    out = []
    for a, b in zip(r1, r2):
        out.append(np.array([x for x in (a, b) if np.isfinite(x) and x > 0]))
    return out


def deflate(c: np.ndarray, m: int) -> np.ndarray:
    """Divide an ascending polynomial by (z - 1)^m (exact factor, remainder dropped),
    keeping the array length (zero-padded) so K-coefficients stay aligned."""
    desc = c[::-1]
    for _ in range(m):
        desc, _ = np.polydiv(desc, [1.0, -1.0])
    out = np.zeros_like(c)
    asc = np.atleast_1d(desc)[::-1]
    out[:asc.size] = asc
    return out
