"""The real crossings of the PEB with a fractional delay over a box of angles and
fractions, in ball arithmetic: the rigorous half of its fractional delay range.

On the unit circle z = e^{j theta} the loop's characteristic function is the quadratic
chi = a_2 K^2 + a_1 K + a_0 of :mod:`~hapstab.analysis.network.modified_z_peb`, its
coefficients analytic in (theta, f). They and their derivatives in theta and f are
evaluated as first-order jets over a box Theta x F in Arb (the ZOH at T and at (1 - f)T
by ``arb_mat.exp``, rigorous for ball entries, as in
:mod:`~hapstab.analysis.network.frac_balls`).

**The two roots on a box.** With D = a_1^2 - 4 a_0 a_2 over the box: if D's ball lies in
the open right or upper or lower half plane, s = sqrt(D) is analytic on the box; if it
lies in the open left half plane, s = j sqrt(-D) is. With the sign sigma for which q =
-(a_1 + sigma s) / 2 keeps away from 0 on the box, the roots

    K_a = q / a_2,   K_b = a_0 / q

are analytic functions of (theta, f) on the box (K_a may pass infinity where a_2 = 0),
their values at the box's centre formed with the same branch. Implicit
differentiation of chi(K(theta, f)) = 0 gives their derivatives over the box,

    dK/dtheta = -(a_2' K^2 + a_1' K + a_0') / (dchi/dK),   dchi/dK = -sigma s at K_a,
    +sigma s at K_b,

so each root has the mean-value form the HVE's G has, and the same bounds apply to it
(:func:`~hapstab.analysis.network.frac_bound.mean_value_lower`). Where a_2's ball holds 0,
|K_a| >= |q| / |a_2| bounds K_a's real values from below; where D's ball meets the
negative real axis's end at 0 (the roots may meet) both roots lie in the disc of centre
-a_1 / (2 a_2) and radius sqrt|D| / (2 |a_2|).

References
----------
F. Johansson, "Arb: efficient arbitrary-precision midpoint-radius interval arithmetic",
IEEE Trans. Computers 66 (2017) 1281-1292; R. E. Moore, R. B. Kearfott and M. J. Cloud,
*Introduction to Interval Analysis*, SIAM 2009, sec. 6.1 (the mean-value form);
W. H. Press et al., *Numerical Recipes*, 3rd ed., sec. 5.6 (the quadratic's roots as
q / a and c / q).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from hapstab.analysis.network.modified_z_peb import PebFractionalPlant
from hapstab.engine.arb_loop import PREC, working_precision

__all__ = ["PebFractionBalls", "PebBox"]

#: Fraction balls kept (one per f-interval of the branch and bound)
FRACTION_CACHE = 4096


@dataclass
class _Jet:
    """A value with its derivatives in theta and f (acb balls)."""

    v: Any
    t: Any
    f: Any

    def __add__(self, o: _Jet) -> _Jet:
        return _Jet(self.v + o.v, self.t + o.t, self.f + o.f)

    def __sub__(self, o: _Jet) -> _Jet:
        return _Jet(self.v - o.v, self.t - o.t, self.f - o.f)

    def __mul__(self, o: _Jet) -> _Jet:
        return _Jet(self.v * o.v, self.t * o.v + self.v * o.t, self.f * o.v + self.v * o.f)

    def scale(self, c: Any) -> _Jet:
        """The jet times the constant ball ``c``."""
        return _Jet(self.v * c, self.t * c, self.f * c)


def _const(c: Any) -> _Jet:
    return _Jet(c, 0 * c, 0 * c)


def _poly(coef: list[Any], y: _Jet) -> _Jet:
    """sum coef[i] y^i (ascending) by Horner's rule, on jets."""
    out = _const(coef[-1])
    for c in coef[-2::-1]:
        out = out * y + _const(c)
    return out


