"""Enclosures of complex functions of one angle over a cell: circular (disc)
arithmetic carrying a first derivative.

A :class:`Jet` holds, for every cell ``[theta_m - rho, theta_m + rho]`` of a batch,
a disc that contains every value of a function f(theta) on the cell and a disc that
contains every value of f'(theta) there. The base functions (``e^{j theta}``,
``e^{-j n theta}``, ...) are enclosed from bounds on their derivatives; sums,
products and quotients use circular arithmetic (Gargantini & Henrici 1972), which
is an enclosure for every pair of points of the operand discs. With ``rho = 0`` a
jet is a point evaluation whose radii bound the floating-point error only.

Rounding: every operation adds ``EPS_OP`` times the magnitudes it combined to the
radius (a running error bound, as for Horner's rule in Higham, *Accuracy and
Stability of Numerical Algorithms*, 2nd ed., sec. 5.1), so an enclosure stays one
in floating point up to the accuracy of the inputs.

References
----------
I. Gargantini and P. Henrici, "Circular arithmetic and the determination of
polynomial zeros", Numer. Math. 18 (1972) 305-320.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Jet", "EPS_OP", "base_jets", "delay_jet", "poly_jet", "geometric_sum_jet",
           "one_minus_delay_jet", "const", "zero", "NO_RADIUS", "NO_DERIV"]

#: Rounding allowance per operation: 4 unit round-offs covers a complex product
#: (at most sqrt(5) u) or sum (at most sqrt(2) u) and the product of the radii.
EPS_OP = 4.0 * np.finfo(float).eps
#: The radii of a *values-only* jet (:meth:`Jet.values_only`; told by identity): no
#: enclosure, only the centres' value and derivative, for a proposer that proves
#: nothing (:mod:`~hapstab.analysis.exact.angle_grid`). An operation with such an
#: operand gives such a result, with the centres computed exactly as with radii.
NO_RADIUS = np.full(0, np.nan)
#: The derivatives of a values-only jet made without them (:meth:`Jet.values_only`,
#: ``deriv=False``; told by identity): a proposer that reads only the values (its grid)
#: skips their cost; an operation with such an operand gives such a result, the values
#: computed exactly as with derivatives.
NO_DERIV = np.full(0, np.nan)


class Jet:
    """Discs enclosing a function's values (vc, vr) and derivatives (dc, dr) on cells."""

    __slots__ = ("_da", "_va", "dc", "dr", "vc", "vr")

    def __init__(self, vc: np.ndarray, vr: np.ndarray, dc: np.ndarray, dr: np.ndarray, *,
                 va: np.ndarray | None = None, da: np.ndarray | None = None) -> None:
        """``va``, ``da``: |vc| and |dc| when already known (a negated jet's are its own)."""
        self.vc, self.vr, self.dc, self.dr = vc, vr, dc, dr
        self._va: np.ndarray | None = va
        self._da: np.ndarray | None = da

    @property
    def va(self) -> np.ndarray:
        """|vc|, computed once."""
        if self._va is None:
            self._va = np.abs(self.vc)
        return self._va

    @property
    def da(self) -> np.ndarray:
        """|dc|, computed once."""
        if self._da is None:
            self._da = np.abs(self.dc)
        return self._da

    def values_only(self, deriv: bool = True) -> Jet:
        """The same centres without enclosures (:data:`NO_RADIUS`); ``deriv`` False:
        without derivatives too (:data:`NO_DERIV`)."""
        return Jet(self.vc, NO_RADIUS, self.dc if deriv else NO_DERIV, NO_RADIUS)

    def __add__(self, o: Jet) -> Jet:
        vc = self.vc + o.vc
        if self.vr is NO_RADIUS or o.vr is NO_RADIUS:
            nd = self.dc is NO_DERIV or o.dc is NO_DERIV
            return Jet(vc, NO_RADIUS, NO_DERIV if nd else self.dc + o.dc, NO_RADIUS)
        dc = self.dc + o.dc
        vr = self.vr + o.vr + EPS_OP * (self.va + o.va)
        dr = self.dr + o.dr + EPS_OP * (self.da + o.da)
        return Jet(vc, vr, dc, dr)

    def __neg__(self) -> Jet:
        return Jet(-self.vc, self.vr, self.dc if self.dc is NO_DERIV else -self.dc, self.dr,
                   va=self._va, da=self._da)

    def __sub__(self, o: Jet) -> Jet:
        return self + (-o)

    def __mul__(self, o: Jet) -> Jet:
        a, b = self, o
        if a.vr is NO_RADIUS or b.vr is NO_RADIUS:
            nd = a.dc is NO_DERIV or b.dc is NO_DERIV
            return Jet(a.vc * b.vc, NO_RADIUS, NO_DERIV if nd else a.dc * b.vc + a.vc * b.dc,
                       NO_RADIUS)
        av, bv, ad, bd = a.va, b.va, a.da, b.da
        vc = a.vc * b.vc
        vr = av * b.vr + a.vr * (bv + b.vr) + EPS_OP * av * bv
        dc = a.dc * b.vc + a.vc * b.dc
        dr = (ad * b.vr + a.dr * (bv + b.vr) + av * b.dr + a.vr * (bd + b.dr)
              + EPS_OP * (ad * bv + av * bd))
        return Jet(vc, vr, dc, dr)

    def scale(self, s: np.ndarray | complex) -> Jet:
        """Multiply by exactly known numbers ``s``."""
        s = np.asarray(s)
        if self.vr is NO_RADIUS:
            nd = self.dc is NO_DERIV
            return Jet(s * self.vc, NO_RADIUS, NO_DERIV if nd else s * self.dc, NO_RADIUS)
        a = np.abs(s)
        return Jet(s * self.vc, a * self.vr + EPS_OP * a * np.abs(self.vc),
                   s * self.dc, a * self.dr + EPS_OP * a * np.abs(self.dc))

    def reciprocal(self) -> Jet:
        """1/f, an enclosure where the value disc excludes 0 (else infinite radii)."""
        c, r = self.vc, self.vr
        if r is NO_RADIUS:          # values only: the same formulas with r = 0
            with np.errstate(all="ignore"):
                vc = np.conj(c) / (np.abs(c) ** 2)
            nd = self.dc is NO_DERIV
            return Jet(vc, NO_RADIUS, NO_DERIV if nd else -(self.dc * (vc * vc)), NO_RADIUS)
        with np.errstate(all="ignore"):
            den = np.abs(c) ** 2 - r * r
            ok = den > 0
            # the image of the disc |x - c| <= r under 1/x is the disc of centre
            # conj(c)/den and radius r/den (Gargantini-Henrici inversion)
            vc = np.where(ok, np.conj(c) / np.where(ok, den, 1.0), 0.0)
            vr = np.where(ok, r / np.where(ok, den, 1.0) + EPS_OP * np.abs(vc), np.inf)
        # (1/f)' = -f' (1/f)^2, in disc arithmetic
        sc, sr = _dmul(vc, vr, vc, vr)
        dc, dr = _dmul(self.dc, self.dr, sc, sr)
        return Jet(vc, vr, -dc, dr)

    def __truediv__(self, o: Jet) -> Jet:
        return self * o.reciprocal()

    def value_disc(self, rho: np.ndarray, point: Jet) -> tuple[np.ndarray, np.ndarray]:
        """Centred form: f(cell) lies in f(theta_m) + [-rho, rho] f'(cell). ``point`` is
        the same function evaluated at the cell centres (rho = 0). Returns the
        tighter of this and the jet's own value disc (both are enclosures)."""
        r_c = point.vr + rho * (np.abs(self.dc) + self.dr)
        use = r_c < self.vr
        return np.where(use, point.vc, self.vc), np.where(use, r_c, self.vr)


