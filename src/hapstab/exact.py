"""Exact stability and exact critical stiffness of the sampled-data loop.

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

from .engine import SampledSystem, build
from .errors import AnalysisError
from .models import HapticLoop, TeleoperationLoop
from .results import CriticalStiffnessResult, StabilityResult

__all__ = ["stability", "exact_critical_stiffness", "exact_kmax_batch", "rigid_body_modes",
           "spectral_radius"]

#: |z| - 1 below this (relative to rounding of the eigenvalue solver) is "on the circle".
MARGINAL_TOL = 1e-9


def rigid_body_modes(A0: np.ndarray, A1: np.ndarray) -> int:
    """Number of independent modes at z = 1 that no K moves: dim null([I - A0; A1])."""
    N = A0.shape[-1]
    S = np.linalg.svd(np.vstack([np.eye(N) - A0, A1]), compute_uv=False)
    scale = max(1.0, float(S[0]))
    return int(np.sum(S < 1e-10 * scale))


def _spectral_radius(eigs: np.ndarray, n_rigid: int) -> np.ndarray:  # noqa: D401
    """Spectral radius over the last axis, excluding the n_rigid eigenvalues nearest 1."""
    if n_rigid:
        order = np.argsort(np.abs(eigs - 1.0), axis=-1)
        eigs = np.take_along_axis(eigs, order[..., n_rigid:], axis=-1)
    return np.abs(eigs).max(axis=-1)


def spectral_radius(sysm: SampledSystem, K: np.ndarray | float) -> np.ndarray:
    """Spectral radius of A(K) for each period (rigid-body modes excluded)."""
    A = sysm.closed_loop(K)
    m = rigid_body_modes(sysm.A0[0], sysm.A1()[0]) if sysm.varies_with_K else 0
    return _spectral_radius(np.linalg.eigvals(A), m)


# ---------------------------------------------------------------------- stability
def stability(loop: HapticLoop | TeleoperationLoop) -> StabilityResult:
    """Exact stability of the sampled-data loop at its own parameters.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop

    Returns
    -------
    StabilityResult
        ``stable`` if every closed-loop pole has |z| < 1, ``unstable`` if one has
        |z| > 1, ``marginal`` if the largest is on the circle (within 1e-9) or a
        rigid-body mode sits at z = 1.

    References
    ----------
    Exact ZOH model of Fig. 2a / Fig. 3 with H(z) of eq. (23).
    """
    sysm = build(loop)
    A = sysm.closed_loop()[0]
    eigs = np.linalg.eigvals(A)
    m = rigid_body_modes(sysm.A0[0], sysm.A1()[0]) if sysm.varies_with_K else 0
    rest = eigs
    if m:
        order = np.argsort(np.abs(eigs - 1.0))
        rest = eigs[order[m:]]
    k = int(np.argmax(np.abs(rest))) if rest.size else 0
    dom = complex(rest[k]) if rest.size else complex(1.0)
    rho = abs(dom)
    T = loop.period
    freq = abs(math.atan2(dom.imag, dom.real)) / (2 * math.pi * T)
    if rho > 1 + MARGINAL_TOL:
        verdict = "unstable"
        reason = (f"closed-loop pole at |z| = {rho:.6g} > 1 ({_describe(dom, T)}): "
                  "the response grows")
    elif rho >= 1 - MARGINAL_TOL:
        verdict = "marginal"
        reason = f"closed-loop pole on the unit circle ({_describe(dom, T)}): sustained oscillation or drift"
    elif m:
        verdict = "marginal"
        reason = (f"{m} rigid-body mode(s) at z = 1: nothing ties the masses to ground, so a "
                  "constant offset persists; all other poles have |z| <= "
                  f"{rho:.6g} < 1")
    else:
        verdict = "stable"
        reason = f"all closed-loop poles inside the unit circle (largest |z| = {rho:.6g})"
    if m and verdict != "marginal":
        reason += f"; {m} rigid-body mode(s) at z = 1 excluded"
    return StabilityResult(verdict, rho, dom, freq, reason, T, tuple(complex(e) for e in eigs), m)


def _describe(z: complex, T: float) -> str:
    th = abs(math.atan2(z.imag, z.real))
    if th < 1e-12:
        return "real pole at z = +1 side (non-oscillatory)"
    if abs(th - math.pi) < 1e-9:
        return f"real pole at z = -1 side (oscillation at the Nyquist frequency {1 / (2 * T):.6g} Hz)"
    return f"complex pair, oscillation at {th / (2 * math.pi * T):.6g} Hz"


# --------------------------------------------------------------- exact K_max core
def _chi_coefficients(A0: np.ndarray, A1: np.ndarray, Ks: np.ndarray, r: int) -> np.ndarray:
    """Coefficients (ascending in z) of chi's K'-polynomial, K' = K/Ks.

    Returns (P, r+1, N+1) real: chi(z, K) = sum_l (K/Ks)^l sum_m c[l, m] z^m.
    """
    P, N, _ = A0.shape
    M = N + 1
    zk = np.exp(2j * np.pi * np.arange(M) / M)
    Kl = np.arange(r + 1)[None, :] * Ks[:, None]                     # (P, r+1)
    A = A0[:, None] + Kl[:, :, None, None] * A1[:, None]               # (P, r+1, N, N)
    mats = zk[None, None, :, None, None] * np.eye(N) - A[:, :, None]   # (P, r+1, M, N, N)
    vals = np.linalg.det(mats)                                         # (P, r+1, M)
    cz = np.fft.fft(vals, axis=-1) / M                                 # coefficients in z
    V = np.vander(np.arange(r + 1, dtype=float), r + 1, increasing=True)  # rows: l^0..l^r
    coef = np.einsum("kl,plm->pkm", np.linalg.inv(V), cz)              # in K'
    return coef.real


def _rev(x: np.ndarray) -> np.ndarray:
    return x[::-1]


def _crossing_poly(c: np.ndarray) -> np.ndarray:
    """Ascending coefficients of the polynomial whose unit-circle roots are all
    frequencies where chi(e^{j theta}, K) = 0 for some real K."""
    mul = np.convolve  # (polymul would trim zeros and misalign the reversal)
    if c.shape[0] == 2:
        a, b = c
        q = mul(a, _rev(b))
        return q - q[::-1]   # exactly anti-palindromic
    a, b, cc = c
    x1 = mul(cc, _rev(a)) - mul(_rev(cc), a)
    x2 = mul(cc, _rev(b)) - mul(_rev(cc), b)
    x3 = mul(b, _rev(a)) - mul(_rev(b), a)
    q = mul(x1, x1) - mul(x2, x3)
    # exact (anti-)palindromic symmetry keeps simple unit-circle roots on the circle
    return 0.5 * (q + q[::-1]) if np.abs(q + q[::-1]).sum() > np.abs(q - q[::-1]).sum() \
        else 0.5 * (q - q[::-1])


def _unit_roots(q: np.ndarray, tol: float = 2e-3) -> np.ndarray:
    """Angles in (0, pi) of the roots of q (ascending coefficients) near |z| = 1."""
    scale = np.abs(q).max()
    if scale == 0:
        return np.zeros(0)
    nz = np.flatnonzero(np.abs(q) > 1e-13 * scale)
    q = q[nz[0]:nz[-1] + 1]
    if q.size < 2:
        return np.zeros(0)
    z = np.roots(q[::-1])
    th = np.angle(z)
    keep = (np.abs(np.abs(z) - 1) < tol) & (th > 1e-9) & (th < np.pi - 1e-9)
    return np.sort(th[keep])


def _mu(A0: np.ndarray, B1: np.ndarray, C1: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Eigenvalues of G(e^{j theta}) = C1 (zI - A0)^-1 B1, shape (n, r)."""
    N = A0.shape[-1]
    z = np.exp(1j * theta)
    X = np.linalg.solve(z[:, None, None] * np.eye(N) - A0, B1.astype(complex))
    G = C1 @ X
    if G.shape[-1] == 1:
        return G[:, :, 0]
    t = G[:, 0, 0] + G[:, 1, 1]
    d = G[:, 0, 0] * G[:, 1, 1] - G[:, 0, 1] * G[:, 1, 0]
    s = np.sqrt(t * t / 4 - d)
    return np.stack([t / 2 + s, t / 2 - s], axis=-1)


