"""The certified crossing search run on a *family* of loops: each item of the
response is a box of operators, its operator port's coefficients enclosed over the
box (:func:`hapstab.engine.operator_family.family_response`). The search's
enclosures then hold for every loop of the family at once, so:

* a box (theta-cell x u-interval) is dropped only when it is proved zero-free for
  every loop of the family; whatever is not is reported (a crossing box or an
  unresolved zone), never skipped: the lowest u reported is a lower bound of the
  lowest crossing of every loop of the family;
* a box where the Krawczyk operator (with the Jacobian enclosed over the family)
  maps into its interior holds exactly one crossing of every loop, with a regular
  Jacobian: when it is the lowest event, the lowest crossing u(p) is a smooth
  function of the operator p on the family's box (implicit functions), and its
  gradient is enclosed from enclosures of F_theta, F_u and F_p over the box
  (:func:`crossing_gradient`);
* the count of poles outside at K -> 0+ is certified for the whole family when
  every cell's enclosure excludes 0 (the argument increments are then the same for
  every loop, and F is real at theta = 0 and pi).

References
----------
R. Krawczyk, Computing 4 (1969) 187-201; R. E. Moore, R. B. Kearfott and M. J.
Cloud, *Introduction to Interval Analysis*, SIAM 2009, ch. 8 (interval Newton
methods and parametric systems).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hapstab.analysis.exact.boxes import (
    U_HI,
    U_LO,
    Cells,
    disc_mul,
    disc_quadratic,
    initial_cells,
    krawczyk,
)
from hapstab.analysis.exact.counts import winding_on_cells
from hapstab.analysis.exact.crossings import TURN_KMAX, branch_and_prune
from hapstab.engine.discs import EPS_OP
from hapstab.engine.frequency import LoopResponse

__all__ = ["FirstEvent", "first_events", "crossing_gradient"]

#: Most Krawczyk contractions of a crossing's box (each shrinks it by 10 % at least, else the
#: contraction stops): from a box of relative size 1 to the rounding takes about 50
#: halvings, far fewer with the quadratic convergence of a single loop.
CONTRACTIONS = 60


@dataclass(frozen=True)
class FirstEvent:
    """The lowest K at which some loop of a family may have a pole on the circle.

    Parameters
    ----------
    anchor : int
        Poles outside the circle as K -> 0+, the same for every loop of the family
        (-1: not certified for the family).
    u_lo : float
        A lower bound (in u = K / scale) of the lowest crossing of every loop of the
        family: 0 if ``anchor`` != 0, inf if no loop has a crossing below U_HI.
    box : tuple or None
        (u_a, u_b, theta, rho, kind) of a box proved to hold exactly one crossing of
        every loop (cell [theta - rho, theta + rho], kind 0 inner, 1/2 centred on 0/pi),
        when it is the lowest event and nothing else is reported below u_b: every
        loop's K_max / scale then lies in [u_a, u_b]; None otherwise.
    """

    anchor: int
    u_lo: float
    box: tuple[float, float, float, float, int] | None


def first_events(resp: LoopResponse) -> tuple[list[FirstEvent], Cells]:
    """The lowest crossing of every family (item) of ``resp``, enclosed.

    Parameters
    ----------
    resp : LoopResponse
        One item per family (a box of operators, or one operator).

    Returns
    -------
    events : list of FirstEvent
        One per item.
    cells : Cells
        The cells built (their enclosures serve :func:`crossing_gradient`).
    """
    L = resp.size
    items = np.arange(L)
    c = Cells()
    first = c.add(resp, *initial_cells(resp, items, TURN_KMAX))
    anchor = winding_on_cells(resp, c, first, np.full(L, U_LO), robust=True)
    need = items[anchor == 0]
    found = branch_and_prune(resp, need, np.where(anchor == 0, U_HI, -np.inf), start=(c, first),
                   robust=True) if need.size else None
    out = []
    todo = [(i, b) for i in range(L) if found is not None and anchor[i] == 0
            for b in sorted(found.boxes[i])          # type: ignore[index]
            if b[0] < min((a for a, _ in found.unsure[i]), default=np.inf)]
    tight = _contract(resp, c, np.array([i for i, _ in todo], int), [b for _, b in todo]) \
        if todo else []
    for i in range(L):
        if anchor[i] != 0 or found is None:
            out.append(FirstEvent(int(anchor[i]), 0.0, None))
            continue
        unsure = [a for a, _ in found.unsure[i]]
        mine = [b for (j, _), b in zip(todo, tight, strict=True) if j == i]
        lows = unsure + [b[0] for b in mine]
        if not lows:
            out.append(FirstEvent(0, np.inf, None))
            continue
        u_lo = min(lows)
        low = [b for b in mine if b[0] == u_lo]
        box = low[0] if len(low) == 1 and sum(x < low[0][1] for x in lows) == 1 else None
        out.append(FirstEvent(0, u_lo, box))
    return out, c


def _contract(resp: LoopResponse, c: Cells, it: np.ndarray, boxes: list[tuple]) -> list[tuple]:
    """Krawczyk boxes of crossings, contracted: X <- K(X) meet X. Each first box is
    proved to hold exactly one crossing of every loop of its family; every zero in X
    lies in the Krawczyk image K(X), so each meet still holds it (for a single loop
    the boxes shrink quadratically to the rounding; for a family, to about its
    spread). Returns (u_a, u_b, theta, rho, kind) per box."""
    cell = np.array([b[2] for b in boxes], int)
    ua, ub = np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes])
    th, rho, kind = c.th[cell].copy(), c.rho[cell].copy(), c.kind[cell].copy()
    live = np.ones(ua.size, bool)
    for _ in range(CONTRACTIONS):
        k = np.flatnonzero(live)
        if not k.size:
            break
        cl = c.add(resp, it[k], th[k], rho[k], kind[k])
        uc, ur = 0.5 * (ua[k] + ub[k]), 0.5 * (ub[k] - ua[k])
        _, shift, half = _krawczyk_image(c, cl, uc, ur)
        t_lo, t_hi = th[k] - shift[0] - half[0], th[k] - shift[0] + half[0]
        nua = np.maximum(ua[k], np.nextafter(uc - shift[1] - half[1], -np.inf))
        nub = np.minimum(ub[k], np.nextafter(uc - shift[1] + half[1], np.inf))
        # a real crossing stays at theta = 0 or pi: its cell stays centred there
        lo_t, hi_t = np.maximum(th[k] - rho[k], t_lo), np.minimum(th[k] + rho[k], t_hi)
        end = kind[k] != 0
        nth = np.where(end, th[k], 0.5 * (lo_t + hi_t))
        nrho = np.where(end, np.minimum(rho[k], np.maximum(np.abs(t_lo - th[k]),
                                                           np.abs(t_hi - th[k]))),
                        0.5 * (hi_t - lo_t) * (1 + 4 * EPS_OP))
        ok = (nub >= nua) & (nrho >= 0) & np.isfinite(nrho) & np.isfinite(nua + nub)
        with np.errstate(all="ignore"):
            gain = np.where(ub[k] > ua[k], (nub - nua) / (ub[k] - ua[k]), 1.0)
        upd = k[ok]
        ua[upd], ub[upd], th[upd], rho[upd] = nua[ok], nub[ok], nth[ok], nrho[ok]
        live[k[~ok | (gain > 0.9)]] = False
    return [(float(ua[j]), float(ub[j]), float(th[j]), float(rho[j]), int(kind[j]))
            for j in range(ua.size)]


def _krawczyk_image(c: Cells, cell: np.ndarray, uc: np.ndarray, ur: np.ndarray) -> tuple:
    """The Krawczyk test and image of boxes (cells x [uc - ur, uc + ur])."""
    g = lambda a: a[:, cell]  # noqa: E731
    vc, vr, dc, dr = g(c.vc), g(c.vr), g(c.dc), g(c.dr)
    tc, tr = disc_quadratic(dc, dr, uc, ur)                      # F_theta
    u2c, u2r = disc_mul(vc[2], vr[2], 2 * uc, 2 * ur)
    kc, kr = vc[1] + u2c, vr[1] + u2r + EPS_OP * (np.abs(vc[1]) + np.abs(u2c))   # F_u
    return krawczyk(c, cell, uc, ur, c.rho[cell], tc, tr, kc, kr, image=True)


# ------------------------------------------------------------------ the gradient
def _parts(zc: np.ndarray, zr: np.ndarray) -> tuple[tuple, tuple]:
    """Real and imaginary parts of discs as intervals (lo, hi)."""
    return (zc.real - zr, zc.real + zr), (zc.imag - zr, zc.imag + zr)


def _imul(a: tuple, b: tuple) -> tuple:
    """Interval product, outward rounded."""
    p = np.stack([a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1]])
    return np.nextafter(p.min(axis=0), -np.inf), np.nextafter(p.max(axis=0), np.inf)


def _isub(a: tuple, b: tuple) -> tuple:
    return np.nextafter(a[0] - b[1], -np.inf), np.nextafter(a[1] - b[0], np.inf)


def _idiv(a: tuple, b: tuple) -> tuple:
    """a / b for b not containing 0 (else (-inf, inf))."""
    ok = (b[0] > 0) | (b[1] < 0)
    with np.errstate(all="ignore"):
        q = _imul(a, (np.where(ok, 1.0 / b[1], -np.inf), np.where(ok, 1.0 / b[0], np.inf)))
    lo, hi = np.nextafter(q[0], -np.inf), np.nextafter(q[1], np.inf)
    return np.where(ok, lo, -np.inf), np.where(ok, hi, np.inf)


def _discs(resp: LoopResponse, items: np.ndarray, th: np.ndarray, rho: np.ndarray,
           kind: np.ndarray, ua: np.ndarray, ub: np.ndarray) -> tuple:
    """Discs of F, F_theta, F_u over the boxes (cells x u-intervals) of ``resp``."""
    c = Cells()
    cell = c.add(resp, items, th, rho, kind)
    uc, ur = 0.5 * (ua + ub), 0.5 * (ub - ua)
    g = lambda a: a[:, cell]  # noqa: E731
    vc, vr, dc, dr = g(c.vc), g(c.vr), g(c.dc), g(c.dr)
    F = disc_quadratic(vc, vr, uc, ur)
    Ft = disc_quadratic(dc, dr, uc, ur)
    u2c, u2r = disc_mul(vc[2], vr[2], 2 * uc, 2 * ur)
    Fu = (vc[1] + u2c, vr[1] + u2r + EPS_OP * (np.abs(vc[1]) + np.abs(u2c)))
    return F, Ft, Fu


def _derivatives(resp: LoopResponse, dresps: list[LoopResponse], items: np.ndarray,
                 box: tuple) -> tuple[np.ndarray, ...]:
    """Enclosures of dtheta/dp and du/dp over the boxes (theta-cells x u-intervals)
    for every loop of the families: (t_lo, t_hi, u_lo, u_hi), each (n, P)."""
    ua, ub, th, rho, kind = box
    end = kind != 0
    rho_e = np.where(end, 0.0, rho)           # a real crossing: at theta = 0 or pi exactly
    _, Ft, Fu = _discs(resp, items, th, rho_e, kind, ua, ub)
    (a, c), (b, d) = _parts(*Ft), _parts(*Fu)
    det = _isub(_imul(a, d), _imul(b, c))
    out = [np.full((items.size, len(dresps)), v) for v in (-np.inf, np.inf, -np.inf, np.inf)]
    for p, dr in enumerate(dresps):
        Fp, _, _ = _discs(dr, items, th, rho_e, kind, ua, ub)
        rp, ip = _parts(*Fp)
        t = _idiv(_isub(_imul(b, ip), _imul(d, rp)), det)
        u = _idiv(_isub(_imul(c, rp), _imul(a, ip)), det)
        u_end = _idiv(rp, (-b[1], -b[0]))
        out[0][:, p], out[1][:, p] = np.where(end, 0.0, t[0]), np.where(end, 0.0, t[1])
        out[2][:, p] = np.where(end, u_end[0], u[0])
        out[3][:, p] = np.where(end, u_end[1], u[1])
    return tuple(out)


def crossing_gradient(resp: LoopResponse, dresps: list[LoopResponse], items: np.ndarray,
                      boxes: list[tuple], centres: list[tuple], half: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, list[tuple]]:
    """Enclosures of du/dp over each family's box, for the crossing isolated in ``boxes``.

    On the box (theta, u) the crossing of every loop is unique and regular, so by the
    implicit function theorem ``[F_theta F_u] [theta'; u'] = -F_p`` (real 2 x 2),
    ``u' = (Im F_theta Re F_p - Re F_theta Im F_p) / det``; at theta = 0 or pi (a real
    crossing, theta fixed) ``u' = -F_p / F_u`` on the real axis. The box is then
    narrowed to the centre's crossing plus ``sum_i [-h_i, h_i] (theta', u')_i`` (the
    mean-value theorem along the segment from the centre, whose crossings all lie in
    the box) and the derivatives enclosed again on the narrower box, a few times.

    Parameters
    ----------
    resp : LoopResponse
        The families.
    dresps : list of LoopResponse
        The derivative responses, one per varying parameter
        (:func:`hapstab.engine.operator_family.derivative_response`).
    items : (n,) int array
        The families to do.
    boxes : list of tuple
        Their boxes (u_a, u_b, theta, rho, kind) from :func:`first_events`.
    centres : list of tuple
        The same for each family's centre operator alone (a single loop).
    half : (n, P) array
        The families' half-widths in the varying parameters.

    Returns
    -------
    lo, hi : (n, P) arrays
        du/dp (u per unit parameter) for every operator of each family's box;
        (-inf, inf) where the enclosure cannot bound it.
    boxes : list of tuple
        The narrowed boxes.
    """
    X = [np.array([b[j] for b in boxes], float) for j in range(5)]
    C = [np.array([b[j] for b in centres], float) for j in range(4)]
    kind = X[4].astype(int)
    for _ in range(4):
        t_lo, t_hi, u_lo, u_hi = _derivatives(resp, dresps, items, (*X[:4], kind))
        # (1 + 1e-12): the rounding of the sums, far above their few unit round-offs
        st = np.sum(np.maximum(np.abs(t_lo), np.abs(t_hi)) * half, axis=1) * (1 + 1e-12)
        su = np.sum(np.maximum(np.abs(u_lo), np.abs(u_hi)) * half, axis=1) * (1 + 1e-12)  # as st
        ok = np.isfinite(st + su)
        na = np.where(ok, np.maximum(X[0], np.nextafter(C[0] - su, -np.inf)), X[0])
        nb = np.where(ok, np.minimum(X[1], np.nextafter(C[1] + su, np.inf)), X[1])
        t0, t1 = np.maximum(X[2] - X[3], C[2] - C[3] - st), np.minimum(X[2] + X[3], C[2] + C[3] + st)
        nt = np.where(ok & (kind == 0), 0.5 * (t0 + t1), X[2])
        nr = np.where(ok & (kind == 0), 0.5 * (t1 - t0) * (1 + 4 * EPS_OP), X[3])
        if not np.all((nb >= na) & (nr >= 0)):
            break
        shrink = np.max((nb - na) / np.maximum(X[1] - X[0], 1e-300))   # (a zero width guarded)
        X[0], X[1], X[2], X[3] = na, nb, nt, nr
        if shrink > 0.9:
            break
    out = [(float(X[0][j]), float(X[1][j]), float(X[2][j]), float(X[3][j]), int(kind[j]))
           for j in range(items.size)]
    return u_lo, u_hi, out