@dataclass
class PebBox:
    """The quadratic's coefficients over a box (``coef``: jets of a_0, a_1, a_2 over it)
    and at its centre (``centre``: acb), and the box's radii (arb)."""

    coef: list[_Jet]
    centre: list[Any]
    r_theta: Any
    r_f: Any
    d_theta: Any = None
    d_f: Any = None

    def lower(self, k_floor: float, target: float = math.inf) -> float | None:
        """A lower bound of the real roots K >= ``k_floor`` over the box, or None when
        it has none (module docstring); ``target`` when chi has no zero on the box for
        K in [k_floor, target] (its mean-value form in K excludes 0)."""
        from hapstab.analysis.network.frac_bound import disc_lower
        if self._excluded(k_floor, target):
            return target
        roots = _roots(self)
        if roots is None:
            a0, a1, a2 = (c.v for c in self.coef)
            return disc_lower(a0, a1, a2, k_floor)
        bounds = [(b, r) for b, r in ((self._root_lower(r, k_floor), r) for r in roots)
                  if b is not None]
        if not bounds:
            return None
        # the split heuristic's scales: the slopes of the lowest root that has them
        slopes = [(b, r) for b, r in bounds if r[2].is_finite() and r[3].is_finite()]
        if slopes:
            root = min(slopes, key=lambda x: x[0])[1]
            self.d_theta, self.d_f = root[2], root[3]
        return min(b for b, _ in bounds)

    def _excluded(self, k_floor: float, target: float) -> bool:
        """Whether a_0 + a_1 K + a_2 K^2 has no zero over the box for K in
        [k_floor, target] (the mean-value form in K about the interval's centre)."""
        from flint import acb, arb
        if not (math.isfinite(target) and target > k_floor):
            return False
        kc, kr = (k_floor + target) / 2, (target - k_floor) / 2
        ks = arb(kc, kr).union(arb(k_floor)).union(arb(target))   # covers the doubles' ends
        a0, a1, a2 = (c.v for c in self.coef)
        c = arb(kc)
        val = a0 + c * (a1 + c * a2) + (a1 + 2 * a2 * ks) * acb(ks - c)
        return not val.contains(0)

    def _root_lower(self, root: tuple[Any, ...], k_floor: float) -> float | None:
        """One root's bound: its mean-value form, or |q| / |a_2| where it is unbounded."""
        from hapstab.analysis.network.frac_bound import double_below, mean_value_lower
        centre, box, d_t, d_f, magnitude = root
        if not (centre.is_finite() and box.is_finite() and d_t.is_finite() and d_f.is_finite()):
            return max(k_floor, double_below(magnitude.lower())) if magnitude.is_finite() else k_floor
        return mean_value_lower(centre, d_t, d_f, self.r_theta, self.r_f, k_floor)

    def split_scales(self) -> tuple[float, float]:
        """|dK/df|, |dK/dtheta| over the box of the root with the lowest bound at K >= 0
        (the split heuristic), else the coefficients' relative scales."""
        if self.d_theta is None:
            self.lower(0.0)
        if self.d_theta is None:        # no root settled: the coefficients' relative scales
            mags = [float(c.v.abs_upper()) for c in self.coef]
            return (sum(float(c.f.abs_upper()) / m for c, m in zip(self.coef, mags, strict=True) if m),
                    sum(float(c.t.abs_upper()) / m for c, m in zip(self.coef, mags, strict=True) if m))
        return float(self.d_f.abs_upper()), float(self.d_theta.abs_upper())


def _branch(a0: Any, a1: Any, a2: Any) -> tuple[int, int] | None:
    """(mode, sigma) of the module docstring from the box's coefficient balls: s =
    sqrt(D) (mode 0) or j sqrt(-D) (mode 1), and the sign keeping q off 0; None if D
    may meet the branch cut or q may vanish."""
    D = a1 * a1 - 4 * a0 * a2
    if D.real > 0 or not D.imag.contains(0):
        mode = 0
    elif D.real < 0:
        mode = 1
    else:
        return None
    s = _sqrt(D, mode)
    sigma = 1 if (a1 + s).abs_lower() >= (a1 - s).abs_lower() else -1
    return None if (a1 + sigma * s).contains(0) else (mode, sigma)


def _sqrt(D: Any, mode: int) -> Any:
    from flint import acb
    return D.sqrt() if mode == 0 else acb(0, 1) * (-D).sqrt()


def _pair(coef: list[Any], branch: tuple[int, int]) -> tuple[Any, Any, Any, Any]:
    """(K_a, K_b, q, s) of the coefficients (a_0, a_1, a_2) with the branch (mode, sigma)."""
    a0, a1, a2 = coef
    mode, sigma = branch
    s = _sqrt(a1 * a1 - 4 * a0 * a2, mode)
    q = -(a1 + sigma * s) / 2
    return q / a2, a0 / q, q, s