def _pick(mu: np.ndarray) -> np.ndarray:
    """The branch closest to the real axis (relative)."""
    rel = np.abs(mu.imag) / np.maximum(np.abs(mu), 1e-300)
    return np.take_along_axis(mu, np.argmin(rel, axis=-1)[:, None], axis=-1)[:, 0]


def _polish(A0, B1, C1, theta, iters: int = 14):
    """Newton on Im mu(theta) = 0 (derivative by central difference)."""
    th = theta.copy()
    for _ in range(iters):
        h = 1e-7 * np.maximum(th, 1e-3)
        f0 = _pick(_mu(A0, B1, C1, th))
        fp = _pick(_mu(A0, B1, C1, th + h))
        fm = _pick(_mu(A0, B1, C1, th - h))
        # follow the branch picked at th: compare the nearer of each
        d = (fp.imag - fm.imag) / (2 * h)
        step = np.where(d != 0, f0.imag / np.where(d != 0, d, 1.0), 0.0)
        lim = 0.2 * np.maximum(np.minimum(th, np.pi - th), 1e-3)   # damped: stay near the candidate
        step = np.clip(step, -lim, lim)
        th = np.clip(th - step, 1e-12, np.pi - 1e-12)
    mu = _pick(_mu(A0, B1, C1, th))
    return th, mu


