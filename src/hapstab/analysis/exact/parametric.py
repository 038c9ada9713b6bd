"""The lowest crossing of a family of loops isolated by a parametric Krawczyk test:
one box X of (theta, u) that holds exactly one crossing of every loop of the family,
with a regular Jacobian.

For the operators p of a box B (centre c, half-widths h) and a point x~ of X (the
centre operator's crossing), the Krawczyk operator

    K(X) = x~ - Y F(x~; p) + (I - Y J(X; B)) (X - x~)

contains every zero in X of F(.; p) for every p in B, and K(X) in the interior of X
proves that each F(.; p) has exactly one zero in X, where J is regular. F(x~; p) is
enclosed by the mean-value form ``F(x~; c) + sum_i [-h_i, h_i] dF/dp_i(x~; B)``: each
parameter's effect is one segment, mapped by Y exactly, so the spread of the family
enters to first order without the loss of one disc per coefficient; J(X; B) is
enclosed over X and B with the coefficient discs (its error is multiplied by the
width of X). X is chosen a few times the spread that the centre's implicit
derivatives predict, then contracted: X <- K(X) meet X.

References
----------
R. Krawczyk, Computing 4 (1969) 187-201; A. Neumaier, *Interval Methods for Systems
of Equations*, Cambridge 1990, sec. 5.1 (the Krawczyk operator) and ch. 6
(parameter-dependent systems).
"""

from __future__ import annotations

import numpy as np

from hapstab.analysis.exact.boxes import Cells, disc_mul, disc_quadratic
from hapstab.engine.discs import EPS_OP
from hapstab.engine.frequency import LoopResponse

__all__ = ["isolate"]

#: X's half-widths tried in turn: (a multiple of the spread the centre's derivatives
#: predict, plus a part relative to the crossing's u and theta). A wide X proves the
#: crossing unique in a wide box (what the search for other crossings may then leave
#: out); a wide X's Jacobian varies more, so narrower ones are tried after it.
SIZES = ((2.0, 1e-3), (4.0, 1e-4), (8.0, 1e-6), (2.0, 1e-9))
#: Contractions X <- K(X) meet X once X is proved.
CONTRACT = 6


def _point(resp: LoopResponse, items, th, kind, u) -> tuple:
    """F, F_theta and F_u (discs) at the points (theta, u) of ``resp``'s items."""
    c = Cells()
    cell = c.add(resp, items, th, np.zeros_like(th), kind)
    z = np.zeros_like(u)
    F = disc_quadratic(c.pc[:, cell], c.pr[:, cell], u, z)
    Ft = c.pd[0, cell] + u * (c.pd[1, cell] + u * c.pd[2, cell])
    Fu = c.pc[1, cell] + 2 * u * c.pc[2, cell]
    return F, Ft, Fu


def _jacobian(resp: LoopResponse, items, th, rho, kind, ua, ub) -> tuple:
    """[[Re F_theta, Re F_u], [Im F_theta, Im F_u]] over the boxes (cells x
    u-intervals): centres (2, 2, n) and a common radius per column (2, n)."""
    c = Cells()
    cell = c.add(resp, items, th, rho, kind)
    uc, ur = 0.5 * (ua + ub), 0.5 * (ub - ua)
    vc, vr = c.vc[:, cell], c.vr[:, cell]
    tc, tr = disc_quadratic(c.dc[:, cell], c.dr[:, cell], uc, ur)
    u2c, u2r = disc_mul(vc[2], vr[2], 2 * uc, 2 * ur)
    kc, kr = vc[1] + u2c, vr[1] + u2r + EPS_OP * (np.abs(vc[1]) + np.abs(u2c))
    return np.array([[tc.real, kc.real], [tc.imag, kc.imag]]), np.array([tr, kr])


