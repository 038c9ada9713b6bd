"""Ball forms the proof's characteristic function is evaluated with
(:class:`~hapstab.engine.arb_loop.ArbLoop`): forward-mode derivatives over acb balls,
the quadratic in K and its derivative, the preconditioned mean-value exclusion test,
and the accuracy of a ball polynomial. Everything here is rigorous given rigorous
(python-flint Arb) inputs; see each docstring.

python-flint is imported lazily (``import hapstab`` stays light) as ``import flint``
inside the functions: ``from flint import acb, arb`` costs ~1.5 us a call (the import
machinery's fromlist), a tenth of an exclusion box, and these run per box."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["Dual", "preconditioned_excludes", "poly_k", "dpoly_k", "accuracy_bits",
           "box_balls", "exclusion_test", "angle_parts", "stiffness_parts"]


class Dual:
    """A value and its derivative (forward mode), over acb balls."""

    __slots__ = ("d", "v")

    def __init__(self, v: Any, d: Any) -> None:
        self.v, self.d = v, d

    def __add__(self, o: Any) -> Dual:
        if isinstance(o, Dual):
            return Dual(self.v + o.v, self.d + o.d)
        return Dual(self.v + o, self.d)

    __radd__ = __add__

    def __mul__(self, o: Any) -> Dual:
        if isinstance(o, Dual):
            return Dual(self.v * o.v, self.v * o.d + self.d * o.v)
        return Dual(self.v * o, self.d * o)

    __rmul__ = __mul__


def preconditioned_excludes(Fc: Any, Ft: Any, Fk: Any, r_theta: Any, r_K: Any) -> bool:
    """Whether 0 is outside the preconditioned mean-value form of det M on a box.

    As a map of (theta, K) to R^2, det M over the box lies in
    ``f + A (dtheta, dK)`` with ``f = (Re Fc, Im Fc)``, ``A`` the 2x2 matrix of the
    real and imaginary parts of the derivative balls ``Ft``, ``Fk`` and
    ``|dtheta| <= r_theta``, ``|dK| <= r_K``. For any real 2x2 matrix Y, det M = 0
    at a point implies Y det M = 0 there, so 0 outside either component of
    ``Y f + (Y A)(dtheta, dK)`` excludes every zero from the box, whatever Y is;
    Y = mid(A)^-1 (in doubles) makes the form nearly the identity near a simple zero,
    where the plain ball of det M (an axis-aligned rectangle around an elongated
    image) needs boxes far smaller than their distance to the zero.

    Parameters
    ----------
    Fc, Ft, Fk : acb
        det M at the centre, d/dtheta and d/dK over the box.
    r_theta, r_K : arb
        The box's radii in theta (rad) and K (N/m).

    Returns
    -------
    bool
    """
    import flint
    arb = flint.arb
    # complex(x) is (float(x.real.mid()), float(x.imag.mid())), in one call
    (a, c), (b, d) = ((z.real, z.imag) for z in (complex(Ft), complex(Fk)))
    det = a * d - b * c
    if not (math.isfinite(det) and det != 0.0):
        return False
    Y = ((d / det, -b / det), (-c / det, a / det))
    # Y A is the identity at its centre, so each component's ball is at least as wide
    # as the box's radius in that variable: where the centre's image is inside both
    # (in doubles, with 1 % to spare for their rounding), no ball can exclude 0
    fc = complex(Fc)
    f1, f2 = fc.real, fc.imag
    rt, rk = float(r_theta), float(r_K)
    if abs(Y[0][0] * f1 + Y[0][1] * f2) < 0.99 * rt and abs(Y[1][0] * f1 + Y[1][1] * f2) < 0.99 * rk:
        return False
    ht, hk = arb(0, r_theta), arb(0, r_K)
    cr, ci, tr, ti, kr, ki = Fc.real, Fc.imag, Ft.real, Ft.imag, Fk.real, Fk.imag
    for y1, y2 in Y:
        if not (math.isfinite(y1) and math.isfinite(y2)):
            return False
        comp = y1 * cr + y2 * ci + (y1 * tr + y2 * ti) * ht + (y1 * kr + y2 * ki) * hk
        if not comp.contains(0):
            return True
    return False


def dpoly_k(c: list[Any], K: Any) -> Any:
    """``c[1] + 2 K c[2]``: the derivative in K of :func:`poly_k`."""
    return c[1] + 2 * K * c[2]


def poly_k(c: list[Any], K: Any) -> Any:
    """``c[0] + K c[1] + K^2 c[2]`` (Horner) on a ball K."""
    return c[0] + K * (c[1] + K * c[2])


def accuracy_bits(poly: Any) -> float:
    """Relative accuracy (bits) of the worst nonzero coefficient of a polynomial."""
    worst = math.inf
    for c in poly.coeffs():
        if c.is_zero():
            continue
        worst = min(worst, c.rel_accuracy_bits())
    return worst


def box_balls(kern: tuple, theta: Any, K: Any) -> tuple[Any, Any, Any, Any, Any, Any]:
    """Balls of P, Q and det M over the box ``theta`` x ``K`` (arb balls) in the centred
    (mean-value) form, from an angle kernel ``(Pm, Qm, Fm, Pd, Qd, Fd)``
    (:meth:`~hapstab.engine.arb_loop.ArbLoop.kernel`): ``f(theta, K) - f(c) =
    f_theta(xi_1, K) dtheta + f_K(theta_c, xi_2) dK``, the first over the whole box, the
    second at the centre angle, so the overestimation is of second order. At the
    precision in force.

    Returns
    -------
    P, Q, F, Fc, Ft, Fk : acb
        The three balls, then det M at the centre and its derivatives d/dtheta (over
        the box) and d/dK (at the centre angle, over K).
    """
    import flint
    acb, arb = flint.acb, flint.arb
    Pm, Qm, Fm, Pd, Qd, Fd = kern
    Kc, km = acb(K), acb(K.mid())         # acb: python-flint's acb x acb is fastest
    hh, kk = acb(arb(0, theta.rad())), acb(arb(0, K.rad()))
    P = poly_k(Pm, km) + hh * poly_k(Pd, Kc) + kk * dpoly_k(Pm, Kc)
    Q = poly_k(Qm, km) + hh * poly_k(Qd, Kc) + kk * dpoly_k(Qm, Kc)
    Ft, Fk = poly_k(Fd, Kc), dpoly_k(Fm, Kc)
    Fc = poly_k(Fm, km)
    return P, Q, Fc + hh * Ft + kk * Fk, Fc, Ft, Fk


def _pk(c: list[Any], nz: tuple[bool, ...], K: Any) -> Any:
    """:func:`poly_k` with exact zero coefficients (``nz`` False) skipped: the same ball
    bit for bit, since Arb multiplies by an exact zero and adds one exactly (no
    rounding, the radius unchanged)."""
    if nz[2]:
        return c[0] + K * (c[1] + K * c[2])
    return c[0] + K * c[1] if nz[1] else c[0]


def angle_parts(theta: Any) -> tuple:
    """What :func:`exclusion_test` forms of the angle's ball before any test: the
    radius as an acb ball about 0, and the radius. At the precision in force."""
    import flint
    rt = theta.rad()
    return flint.acb(flint.arb(0, rt)), rt


def stiffness_parts(K: Any) -> tuple:
    """What :func:`exclusion_test` forms of the stiffness's ball before any test: the
    ball, its centre and its radius about 0 as acb, and the radius. At the precision in
    force (a subdivision forms these once per K-range, the angle's once per piece)."""
    import flint
    acb = flint.acb
    rk = K.rad()
    return acb(K), acb(K.mid()), acb(flint.arb(0, rk)), rk


def exclusion_test(kern: tuple, theta: Any, K: Any, nz: tuple | None = None,
                   parts: tuple | None = None) -> tuple[str | None, float, float]:
    """The tests a certificate names, in order, on the balls of :func:`box_balls`
    (each formed only when the test before it fails): ``"P"`` (|P| > |Q|), ``"Q"``
    (|Q| > |P|), ``"F"`` (0 not in det M's ball), ``"N"``
    (:func:`preconditioned_excludes`). At the precision in force. ``nz``: the kernel's
    :class:`~hapstab.engine.arb_kernel.KernelPolys` ``nonzero`` flags (terms that
    are exact zeros are skipped: the same balls); ``parts``: :func:`angle_parts` and
    :func:`stiffness_parts` of ``theta`` and ``K``, formed already.

    Returns
    -------
    how : {"P", "Q", "F", "N"} or None
        The test that excludes the box (None: none does).
    spread_theta, spread_K : float
        With ``how`` None: upper bounds of |d det M/d theta| rad(theta) and
        |d det M/dK| rad(K) over the box (to choose a split); else 0.
    """
    Pm, Qm, Fm, Pd, Qd, Fd = kern
    zP, zQ, zF, zPd, zQd, zFd = nz or ((True,) * 3,) * 6
    (hh, rt), (Kc, km, kk, rk) = parts or (angle_parts(theta), stiffness_parts(K))
    P, Q = _pk(Pm, zP, km), _pk(Qm, zQ, km)
    # each term below is skipped only where box_balls' is an exact zero: the same ball
    if any(zPd):
        P = P + hh * _pk(Pd, zPd, Kc)
    if zP[1] or zP[2]:
        P = P + kk * (Pm[1] + 2 * Kc * Pm[2] if zP[2] else Pm[1])
    if any(zQd):
        Q = Q + hh * _pk(Qd, zQd, Kc)
    if zQ[1] or zQ[2]:
        Q = Q + kk * (Qm[1] + 2 * Kc * Qm[2] if zQ[2] else Qm[1])
    if P.abs_lower() > Q.abs_upper():
        return "P", 0.0, 0.0
    if Q.abs_lower() > P.abs_upper():
        return "Q", 0.0, 0.0
    Ft, Fc = _pk(Fd, zFd, Kc), _pk(Fm, zF, km)
    Fk = Fm[1] + 2 * Kc * Fm[2] if zF[2] else Fm[1]
    if not (Fc + hh * Ft + kk * Fk).contains(0):
        return "F", 0.0, 0.0
    if preconditioned_excludes(Fc, Ft, Fk, rt, rk):
        return "N", 0.0, 0.0
    return None, float(Ft.abs_upper() * rt), float(Fk.abs_upper() * rk)
