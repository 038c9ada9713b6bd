"""The HVE with a fractional delay as a modified z-transform, analytic in the fraction f.

**The model.** One port (device + operator, total mass M, damping b, spring k to
ground, state s = [x, v]), a zero-order hold on the actuator force -u, and the
controller u[k] = K e[k] + beta (e[k] - e[k-1]), beta = B/T, acting on the position
sampled between the instants: e[k] = s_e x(kT - (n + f)T), n whole, f in [0, 1]
(s_e the sign of the measurement, +1 for the HVE).

**Derivation.** With A, B_v the continuous plant and [Phi_t, Gamma_t; 0, 1] =
exp([A, B_v; 0, 0] t) (Phi_t = e^{At}, Gamma_t = int_0^t e^{As} ds B_v), the position
(1 - f)T after the instant kT is

    x((k + 1)T - fT) = C Phi_{(1-f)T} s[k] + C Gamma_{(1-f)T} (-u[k]),

so with s[k+1] = Phi_T s[k] + Gamma_T (-u[k]) and X_f(z) the z-transform of
x(kT - fT): z X_f = [c_f (zI - Phi_T)^-1 Gamma_T + g_f] (-U), c_f = C Phi_{(1-f)T},
g_f = C Gamma_{(1-f)T} (Jury's modified z-transform, with m = 1 - f). In y = z - 1,
E = Phi_T - I, d(y) = det(yI - E):

    X_f / (-U) = z^-1 Nt_f(y) / d(y),   Nt_f(y) = c_f adj(yI - E) Gamma_T + g_f d(y),

and, for a 2 x 2 plant, c adj(yI - E) Gamma = c_0 a_0(y) + c_1 a_1(y) with
a_0 = Gamma_0 y + E_01 Gamma_1 - E_11 Gamma_0, a_1 = Gamma_1 y + E_10 Gamma_0 - E_00 Gamma_1.
The closed loop's characteristic function, with H(z) = K + beta (1 - z^-1), is

    det M(z, K, f) = d(y) + s_e z^-(n+1) Nt_f(y) H(z),

and chi(z) = z^(n+2) det M = z^(n+2) d + s_e Nt_f (K z + beta (z - 1)) is monic of
degree n + 4 for every f in [0, 1]: its roots are the closed-loop poles (the engine's
state: plant 2, controller 1, the fractional state x(kT - fT) and its n registers),
continuous in (K, f). At f = 0, Nt_0 = z N (N = C adj(yI - E) Gamma_T: whole delay n,
and a pole at z = 0); at f = 1, Nt_1 = N (whole delay n + 1).

K enters linearly, so the loop has a pole on the unit circle at z = e^{j theta} for
the real K = G(theta, f) only, where

    G(theta, f) = -s_e z^(n+1) d(y) / Nt_f(y) - beta (1 - z^-1)

is real. The coefficients c_f, g_f are entire in f, with d/df [c_f, g_f] = -T [row 1
of exp([A, B_v; 0, 0](1 - f)T)] (the velocity row: d/dt of the position row).

References
----------
E. I. Jury, *Theory and Application of the z-Transform Method*, Wiley 1964, ch. 2
(the modified z-transform); K. J. Astrom and B. Wittenmark, *Computer-Controlled
Systems*, 3rd ed., sec. 2.3 (ZOH sampling) and sec. 2.7 / 7.7 (a delay that is not a
multiple of the period: the modified z-transform).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.errors import AnalysisError

__all__ = ["FractionalPlant", "fractional_plant", "full_period"]


@dataclass(frozen=True)
class FractionalPlant:
    """The numbers of an HVE with a fractional delay (module docstring).

    Parameters
    ----------
    mass_kg, damping_N_s_per_m, stiffness_N_per_m : float
        M, b, k: the port's totals (device + operator).
    beta_N_per_m : float
        beta = B / T, the controller's virtual damping over the period.
    sign : float
        s_e, the sign of the measured position.
    period_s : float
        T.
    whole : int
        n, the whole samples of delay.
    """

    mass_kg: float
    damping_N_s_per_m: float
    stiffness_N_per_m: float
    beta_N_per_m: float
    sign: float
    period_s: float
    whole: int

    def aug(self, t: float) -> np.ndarray:
        """[A, B_v; 0, 0] t (3 x 3), the matrix whose exponential is [Phi_t, Gamma_t; 0, 1]."""
        M, b, k = self.mass_kg, self.damping_N_s_per_m, self.stiffness_N_per_m
        return np.array([[0.0, t, 0.0], [-k / M * t, -b / M * t, t / M], [0.0, 0.0, 0.0]])

    def coefficients(self, f: float) -> tuple[np.ndarray, np.ndarray]:
        """(d, Nt_f): ascending coefficients in y = z - 1 (doubles, for the float
        search and the point checks; the proof uses balls)."""
        from hapstab.engine.zoh import expm_batched
        d, a0, a1 = full_period(self)
        Xf = expm_batched(self.aug((1.0 - f) * self.period_s)[None])[0]
        return d, Xf[0, 0] * a0 + Xf[0, 1] * a1 + Xf[0, 2] * d

    def gain(self, theta: np.ndarray, f: float) -> np.ndarray:
        """G(theta, f) (module docstring) at each angle of ``theta`` (rad/sample)."""
        return self._gain(self.coefficients(f), theta)

    def _gain(self, coef: tuple[np.ndarray, np.ndarray], theta: np.ndarray) -> np.ndarray:
        """G at the angles from the coefficients (d, Nt_f) of one fraction."""
        d, nt = coef
        th = np.asarray(theta, float)
        z, y = np.exp(1j * th), np.expm1(1j * th)
        with np.errstate(all="ignore"):
            return (-self.sign * z ** (self.whole + 1) * np.polyval(d[::-1], y)
                    / np.polyval(nt[::-1], y) - self.beta_N_per_m * (1.0 - 1.0 / z))

    def char_poly(self, K: float, f: float) -> np.ndarray:
        """chi(z) = z^(n+2) d + s_e Nt_f (K z + beta (z - 1)), descending coefficients in z."""
        d, nt = self.coefficients(f)
        shift = np.poly1d([1.0, -1.0])                   # y = z - 1
        dz = np.polyval(np.poly1d(d[::-1]), shift)
        ntz = np.polyval(np.poly1d(nt[::-1]), shift)
        head = np.poly1d(dz) * np.poly1d([1.0] + [0.0] * (self.whole + 2))
        tail = self.sign * ntz * np.poly1d([K + self.beta_N_per_m, -self.beta_N_per_m])
        return np.asarray((head + tail).coeffs)

    def balls(self) -> Any:
        """The ball evaluator of this model (:class:`~hapstab.analysis.network.frac_balls.FractionBalls`)."""
        from hapstab.analysis.network.frac_balls import FractionBalls
        return FractionBalls(self)

    def first_crossing(self, f: float, k_floor: float, points: int | None = None) -> tuple[float, float]:
        """The smallest K > ``k_floor`` at which a pole lies on the unit circle, and its
        angle (doubles: the float search that proposes the worst fraction; nothing proved).

        Parameters
        ----------
        f : float
            The fraction.
        k_floor : float
            Crossings at or below it are ignored (the base point K_0).
        points : int, optional
            Angles of the scan of [0, pi] (default 64 (n + 1), at least 2049).

        Returns
        -------
        (K, theta) : (float, float)
            (inf, nan) when none.
        """
        from scipy.optimize import brentq
        m = points or max(2049, 64 * (self.whole + 1))
        th = np.linspace(0.0, math.pi, m)
        coef = self.coefficients(f)
        G = self._gain(coef, th)
        best = (math.inf, math.nan)
        for t in (0, m - 1):                      # z = 1 and z = -1: G is real there
            if np.isfinite(G[t]) and k_floor < G[t].real < best[0]:
                best = (float(G[t].real), float(th[t]))
        im, re = G.imag, G.real
        brackets = np.flatnonzero((np.sign(im[:-1]) * np.sign(im[1:]) < 0)
                                  & np.isfinite(im[:-1]) & np.isfinite(im[1:]))
        # Re G within a bracket stays near its ends: the lowest first, and none that
        # cannot beat the best
        spread = np.abs(np.diff(re)[brackets])
        low = np.minimum(re[brackets], re[brackets + 1]) - spread
        high = np.maximum(re[brackets], re[brackets + 1]) + spread
        for i in brackets[np.argsort(low)][high[np.argsort(low)] > k_floor]:
            if min(re[i], re[i + 1]) - abs(re[i] - re[i + 1]) >= best[0]:
                break
            r = brentq(lambda x: float(self._gain(coef, np.array([x]))[0].imag), th[i], th[i + 1],
                       xtol=1e-15, rtol=4 * np.finfo(float).eps)   # 1e-15: the angle to rounding
            g = complex(self._gain(coef, np.array([r]))[0])
            # a sign change through a pole of G (Nt_f = 0) is no crossing
            if abs(g.imag) <= 1e-6 * max(1.0, abs(g)) and k_floor < g.real < best[0]:  # 1e-6: root's
                best = (g.real, float(r))                                            # imag, relative
        return best


@functools.lru_cache(maxsize=256)
def full_period(plant: FractionalPlant) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(d, a_0, a_1) of the module docstring, ascending in y, from the ZOH over T."""
    from hapstab.engine.zoh import expm_batched
    X = expm_batched(plant.aug(plant.period_s)[None])[0]
    E, g = X[:2, :2] - np.eye(2), X[:2, 2]
    d = np.array([E[0, 0] * E[1, 1] - E[0, 1] * E[1, 0], -(E[0, 0] + E[1, 1]), 1.0])
    a0 = np.array([E[0, 1] * g[1] - E[1, 1] * g[0], g[0], 0.0])
    a1 = np.array([E[1, 0] * g[0] - E[0, 0] * g[1], g[1], 0.0])
    return d, a0, a1


