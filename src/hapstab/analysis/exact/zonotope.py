"""A lower bound of the lowest crossing of every loop of a family, from a
first-order (mean-value) enclosure of the characteristic function over the
family's box of parameters.

For an operator p in the box B with centre c and half-widths h,

    F(theta, u; p) = F(theta, u; c) + sum_i (p_i - c_i) int_0^1 dF/dp_i(theta, u; c + s (p - c)) ds,

and each integral lies in the disc G_i that encloses dF/dp_i over B (discs are
convex). So on a box (theta-cell x u-interval), every F(.; p) lies in the rounded
zonotope ``Z = D_c + sum_i [-h_i, h_i] G_i``: the disc D_c of the centre's F plus a
segment per parameter plus the discs' radii. Z excludes 0 when some direction
separates it from 0; the candidates are the normals of its edges and the
directions of its vertices (the nearest point of a convex polygon with a rounded
boundary is on an edge or at a vertex). Unlike one disc per coefficient (which
loses how the coefficients move together), Z is exact to first order in h: near a
lightly damped resonance that the operators of B move across, the family's values
at a fixed angle form a short curve that misses 0, which Z keeps and a disc does not.

The search is branch and prune over (theta-cell x u-interval) from U_LO to a cap:
boxes excluded by Z are dropped (proved zero-free for every loop of B); a box whose
centre's own zonotope holds 0 (a loop of B may have a crossing there) lowers the
cap to its centre (nothing above it matters any more); a box narrower in u than a
tolerance is recorded at its lower end u_a, which lowers the cap to u_a; the others
are split. Every u below the final cap has been proved zero-free for every loop of
B: it is a lower bound of every loop's lowest crossing above U_LO.

References
----------
R. E. Moore, R. B. Kearfott and M. J. Cloud, *Introduction to Interval Analysis*,
SIAM 2009, sec. 6.4 (mean-value form); W. Kuhn, "Rigorously computed orbits of
dynamical systems without the wrapping effect", Computing 61 (1998) 47-67 (zonotopes).
"""

from __future__ import annotations

import numpy as np

from hapstab.analysis.exact.boxes import (
    THETA_FLOOR,
    U_FLOOR,
    U_LO,
    Cells,
    disc_mul,
    disc_quadratic,
    initial_cells,
)
from hapstab.analysis.exact.crossings import TURN_KMAX
from hapstab.engine.discs import EPS_OP
from hapstab.engine.frequency import LoopResponse

__all__ = ["family_floor"]

#: Rounds of splitting before the boxes left are recorded as they are (a safety
#: valve: every recorded box only lowers the bound, so it stays a bound).
MAX_ROUNDS = 80


def _evaluate(c: Cells, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray) -> tuple:
    """Discs of F over the boxes (cells x u-intervals) and at their centres, and the
    theta / u parts of the box disc's radius."""
    uc, ur = 0.5 * (ua + ub), 0.5 * (ub - ua)
    box = disc_quadratic(c.vc[:, cell], c.vr[:, cell], uc, ur)
    point = disc_quadratic(c.pc[:, cell], c.pr[:, cell], uc, np.zeros_like(uc))
    tc, tr = disc_quadratic(c.dc[:, cell], c.dr[:, cell], uc, ur)
    u2c, u2r = disc_mul(c.vc[2, cell], c.vr[2, cell], 2 * uc, 2 * ur)
    kc = np.abs(c.vc[1, cell] + u2c) + c.vr[1, cell] + u2r
    return box, point, c.rho[cell] * (np.abs(tc) + tr), ur * kc