def _roots(bx: PebBox) -> list[tuple[Any, ...]] | None:
    """Each root's (centre value, ball over the box, dK/dtheta, dK/df, |K| lower end),
    or None when the branch is not settled on the box."""
    a0, a1, a2 = bx.coef
    br = _branch(a0.v, a1.v, a2.v)
    if br is None:
        return None
    ka, kb, q, s = _pair([a0.v, a1.v, a2.v], br)
    ca, cb, _, _ = _pair(bx.centre, br)
    from flint import acb, arb
    ht, hf = acb(arb(0, bx.r_theta)), acb(arb(0, bx.r_f))
    out = []
    # |K_a| >= |q| / |a_2| (K_a passes infinity where a_2 = 0); K_b = a_0 / q is bounded
    for k, c, dk, mag in ((ka, ca, -br[1] * s, q.abs_lower() / a2.v.abs_upper()),
                          (kb, cb, br[1] * s, arb(0))):
        d_t, d_f = _slopes(bx.coef, k, dk)
        # the root's values over the box by its mean-value form, when narrower than the
        # quotient's ball, give narrower slopes (both balls hold every value of the box)
        narrow = c + d_t * ht + d_f * hf
        if narrow.is_finite() and (not k.is_finite() or narrow.rad() < k.rad()):
            d_t, d_f = _slopes(bx.coef, narrow, dk)
        out.append((c, k, d_t, d_f, mag))
    return out


def _slopes(coef: list[_Jet], k: Any, dk: Any) -> tuple[Any, Any]:
    """(dK/dtheta, dK/df) over the box for the root's values in the ball ``k`` and
    dchi/dK in ``dk`` (implicit differentiation, module docstring)."""
    a0, a1, a2 = coef
    return (-((a2.t * k + a1.t) * k + a0.t) / dk, -((a2.f * k + a1.f) * k + a0.f) / dk)