def _dmul(ac, ar, bc, br):
    """Disc product: every a*b with |a - ac| <= ar, |b - bc| <= br."""
    aa, ba = np.abs(ac), np.abs(bc)
    return ac * bc, aa * br + ar * ba + ar * br + EPS_OP * aa * ba


def const(c: np.ndarray, radius: np.ndarray | float = 0.0) -> Jet:
    """A constant known to within ``radius``."""
    c = np.asarray(c, complex)
    z = np.zeros(c.shape)
    return Jet(c, z + radius, np.zeros_like(c), z)


def zero(shape: tuple[int, ...]) -> Jet:
    z = np.zeros(shape)
    return Jet(z.astype(complex), z, z.astype(complex), z.copy())


def base_jets(theta: np.ndarray, rho: np.ndarray) -> dict[str, Jet]:
    """Jets of z = e^{j theta}, y = z - 1, 1/z and 1 - 1/z on the cells.

    ``|e^{j a} - e^{j b}| <= |a - b|``: the value radius of each is rho (plus the
    rounding of its centre); the derivatives are j z and -j/z, of modulus 1, whose
    variation on the cell is again at most rho.
    """
    th = np.asarray(theta)
    h = 0.5 * th
    ez, ezi = np.exp(1j * th), np.exp(-1j * th)
    s = np.sin(h)
    y = 2j * s * np.exp(1j * h)                  # e^{j theta} - 1 without cancellation
    omz = 2j * s * np.exp(-1j * h)               # 1 - e^{-j theta}
    # theta is exact (chosen by the caller); the centres carry a few rounding errors
    # relative to their own size, which matters near theta = 0 where y is tiny
    r1 = rho + EPS_OP
    return {"z": Jet(ez, r1, 1j * ez, r1), "y": Jet(y, rho + EPS_OP * np.abs(y), 1j * ez, r1),
            "zinv": Jet(ezi, r1, -1j * ezi, r1),
            "1-zinv": Jet(omz, rho + EPS_OP * np.abs(omz), 1j * ezi, r1)}