def _margin(fc: np.ndarray, fr: np.ndarray, gens: list[tuple[np.ndarray, np.ndarray]]
            ) -> np.ndarray:
    """The largest distance by which a direction separates the rounded zonotope
    ``(fc +- fr) + sum_i [-1, 1] (gc_i +- gr_i)`` from 0 (<= 0: not separated)."""
    gc = [g[0] for g in gens]
    rad = fr + sum((g[1] for g in gens), np.zeros_like(fr))
    dirs = [fc]
    for g in gc:
        dirs += [1j * g, -1j * g]
    for signs in np.ndindex(*(2,) * len(gc)):
        dirs.append(fc + sum(((1 - 2 * s) * g for s, g in zip(signs, gc, strict=True)),
                             np.zeros_like(fc)))
    best = np.full(fc.shape, -np.inf)
    size = np.abs(fc) + rad + sum((np.abs(g) for g in gc), np.zeros_like(fr))
    with np.errstate(all="ignore"):
        for d in dirs:
            e = np.where(np.abs(d) > 0, d / np.abs(d), 1.0)
            m = np.real(np.conj(e) * fc) - sum((np.abs(np.real(np.conj(e) * g)) for g in gc),
                                               np.zeros_like(fr)) - rad
            best = np.maximum(best, np.where(np.isfinite(m), m, -np.inf))
    return best - 8 * EPS_OP * size           # the rounding of the test itself


def _split_cells(cs: list[Cells], resps: list[LoopResponse], cell: np.ndarray) -> np.ndarray:
    """Children of theta-cells (as :func:`hapstab.analysis.exact.boxes.split_cells`:
    an end cell [-rho, rho] around 0 or pi covers one side of it), added to every
    response's cells alike (same indices); returns the left children, then the right."""
    c = cs[0]
    it, th, rho, kind = c.item[cell], c.th[cell], c.rho[cell], c.kind[cell]
    h = rho / 2
    end = kind != 0
    lt = np.where(kind == 1, 0.0, np.where(kind == 2, np.pi - 1.5 * h, th - h))
    lr = np.where(end, np.where(kind == 1, h, 0.5 * h), h)
    rt = np.where(kind == 1, 1.5 * h, np.where(kind == 2, np.pi, th + h))
    rr = np.where(end, np.where(kind == 1, 0.5 * h, h), h)
    args = (np.concatenate([it, it]), np.concatenate([lt, rt]), np.concatenate([lr, rr]),
            np.concatenate([np.where(kind == 1, 1, 0), np.where(kind == 2, 2, 0)]))
    return [ci.add(r, *args) for ci, r in zip(cs, resps, strict=True)][0]  # noqa: RUF015


def _split(cs, resps, cell, ua, ub, w_th, w_u) -> tuple:
    """Split boxes in theta, in u or both, by which contributes to the disc's radius
    (within a factor 4 of each other: both); u at the geometric mean of a range over
    a factor of 4, else at the midpoint."""
    c = cs[0]
    can_t = c.rho[cell] > THETA_FLOOR * (1 + c.th[cell])
    t = (w_th >= 0.25 * w_u) & can_t
    need_u = (w_u >= 0.25 * w_th) | ~can_t
    kids = cell[:0]
    if t.any():                       # each parent cell once, however many boxes share it
        parents, inv = np.unique(cell[t], return_inverse=True)
        both = _split_cells(cs, resps, parents)
        kids = np.concatenate([both[:parents.size][inv], both[parents.size:][inv]])
    cell = np.concatenate([cell[~t], kids])
    ua, ub, need_u = (np.concatenate([a[~t], a[t], a[t]]) for a in (ua, ub, need_u))
    m = need_u
    mid = np.where(ub[m] > 4 * ua[m], np.sqrt(ua[m] * ub[m]), 0.5 * (ua[m] + ub[m]))
    return (np.concatenate([cell[~m], cell[m], cell[m]]), np.concatenate([ua[~m], ua[m], mid]),
            np.concatenate([ub[~m], mid, ub[m]]))


def _inside(c: Cells, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray,
            skip: np.ndarray) -> np.ndarray:
    """Boxes inside their item's excluded box ``skip`` (n_items, 4: theta_lo,
    theta_hi, u_lo, u_hi; nan: none)."""
    it = c.item[cell]
    th, rho, kind = c.th[cell], c.rho[cell], c.kind[cell]
    t_lo = np.where(kind == 1, -rho, th - rho)          # an end cell is symmetric
    t_hi = np.where(kind == 1, rho, th + rho)
    s = skip[it]
    return (t_lo >= s[:, 0]) & (t_hi <= s[:, 1]) & (ua >= s[:, 2]) & (ub <= s[:, 3])


