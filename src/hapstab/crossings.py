"""The crossing analysis behind the exact critical stiffness: every K at which a
closed-loop pole of ``A(K) = A0 + K B1 C1`` reaches |z| = 1, and the stable set.

Method
------
The closed loop at the sampling instants is ``A(K) = A0 + K B1 C1`` (see
:mod:`hapstab.engine`), with ``r = rank(B1 C1)`` equal to the number of ports
(1 for the HVE, 2 for PEB).  Its characteristic polynomial
``chi(z, K) = det(zI - A(K))`` has degree N in z and r in K.

1. Coefficients of chi are recovered *exactly* (to rounding) by evaluating
   determinants at N+1 roots of unity and r+1 values of K and inverting the DFT,
   which is perfectly conditioned on the unit circle.
2. A pole reaches |z| = 1 for real K only where chi(z, K) and its reciprocal
   ``z^N chi(1/z, K)`` have a common root K: for r = 1 this is the polynomial
   ``a(z) b~(z) - a~(z) b(z)``; for r = 2 the resultant of two quadratics in K.
   All its roots on the unit circle are candidates (none can be missed: no grid).
3. Each candidate frequency is polished by Newton iteration on
   ``Im mu(theta) = 0``, mu an eigenvalue of ``G(e^{j theta}) = C1 (zI - A0)^-1 B1``
   (so K = 1/mu), evaluated by linear solves, not polynomials: the result is
   accurate to rounding.  Crossings at z = +-1 come from real roots of chi(+-1, K).
4. The stable set in K is the union of the gaps between consecutive crossings
   whose midpoint has spectral radius < 1.

Modes at z = 1 that exist for every K (a mass nothing ties to ground) are
rigid-body modes: they are counted, excluded and reported, never called unstable.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .engine import SampledSystem
from .errors import AnalysisError

__all__ = ["exact_kmax_batch", "K_CAP", "K_MIN"]

#: The analysed range of K is (K_MIN, K_CAP] * K_scale, K_scale = ||A0|| / ||A1|| (about
#: 2m/T^2 for a light damper, less for a heavy one): beyond it the closed loop's
#: entries dwarf rounding and its eigenvalues carry no information.
K_CAP = 1e12

#: ... and K below K_MIN * K_scale is not resolved: a free mass's pole leaves z = 1
#: at a rate proportional to K, and rounding blurs the first 1e-9 of |z| - 1.
K_MIN = 1e-6


# --------------------------------------------------------------- exact K_max core
def _chi_coefficients(A0: np.ndarray, A1: np.ndarray, Ks: np.ndarray, r: int,
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


def _rev(x: np.ndarray) -> np.ndarray:
    return x[::-1]


def _bconv(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Row-wise polynomial product (ascending coefficients), batched."""
    out = np.zeros((x.shape[0], x.shape[1] + y.shape[1] - 1))
    for i in range(x.shape[1]):
        out[:, i:i + y.shape[1]] += x[:, i:i + 1] * y
    return out


def _crossing_polys(c: np.ndarray) -> np.ndarray:
    """Rows of ascending coefficients of the polynomials whose unit-circle roots are
    all frequencies where chi(e^{j theta}, K) = 0 for some real K; c is (P, r+1, N+1).

    r = 1: a b~ - a~ b (x~ the reversal): exactly anti-palindromic by construction.
    r = 2: the resultant in K of chi(z, K) and its reversal; made exactly
    (anti-)palindromic, which keeps simple unit-circle roots on the circle.
    """
    rev = lambda x: x[:, ::-1]  # noqa: E731
    if c.shape[1] == 2:
        a, b = c[:, 0], c[:, 1]
        q = _bconv(a, rev(b))
        return q - rev(q)
    a, b, cc = c[:, 0], c[:, 1], c[:, 2]
    x1 = _bconv(cc, rev(a)) - _bconv(rev(cc), a)
    x2 = _bconv(cc, rev(b)) - _bconv(rev(cc), b)
    x3 = _bconv(b, rev(a)) - _bconv(rev(b), a)
    q = _bconv(x1, x1) - _bconv(x2, x3)
    pal = np.abs(q + rev(q)).sum(axis=1) > np.abs(q - rev(q)).sum(axis=1)
    return np.where(pal[:, None], 0.5 * (q + rev(q)), 0.5 * (q - rev(q)))