def exact_kmax_batch(sysm: SampledSystem) -> list[dict[str, Any]]:
    """Exact K_max and the stable intervals in K for every period of ``sysm``.

    Returns one dict per period with ``kmax``, ``intervals``, ``theta`` (angle of
    the crossing at K_max, nan if none), ``rigid`` and ``reason``.
    """
    if not sysm.varies_with_K:
        raise AnalysisError("controller: critical stiffness needs SpringDamper controllers "
                            "(a general H(z) has no stiffness K to vary)")
    A1 = sysm.B1 @ sysm.C1
    # K enters with the numerical rank of A1 (PEB without delay: rank 1, the two
    # error signals being opposite); factor A1 = B1 C1 at that rank, by groups.
    U, S, Vt = np.linalg.svd(A1)
    ranks = np.sum(S > 1e-12 * S[:, :1], axis=1)
    out: list[dict[str, Any] | None] = [None] * A1.shape[0]
    for r in np.unique(ranks):
        idx = np.flatnonzero(ranks == r)
        if not 1 <= r <= 2:
            raise AnalysisError(f"stiffness enters the loop with rank {r}; only 1 or 2 is supported")
        B1 = U[idx, :, :r] * S[idx, None, :r]
        C1 = Vt[idx, :r, :]
        for i, res in zip(idx, _kmax_core(sysm.A0[idx], B1, C1)):
            out[i] = res
    return out  # type: ignore[return-value]