class PebFractionBalls:
    """Balls of the PEB's crossing quadratic (module docstring) for one
    :class:`PebFractionalPlant`.

    Parameters
    ----------
    plant : PebFractionalPlant
        The loop's numbers.
    prec : int
        Working precision in bits (the exact core's).
    """

    def __init__(self, plant: PebFractionalPlant, prec: int = PREC) -> None:
        from flint import acb, arb, arb_mat
        self.plant, self.prec = plant, prec
        self._fr: dict[tuple[float, float], tuple[Any, ...]] = {}
        self.ports: list[dict[str, Any]] = []
        with working_precision(prec):
            self.T = arb(plant.ports[0].period_s)
            for p, r in zip(plant.ports, plant.ratios, strict=True):
                M, b, k = arb(p.mass_kg), arb(p.damping_N_s_per_m), arb(p.stiffness_N_per_m)
                A = arb_mat([[0, 1, 0], [-k / M, -b / M, 1 / M], [0, 0, 0]])
                X = (A * self.T).exp()
                E00, E01, E10, E11 = X[0, 0] - 1, X[0, 1], X[1, 0], X[1, 1] - 1
                g0, g1 = X[0, 2], X[1, 2]
                self.ports.append({
                    "A": A, "d": [acb(E00 * E11 - E01 * E10), acb(-(E00 + E11)), acb(1)],
                    "a0": [acb(E01 * g1 - E11 * g0), acb(g0)],
                    "a1": [acb(E10 * g0 - E00 * g1), acb(g1)],
                    "s": acb(p.sign), "beta": acb(p.beta_N_per_m), "r": acb(r)})
            self.cross = acb(plant.cross)
        self.n2 = 2 * plant.whole + 2
        #: the angle pieces of the branch and bound grow with the degree (2n + 8)
        self.n1 = self.n2

    def fraction(self, f: Any, key: tuple[float, float] | None = None) -> tuple[Any, ...]:
        """Per port (c_0, c_1, g, dc_0/df, dc_1/df, dg/df) as acb over the arb ball ``f``."""
        if key is not None and key in self._fr:
            return self._fr[key]
        from flint import acb
        out = []
        with working_precision(self.prec):
            for p in self.ports:
                X = (p["A"] * (self.T * (1 - f))).exp()
                out.append(tuple(acb(v) for v in (X[0, 0], X[0, 1], X[0, 2], -self.T * X[1, 0],
                                                  -self.T * X[1, 1], -self.T * X[1, 2])))
        if key is not None:
            if len(self._fr) >= FRACTION_CACHE:
                self._fr.clear()
            self._fr[key] = tuple(out)
        return tuple(out)

    def coefficients(self, theta: Any, fr: tuple[Any, ...]) -> list[_Jet]:
        """Jets of (a_0, a_1, a_2) at the angle ball ``theta`` and fraction balls ``fr``."""
        from flint import acb
        jt = acb(0, theta)
        y = jt.expm1()
        zj = _Jet(1 + y, acb(0, 1) * (1 + y), acb(0))
        yj = _Jet(y, zj.t, acb(0))
        zn = (jt * self.n2).exp()
        znj = _Jet(zn, acb(0, self.n2) * zn, acb(0))
        L, R, Nt = [], [], []
        for p, (c0, c1, g, e0, e1, eg) in zip(self.ports, fr, strict=True):
            d, a0, a1 = _poly(p["d"], yj), _poly(p["a0"], yj), _poly(p["a1"], yj)
            L.append(zj * d + (yj * a0).scale(p["s"] * p["beta"]))
            R.append((zj * a0).scale(p["s"] * p["r"]))
            Nt.append(_Jet(c0, acb(0), e0) * a0 + _Jet(c1, acb(0), e1) * a1
                      + _Jet(g, acb(0), eg) * d)
        (m, s), w = self.ports, (Nt[0] * Nt[1]).scale(self.cross)
        c = [(yj * yj).scale(m["beta"] * s["beta"]),
             (zj * yj).scale(m["r"] * s["beta"] + s["r"] * m["beta"]),
             (zj * zj).scale(m["r"] * s["r"])]
        P = [L[0] * L[1], L[0] * R[1] + R[0] * L[1], R[0] * R[1]]
        return [znj * Pi - ci * w for Pi, ci in zip(P, c, strict=True)]

    def value(self, theta: Any, f: Any, key: tuple[float, float] | None = None) -> list[Any]:
        """(a_0, a_1, a_2) on the balls ``theta`` (rad) and ``f`` (arb), plain evaluation
        (``key``: the interval ``f`` is exactly, for the cache)."""
        with working_precision(self.prec):
            return [j.v for j in self.coefficients(theta, self.fraction(f, key))]

    def box(self, theta: Any, f: Any, key: tuple[float, float] | None = None) -> PebBox:
        """The coefficients over the box ``theta`` x ``f`` and at its centre."""
        from flint import acb, arb
        with working_precision(self.prec):
            fm = float(f.mid())
            # cached under (fm, fm) only when the centre is that double: the point ball
            # arb(fm) is exactly [fm, fm]
            exact = arb(fm) == f.mid()
            centre = self.value(arb(theta.mid()), f.mid(), key=(fm, fm) if exact else None)
            coef = self.coefficients(theta, self.fraction(f, key))
            # the values over the box by their mean-value form: a plain evaluation loses
            # z^(2n+2) P_i - c_i Nt_m Nt_s's cancellation to first order in the radii
            ht, hf = acb(arb(0, theta.rad())), acb(arb(0, f.rad()))
            coef = [_Jet(c + j.t * ht + j.f * hf, j.t, j.f) for c, j in zip(centre, coef, strict=True)]
            return PebBox(coef, centre, theta.rad(), f.rad())

    def proved_crossing(self, theta: float, f: float) -> float:
        """An upper bound, proved, of a real crossing K > 0 at the fraction ``f`` near the
        angle ``theta`` (a float root), or inf: at theta = 0 or pi a positive real root
        (D > 0, the coefficients real there); else one root's imaginary part of opposite
        signs at theta (1 -/+ rel), rel = 1e-12 ... 1e-4, on a branch analytic over that
        interval (so the root is real in between), and the upper end of its real part there.

        Parameters
        ----------
        theta, f : float
            The crossing's angle (rad/sample) and fraction.

        Returns
        -------
        float
        """
        with working_precision(self.prec):
            return self._proved_crossing(theta, f)

    def _proved_crossing(self, theta: float, f: float) -> float:
        from flint import arb

        from hapstab.analysis.network.frac_bound import double_above
        fb = arb(f)
        if theta in (0.0, math.pi):
            a0, a1, a2 = (c.real for c in self.value(arb.pi() if theta else arb(0), fb))
            D = a1 * a1 - 4 * a0 * a2
            if not D > 0 or a1.contains(0):
                return math.inf
            # both roots real: q / a_2 and a_0 / q (a_2 = 0 at z = 1: only the second finite)
            q = -(a1 + (1 if a1 > 0 else -1) * D.sqrt()) / 2
            ks = [k for k in (q / a2, a0 / q) if k.is_finite() and k > 0]
            return min((double_above(k.upper()) for k in ks), default=math.inf)
        for rel in (1e-12, 1e-10, 1e-8, 1e-6, 1e-4):    # 1e-12..1e-4: brackets around a
            a, b = theta * (1 - rel), min(theta * (1 + rel), math.pi)   # float root
            span = arb((a + b) / 2, (b - a) / 2).union(arb(a)).union(arb(b))
            over = self.value(span, fb)
            br = _branch(over[0], over[1], over[2])
            if br is None:
                continue
            ends = [_pair(self.value(arb(t), fb), br)[:2] for t in (a, b)]
            roots = _pair(over, br)[:2]
            for i in (0, 1):
                ia, ib = ends[0][i].imag, ends[1][i].imag
                if ((ia < 0 < ib) or (ib < 0 < ia)) and roots[i].is_finite() and roots[i].real > 0:
                    return double_above(roots[i].real.upper())
        return math.inf