def _mu_and_slope(A0: np.ndarray, B1: np.ndarray, C1: np.ndarray, theta: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalue mu of ``G(e^{j theta}) = C1 (zI - A0)^-1 B1`` nearest the real
    axis (K = 1/mu) and d mu / d theta, by one batched inverse."""
    N = A0.shape[-1]
    z = np.exp(1j * theta)
    R = np.linalg.inv(z[:, None, None] * np.eye(N) - A0)
    X = R @ B1
    G = C1 @ X
    dG = -1j * z[:, None, None] * (C1 @ (R @ X))          # dG/dtheta = -j z C1 R^2 B1
    if G.shape[-1] == 1:
        return G[:, 0, 0], dG[:, 0, 0]
    t = G[:, 0, 0] + G[:, 1, 1]
    d = G[:, 0, 0] * G[:, 1, 1] - G[:, 0, 1] * G[:, 1, 0]
    sq = np.sqrt(t * t / 4 - d)
    mus = np.stack([t / 2 + sq, t / 2 - sq], axis=-1)
    rel = np.abs(mus.imag) / np.maximum(np.abs(mus), 1e-300)
    mu = np.take_along_axis(mus, np.argmin(rel, axis=-1)[:, None], axis=-1)[:, 0]
    dt = dG[:, 0, 0] + dG[:, 1, 1]
    dd = dG[:, 0, 0] * G[:, 1, 1] + G[:, 0, 0] * dG[:, 1, 1] - dG[:, 0, 1] * G[:, 1, 0] \
        - G[:, 0, 1] * dG[:, 1, 0]
    den = 2 * mu - t
    dmu = (dt * mu - dd) / np.where(den != 0, den, 1e-300)   # from mu^2 - t mu + d = 0
    return mu, dmu


def _polish(A0, B1, C1, theta, iters: int = 30):
    """Newton on Im mu(theta) = 0, damped, each candidate until its step is at rounding."""
    th = theta.copy()
    mu = np.empty(th.size, complex)
    active = np.ones(th.size, bool)
    for _ in range(iters):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        m, dm = _mu_and_slope(A0[idx], B1[idx], C1[idx], th[idx])
        mu[idx] = m
        slope = dm.imag
        step = m.imag / np.where(slope != 0, slope, np.inf)
        lim = 0.2 * np.maximum(np.minimum(th[idx], np.pi - th[idx]), 1e-3)  # stay near the candidate
        step = np.clip(step, -lim, lim)
        th[idx] = np.clip(th[idx] - step, 1e-12, np.pi - 1e-12)
        # 1e-12 relative in theta is below the noise of Im mu near the root and
        # gives K to ~1e-12; quadratic convergence has done its work by then
        active[idx] = np.abs(step) > 1e-12 * np.maximum(th[idx], 1e-3)
    idx = np.flatnonzero(~active)
    if idx.size:  # value at the converged angle
        mu[idx] = _mu_and_slope(A0[idx], B1[idx], C1[idx], th[idx])[0]
    return th, mu


def _unit_roots_batch(Q: np.ndarray, tol: float = 2e-3) -> list[np.ndarray]:
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


def _rough_mu(c: np.ndarray, Ks: np.ndarray, theta: np.ndarray) -> np.ndarray:
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


def _real_roots_pos(vals: np.ndarray) -> list[np.ndarray]:
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


def exact_kmax_batch(sysm: SampledSystem, intervals: bool = True) -> list[dict[str, Any]]:
    """Exact K_max and the stable intervals in K for every period of ``sysm``.

    Parameters
    ----------
    sysm : SampledSystem
    intervals : bool
        If False, only K_max is wanted (``boundary``): only the crossings near
        the lowest one are polished and only the first two gaps are classified;
        a point whose first gaps do not settle K_max falls back to the full path.
        ``intervals`` is then ``((0, K_max),)`` only.

    Returns
    -------
    list of dict
        One per period: ``kmax``, ``intervals``, ``theta`` (angle of the crossing
        at K_max, nan if none), ``rigid``, ``rho_small_K``.
    """
    if not sysm.varies_with_K:
        raise AnalysisError("controller: critical stiffness needs SpringDamper controllers "
                            "(a general H(z) has no stiffness K to vary)")
    # K enters with the rank of A1 = B1 C1; B1 has one independent column per port
    # (its ZOH input), so that is the rank of the small C1 (PEB without delay: 1, the
    # two error signals being opposite). Factor at that rank, by groups.
    U, S, Vt = np.linalg.svd(sysm.C1, full_matrices=False)      # (P, p, p), (P, p), (P, p, N)
    ranks = np.sum(S > 1e-12 * S[:, :1], axis=1)
    out: list[dict[str, Any] | None] = [None] * sysm.C1.shape[0]
    for r in np.unique(ranks):
        idx = np.flatnonzero(ranks == r)
        if not 1 <= r <= 2:
            raise AnalysisError(f"stiffness enters the loop with rank {r}; only 1 or 2 is supported")
        B1 = sysm.B1[idx] @ (U[idx, :, :r] * S[idx, None, :r])
        C1 = Vt[idx, :r, :]
        for i, res in zip(idx, _kmax_core(sysm.A0[idx], B1, C1, intervals)):
            out[i] = res
    return out  # type: ignore[return-value]


def _kmax_core(A0: np.ndarray, B1: np.ndarray, C1: np.ndarray, full: bool = True
               ) -> list[dict[str, Any]]:
    A1 = B1 @ C1
    P, N, _ = A0.shape
    r = B1.shape[-1]
    Ks = np.linalg.norm(A0, axis=(1, 2)) / np.maximum(np.linalg.norm(A1, axis=(1, 2)), 1e-300)
    Ks = 2.0 ** np.round(np.log2(Ks))   # a power of two keeps K/Ks exact
    eig0 = np.linalg.eigvals(A0)
    # rigid-body modes need a pole of A0 at z = 1: look for them only there
    rigid = np.zeros(P, int)
    near1 = np.flatnonzero(np.abs(eig0 - 1.0).min(axis=1) < 1e-6)
    if near1.size:
        Sv = np.linalg.svd(np.concatenate([np.eye(N) - A0[near1], A1[near1]], axis=1),
                           compute_uv=False)
        rigid[near1] = np.sum(Sv < 1e-10 * np.maximum(1.0, Sv[:, :1]), axis=1)  # as rigid_body_modes()
    coef = _chi_coefficients(A0, A1, Ks, r, eig0, B1, C1)

    # --- complex crossings: candidates, then polish on the exact frequency response
    cs = coef.copy()
    for p in np.flatnonzero(rigid):
        cs[p] = [_deflate(ci, rigid[p]) for ci in coef[p]]
    ths = _unit_roots_batch(_crossing_polys(cs))
    cand_p = np.repeat(np.arange(P), [t.size for t in ths])
    crossings: list[list[tuple[float, float]]] = [[] for _ in range(P)]  # (K, theta)
    if cand_p.size:
        th0 = np.concatenate(ths)
        mu0 = _rough_mu(cs[cand_p], Ks[cand_p], th0)
        # K = 1/mu must be positive; the rough angle (resultant near z = 1) can be
        # a few % off, so the test on Im is generous and the polish decides
        ok0 = (np.abs(mu0.imag) < (0.5 if r == 2 else 0.05) * np.abs(mu0)) & (mu0.real > 0)
        if not full and ok0.any():
            # only the lowest crossings can decide K_max; rough K is accurate for r = 1
            # (a crossing polynomial of moderate degree) but can be a few % off for r = 2
            Krough = np.where(ok0, 1.0 / np.where(ok0, mu0.real, 1.0), np.inf)
            lowest = np.full(P, np.inf)
            np.minimum.at(lowest, cand_p, Krough)
            ok0 &= Krough <= (1.01 if r == 1 else 4.0) * lowest[cand_p]
        if ok0.any():
            ps, th1 = cand_p[ok0], th0[ok0]
            th, mu = _polish(A0[ps], B1[ps], C1[ps], th1)
            good = (np.abs(mu.imag) <= 1e-9 * np.abs(mu)) & (mu.real > 0)
            for p, t, m in zip(ps[good], th[good], mu[good]):
                crossings[p].append((1.0 / m.real, float(t)))

    # --- real crossings at z = +1 and z = -1: K = 1/mu for the real eigenvalues mu of
    # the real r x r matrix G(+-1), by linear solves (det(I - A) itself is tiny and
    # inaccurate at small T); where +-1 is a pole of A0 (a free mass) use chi(+-1, K)
    for zsign, theta in ((1.0, 0.0), (-1.0, math.pi)):
        M = zsign * np.eye(N) - A0
        direct = np.abs(eig0 - zsign).min(axis=1) > 1e-7
        if direct.any():
            idx = np.flatnonzero(direct)
            G = C1[idx] @ np.linalg.solve(M[idx], B1[idx])
            for p, mus in zip(idx, np.linalg.eigvals(G)):
                crossings[p].extend((1.0 / m.real, theta) for m in mus
                                    if abs(m.imag) <= 1e-12 * abs(m) and m.real > 0)
        if (~direct).any():
            zpow = zsign ** np.arange(N + 1)
            idx = np.flatnonzero(~direct)
            vals = np.array([cs[p] @ zpow for p in idx])
            # chi(+-1, K) has a root at K = 0 for each pole of A0 at +-1 (rigid modes
            # already divided out): remove it exactly rather than let rounding move it
            n0 = np.sum(np.abs(eig0[idx] - zsign) <= 1e-7, axis=1) - (rigid[idx] if zsign > 0 else 0)
            for j, k in enumerate(n0):
                if k > 0:
                    vals[j] = np.concatenate([vals[j, k:], np.zeros(k)])
            for p, roots in zip(idx, _real_roots_pos(vals)):
                crossings[p].extend((k * Ks[p], theta) for k in roots)

    # crossings beyond K_CAP x the loop's stiffness scale are out of the analysed range:
    # there the closed loop's entries are so large that its eigenvalues are noise
    # crossings below K_MIN x the scale are K = 0 roots blurred by rounding
    for p in range(P):
        kept: list[tuple[float, float]] = []
        for K, th in sorted(crossings[p]):
            if K_MIN * Ks[p] < K <= K_CAP * Ks[p] and (not kept or K > kept[-1][0] * (1 + 1e-10)):
                kept.append((K, th))
        crossings[p] = kept

    probes = [_probes([k for k, _ in crossings[p]], Ks[p]) for p in range(P)]
    if not full:
        # anchor, gap (0, K1), and just above K1: inside the window of rough K in
        # which no candidate was dropped (1 % for r = 1, 4x for r = 2)
        win = 1.005 if r == 1 else 1.5
        probes = [m[:2] + ([min(m[2], win * crossings[p][0][0])] if len(m) > 2 else [])
                  for p, m in enumerate(probes)]
    mp = np.repeat(np.arange(P), [len(m) for m in probes])
    mK = np.concatenate(probes)
    outside = np.empty(mK.size, dtype=int)
    on = np.empty(mK.size, dtype=int)
    rho = np.empty(mK.size)
    # the anchor (K_MIN * Ks) counts like K = 0 unless A0 has a pole on the circle
    off_circle = np.abs(np.abs(eig0) - 1.0).min(axis=1) > 1e-6
    anchor_idx = np.cumsum([0] + [len(m) for m in probes[:-1]])
    reuse = np.zeros(mK.size, bool)
    reuse[anchor_idx] = off_circle
    for s in range(0, mK.size, 2048):
        sl = slice(s, s + 2048)
        k0 = reuse[sl]
        eig = np.empty((k0.size, N), complex)
        eig[k0] = eig0[mp[sl][k0]]                 # already known
        if (~k0).any():
            pp = mp[sl][~k0]
            eig[~k0] = np.linalg.eigvals(A0[pp] + mK[sl][~k0, None, None] * A1[pp])
        outside[sl], rho[sl], on[sl] = _count_outside_batch(eig, rigid[mp[sl]])
    # away from the anchor a pole on the circle (within 1e-9) counts as outside: not stable
    anchor = np.concatenate([[True] + [False] * (len(m) - 1) for m in probes])
    outside = np.where(anchor, outside, outside + on)
    out: list[dict[str, Any] | None] = []
    redo = []
    pos = 0
    for p in range(P):
        cnt = len(probes[p])
        u, rh, on0 = outside[pos:pos + cnt], rho[pos:pos + cnt], int(on[pos])
        pos += cnt
        cr = crossings[p]
        if not full:
            settled = u[1] > 0 or not cr or (cnt == 3 and u[2] > 0)
            if settled and _consistent(cr[:cnt - 2], u, on0):
                if u[1] > 0 or rh[1] >= 1.0:
                    res = {"kmax": 0.0, "intervals": (), "theta": math.nan}
                elif not cr:
                    res = {"kmax": math.inf, "intervals": ((0.0, math.inf),), "theta": math.nan}
                else:
                    K1, th1 = cr[0]
                    if th1 in (0.0, math.pi):
                        K1 = _refine_endpoints({"kmax": K1, "intervals": ()}, A0[p], A1[p],
                                               int(rigid[p]), {K1})["kmax"]
                    res = {"kmax": K1, "intervals": ((0.0, K1),), "theta": th1}
                out.append({**res, "rigid": int(rigid[p]), "rho_small_K": float(rh[1])})
            else:
                out.append(None)
                redo.append(p)
            continue
        if not _consistent(cr, u, on0):
            cr, u, rh = _repair(A0[p], A1[p], B1[p], C1[p], int(rigid[p]), cr, Ks[p], on0)
            crossings[p] = cr
        res = _intervals(cr, u[1:], rh[1:], int(rigid[p]))
        real_K = {k for k, th in cr if th in (0.0, math.pi)}
        ends = {e for iv in res["intervals"] for e in iv}
        if real_K & ends:
            res = _refine_endpoints(res, A0[p], A1[p], int(rigid[p]), real_K)
        out.append(res)
    if redo:
        for p, res in zip(redo, _kmax_core(A0[redo], B1[redo], C1[redo], True)):
            out[p] = res
    return out  # type: ignore[return-value]


def _count_outside_batch(eig: np.ndarray, n_rigid: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vectorised :func:`_count_outside` over rows (rigid modes excluded per row),
    plus the number of poles on the circle (within 1e-9)."""
    a = np.abs(eig)
    if np.any(n_rigid):
        order = np.argsort(np.abs(eig - 1.0), axis=-1)
        mask = np.ones_like(a, bool)
        for m in np.unique(n_rigid[n_rigid > 0]):
            rows = np.flatnonzero(n_rigid == m)
            np.put_along_axis(mask[rows], order[rows, :m], False, axis=-1)
            sub = mask[rows]
            np.put_along_axis(sub, order[rows, :m], False, axis=-1)
            mask[rows] = sub
        a = np.where(mask, a, 0.0)
    on = np.abs(a - 1.0) <= 1e-9
    return np.sum((a >= 1.0) & ~on, axis=-1), a.max(axis=-1), np.sum(on, axis=-1)


def _probes(Kv: list[float], Ks: float) -> list[float]:
    """Where to count poles outside the circle: K_MIN * Ks (anchors the count; a
    pole still on the circle there may go either way), then one point inside each
    gap between consecutive crossings."""
    if not Kv:
        return [K_MIN * Ks, Ks]
    return [K_MIN * Ks, Kv[0] / 2] + [(a + b) / 2 for a, b in zip(Kv, Kv[1:])] + [2 * Kv[-1]]


def _count_outside(eig: np.ndarray, n_rigid: int) -> tuple[int, float, int]:
    """(poles strictly outside, spectral radius, poles on the circle within 1e-9),
    rigid-body modes excluded."""
    if n_rigid:
        eig = eig[np.argsort(np.abs(eig - 1.0))[n_rigid:]]
    a = np.abs(eig)
    on = np.abs(a - 1.0) <= 1e-9
    return int(np.sum((a >= 1.0) & ~on)), float(a.max()), int(on.sum())


def _mult(th: float) -> int:
    return 1 if th in (0.0, math.pi) else 2


def _consistent(cr: list[tuple[float, float]], u: np.ndarray, on0: int = 0) -> bool:
    """Counts at the probes agree with the crossings found: between K = 0 (count
    u[0] strictly outside, on0 on the circle) and the first gap only the poles on
    the circle may leave; each crossing moves 2 poles (complex pair) or 1 (real,
    z = +-1) across the circle, so a larger jump means a crossing was missed."""
    if not u[0] <= u[1] <= u[0] + on0:
        return False
    return all(abs(int(u[g + 2]) - int(u[g + 1])) <= _mult(th) for g, (_, th) in enumerate(cr))


def _repair(A0, A1, B1, C1, rigid, cr, Ks, on0: int, rounds: int = 8):
    """Fallback when a crossing was missed: bisect on the outside count where it
    disagrees with the crossings found, then polish the new crossing exactly."""
    def count(K: float) -> int:   # on the circle counts as outside (K > 0: not stable)
        c = _count_outside(np.linalg.eigvals(A0 + K * A1), rigid)
        return c[0] + c[2]

    def bisect(lo: float, hi: float, ulo: int) -> float:
        for _ in range(200):   # to rounding of K
            mid = 0.5 * (lo + hi)
            if hi - lo <= 4e-16 * hi:
                break
            if count(mid) == ulo:
                lo = mid
            else:
                hi = mid
        return hi

    for _ in range(rounds):
        pr = _probes([k for k, _ in cr], Ks)
        u = np.array([count(k) for k in pr])
        u[0] = _count_outside(np.linalg.eigvals(A0 + pr[0] * A1), rigid)[0]
        if _consistent(cr, u, on0):
            break
        if not u[0] <= u[1] <= u[0] + on0:
            segs = [(pr[0], pr[1], u[0] + on0)]
        else:
            segs = []
            for g, (K, th) in enumerate(cr):
                if abs(int(u[g + 2]) - int(u[g + 1])) > _mult(th):
                    # counts are noisy right at a crossing when poles crowd z = 1
                    # (small T): look 1e-3 away from the known one
                    lo_k, hi_k = K * (1 - 1e-3), K * (1 + 1e-3)
                    below, above = count(lo_k), count(hi_k)
                    if below != u[g + 1] and pr[g + 1] < lo_k:
                        segs.append((pr[g + 1], lo_k, u[g + 1]))
                    if above != u[g + 2] and hi_k < pr[g + 2]:
                        segs.append((hi_k, pr[g + 2], above))
                    break
        if not segs:
            break
        added = False
        for lo, hi, ulo in segs:
            new = _polish_at(A0, A1, B1, C1, bisect(lo, hi, ulo))
            if all(abs(new[0] / k - 1) > 1e-9 for k, _ in cr):
                cr = sorted(cr + [new])
                added = True
        if not added:
            break
    pr = _probes([k for k, _ in cr], Ks)
    res = [_count_outside(np.linalg.eigvals(A0 + k * A1), rigid) for k in pr]
    u = np.array([r[0] + (r[2] if i > 0 else 0) for i, r in enumerate(res)])
    return cr, u, np.array([r[1] for r in res])


def _polish_at(A0, A1, B1, C1, K: float) -> tuple[float, float]:
    """(K, theta) of the crossing found by bisection at K, polished on the exact
    frequency response when it is a complex pair."""
    eig = np.linalg.eigvals(A0 + K * A1)
    z = eig[np.argmin(np.abs(np.abs(eig) - 1.0))]
    th = abs(math.atan2(z.imag, z.real))
    if th < 1e-9:
        return K, 0.0
    if th > math.pi - 1e-9:
        return K, math.pi
    t, mu = _polish(A0[None], B1[None], C1[None], np.array([th]))
    # the bisection's K is only as good as the eigenvalues near z = 1; the polished
    # crossing is exact, and must be the same crossing (within a few %)
    if abs(mu[0].imag) <= 1e-9 * abs(mu[0]) and mu[0].real > 0 and abs(1 / mu[0].real / K - 1) < 3e-2:
        return 1.0 / mu[0].real, float(t[0])
    return K, th


def _intervals(cr, u, rho, rigid) -> dict[str, Any]:
    edges = [0.0] + [k for k, _ in cr] + [math.inf]
    intervals: list[tuple[float, float]] = []
    for g in range(len(u)):
        if u[g] == 0 and rho[g] < 1.0:
            lo, hi = edges[g], edges[g + 1]
            if intervals and intervals[-1][1] == lo:   # a touching crossing: merge
                intervals[-1] = (intervals[-1][0], hi)
            else:
                intervals.append((lo, hi))
    if intervals and intervals[0][0] == 0.0:
        kmax = intervals[0][1]
        theta = next((th for k, th in cr if k == kmax), math.nan)
    else:
        kmax, theta = 0.0, math.nan
    return {"kmax": float(kmax), "intervals": tuple((float(a), float(b)) for a, b in intervals),
            "theta": theta, "rigid": rigid, "rho_small_K": float(rho[0])}


def _deflate(c: np.ndarray, m: int) -> np.ndarray:
    """Divide an ascending polynomial by (z - 1)^m (exact factor, remainder dropped),
    keeping the array length (zero-padded) so K-coefficients stay aligned."""
    desc = c[::-1]
    for _ in range(m):
        desc, _ = np.polydiv(desc, [1.0, -1.0])
    out = np.zeros_like(c)
    asc = np.atleast_1d(desc)[::-1]
    out[:asc.size] = asc
    return out


def _refine_endpoints(res: dict[str, Any], A0: np.ndarray, A1: np.ndarray, rigid: int,
                      real_K: set[float]) -> dict[str, Any]:
    """Polish interval endpoints that are real crossings (z = +-1)."""
    def fix(K: float) -> float:
        if K not in real_K:
            return K
        for z in (1.0, -1.0):
            k = _refine_real(A0, A1, z, K, rigid)
            if k != K:
                return k
        return K
    iv = tuple((fix(a) if a > 0 else a, fix(b) if math.isfinite(b) else b)
               for a, b in res["intervals"])
    kmax = fix(res["kmax"]) if 0 < res["kmax"] < math.inf else res["kmax"]
    return {**res, "intervals": iv, "kmax": kmax}


def _refine_real(A0: np.ndarray, A1: np.ndarray, z: float, K0: float, m: int) -> float:
    """Polish a real crossing K of det(zI - A0 - K A1) = 0 (z = +-1) by the
    generalised eigenvalues of the pencil (zI - A0, A1), nearest to K0."""
    if m:
        return K0
    from scipy.linalg import eigvals
    N = A0.shape[0]
    with np.errstate(all="ignore"):
        ev = eigvals(z * np.eye(N) - A0, A1)
    ev = ev[np.isfinite(ev)]
    if ev.size == 0:
        return K0
    k = ev[np.argmin(np.abs(ev - K0))]
    return float(k.real) if abs(k - K0) < 1e-6 * abs(K0) else K0