def _image(resps, F0, gens, Y, x0, th, rho, kind, ua, ub, items) -> tuple:
    """K(X) as (lo, hi) per coordinate (theta, u). ``resps``: the centre operator's
    response and the derivative responses with their half-widths: J(X; B) lies in
    J(X; c) + sum_i [-h_i, h_i] dJ/dp_i(X; B), so I - Y J is enclosed with Y applied
    to each parameter's term before taking magnitudes."""
    cen, derivs = resps
    Jc, Jr = _jacobian(cen, items, th, rho, kind, ua, ub)
    Yabs = np.abs(Y)
    M = np.eye(2)[:, :, None] - np.einsum("kin,ijn->kjn", Y, Jc)
    Mr = np.einsum("kin,jn->kjn", Yabs, Jr)
    for h, dr in derivs:
        Jic, Jir = _jacobian(dr, items, th, rho, kind, ua, ub)
        Mr = Mr + h * (np.abs(np.einsum("kin,ijn->kjn", Y, Jic)) + np.einsum("kin,jn->kjn", Yabs, Jir))
    fc, fr = F0
    rad = np.array([rho, 0.5 * (ub - ua)])
    # X's centre may differ from x~: the Krawczyk form around x~ needs X - x~
    off = np.array([th - x0[0], 0.5 * (ua + ub) - x0[1]])
    shift, half = np.zeros_like(rad), np.zeros_like(rad)
    total_r = fr + sum((h * g[1] for h, g in gens), np.zeros_like(fr))
    for k in range(2):
        shift[k] = Y[k, 0] * fc.real + Y[k, 1] * fc.imag
        half[k] = (Yabs[k, 0] + Yabs[k, 1]) * total_r
        for h, (gc, _) in gens:
            half[k] += h * np.abs(Y[k, 0] * gc.real + Y[k, 1] * gc.imag)
        for j in range(2):
            shift[k] -= M[k, j] * off[j]
            half[k] += np.abs(M[k, j]) * rad[j] + Mr[k, j] * (rad[j] + np.abs(off[j]))
        half[k] += EPS_OP * (np.abs(shift[k]) + half[k] + np.abs(x0[k]))
    return x0 - shift - half, x0 - shift + half