def _kmax_core(A0: np.ndarray, B1: np.ndarray, C1: np.ndarray) -> list[dict[str, Any]]:
    A1 = B1 @ C1
    P, N, _ = A0.shape
    r = B1.shape[-1]
    Ks = np.linalg.norm(A0, axis=(1, 2)) / np.maximum(np.linalg.norm(A1, axis=(1, 2)), 1e-300)
    Ks = 2.0 ** np.round(np.log2(Ks))   # a power of two keeps K/Ks exact
    rigid = np.array([rigid_body_modes(A0[p], A1[p]) for p in range(P)])

    coef = np.concatenate([_chi_coefficients(A0[s:s + 256], A1[s:s + 256], Ks[s:s + 256], r)
                           for s in range(0, P, 256)])

    # --- complex crossings: candidates, then polish on the exact frequency response
    cand_p, cand_th = [], []
    for p in range(P):
        c = coef[p]
        if rigid[p]:
            c = np.array([_deflate(ci, rigid[p]) for ci in c])
        th = _unit_roots(_crossing_poly(c))
        cand_p.extend([p] * th.size)
        cand_th.extend(th.tolist())
    cand_p = np.array(cand_p, dtype=int)
    crossings: list[list[tuple[float, float]]] = [[] for _ in range(P)]  # (K, theta)
    if cand_p.size:
        th0 = np.array(cand_th)
        mu0 = _pick(_mu(A0[cand_p], B1[cand_p], C1[cand_p], th0))
        ok0 = np.abs(mu0.imag) < 0.5 * np.abs(mu0)   # rough candidates near z = 1: be generous
        if ok0.any():
            ps, th1 = cand_p[ok0], th0[ok0]
            th, mu = _polish(A0[ps], B1[ps], C1[ps], th1)
            good = (np.abs(mu.imag) <= 1e-9 * np.abs(mu)) & (mu.real > 0)
            for p, t, m in zip(ps[good], th[good], mu[good]):
                crossings[p].append((1.0 / m.real, float(t)))

    # --- real crossings at z = +1 and z = -1: real roots of chi(+-1, K)
    for zsign, theta in ((1.0, 0.0), (-1.0, math.pi)):
        zpow = zsign ** np.arange(N + 1)
        for p in range(P):
            c = coef[p]
            if zsign > 0 and rigid[p]:
                c = np.array([_deflate(ci, rigid[p]) for ci in c])
                vals = c[:, :].sum(axis=1)
            else:
                vals = c @ zpow
            if not np.any(vals[1:]):
                continue
            for k in np.roots(vals[::-1]):
                if abs(k.imag) <= 1e-9 * abs(k) and k.real > 0:
                    crossings[p].append((_refine_real(A0[p], A1[p], zsign, k.real * Ks[p],
                                                      rigid[p]), theta))

    # --- classify the gaps between crossings (batched), with a consistency net
    for p in range(P):
        Kc: list[tuple[float, float]] = []
        for K, th in sorted(crossings[p]):
            if K > 1e-12 * Ks[p] and np.isfinite(K) and (not Kc or K > Kc[-1][0] * (1 + 1e-10)):
                Kc.append((K, th))
        crossings[p] = Kc
    mids = [_midpoints([k for k, _ in crossings[p]], Ks[p]) for p in range(P)]
    mp = np.repeat(np.arange(P), [len(m) for m in mids])
    mK = np.concatenate(mids)
    outside = np.empty(mK.size, dtype=int)
    rho = np.empty(mK.size)
    for s in range(0, mK.size, 2048):
        sl = slice(s, s + 2048)
        eig = np.linalg.eigvals(A0[mp[sl]] + mK[sl, None, None] * A1[mp[sl]])
        for i, p in enumerate(mp[sl]):
            outside[s + i], rho[s + i] = _count_outside(eig[i], rigid[p])
    out = []
    pos = 0
    for p in range(P):
        cnt = len(mids[p])
        u, rh = outside[pos:pos + cnt], rho[pos:pos + cnt]
        pos += cnt
        if not _consistent(crossings[p], u):
            crossings[p], u, rh = _repair(A0[p], A1[p], rigid[p], crossings[p], Ks[p])
        out.append(_intervals(crossings[p], u, rh, int(rigid[p])))
    return out


def _midpoints(Kv: list[float], Ks: float) -> list[float]:
    if not Kv:
        return [Ks]
    return [Kv[0] / 2] + [(a + b) / 2 for a, b in zip(Kv, Kv[1:])] + [2 * Kv[-1]]


def _count_outside(eig: np.ndarray, n_rigid: int) -> tuple[int, float]:
    """(number of poles with |z| > 1, spectral radius), rigid-body modes excluded."""
    if n_rigid:
        eig = eig[np.argsort(np.abs(eig - 1.0))[n_rigid:]]
    a = np.abs(eig)
    return int(np.sum(a >= 1.0)), float(a.max())


def _consistent(cr: list[tuple[float, float]], u: np.ndarray) -> bool:
    """Each crossing moves 2 poles (complex pair) or 1 (real, at z = +-1) across
    the circle; a larger jump in the outside count means a crossing was missed."""
    for g, (_, th) in enumerate(cr):
        mult = 1 if th in (0.0, math.pi) else 2
        if abs(int(u[g + 1]) - int(u[g])) > mult:
            return False
    return True


