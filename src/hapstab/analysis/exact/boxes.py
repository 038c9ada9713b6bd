"""The certified tests on one box of (theta-cell x u-interval), for
:mod:`~hapstab.analysis.exact.crossings`: the cells and their enclosures of the
characteristic function (from :mod:`hapstab.engine.discs`), the exact trimming of
the u-interval (four quadratic inequalities), the exclusion test and the Krawczyk
isolation test.

References
----------
R. Krawczyk, "Newton-Algorithmen zur Bestimmung von Nullstellen mit
Fehlerschranken", Computing 4 (1969) 187-201; R. E. Moore, R. B. Kearfott and
M. J. Cloud, *Introduction to Interval Analysis*, SIAM 2009, ch. 8.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.engine.discs import EPS_OP
from hapstab.engine.frequency import LoopResponse
from hapstab.tolerances import DIVISOR_FLOOR, NEWTON_ANGLE_STEP

__all__ = ["Cells", "Found", "THETA_FLOOR", "U_FLOOR", "U_LO", "U_HI", "initial_cells",
           "at_theta_floor", "split_cells", "disc_mul", "disc_quadratic", "trim_boxes",
           "classify_boxes", "krawczyk", "estimate_lowest", "polish_boxes"]

#: The analysed range of the dimensionless stiffness u = K T^2 / m (m the lightest
#: port's mass): below 1e-14 the loop is the continuous one to 1e-14 and nothing
#: can cross; above 1e10 the loop is far beyond any device (K = 1e10 m/T^2) and poles
#: approach the circle asymptotically, closer than rounding can resolve.
U_LO, U_HI = 1e-14, 1e10
#: A cell narrower than this (relative to theta + 1) cannot be split any more.
THETA_FLOOR = 64 * np.finfo(float).eps
#: A u-interval narrower than this (relative) cannot be split any more: 64 unit
#: round-offs, below which the midpoint of a split is no longer a distinct number
#: from its ends for the trimming's quadratic evaluations.
U_FLOOR = 64 * np.finfo(float).eps

# ----------------------------------------------------------------------- cells
class Cells:
    """theta-cells [th - rho, th + rho] with their enclosures of F0, F1, F2.

    Attributes (views of the first ``size`` cells): ``item``, ``th``, ``rho``, ``kind``
    (0 inner, 1 centred on 0, 2 centred on pi); per coefficient l = 0, 1, 2 (first
    axis): ``pc``, ``pr`` the value at th and its error, ``pd`` the derivative at th,
    ``vc``, ``vr`` a disc of the values on the cell, ``dc``, ``dr`` of the derivatives.
    Storage grows geometrically, so adding cells round after round stays linear.
    """

    _ONE = ("item", "th", "rho", "kind")
    _THREE = ("pc", "pr", "pd", "vc", "vr", "dc", "dr")
    # the views, set by _views()
    item: np.ndarray
    th: np.ndarray
    rho: np.ndarray
    kind: np.ndarray
    pc: np.ndarray
    pr: np.ndarray
    pd: np.ndarray
    vc: np.ndarray
    vr: np.ndarray
    dc: np.ndarray
    dr: np.ndarray

    def __init__(self) -> None:
        self.size = 0
        self._cap = 0
        self._buf: dict[str, np.ndarray] = {}
        self._grow(1024)

    def _grow(self, need: int) -> None:
        cap = max(need, 2 * self._cap)
        dt = {"item": int, "kind": int, "pc": complex, "pd": complex, "vc": complex, "dc": complex}
        for name in self._ONE + self._THREE:
            shape = (cap,) if name in self._ONE else (3, cap)
            new: np.ndarray = np.zeros(shape, dt.get(name, float))
            if name in self._buf:
                new[..., :self.size] = self._buf[name][..., :self.size]
            self._buf[name] = new
        self._cap = cap

    def _views(self) -> None:
        for name, arr in self._buf.items():
            setattr(self, name, arr[..., :self.size])

    def add(self, resp: LoopResponse, item, th, rho, kind) -> np.ndarray:
        """Append cells, computing their enclosures; returns their indices."""
        item, th, rho = np.asarray(item, int), np.asarray(th, float), np.asarray(rho, float)
        n = th.size
        both = resp.coefficients(np.concatenate([item, item]), np.concatenate([th, th]),
                                 np.concatenate([np.zeros_like(rho), rho]))
        pts = [_half(j, slice(0, n)) for j in both]
        cel = [_half(j, slice(n, 2 * n)) for j in both]
        vd = [c.value_disc(rho, p) for c, p in zip(cel, pts, strict=True)]
        start = self.size
        if start + n > self._cap:
            self._grow(start + n)
        sl = slice(start, start + n)
        b = self._buf
        b["item"][sl], b["th"][sl], b["rho"][sl] = item, th, rho
        b["kind"][sl] = np.broadcast_to(kind, th.shape)
        for deg in range(3):
            b["pc"][deg, sl], b["pr"][deg, sl], b["pd"][deg, sl] = pts[deg].vc, pts[deg].vr, pts[deg].dc
            b["vc"][deg, sl], b["vr"][deg, sl] = vd[deg]
            b["dc"][deg, sl], b["dr"][deg, sl] = cel[deg].dc, cel[deg].dr
        self.size = start + n
        self._views()
        return np.arange(start, self.size)


def _half(j, sl: slice):
    """One half of a jet evaluated on two stacked batches (points, then cells)."""
    return type(j)(j.vc[sl], j.vr[sl], j.dc[sl], j.dr[sl])


def initial_cells(resp: LoopResponse, items: np.ndarray, turn: float = 1.2
                   ) -> tuple[np.ndarray, ...]:
    """A uniform partition of [0, pi] in which the delay's phase turns by at most
    ``turn`` rad per cell; end cells are centred on 0 and pi. Only the cost depends
    on it: cells are split wherever their enclosures need it."""
    m = max(8, int(np.ceil(np.pi * resp.phase_rate / turn)))
    h = np.pi / m
    th = (np.arange(m + 1) * h)
    th[-1] = np.pi
    rho = np.full(m + 1, h / 2)
    th[1:-1] = (np.arange(1, m) * h)            # interior cells [(k-1/2)h, (k+1/2)h]
    kind = np.zeros(m + 1, int)
    kind[0], kind[-1] = 1, 2
    rho[0] = rho[-1] = h / 2
    it = np.repeat(items, m + 1)
    return it, np.tile(th, items.size), np.tile(rho, items.size), np.tile(kind, items.size)


def at_theta_floor(c: Cells, cell: np.ndarray) -> np.ndarray:
    """Cells that cannot be split further: theta is stored with a relative error of
    one unit round-off, so inner cells stop at THETA_FLOOR relative to theta; the
    end cell at 0 is exact down to underflow; the one at pi to THETA_FLOOR * pi."""
    th, rho, kind = c.th[cell], c.rho[cell], c.kind[cell]
    # the cell at 0 has no relative floor (theta = 0 is exact): it may shrink to 1e-290,
    # just above underflow (the smallest normal double is 2.2e-308)
    lim = np.where(kind == 1, 1e-290, THETA_FLOOR * np.where(kind == 2, np.pi, th))
    return rho <= lim


def split_cells(c: Cells, idx: np.ndarray) -> tuple[np.ndarray, ...]:
    """Children (item, th, rho, kind) of cells idx: two per cell."""
    th, rho, kind, item = c.th[idx], c.rho[idx], c.kind[idx], c.item[idx]
    h = rho / 2
    end = kind != 0
    # an end cell [-rho, rho] around 0 (or pi) covers [0, rho]: its children are the
    # end cell [-rho/2, rho/2] and the inner cell [rho/2, rho]
    left_th = np.where(kind == 1, 0.0, np.where(kind == 2, np.pi - 1.5 * h, th - h))
    left_rho = np.where(end, np.where(kind == 1, h, 0.5 * h), h)
    left_kind = np.where(kind == 1, 1, 0)
    right_th = np.where(kind == 1, 1.5 * h, np.where(kind == 2, np.pi, th + h))
    right_rho = np.where(end, np.where(kind == 1, 0.5 * h, h), h)
    right_kind = np.where(kind == 2, 2, 0)
    return (np.concatenate([item, item]), np.concatenate([left_th, right_th]),
            np.concatenate([left_rho, right_rho]), np.concatenate([left_kind, right_kind]))


# ------------------------------------------------------------------- disc algebra
def disc_mul(ac, ar, bc, br):
    """Disc enclosure of the product of two complex discs, with the rounding of the
    product.

    Parameters
    ----------
    ac, ar : array_like
        The first disc's centre (complex) and radius.
    bc, br : array_like
        The second disc's centre (complex) and radius.

    Returns
    -------
    tuple of ndarray
        The product's centre ``ac * bc`` and a radius that holds every product of a
        point of each disc, plus one rounding of the centre (``EPS_OP``).
    """
    aa, ba = np.abs(ac), np.abs(bc)
    return ac * bc, aa * br + ar * ba + ar * br + EPS_OP * aa * ba


def disc_quadratic(c: np.ndarray, r: np.ndarray, uc: np.ndarray, ur: np.ndarray):
    """Disc enclosure of c0 + c1 u + c2 u^2 over the real disc (uc, ur)."""
    ac, ar = c[2], r[2]
    for deg in (1, 0):
        ac, ar = disc_mul(ac, ar, uc, ur)
        ar = ar + r[deg] + EPS_OP * (np.abs(ac) + np.abs(c[deg]))
        ac = ac + c[deg]
    return ac, ar


# -------------------------------------------------------------------- the boxes
@dataclass
class Found:
    """Crossings (u, theta, direction, multiplicity) and unresolved u-intervals per item;
    for a search over a family of loops (``robust``) also the boxes that isolate each
    crossing: (u_lo, u_hi, cell, u, theta), u and theta polished inside the box."""

    cross: list[list[tuple[float, float, int, int]]]
    unsure: list[list[tuple[float, float]]]
    boxes: list[list[tuple[float, float, int, float, float]]] | None = None


def _quad_roots(a0: np.ndarray, a1: np.ndarray, a2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real roots of a0 + a1 u + a2 u^2 (nan where none), without cancellation."""
    with np.errstate(all="ignore"):
        disc = a1 * a1 - 4 * a0 * a2
        sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
        qq = -0.5 * (a1 + np.copysign(sq, a1))
        r1 = np.where(a2 != 0, qq / a2, -a0 / a1)
        r2 = np.where(a2 != 0, a0 / qq, np.nan)
    return r1, r2