def fractional_plant(loop: Any, whole: int) -> FractionalPlant:
    """The :class:`FractionalPlant` of an HVE loop with ``whole`` samples of delay.

    Parameters
    ----------
    loop : HapticLoop
        Device, operator (a spring, damper, mass or mass-spring-damper: no internal
        states), a :class:`~hapstab.models.controllers.SpringDamper`; its delay is
        replaced.
    whole : int
        n.

    Returns
    -------
    FractionalPlant

    Raises
    ------
    AnalysisError
        A loop outside this model, naming what.
    """
    from hapstab.engine.arb_loop import arb_parameters
    if tuple(getattr(loop, "port_names", ())) != ("device",):
        raise AnalysisError(f"loop kind = {getattr(loop, 'kind', type(loop).__name__)!r}: the "
                            "fractional delay range is modelled for the hve loop (one port) "
                            "and for peb (two ports, the same delay both ways)")
    params = arb_parameters(loop.with_whole_delay(whole))
    if params is None:
        raise AnalysisError("delay range with fractional delays: covered for a spring-damper "
                            "controller and an operator without internal states (spring, "
                            "damper, mass, msd), the exact core's ball-arithmetic loops")
    p, ch = params["ports"][0], params["channels"][0]
    (_j, s, _n), = ch["terms"]
    T = params["period_s"]
    return FractionalPlant(p["mass_kg"] + p["termination_mass_kg"],
                           p["damping_N_s_per_m"] + p["termination_damping_N_s_per_m"],
                           p["termination_stiffness_N_per_m"], ch["damping_N_s_per_m"] / T,
                           float(s), T, int(whole))