def isolate(fam: LoopResponse, cen: LoopResponse, dres: list[LoopResponse], items: np.ndarray,
            half: np.ndarray, cbox: list[tuple]) -> list[tuple | None]:
    """A box (u_a, u_b, theta, rho, kind) proved to hold exactly one crossing of every
    loop of each family, around its centre's crossing, and the same box contracted
    around the crossings; None where none is proved.

    Parameters
    ----------
    fam : LoopResponse
        The families (coefficients enclosed over each box of operators).
    cen : LoopResponse
        Each family's centre operator.
    dres : list of LoopResponse
        dF/dp for each varying parameter, enclosed over each family's box.
    items : (n,) int array
        The families to do.
    half : (n, P) array
        Their half-widths in the varying parameters.
    cbox : list of tuple
        The centre operator's crossing box (u_a, u_b, theta, rho, kind) for each.

    Returns
    -------
    list of (tuple, tuple) or None
        (proved box, contracted box) per family.
    """
    u0 = np.array([0.5 * (b[0] + b[1]) for b in cbox])
    th0 = np.array([b[2] for b in cbox])
    kind = np.array([b[4] for b in cbox], int)
    F0, ft, fu = _point(cen, items, th0, kind, u0)
    det = ft.real * fu.imag - fu.real * ft.imag
    with np.errstate(all="ignore"):
        Y = np.array([[fu.imag, -fu.real], [-ft.imag, ft.real]]) / det
    gens, s_th, s_u = [], np.zeros(items.size), np.zeros(items.size)
    for p, dr in enumerate(dres):
        (gc, gr), _, _ = _point(dr, items, th0, kind, u0)
        gens.append((half[:, p], (gc, gr)))
        # the centre's implicit derivatives (theta', u') = -Y F_p: the family's spread
        s_th += half[:, p] * np.abs(Y[0, 0] * gc.real + Y[0, 1] * gc.imag)
        s_u += half[:, p] * np.abs(Y[1, 0] * gc.real + Y[1, 1] * gc.imag)
    out: list = [None] * items.size
    x0 = np.array([th0, u0])
    # X also holds the centre's own enclosure, and 1e-13 (the exact core's accuracy) more
    floor_u = np.array([0.5 * (b[1] - b[0]) for b in cbox]) + 1e-13 * u0
    floor_t = np.array([b[3] for b in cbox]) + 1e-13 * (1 + th0)   # the same, in theta
    todo = np.isfinite(det) & (det != 0)
    for f, r in SIZES:
        k = np.flatnonzero(todo)
        if not k.size:
            break
        rho = np.minimum(f * s_th[k] + floor_t[k] + r * np.maximum(th0[k], 1e-3), np.pi / 4)
        rho = np.where(kind[k] != 0, rho, np.minimum(rho, np.minimum(th0[k], np.pi - th0[k])))
        ua = np.maximum(u0[k] - f * s_u[k] - floor_u[k] - r * u0[k], 0.5 * u0[k])
        ub = u0[k] + f * s_u[k] + floor_u[k] + r * u0[k]
        sub = ([g[0][k] for g in gens], [(g[1][0][k], g[1][1][k]) for g in gens])
        lo, hi = _image(_sub(cen, dres, half, k), (F0[0][k], F0[1][k]),
                        list(zip(*sub, strict=True)), Y[:, :, k], x0[:, k], th0[k], rho,
                        kind[k], ua, ub, items[k])
        ok = (lo[0] > th0[k] - rho) & (hi[0] < th0[k] + rho) & (lo[1] > ua) & (hi[1] < ub)
        ok &= np.isfinite(lo).all(axis=0) & np.isfinite(hi).all(axis=0)
        for j in np.flatnonzero(ok):
            proved = (float(ua[j]), float(ub[j]), float(th0[k[j]]), float(rho[j]), int(kind[k[j]]))
            out[int(k[j])] = proved, _contract(_sub(cen, dres, half, k[j:j + 1]),
                                       (F0[0][k[j]:k[j] + 1], F0[1][k[j]:k[j] + 1]),
                                       [(g[0][k[j]:k[j] + 1], (g[1][0][k[j]:k[j] + 1],
                                                               g[1][1][k[j]:k[j] + 1]))
                                        for g in gens],
                                       Y[:, :, k[j]:k[j] + 1], x0[:, k[j]:k[j] + 1],
                                       (float(th0[k[j]]), float(rho[j]), int(kind[k[j]]),
                                        float(ua[j]), float(ub[j])), items[k[j]:k[j] + 1])
        todo[k[ok]] = False
    return out


def _sub(cen: LoopResponse, dres: list[LoopResponse], half: np.ndarray, k: np.ndarray) -> tuple:
    """The responses for :func:`_image` (the families k: their half-widths)."""
    return cen, [(half[k, p], dr) for p, dr in enumerate(dres)]


def _contract(resps, F0, gens, Y, x0, box, item) -> tuple:
    """X <- K(X) meet X a few times (every zero in X lies in K(X)); returns
    (u_a, u_b, theta, rho, kind)."""
    th, rho, kind, ua, ub = box
    for _ in range(CONTRACT):
        lo, hi = _image(resps, F0, gens, Y, x0, np.array([th]), np.array([rho]),
                        np.array([kind]), np.array([ua]), np.array([ub]), item)
        nua, nub = max(ua, float(lo[1][0])), min(ub, float(hi[1][0]))
        t0, t1 = max(th - rho, float(lo[0][0])), min(th + rho, float(hi[0][0]))
        if not (nub >= nua and t1 >= t0):
            break
        if kind:
            nth, nrho = th, min(rho, max(abs(t0 - th), abs(t1 - th)))
        else:
            nth, nrho = 0.5 * (t0 + t1), 0.5 * (t1 - t0) * (1 + 4 * EPS_OP)
        gain = (nub - nua) / (ub - ua) if ub > ua else 1.0
        th, rho, ua, ub = nth, nrho, nua, nub
        if gain > 0.9:
            break
    return (ua, ub, th, rho, kind)