def delay_jet(theta: np.ndarray, rho: np.ndarray, n: int) -> Jet:
    """Jet of w = e^{-j n theta}: |w(theta) - w(theta_m)| <= min(n rho, 2)."""
    th = np.asarray(theta)
    w = np.exp(-1j * n * th)
    spread = np.minimum(n * rho, 2.0) + EPS_OP * (1.0 + n * np.abs(th))
    return Jet(w, spread, -1j * n * w, n * spread)


def one_minus_delay_jet(theta: np.ndarray, rho: np.ndarray, n: int) -> Jet:
    """Jet of 1 - e^{-j n theta} = 2j sin(n theta / 2) e^{-j n theta / 2} (no cancellation)."""
    th = np.asarray(theta)
    v = 2j * np.sin(0.5 * n * th) * np.exp(-0.5j * n * th)
    # the rounding of n theta itself (an absolute phase error) matters where 1 - w
    # vanishes (theta = 2 pi k / n)
    spread = np.minimum(n * rho, 2.0) + EPS_OP * (np.abs(v) + n * np.abs(th))
    return Jet(v, spread, 1j * n * np.exp(-1j * n * th), n * spread)


def geometric_sum_jet(theta: np.ndarray, rho: np.ndarray, n: int) -> Jet:
    """Jet of G_n = sum_{k<n} e^{j k theta} = (z^n - 1)/(z - 1) (G_n(0) = n).

    Away from theta = 0 it is the quotient of two jets; on cells that reach
    within 2 rho of 0 the global bounds |G_n'| <= n(n-1)/2 and
    |G_n''| <= (n-1)n(2n-1)/6 are used instead.
    """
    th = np.asarray(theta)
    rho = np.asarray(rho, float)
    if n <= 1:
        one = np.full(th.shape, float(n), complex)
        return Jet(one, np.zeros(th.shape), np.zeros(th.shape, complex), np.zeros(th.shape))
    h = 0.5 * th
    with np.errstate(all="ignore"):
        s = np.sin(h)
        g = np.where(s != 0, np.exp(1j * (n - 1) * h) * np.sin(n * h) / np.where(s != 0, s, 1.0), n)
    s1 = n * (n - 1) / 2.0
    s2 = (n - 1) * n * (2 * n - 1) / 6.0
    # derivative at the centre: closed form where n theta is not small, else Taylor
    # (the closed form divides a difference of O(n) terms by y ~ j theta, losing about
    # log10(1 / (n theta)) digits: below 1e-2 the Taylor polynomial takes over, its
    # remainder, ~(n theta)^4 relative, bounded by `tail` below)
    small = np.abs(n * th) < 1e-2
    ez = np.exp(1j * th)
    y = 2j * s * np.exp(1j * h)
    with np.errstate(all="ignore"):
        dg_exact = 1j * (n * np.exp(1j * n * th) - ez * g) / np.where(small, 1.0, y)
    s3 = (n * (n - 1) / 2.0) ** 2
    s4 = (n - 1) * n * (2 * n - 1) * (3 * (n - 1) ** 2 + 3 * (n - 1) - 1) / 30.0
    dg_taylor = 1j * s1 - th * s2 - 0.5j * th ** 2 * s3 + th ** 3 / 6.0 * s4
    dg = np.where(small, dg_taylor, dg_exact)
    rnd = EPS_OP * n * (1.0 + n * np.abs(th))
    # the Taylor centre of G' stops at theta^3: its remainder is below
    # theta^4 sum k^5 / 24, doubled for the tail of the series (|n theta| < 1e-2)
    s5 = float(n) ** 6 / 6.0
    tail = np.where(small, 2.0 * np.abs(th) ** 4 * s5 / 24.0, 0.0)
    # the closed form loses digits to cancellation: its numerator's terms are O(n) with
    # errors of a few units of EPS_OP each (about 8 n EPS_OP in all), divided by |y| ~ theta
    with np.errstate(all="ignore"):
        canc = np.where(small, 0.0, 8.0 * EPS_OP * n / np.where(small, 1.0, np.abs(y)))
    near = np.abs(th) - 2.0 * rho <= 1.0 / n
    out = Jet(g, rho * s1 + rnd, dg, rho * s2 + n * rnd + tail + canc)
    if not np.all(near):
        b = base_jets(th, rho)
        zn = np.exp(1j * n * th)
        spread = np.minimum(n * rho, 2.0) + EPS_OP * (1.0 + n * np.abs(th))
        num = Jet(2j * np.sin(n * h) * np.exp(1j * n * h), spread, 1j * n * zn, n * spread)
        with np.errstate(all="ignore"):
            q = num / b["y"]
        far = ~near
        out = Jet(np.where(far, q.vc, out.vc), np.where(far, q.vr, out.vr),
                  np.where(far, q.dc, out.dc), np.where(far, q.dr, out.dr))
    return out


def poly_jet(coef: np.ndarray, err: np.ndarray, x: Jet) -> Jet:
    """Horner's rule for sum_k coef[:, k] x^k (ascending) in jet arithmetic.

    ``coef`` has one row per cell (already gathered); ``err`` bounds the error of
    each coefficient itself (same shape).
    """
    if x.vr is NO_RADIUS:       # values only: the same centres, without the discs
        v = coef[:, -1].astype(complex)
        if x.dc is NO_DERIV:
            for k in range(coef.shape[-1] - 2, -1, -1):
                v = v * x.vc + coef[:, k]
            return Jet(v, NO_RADIUS, NO_DERIV, NO_RADIUS)
        d = np.zeros(coef.shape[0], complex)
        for k in range(coef.shape[-1] - 2, -1, -1):
            v, d = v * x.vc + coef[:, k], d * x.vc + v * x.dc
        return Jet(v, NO_RADIUS, d, NO_RADIUS)
    acc = const(coef[:, -1], err[:, -1])
    for k in range(coef.shape[-1] - 2, -1, -1):
        acc = acc * x + const(coef[:, k], err[:, k])
    return acc