def family_floor(centre: LoopResponse, derivs: list[LoopResponse], half: np.ndarray,
                 cap: np.ndarray, utol: np.ndarray | float = 0.0,
                 skip: np.ndarray | None = None) -> np.ndarray:
    """Per family, a u below which no loop of it has a pole on the unit circle
    (between U_LO and it).

    Parameters
    ----------
    centre : LoopResponse
        Each family's centre operator (one item per family).
    derivs : list of LoopResponse
        Per varying parameter, dF/dp enclosed over each family's box
        (:func:`hapstab.engine.operator_family.derivative_response`).
    half : (L, P) array
        The half-widths of the boxes in those parameters.
    cap : (L,) array
        Search each family only below this u.
    utol : float or (L,) array
        A box narrower than this (relative, in u) is recorded as it is rather than
        split: the bound is then at most that much below the sharpest one.
    skip : (L, 4) array, optional
        Per family, a box (theta_lo, theta_hi, u_lo, u_hi) left out of the search
        (nan: none): one whose crossings are accounted for otherwise (isolated).

    Returns
    -------
    (L,) array
        The bound (``cap`` where nothing was found below it; U_LO where a loop may
        have a crossing at once).
    """
    L = centre.size
    floor = np.asarray(cap, float).copy()
    utols = np.broadcast_to(np.asarray(utol, float), (L,))
    resps = [centre, *derivs]
    cs = [Cells() for _ in resps]
    init = initial_cells(centre, np.arange(L), TURN_KMAX)
    cell = [ci.add(r, *init) for ci, r in zip(cs, resps, strict=True)][0]  # noqa: RUF015
    # u from U_LO to the cap in steps of a factor 4 at most (most are excluded at once)
    top = floor[cs[0].item[cell]]
    steps = int(np.ceil(np.log(max(float(np.max(top / U_LO)), 4.0)) / np.log(4.0)))
    edges = np.maximum(U_LO, top[:, None] * 4.0 ** -np.arange(steps, -1, -1)[None, :])
    edges[:, 0] = U_LO
    cell = np.repeat(cell, steps)
    ua, ub = edges[:, :-1].ravel(), edges[:, 1:].ravel()
    for rnd in range(MAX_ROUNDS):
        it = cs[0].item[cell]
        ub = np.minimum(ub, floor[it])
        keep = ua < ub
        if skip is not None:
            keep &= ~_inside(cs[0], cell, ua, ub, skip)
        cell, ua, ub, it = cell[keep], ua[keep], ub[keep], it[keep]
        if not cell.size:
            break
        (fc, fr), (pc, pr), w_th, w_u = _evaluate(cs[0], cell, ua, ub)
        gens, pgens = [], []
        for p in range(len(derivs)):
            (gc, gr), (qc, qr), _, _ = _evaluate(cs[p + 1], cell, ua, ub)
            h = half[it, p]
            gens.append((h * gc, h * gr))
            pgens.append((h * qc, h * qr))
        out = _margin(fc, fr, gens) > 0
        rho, th = cs[0].rho[cell], cs[0].th[cell]
        tiny = (rho <= THETA_FLOOR * (1 + th)) & (ub - ua <= U_FLOOR * ub)
        # a box whose centre may hold a zero caps its family's search at the centre
        # (nothing above matters); one narrow in u, or at the floors, is recorded at
        # its lower end
        inside = ~out & (_margin(pc, pr, pgens) <= 0)
        np.minimum.at(floor, it[inside], 0.5 * (ua[inside] + ub[inside]))
        stuck = ~out & ((ub - ua <= utols[it] * ub) | tiny | (rnd == MAX_ROUNDS - 1))
        np.minimum.at(floor, it[stuck], ua[stuck])
        go = ~out & ~stuck
        cell, ua, ub = _split(cs, resps, cell[go], ua[go], ub[go], w_th[go], w_u[go])
    return floor
