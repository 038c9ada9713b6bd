"""PEB with the same fractional one-way delay in both directions as a modified
z-transform, analytic in the fraction f: a quadratic in K on the unit circle.

**The model.** Two ports j = m (master + operator) and s (slave + environment), each a
mass M_j, damping b_j, spring k_j to ground (state [x_j, v_j]) driven by the held force
-u_j (ZOH), and two spring-damper controllers H_j(z) = K r_j + beta_j (1 - z^-1) (r_m =
1, r_s = K_s / K_m: the engine's one rule for K; beta_j = B_j / T) on

    u_m = H_m (s_mm x_m[k] + s_ms x_s(kT - tau)),   u_s = H_s (s_ss x_s[k] + s_sm x_m(kT - tau)),

tau = (n + f) T the same one-way delay in both directions (``--delay-s`` for the PEB), the
signs those of the engine's channels (s_mm = a b, s_ms = -b, s_ss = 1, s_sm = -a with the
position and force scales a, b; eq. (20) of the paper when both are 1).

**Derivation.** Each port alone is the HVE's plant of
:mod:`~hapstab.analysis.network.modified_z`: with E_j = Phi_{j,T} - I, y = z - 1 and
d_j(y) = det(yI - E_j), its undelayed position is X_j / (-U_j) = N_j / d_j (N_j = C
adj(yI - E_j) Gamma_{j,T}, the a_0 polynomial there), and its position sampled fT before
the instants is z X_{j,f} / (-U_j) = Nt_{j,f} / d_j (Jury's modified z-transform, m = 1 -
f). With P_j = N_j / d_j and Q_j = z^-(n+1) Nt_{j,f} / d_j the loop is

    (1 + s_mm H_m P_m) U_m + s_ms H_m Q_s U_s = 0,
    s_sm H_s Q_m U_m + (1 + s_ss H_s P_s) U_s = 0,

and its determinant times z^(2n+4) d_m d_s, with h_j = z H_j = K r_j z + beta_j y, is

    chi(z, K, f) = z^(2n+2) (z d_m + s_mm h_m N_m)(z d_s + s_ss h_s N_s)
                   - s_ms s_sm h_m h_s Nt_{m,f} Nt_{s,f},

monic of degree 2n + 8 for every (K, f) (the first product is monic of degree 6 in z,
the second term of degree at most 6): its roots are the closed-loop poles (the engine's
state: plants 4, controllers 2, each direction's fractional state and its n registers),
continuous in (K, f). At f = 0 (Nt_0 = z N) it is z^2 times the whole-delay loop's
polynomial (round trip 2n); at f = 1 it is the whole delay n + 1 in each direction.

K enters both controllers, so chi = a_2 K^2 + a_1 K + a_0 with

    a_i(z, f) = z^(2n+2) P_i(y) - s_ms s_sm c_i(y) Nt_{m,f} Nt_{s,f},

L_j = z d_j + s_jj beta_j y N_j, R_j = s_jj r_j z N_j, P_0 = L_m L_s, P_1 = L_m R_s +
R_m L_s, P_2 = R_m R_s, c_0 = beta_m beta_s y^2, c_1 = (r_m beta_s + r_s beta_m) z y,
c_2 = r_m r_s z^2. A pole lies on the unit circle at z = e^{j theta} for a real K exactly
when K is a real root of this quadratic, whose coefficients are entire in f and
analytic in theta.

References
----------
E. I. Jury, *Theory and Application of the z-Transform Method*, Wiley 1964, ch. 2
(the modified z-transform); K. J. Astrom and B. Wittenmark, *Computer-Controlled
Systems*, 3rd ed., sec. 2.3 (ZOH sampling) and sec. 2.7 / 7.7 (a delay that is not a
multiple of the period); the paper, Fig. 3 and eq. (20) (the PEB loop).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.analysis.network.modified_z import FractionalPlant, full_period
from hapstab.errors import AnalysisError

__all__ = ["PebFractionalPlant", "peb_fractional_plant"]


@dataclass(frozen=True)
class PebFractionalPlant:
    """The numbers of a PEB with the same fractional delay both ways (module docstring).

    Parameters
    ----------
    ports : (FractionalPlant, FractionalPlant)
        Master and slave: each port's totals, its controller's beta_j and its own sign
        s_jj (``sign``), the period and n (``whole``).
    ratios : (float, float)
        r_m, r_s: each controller's stiffness per unit K.
    cross : float
        s_ms s_sm, the product of the cross terms' signs.
    """

    ports: tuple[FractionalPlant, FractionalPlant]
    ratios: tuple[float, float]
    cross: float

    @property
    def whole(self) -> int:
        """n."""
        return self.ports[0].whole

    def balls(self) -> Any:
        """The ball evaluator of this model
        (:class:`~hapstab.analysis.network.frac_balls_peb.PebFractionBalls`)."""
        from hapstab.analysis.network.frac_balls_peb import PebFractionBalls
        return PebFractionBalls(self)

    def polys(self, f: float) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(d_j, N_j, Nt_{j,f}) of each port, ascending in y (doubles)."""
        out = []
        for p in self.ports:
            d, nt = p.coefficients(f)
            out.append((d, full_period(p)[1], nt))
        return out

    def quadratic(self, theta: np.ndarray, f: float, polys: list[Any] | None = None
                  ) -> tuple[np.ndarray, ...]:
        """(a_0, a_1, a_2) of the module docstring at each angle (rad/sample); ``polys``:
        :meth:`polys` at f, if already formed."""
        th = np.asarray(theta, float)
        z, y = np.exp(1j * th), np.expm1(1j * th)
        (dm, nm, tm), (ds, ns, ts) = (tuple(np.polyval(c[::-1], y) for c in q)
                                      for q in (polys or self.polys(f)))
        (pm, ps), (rm, rs) = self.ports, self.ratios
        Lm, Ls = z * dm + pm.sign * pm.beta_N_per_m * y * nm, z * ds + ps.sign * ps.beta_N_per_m * y * ns
        Rm, Rs = pm.sign * rm * z * nm, ps.sign * rs * z * ns
        w, zn = self.cross * tm * ts, z ** (2 * self.whole + 2)
        bm, bs = pm.beta_N_per_m, ps.beta_N_per_m
        return (zn * Lm * Ls - bm * bs * y * y * w,
                zn * (Lm * Rs + Rm * Ls) - (rm * bs + rs * bm) * z * y * w,
                zn * Rm * Rs - rm * rs * z * z * w)

    def char_poly(self, K: float, f: float) -> np.ndarray:
        """chi(z) (module docstring), descending coefficients in z."""
        P = np.polynomial.Polynomial
        y = P([-1.0, 1.0])                             # y = z - 1 as a polynomial in z
        z = P([0.0, 1.0])
        (dm, nm, tm), (ds, ns, ts) = ([P(c)(y) for c in q] for q in self.polys(f))
        (pm, ps), (rm, rs) = self.ports, self.ratios
        hm = K * rm * z + pm.beta_N_per_m * y
        hs = K * rs * z + ps.beta_N_per_m * y
        chi = (z ** (2 * self.whole + 2) * (z * dm + pm.sign * hm * nm) * (z * ds + ps.sign * hs * ns)
               - self.cross * hm * hs * tm * ts)
        return np.asarray(chi.coef[::-1])

    def crossings(self, theta: np.ndarray, f: float, polys: list[Any] | None = None
                  ) -> np.ndarray:
        """The two roots K of the quadratic at each angle, shape (angles, 2) (their order
        is not continuous in theta)."""
        a0, a1, a2 = self.quadratic(theta, f, polys)
        with np.errstate(all="ignore"):
            s = np.sqrt(a1 * a1 - 4 * a0 * a2)
            q = -(a1 + np.where(np.real(np.conj(a1) * s) >= 0, s, -s)) / 2
            return np.stack([q / a2, a0 / q], axis=-1)

    def first_crossing(self, f: float, k_floor: float, points: int | None = None
                       ) -> tuple[float, float]:
        """The smallest real crossing K > ``k_floor`` at the fraction ``f`` and its angle
        (doubles: the float search that proposes the worst fraction; nothing proved).

        A root K of the quadratic is real where Im K_1 Im K_2 (symmetric in the two roots,
        so continuous in theta) changes sign; each such angle is refined by Brent's method.

        Parameters
        ----------
        f : float
            The fraction.
        k_floor : float
            Crossings at or below it are ignored.
        points : int, optional
            Angles of the scan of [0, pi] (default 64 (2n + 2), at least 2049).

        Returns
        -------
        (K, theta) : (float, float)
            (inf, nan) when none.
        """
        from scipy.optimize import brentq
        m = points or max(2049, 128 * (self.whole + 1))
        th = np.linspace(0.0, math.pi, m)
        polys = self.polys(f)
        R = self.crossings(th, f, polys)
        best = (math.inf, math.nan)
        for t in (0, m - 1):                      # z = +-1: real coefficients
            for k in R[t]:
                if abs(k.imag) <= 1e-9 * abs(k) and k_floor < k.real < best[0]:  # 1e-9: a
                    best = (float(k.real), float(th[t]))                         # real root
        phi = np.prod(R.imag, axis=-1)
        ok = np.isfinite(phi)
        br = np.flatnonzero((np.sign(phi[:-1]) * np.sign(phi[1:]) < 0) & ok[:-1] & ok[1:])
        # the root nearer the real axis at each angle: the lowest brackets first, and none
        # whose root cannot be above K_floor or beat the best
        near = np.take_along_axis(R, np.argmin(np.abs(R.imag), axis=-1)[:, None], -1)[:, 0].real
        spread = np.abs(np.diff(near)[br])
        low = np.minimum(near[br], near[br + 1]) - spread
        high = np.maximum(near[br], near[br + 1]) + spread
        for i in br[np.argsort(low)][high[np.argsort(low)] > k_floor]:
            if min(near[i], near[i + 1]) - abs(near[i] - near[i + 1]) >= best[0]:
                break
            r = brentq(lambda x: float(np.prod(self.crossings(np.array([x]), f, polys).imag)),
                       th[i], th[i + 1], xtol=1e-15, rtol=4 * np.finfo(float).eps)  # 1e-15: angle
            ks = self.crossings(np.array([r]), f, polys)[0]
            k = ks[int(np.argmin(np.abs(ks.imag)))]
            # a sign change where a root passes infinity is no crossing
            if abs(k.imag) <= 1e-6 * max(1.0, abs(k)) and k_floor < k.real < best[0]:  # 1e-6:
                best = (float(k.real), float(r))                                     # rel. imag
        return best


