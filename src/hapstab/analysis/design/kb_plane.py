"""The (K, B) plane of a loop with equal spring-damper controllers: the loop of a unit
stiffness, and the exact boundary where a pole is on |z| = 1 (D-decomposition).

With C = K + B (z - 1)/(T z) on every port, the loop depends on (K, B) only through
``h(z) = K + (B/T)(1 - z^-1)``; a pole sits on |z| = 1 exactly where
``h(e^{j theta}) = 1/mu`` for an eigenvalue mu of ``G(e^{j theta})`` (see
:mod:`hapstab.analysis.design.regions`).

References
----------
Gil, Avello, Rubio, Florez 2004; Hulin, Preusche, Hirzinger 2008 (K-B charts).
"""

from __future__ import annotations

import contextlib
import dataclasses
from typing import Any, cast

import numpy as np

from hapstab.engine.structure import structure_of
from hapstab.engine.system import build
from hapstab.errors import AnalysisError
from hapstab.models.controllers import SpringDamper
from hapstab.models.loops import HapticLoop, TeleoperationLoop, require_loop
from hapstab.tolerances import DIVISOR_FLOOR

__all__ = ["check_equal_gains", "with_gains", "d_decomposition", "REFINE_STEP", "Loop"]

Loop = HapticLoop | TeleoperationLoop


def check_equal_gains(loop: Loop) -> float:
    """Validate a K-B study's assumptions: spring-damper controllers, all equal (C_m = C_s).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop.

    Returns
    -------
    float
        The reference damping b: the smallest device damping in N*s/m.

    Raises
    ------
    AnalysisError
        A controller that is not a spring-damper, or unequal controllers.
    """
    require_loop(loop)
    cs = loop.controllers
    if not all(c.gains() is not None for c in cs):
        raise AnalysisError("controller: a K-B region needs SpringDamper (or "
                            "FilteredSpringDamper) controllers")
    if any(c != cs[0] for c in cs):
        raise AnalysisError("controllers: a K-B region is drawn for C_m = C_s (equal K and B)")
    return min(pt.device.damping for pt in structure_of(loop).ports)


def with_gains(loop: Loop, K: float, B: float) -> Loop:
    """The loop with stiffness K and virtual damping B on every controller (a velocity
    filter kept)."""
    c = loop.controllers[0]
    if c.gains() is not None:     # a spring-damper: its fields K and B (its filter kept)
        return loop.with_controllers(dataclasses.replace(cast(Any, c), stiffness=K, damping=B))
    return loop.with_controllers(SpringDamper(K, B))


def damper_factor(loop: Loop, theta: np.ndarray) -> np.ndarray | None:
    """g(theta) with h = K + B g on |z| = 1: ``(1 - z^-1) F(z) / T`` for a filtered
    damper (:class:`~hapstab.models.controllers.VelocityFilter`), ``None`` for eq. (23)'s
    plain one (``(1 - z^-1)/T``, which :func:`_kb` takes in closed form)."""
    vf = getattr(loop.controllers[0], "velocity_filter", None)
    if vf is None:
        return None
    T = loop.period
    z = np.exp(1j * theta)
    num, den = vf.transfer(T)
    # 1 - e^{-j theta} = 2j sin(theta/2) e^{-j theta/2}: no cancellation near theta = 0
    diff = 2j * np.sin(theta / 2) * np.exp(-0.5j * theta)
    return diff / T * np.polyval(num, z) / np.polyval(den, z)


