"""G(theta, f) of :mod:`~hapstab.analysis.network.modified_z` over a box of angles and
fractions, in ball arithmetic (python-flint's Arb): the rigorous half of the fractional
delay range.

Every number of the loop is a double taken as exact; the ZOH at the full period and at
(1 - f)T is Arb's matrix exponential (``arb_mat.exp``, rigorous for ball entries, so
one exponential with f a ball encloses c_f, g_f for every f of it). Over a box
Theta x F (centres theta_c, f_c, radii r_t, r_f) the mean-value form

    G(Theta, F) in G(theta_c, f_c) + G_t(Theta, F) [-r_t, r_t] + G_f(Theta, F) [-r_f, r_f]

holds (G is analytic where Nt_f != 0; the derivatives' balls are evaluated over the
whole box), with

    G_t = -s_e j z^(n+1) [(n + 1) d / Nt + z (d' Nt - d Nt') / Nt^2] - j beta z^-1,
    G_f = s_e z^(n+1) d (dNt/df) / Nt^2,

primes in y. Its overestimation is of second order in the radii once the derivatives'
balls are narrow, which is what lets the branch and bound of
:mod:`~hapstab.analysis.network.frac_bound` close to 1e-8 on few boxes.

References
----------
F. Johansson, "Arb: efficient arbitrary-precision midpoint-radius interval arithmetic",
IEEE Trans. Computers 66 (2017) 1281-1292; R. E. Moore, R. B. Kearfott and M. J. Cloud,
*Introduction to Interval Analysis*, SIAM 2009, sec. 6.1 (the mean-value form).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from hapstab.analysis.network.modified_z import FractionalPlant
from hapstab.engine.arb_loop import PREC, working_precision

__all__ = ["FractionBalls", "BoxGain"]

#: Fraction balls kept (one per f-interval of the branch and bound)
FRACTION_CACHE = 4096


@dataclass
class BoxGain:
    """G over a box: its centre value, its derivatives over the box (acb balls), the
    box's radii (arb), and ``d``, ``Nt`` over the box (near a pole of G, where Nt may
    vanish, det M = d + s z^-(n+1) Nt H has no zero while |d| > |Nt| |H|)."""

    centre: Any
    d_theta: Any
    d_f: Any
    r_theta: Any
    r_f: Any
    nt: Any
    d: Any
    beta: Any

    def enclosure(self) -> Any:
        """The mean-value enclosure of G over the box (acb)."""
        from flint import acb, arb
        return (self.centre + self.d_theta * acb(arb(0, self.r_theta))
                + self.d_f * acb(arb(0, self.r_f)))

    def lower(self, k_floor: float, target: float = math.inf) -> float | None:
        """The box's lower bound of the real crossings >= ``k_floor``, or None when it has
        none (:mod:`~hapstab.analysis.network.frac_bound`; ``target`` is not used: G is
        linear in K)."""
        from hapstab.analysis.network.frac_bound import box_lower
        return box_lower(self, k_floor)

    def split_scales(self) -> tuple[float, float]:
        """|dG/df|, |dG/dtheta| over the box (the split heuristic)."""
        return float(self.d_f.abs_upper()), float(self.d_theta.abs_upper())


class FractionBalls:
    """Balls of G(theta, f) (module docstring) for one :class:`FractionalPlant`.

    Parameters
    ----------
    plant : FractionalPlant
        The loop's numbers.
    prec : int
        Working precision in bits (the exact core's).
    """

    def __init__(self, plant: FractionalPlant, prec: int = PREC) -> None:
        from flint import acb, arb, arb_mat
        self.plant, self.prec = plant, prec
        self._fr: dict[tuple[float, float], tuple[Any, ...]] = {}
        with working_precision(prec):
            M, b, k = (arb(plant.mass_kg), arb(plant.damping_N_s_per_m),
                       arb(plant.stiffness_N_per_m))
            self.T = arb(plant.period_s)
            self.A = arb_mat([[0, 1, 0], [-k / M, -b / M, 1 / M], [0, 0, 0]])
            X = (self.A * self.T).exp()
            E00, E01, E10, E11 = X[0, 0] - 1, X[0, 1], X[1, 0], X[1, 1] - 1
            g0, g1 = X[0, 2], X[1, 2]
            # d(y) = y^2 - (E00 + E11) y + det E;  a_0, a_1 (module doc of modified_z)
            self.d = [acb(E00 * E11 - E01 * E10), acb(-(E00 + E11)), acb(1)]
            self.a0 = [acb(E01 * g1 - E11 * g0), acb(g0)]
            self.a1 = [acb(E10 * g0 - E00 * g1), acb(g1)]
            self.s = acb(plant.sign)
            self.beta = acb(plant.beta_N_per_m)
            self.n1 = plant.whole + 1

    def fraction(self, f: Any, key: tuple[float, float] | None = None) -> tuple[Any, ...]:
        """(c_0, c_1, g, dc_0/df, dc_1/df, dg/df) as acb over the arb ball ``f``."""
        if key is not None and key in self._fr:
            return self._fr[key]
        from flint import acb
        with working_precision(self.prec):
            X = (self.A * (self.T * (1 - f))).exp()
            out = tuple(acb(v) for v in (X[0, 0], X[0, 1], X[0, 2],
                                         -self.T * X[1, 0], -self.T * X[1, 1],
                                         -self.T * X[1, 2]))
        if key is not None:
            if len(self._fr) >= FRACTION_CACHE:
                self._fr.clear()
            self._fr[key] = out
        return out

    def _parts(self, theta: Any, fr: tuple[Any, ...]) -> tuple[Any, ...]:
        """z, y and d, d', Nt, Nt', dNt/df at the angle ball and fraction balls."""
        from flint import acb
        jt = acb(0, theta)
        y = jt.expm1()
        z = 1 + y
        c0, c1, g, e0, e1, eg = fr
        d = self.d[0] + y * (self.d[1] + y * self.d[2])
        dd = self.d[1] + 2 * y * self.d[2]
        a0, a1 = self.a0[0] + y * self.a0[1], self.a1[0] + y * self.a1[1]
        nt = c0 * a0 + c1 * a1 + g * d
        ntp = c0 * self.a0[1] + c1 * self.a1[1] + g * dd
        ntf = e0 * a0 + e1 * a1 + eg * d
        return jt, z, d, dd, nt, ntp, ntf

    def value(self, theta: Any, f: Any) -> Any:
        """G on the balls ``theta`` (rad) and ``f`` (arb), plain ball evaluation."""
        with working_precision(self.prec):
            jt, z, d, _dd, nt, _ntp, _ntf = self._parts(theta, self.fraction(f))
            w = (jt * self.n1).exp()
            return -self.s * w * d / nt - self.beta * (1 - 1 / z)

    def proved_crossing(self, theta: float, f: float) -> float:
        """:func:`~hapstab.analysis.network.frac_bound.proved_crossing` for this loop."""
        from hapstab.analysis.network.frac_bound import proved_crossing
        return proved_crossing(self, theta, f)

    def box(self, theta: Any, f: Any, key: tuple[float, float] | None = None) -> BoxGain:
        """The centre value and the derivatives over the box ``theta`` x ``f`` (arb
        balls; ``key`` names f's interval for the cache)."""
        from flint import acb, arb
        with working_precision(self.prec):
            centre = self.value(arb(theta.mid()), arb(f.mid()))
            jt, z, d, dd, nt, ntp, ntf = self._parts(theta, self.fraction(f, key))
            w = (jt * self.n1).exp()
            j = acb(0, 1)
            g_t = (-self.s * j * w * (self.n1 * d / nt + z * (dd * nt - d * ntp) / (nt * nt))
                   - j * self.beta / z)
            g_f = self.s * w * d * ntf / (nt * nt)
            return BoxGain(centre, g_t, g_f, theta.rad(), f.rad(), nt, d, self.beta)