def trim_boxes(c: Cells, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The parts of each box's u-interval where a zero of F may lie, exactly in u.

    For every u, F(cell, u) lies in the disc q(u) +- R(u), q = sum c_l u^l and
    R = sum r_l u^l (the cell's enclosures of F0, F1, F2). A zero needs
    |Re(e^{-j phi} q(u))| <= R(u) and |Im(e^{-j phi} q(u))| <= R(u) for any phi:
    four real quadratic inequalities in u, solved exactly. phi is the argument of
    q'(u) at the box's centre, so one of the two is sharp at a crossing and the
    other excludes the box when q passes the real axis away from 0.
    Returns boxes (cell, ua, ub): zero, one or several per input box.
    """
    vc, vr = c.vc[:, cell], c.vr[:, cell]
    um = np.where(ub > 4 * ua, np.sqrt(ua * ub), 0.5 * (ua + ub))
    dq = vc[1] + 2 * um * vc[2]
    dq = np.where(np.abs(dq) > 0, dq, np.where(np.abs(vc[2]) > 0, vc[2], 1.0))
    rot = np.exp(-1j * np.angle(dq))
    # R(u) gets the rounding of evaluating q in the rotated frame
    R = vr + 4 * EPS_OP * np.abs(vc)
    roots = [ua, ub]
    quads = []
    for part in (np.real, np.imag):
        g = part(rot[None] * vc)
        for sgn in (1.0, -1.0):
            a = g - sgn * R                      # g - R <= 0 and g + R >= 0
            quads.append((a, sgn))
            roots.extend(_quad_roots(a[0], a[1], a[2]))
    br = np.sort(np.stack(roots, axis=1), axis=1)           # nan sort last
    br = np.where(np.isnan(br), ub[:, None], br)
    br = np.clip(br, ua[:, None], ub[:, None])
    lo, hi = br[:, :-1], br[:, 1:]
    mid = 0.5 * (lo + hi)
    ok = hi > lo
    for a, sgn in quads:
        val = a[0][:, None] + mid * (a[1][:, None] + mid * a[2][:, None])
        ok &= (val <= 0) if sgn > 0 else (val >= 0)
    # also keep a zero-width feasible point at a breakpoint (tangency): test the
    # breakpoints themselves
    pt_ok = np.ones(br.shape, bool)
    for a, sgn in quads:
        val = a[0][:, None] + br * (a[1][:, None] + br * a[2][:, None])
        pt_ok &= (val <= 0) if sgn > 0 else (val >= 0)
    # merge feasible pieces: a piece is [lo, hi] if ok; isolated feasible breakpoints
    # become tiny pieces. Breakpoints carry rounding: widen by a few ulps (relative).
    rows, cols = np.nonzero(ok)
    pieces_c: list[np.ndarray] = [rows]
    pieces_a: list[np.ndarray] = [lo[rows, cols]]
    pieces_b: list[np.ndarray] = [hi[rows, cols]]
    rows, cols = np.nonzero(pt_ok & ~np.concatenate([ok, np.zeros((ok.shape[0], 1), bool)], axis=1)
                            & ~np.concatenate([np.zeros((ok.shape[0], 1), bool), ok], axis=1))
    pieces_c.append(rows)
    pieces_a.append(br[rows, cols])
    pieces_b.append(br[rows, cols])
    r = np.concatenate(pieces_c)
    a = np.concatenate(pieces_a)
    b = np.concatenate(pieces_b)
    # 1e-12 relative (~4500 ulps, more than the few needed): a wider piece only keeps
    # more of the box to test, it never drops a zero
    widen = 1e-12 * np.maximum(np.abs(a), np.abs(b))
    a = np.maximum(a - widen, ua[r])
    b = np.minimum(b + widen, ub[r])
    order = np.lexsort((a, r))
    r, a, b = r[order], a[order], b[order]
    if r.size:   # merge overlapping pieces of one box
        new = np.ones(r.size, bool)
        new[1:] = (r[1:] != r[:-1]) | (a[1:] > _running_max(r, b)[:-1])
        grp = np.cumsum(new) - 1
        rr, aa = r[new], a[new]
        bb = np.full(rr.size, -np.inf)
        np.maximum.at(bb, grp, b)
        r, a, b = rr, aa, bb
    return cell[r], a, b


def _running_max(r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The running maximum of ``b`` within each run of equal ``r`` (``r`` sorted): one
    box's pieces merge only with that box's own (a running maximum over every box let a
    wide piece of one box, or of another loop in a batch, swallow the gaps of the next)."""
    start = np.ones(r.size, bool)
    start[1:] = r[1:] != r[:-1]
    g = (np.cumsum(start) - 1).astype(np.int64)
    order = np.argsort(b, kind="stable")
    rank = np.empty(b.size, np.int64)
    rank[order] = np.arange(b.size)
    # groups ascend, so a running maximum of (group, rank) never leaves its group
    key = np.maximum.accumulate(g * b.size + rank)
    return b[order[key - g * b.size]]


def classify_boxes(c: Cells, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray):
    """Classify boxes: 0 excluded, 1 one zero (Krawczyk), 2 split. Also returns the
    contributions of theta and u to the enclosure radius (which to split)."""
    uc, ur = 0.5 * (ua + ub), 0.5 * (ub - ua)
    g = lambda a: a[:, cell]  # noqa: E731
    vc, vr, dc, dr = g(c.vc), g(c.vr), g(c.dc), g(c.dr)
    fc, fr = disc_quadratic(vc, vr, uc, ur)
    status = np.full(cell.size, 2)
    status[np.abs(fc) > fr] = 0
    # Jacobian enclosures over the box
    tc, tr = disc_quadratic(dc, dr, uc, ur)                      # F_theta
    u2c, u2r = disc_mul(vc[2], vr[2], 2 * uc, 2 * ur)
    kc, kr = vc[1] + u2c, vr[1] + u2r + EPS_OP * (np.abs(vc[1]) + np.abs(u2c))   # F_u
    rho = c.rho[cell]
    w_theta, w_u = rho * (np.abs(tc) + tr), ur * (np.abs(kc) + kr)
    live = np.flatnonzero(status == 2)
    if live.size:
        status[live] = krawczyk(c, cell[live], uc[live], ur[live], rho[live],
                                 tc[live], tr[live], kc[live], kr[live])
    # the error of F at the box's centre (rounding and the coefficients' own error):
    # once the box's extent contributes less than that, splitting cannot decide it
    _, noise = disc_quadratic(c.pc[:, cell], c.pr[:, cell], uc, np.zeros_like(uc))
    return status, w_theta, w_u, np.abs(fc), noise


def krawczyk(c: Cells, cell, uc, ur, rho, tc, tr, kc, kr, image: bool = False) -> Any:
    """1 where the Krawczyk operator maps the box into its interior (exactly one
    zero), 0 where it misses the box (no zero), else 2. With ``image``, also the
    image's shift and half-width per coordinate (theta, u): every zero in the box
    lies in ``centre - shift +- half``."""
    z = np.zeros(uc.shape)
    pc, pr, pd = c.pc[:, cell], c.pr[:, cell], c.pd[:, cell]
    f, frad = disc_quadratic(pc, pr, uc, z)                      # F at the centre
    ft = pd[0] + uc * (pd[1] + uc * pd[2])                       # F_theta at the centre
    fu = pc[1] + 2 * uc * pc[2]                                  # F_u at the centre
    a, b, cc, d = ft.real, fu.real, ft.imag, fu.imag             # J = [[a, b], [cc, d]]
    det = a * d - b * cc
    ok = np.isfinite(det) & (np.abs(det) > DIVISOR_FLOOR)
    with np.errstate(all="ignore"):
        Y = np.array([[d, -b], [-cc, a]]) / np.where(ok, det, 1.0)   # (2, 2, n)
        # interval entries of J over the box: [centre - radius, centre + radius]
        Jc = np.array([[tc.real, kc.real], [tc.imag, kc.imag]])
        Jr = np.array([[tr, kr], [tr, kr]])
        rad = np.array([rho, ur])
        out = np.full(uc.shape, 2)
        half = np.zeros((2, *uc.shape))
        shift = np.zeros((2, *uc.shape))
        for i in range(2):
            # (Y F)_i for F in its disc
            shift[i] = Y[i, 0] * f.real + Y[i, 1] * f.imag
            half[i] = (np.abs(Y[i, 0]) + np.abs(Y[i, 1])) * frad
            for k in range(2):
                mc = (1.0 if i == k else 0.0) - (Y[i, 0] * Jc[0, k] + Y[i, 1] * Jc[1, k])
                mr = np.abs(Y[i, 0]) * Jr[0, k] + np.abs(Y[i, 1]) * Jr[1, k]
                half[i] += (np.abs(mc) + mr) * rad[k]
            half[i] += EPS_OP * (np.abs(shift[i]) + half[i])
        inside = np.all(np.abs(shift) + half < rad, axis=0)
        outside = np.any(np.abs(shift) - half > rad, axis=0)
    out[ok & inside] = 1
    out[ok & outside & ~inside] = 0
    if image:
        return out, np.where(ok, shift, 0.0), np.where(ok, half, np.inf)
    return out


def estimate_lowest(c: Cells, cells: np.ndarray, L: int) -> np.ndarray:
    """Per item, 1.05 times the lowest positive u that is a nearly real root of
    F(theta_m, u) at some cell centre (inf if none): a guess, never trusted."""
    p0, p1, p2 = c.pc[0, cells], c.pc[1, cells], c.pc[2, cells]
    with np.errstate(all="ignore"):
        sq = np.sqrt(p1 * p1 - 4 * p0 * p2)
        qq = -0.5 * (p1 + np.where(np.real(np.conj(p1) * sq) >= 0, sq, -sq))
        roots = [np.where(np.abs(p2) > 0, qq / p2, np.nan), p0 / qq]
    est = np.full(L, np.inf)
    for r in roots:
        ok = np.isfinite(r) & (r.real > U_LO) & (np.abs(r.imag) <= 0.3 * np.abs(r))
        np.minimum.at(est, c.item[cells[ok]], 1.05 * r.real[ok])
    return est


def polish_boxes(resp: LoopResponse, c: Cells, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray
            ) -> list[tuple[float, float, int]]:
    """Newton's method inside boxes proved to hold exactly one zero: (u, theta, direction).

    In an end box (theta = 0 or pi) the zero is real: Newton on Re F in u alone.
    The iterate is kept in its box; the box's centre is the fallback (the box
    already pins the zero to within its size)."""
    th = c.th[cell].copy()
    end = c.kind[cell] != 0
    lo_t, hi_t = th - c.rho[cell], th + c.rho[cell]
    u = 0.5 * (ua + ub)
    item = c.item[cell]
    z = np.zeros(th.shape)
    live = np.arange(th.size)        # the boxes of the items not yet converged
    for _ in range(12):
        it, e = item[live], end[live]
        uu = u[live]
        F = resp.coefficients(it, th[live], z[live])
        f = F[0].vc + uu * (F[1].vc + uu * F[2].vc)
        ft = F[0].dc + uu * (F[1].dc + uu * F[2].dc)
        fu = F[1].vc + 2 * uu * F[2].vc
        a, b, cc, d = ft.real, fu.real, ft.imag, fu.imag
        det = a * d - b * cc
        with np.errstate(all="ignore"):
            dth = np.where(e, 0.0, -(d * f.real - b * f.imag) / det)
            du = np.where(e, -f.real / b, -(-cc * f.real + a * f.imag) / det)
        dth = np.where(np.isfinite(dth), dth, 0.0)
        du = np.where(np.isfinite(du), du, 0.0)
        th[live] = np.clip(th[live] + dth, lo_t[live], hi_t[live])
        u[live] = np.clip(uu + du, ua[live], ub[live])
        # an item stops once all its boxes have converged: each item's iterates are
        # then those of its own search, whatever else is in the batch
        done = (np.abs(du) <= 4 * np.finfo(float).eps * u[live]) & \
            (np.abs(dth) <= NEWTON_ANGLE_STEP * (1 + th[live]))
        live = live[np.isin(it, it[~done])]
        if not live.size:
            break
    F = resp.coefficients(item, th, z)
    ft = F[0].dc + u * (F[1].dc + u * F[2].dc)
    fu = F[1].vc + 2 * u * F[2].vc
    det = ft.real * fu.imag - fu.real * ft.imag
    th = np.where(c.kind[cell] == 1, 0.0, np.where(c.kind[cell] == 2, np.pi, th))
    return [(float(uu), float(tt), int(np.sign(dd))) for uu, tt, dd in zip(u, th, det, strict=True)]