def _unit_loop(loop: Loop) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A0, B1, C1) of the loop with no controller and the K-injection of a unit gain."""
    s = build(with_gains(loop, 0.0, 0.0))
    return s.A0[0], s.B1[0], s.C1[0]


def _mu(A0: np.ndarray, B1: np.ndarray, C1: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Eigenvalues of G(z) for each z, shape (len(z), p), in numpy's order; NaN at a z
    where zI - A0 is singular to working precision (an undamped mode of the loop without
    controller exactly at a grid angle: G has a pole there, the boundary a gap)."""
    N = A0.shape[0]
    # in chunks of at most ~64 MB of N x N complex matrices: the memory stays flat in
    # the number of angles (4000 angles of a 200-state loop were 5 GB at once)
    chunk = max(1, int(64e6 // (16 * N * N)))
    G = np.concatenate([_transfer(A0, B1, C1, zc)
                        for zc in np.array_split(z, -(-z.size // chunk))])
    out = np.full(G.shape[:2], np.nan + 0j)
    ok = np.isfinite(G).all(axis=(1, 2))
    out[ok] = np.linalg.eigvals(G[ok])
    return out


def _transfer(A0: np.ndarray, B1: np.ndarray, C1: np.ndarray, z: np.ndarray) -> np.ndarray:
    """C1 (zI - A0)^-1 B1 at each z (NaN where the solve meets a singular matrix)."""
    M = z[:, None, None] * np.eye(A0.shape[0]) - A0
    rhs = np.broadcast_to(B1, (z.size, *B1.shape))
    try:
        return C1 @ np.linalg.solve(M, rhs)
    except np.linalg.LinAlgError:        # one singular angle: the others one by one
        out = np.full((z.size, C1.shape[0], B1.shape[1]), np.nan + 0j)
        for i in range(z.size):
            with contextlib.suppress(np.linalg.LinAlgError):
                out[i] = C1 @ np.linalg.solve(M[i], B1)
        return out


def _follow(mu: np.ndarray) -> np.ndarray:
    """Keep each of two branches continuous: swap where that is nearer the previous point."""
    if mu.shape[1] == 2:
        for i in range(1, mu.shape[0]):
            a, b = mu[i]
            if abs(a - mu[i - 1, 0]) + abs(b - mu[i - 1, 1]) > abs(b - mu[i - 1, 0]) + abs(a - mu[i - 1, 1]):
                mu[i] = b, a
    return mu


def _kb(mu: np.ndarray, th: np.ndarray, T: float, g: np.ndarray | None = None
        ) -> tuple[np.ndarray, np.ndarray]:
    """(K, B) on |z| = 1 at angles ``th`` for each branch (columns), from h = 1/mu =
    K + B g (g = :func:`damper_factor`; ``None``: (1 - z^-1)/T)."""
    with np.errstate(all="ignore"):
        h = 1.0 / mu
        if g is None:
            K = h.real - h.imag * np.tan(th / 2)[:, None]
            B = T * h.imag / np.sin(th)[:, None]
        else:
            B = h.imag / g.imag[:, None]
            K = h.real - B * g.real[:, None]
        bad = ~(np.isfinite(K) & np.isfinite(B) & (np.abs(mu) > DIVISOR_FLOOR))
    K[bad], B[bad] = np.nan, np.nan
    return K, B


#: A boundary step longer than this fraction of the window is refined (a step of 1/250
#: of the window is below a line's width on a figure).
REFINE_STEP = 0.004


def _refine(A0: np.ndarray, B1: np.ndarray, C1: np.ndarray, kb: Any, th: np.ndarray,
            mu: np.ndarray, window: tuple[tuple[float, float], tuple[float, float]],
            extra: int) -> tuple[np.ndarray, np.ndarray]:
    """Add angles where the boundary jumps across the window (where it turns fast with
    theta), by bisection, until every step inside it is shorter than REFINE_STEP of the
    window or ``extra`` angles were added."""
    (K0, K1), (Bl, Bh) = window
    added = 0
    for _ in range(12):                       # each round halves the worst steps
        K, B = kb(mu, th)
        with np.errstate(over="ignore", invalid="ignore"):
            # (a point more than ~1e308 window widths away -- a window of 1e-300 N/m and a
            # boundary K of 1e9 -- overflows to inf: outside the window, as it is; and
            # inf - inf, a step between two such points, is NaN, taken as a gap below)
            u = (K - K0) / max(K1 - K0, DIVISOR_FLOOR)
            v = (B - Bl) / max(Bh - Bl, DIVISOR_FLOOR)
            step = np.hypot(np.diff(u, axis=0), np.diff(v, axis=0))
        inside = (u >= -0.1) & (u <= 1.1) & (v >= -0.1) & (v <= 1.1)
        step = np.where(np.isnan(step), np.inf, step)       # a gap next to a point inside
        want = ((inside[1:] | inside[:-1]) & (step > REFINE_STEP)).any(axis=1)
        idx = np.flatnonzero(want & (np.diff(th) > 1e-12))   # (angles 1e-12 apart: a jump)
        if idx.size == 0 or added >= extra:
            break
        idx = idx[np.argsort(-np.nanmax(np.where(np.isfinite(step), step, 1e9), axis=1)[idx])]
        idx = idx[:extra - added]
        new = 0.5 * (th[idx] + th[idx + 1])
        added += new.size
        th = np.concatenate([th, new])
        mu = np.concatenate([mu, _mu(A0, B1, C1, np.exp(1j * new))])
        order = np.argsort(th)
        th, mu = th[order], _follow(mu[order])
    return th, mu


def d_decomposition(loop: Loop, n_theta: int = 4000,
                    window: tuple[tuple[float, float], tuple[float, float]] | None = None
                    ) -> dict[str, Any]:
    """The exact K-B boundary: every (K, B) at which a closed-loop pole is on |z| = 1.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Equal spring-damper controllers (their K and B are the unknowns).
    n_theta : int
        Angles of the first sweep of the unit circle.
    window : ((K_lo, K_hi), (B_lo, B_hi)), optional
        Where the boundary is drawn: angles are added (up to ``n_theta`` more) where it
        crosses the window in steps longer than :data:`REFINE_STEP` of it, so that it is
        drawn wherever it exists (near a resonance it turns fast with theta).

    Returns
    -------
    dict
        ``curves``: list of (m, 2) arrays of (K, B) for complex crossings (one per
        eigenvalue branch, theta from ~0 to pi); ``z1``: K of the vertical lines
        (z = 1); ``zm1``: c of the lines K + g B = c (z = -1), ``zm1_B_per_s`` = g
        (2/T without a velocity filter).
    """
    check_equal_gains(loop)
    T = loop.period
    A0, B1, C1 = _unit_loop(loop)
    # dense near theta = 0, where the slow (physical) dynamics live, from 1e-6 rad/sample
    # (w = 1e-6/T, slower than any device mode; theta -> 0 itself is the z = 1 line) to
    # 1e-9 short of pi, where B = T Im(h) / sin(theta) is 0/0 (pi is the z = -1 line)
    th = np.unique(np.concatenate([np.geomspace(1e-6, 0.2, n_theta // 2),
                                   np.linspace(0.2, np.pi - 1e-9, n_theta // 2)]))  # see above
    mu = _follow(_mu(A0, B1, C1, np.exp(1j * th)))

    def kb(m: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _kb(m, t, T, damper_factor(loop, t))

    if window is not None:
        th, mu = _refine(A0, B1, C1, kb, th, mu, window, n_theta)
    K, B = kb(mu, th)
    curves = [np.column_stack([K[ok, i], B[ok, i]])
              for i in range(mu.shape[1]) for ok in [np.isfinite(K[:, i])]]
    g_pi = damper_factor(loop, np.array([np.pi]))
    return {"curves": curves, **_real_lines(A0, B1, C1), "period": T,
            "zm1_B_per_s": 2.0 / T if g_pi is None else float(g_pi[0].real)}


def _real_lines(A0: np.ndarray, B1: np.ndarray, C1: np.ndarray) -> dict[str, list[float]]:
    """The crossings at z = 1 (vertical lines K = const) and z = -1 (K + g B = const,
    g = 2/T, or ``zm1_B_per_s`` with a velocity filter)."""
    lines = {}
    for name, z in (("z1", 1.0), ("zm1", -1.0)):
        vals = []
        M = z * np.eye(A0.shape[0]) - A0
        if np.linalg.cond(M) < 1e12:
            for m in np.linalg.eigvals(C1 @ np.linalg.solve(M, B1)):
                # real to rounding: eigvals leaves a simple real eigenvalue ~1e-15 |m| of
                # imaginary part; a genuine complex m is far from real
                if abs(m.imag) <= 1e-9 * abs(m) and m.real != 0:
                    vals.append(1.0 / m.real)
        else:
            vals.append(0.0)          # a pole of the open loop at z = 1 (a free mass): K = 0
        lines[name] = sorted(vals)
    return lines