def _repair(A0, A1, rigid, cr, Ks, rounds: int = 4):
    """Fallback: locate missed crossings by bisection on the outside count."""
    def count(K: float) -> tuple[int, float, complex]:
        eig = np.linalg.eigvals(A0 + K * A1)
        if rigid:
            eig = eig[np.argsort(np.abs(eig - 1.0))[rigid:]]
        i = int(np.argmin(np.abs(np.abs(eig) - 1.0)))
        return int(np.sum(np.abs(eig) >= 1.0)), float(np.abs(eig).max()), complex(eig[i])

    for _ in range(rounds):
        Kv = [k for k, _ in cr]
        mids = _midpoints(Kv, Ks)
        res = [count(k) for k in mids]
        u = np.array([r[0] for r in res])
        if _consistent(cr, u):
            return cr, u, np.array([r[1] for r in res])
        for g, (_, th) in enumerate(cr):
            mult = 1 if th in (0.0, math.pi) else 2
            if abs(int(u[g + 1]) - int(u[g])) > mult:
                lo, hi, ulo = mids[g], mids[g + 1], u[g]
                # bisect for the change of count away from the known crossing
                for _ in range(200):
                    mid = 0.5 * (lo + hi)
                    if hi - lo <= 1e-15 * hi:
                        break
                    if count(mid)[0] == ulo:
                        lo = mid
                    else:
                        hi = mid
                if abs(hi / cr[g][0] - 1) > 1e-9:
                    z = count(hi)[2]
                    cr = sorted(cr + [(hi, abs(math.atan2(z.imag, z.real)))])
                break
    Kv = [k for k, _ in cr]
    res = [count(k) for k in _midpoints(Kv, Ks)]
    return cr, np.array([r[0] for r in res]), np.array([r[1] for r in res])


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


def exact_critical_stiffness(loop: HapticLoop | TeleoperationLoop) -> CriticalStiffnessResult:
    """Exact K_max of the sampled-data loop (see the module docstring).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controller(s); B, T, n and impedances fixed. For
        teleoperation, K is the master's stiffness and K_s/K_m is kept.

    Returns
    -------
    CriticalStiffnessResult
        ``method="exact"``; ``stable_intervals`` lists every stable interval.

    Raises
    ------
    AnalysisError
        If the controller is not a spring-damper.
    """
    sysm = build(loop)
    res = exact_kmax_batch(sysm)[0]
    return _to_result(res, loop.period, loop.delay_samples)


def _to_result(res: dict[str, Any], T: float, n: int | float) -> CriticalStiffnessResult:
    kmax, th = res["kmax"], res["theta"]
    freq = th / (2 * math.pi * T) if np.isfinite(th) else math.nan
    if kmax == 0.0:
        reason = (f"unstable for every K > 0: already as K -> 0+ the spectral radius is "
                  f"{res['rho_small_K']:.6g} > 1 (the virtual damping, delay and terminations "
                  "alone destabilise the loop)")
    elif math.isinf(kmax):
        reason = "stable for every K > 0 (no closed-loop pole reaches the unit circle)"
    elif th == 0.0:
        reason = "a real closed-loop pole crosses z = +1 at K_max (static divergence)"
    elif th == math.pi:
        reason = (f"a real closed-loop pole crosses z = -1 at K_max (oscillation at the "
                  f"Nyquist frequency, {1 / (2 * T):.6g} Hz)")
    else:
        reason = f"a complex pole pair crosses |z| = 1 at K_max, oscillating at {freq:.6g} Hz"
    if len(res["intervals"]) > 1:
        reason += f"; the stable set in K is not one interval ({len(res['intervals'])} intervals)"
    if res["rigid"]:
        reason += f"; {res['rigid']} rigid-body mode(s) at z = 1 (marginal, K-independent) excluded"
    return CriticalStiffnessResult(kmax, "exact", res["intervals"], reason, T, n, freq,
                                   {"rigid_body_modes": res["rigid"]})