def peb_fractional_plant(loop: Any, whole: int) -> PebFractionalPlant:
    """The :class:`PebFractionalPlant` of a PEB loop with ``whole`` samples of delay
    each way.

    Parameters
    ----------
    loop : TeleoperationLoop
        Spring-damper controllers, terminations without internal states, no rigid-body
        mode (the exact core's ball-arithmetic loops); its delay is replaced.
    whole : int
        n.

    Returns
    -------
    PebFractionalPlant

    Raises
    ------
    AnalysisError
        A loop outside this model, naming what.
    """
    from hapstab.engine.arb_loop import arb_parameters
    params = arb_parameters(loop.with_whole_delay(whole))
    if params is None or len(params["ports"]) != 2:
        raise AnalysisError("delay range with fractional delays for a teleoperator: covered "
                            "for spring-damper controllers, terminations without internal "
                            "states (spring, damper, mass, msd) and no rigid-body mode (the "
                            "exact core's ball-arithmetic loops)")
    T = params["period_s"]
    ports, signs = [], {}
    for i, (p, ch) in enumerate(zip(params["ports"], params["channels"], strict=True)):
        for j, s, _n in ch["terms"]:
            signs[(i, j)] = float(s)
        ports.append(FractionalPlant(p["mass_kg"] + p["termination_mass_kg"],
                                     p["damping_N_s_per_m"] + p["termination_damping_N_s_per_m"],
                                     p["termination_stiffness_N_per_m"],
                                     ch["damping_N_s_per_m"] / T, signs[(i, i)], T, int(whole)))
    return PebFractionalPlant((ports[0], ports[1]),
                              tuple(float(c["stiffness_ratio"]) for c in params["channels"]),  # type: ignore[arg-type]
                              signs[(0, 1)] * signs[(1, 0)])
