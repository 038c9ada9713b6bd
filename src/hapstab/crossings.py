"""The crossing analysis behind the exact critical stiffness: every K at which a
closed-loop pole of ``A(K) = A0 + K B1 C1`` reaches |z| = 1, and the stable set in K.

``r = rank(B1 C1)`` is 1 for the HVE and 2 for PEB (1 without delay), so
``chi(z, K) = det(zI - A(K))`` has degree N in z and r in K.

1. Coefficients: chi(z, 0) from the eigenvalues of A0 (a product of root factors,
   backward stable); for r = 1 the K-coefficient by Faddeev-LeVerrier applied to
   B1; for r = 2 eigenvalues at two more K and interpolation in K.
2. Candidates: a pole is on |z| = 1 for real K only where chi(z, K) and its
   reversal ``z^N chi(1/z, K)`` share the root K: for r = 1 the polynomial
   ``a b~ - a~ b``, for r = 2 the resultant of two quadratics in K. It is exactly
   (anti-)palindromic, so its unit-circle roots are the real roots in cos(theta) of
   a Chebyshev series of half the degree (colleague matrix). No grid.
3. Polish: Newton on ``Im mu(theta) = 0``, mu an eigenvalue of
   ``G(e^{j theta}) = C1 (zI - A0)^-1 B1`` (K = 1/mu) by linear solves, to rounding.
   Crossings at z = +-1 come from the real eigenvalues of G(+-1).
4. Classification: poles outside the circle are counted at an anchor near K = 0
   and inside each gap between crossings. Each crossing moves 2 poles (1 at
   z = +-1); a count that jumps by more means a missed crossing, which is then
   found by bisection on the count and polished. Near a crossing the count is only
   as good as eigenvalues of poles crowding z = 1, so it never sets a value.

Modes at z = 1 that exist for every K (a mass nothing ties to ground) are
rigid-body modes: counted, divided out and reported, never called unstable.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .charpoly import (chi_coefficients, crossing_polys, deflate, positive_real_roots,
                       rough_mu, unit_circle_angles)
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
        raise AnalysisError(sysm.fixed_reason or "controller: no stiffness K to vary")
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
    coef = chi_coefficients(A0, A1, Ks, r, eig0, B1, C1)

    # --- complex crossings: candidates, then polish on the exact frequency response
    cs = coef.copy()
    for p in np.flatnonzero(rigid):
        cs[p] = [deflate(ci, rigid[p]) for ci in coef[p]]
    ths = unit_circle_angles(crossing_polys(cs))
    cand_p = np.repeat(np.arange(P), [t.size for t in ths])
    crossings: list[list[tuple[float, float]]] = [[] for _ in range(P)]  # (K, theta)
    if cand_p.size:
        th0 = np.concatenate(ths)
        mu0 = rough_mu(cs[cand_p], Ks[cand_p], th0)
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
            for p, roots in zip(idx, positive_real_roots(vals)):
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
