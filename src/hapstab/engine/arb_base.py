"""The base point K_0 standing for K -> 0+ of the certified core, from a loop's numbers
alone (:func:`base_point`): the proof counts the poles there and proves stability on
[K_0, K_max]; a certificate's K_0 is re-derived with it
(:mod:`hapstab.analysis.verify`). Re-exported by :mod:`~hapstab.engine.arb_loop`.
Also one port's ZOH in balls (:class:`PortZoh`), the one builder of the ports of the
whole-delay and the fractional-delay characteristic functions.

References
----------
K. J. Astrom and B. Wittenmark, *Computer-Controlled Systems*, 3rd ed., sec. 2.3 (the
sampled plant's scales m/T^2 and b/T).
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["base_point", "k_scale", "damping_scale", "BASE_RATIO", "NEGLIGIBLE_DAMPING",
           "PortZoh"]

#: The base point K_0 standing for K -> 0+, relative to the loop's K scale (the
#: smaller of m/T^2 and b/T): the float search's lower end U_LO
#: (:mod:`hapstab.analysis.exact.boxes`, the same number; a test pins it). What holds
#: for K in (0, K_0) is not proved.
BASE_RATIO = 1e-14


def k_scale(params: dict[str, Any]) -> float:
    """The loop's K scale (N/m): the power of two nearest min M / T^2 over the ports
    (M = device + termination mass), as :mod:`hapstab.engine.frequency` takes it."""
    import numpy as np
    T = params["period_s"]
    masses = [p["mass_kg"] + p["termination_mass_kg"] for p in params["ports"]]
    with np.errstate(all="ignore"):     # a scale beyond doubles is inf: no K_0 matches it
        return float(2.0 ** np.round(np.log2(np.float64(min(masses)) / np.float64(T) ** 2)))


#: A damping below this fraction of the total damping at its port does not set the
#: damping scale: it is within double rounding of the sum it enters (b + B = b to the
#: last bit; 2^-52), so it cannot move K_max's scale (2 (b + B)/T in the heavy
#: limit), while a K_0 it set (1e-14 |B|/T, e.g. 1e-182 N/m for |B| = 1e-168) puts
#: the poles near z = 1 closer to the circle than the proof's pieces resolve.
NEGLIGIBLE_DAMPING = 2.0 ** -52


def damping_scale(params: dict[str, Any]) -> float:
    """The smallest positive b/T or |B|/T of the loop (N/m; inf if none), leaving out a
    damping negligible at its port (:data:`NEGLIGIBLE_DAMPING`; channel i acts on port
    i): with m/T^2 it sets the base point K_0 standing for K -> 0+, so that a heavy
    device (m/T^2 far above the stiffness its damping allows, K_max ~ 2 b/T) is not
    examined from a K_0 above its K_max."""
    T = params["period_s"]
    own = [p["damping_N_s_per_m"] + p["termination_damping_N_s_per_m"] for p in params["ports"]]
    chan = [abs(c["damping_N_s_per_m"]) for c in params["channels"]]
    # the total damping at each port: its device and termination, and its channel's |B|
    total = [abs(b) + (chan[i] if i < len(chan) else 0.0) for i, b in enumerate(own)]
    vals = [(v, total[i]) for i, v in enumerate(own)]
    vals += [(v, total[i] if i < len(total) else v) for i, v in enumerate(chan)]
    pos = [v / T for v, tot in vals if v > 0 and v >= NEGLIGIBLE_DAMPING * tot]
    return min(pos) if pos else math.inf


def base_point(params: dict[str, Any]) -> float:
    """The base point K_0 (N/m) standing for K -> 0+, from the loop's numbers alone:
    :data:`BASE_RATIO` times the smaller of :func:`k_scale` and :func:`damping_scale`.
    The proof counts the poles there and proves stability on [K_0, K_max]; a
    certificate's K_0 is re-derived with this (:mod:`hapstab.analysis.verify`)."""
    return BASE_RATIO * min(k_scale(params), damping_scale(params))


class PortZoh:
    """One port's ZOH in balls (:mod:`~hapstab.engine.arb_loop`'s docstring): the mass
    M, damping b and spring k of the device with its termination, ``aug(t) =
    exp([A, B; 0, 0] t)`` by ``arb_mat.exp`` (rigorous), and over one period T,
    ``E = Phi - I``, ``Gamma`` and ``d(y) = det(yI - E)`` (arb_poly in ``y = z - 1``).
    The one builder of a port for :class:`~hapstab.engine.arb_loop.ArbLoop` (whole
    delays) and :mod:`~hapstab.engine.arb_fraction` (fractional ones), at the
    precision in force.

    Parameters
    ----------
    p : dict
        A port of :func:`~hapstab.engine.arb_loop.arb_parameters`.
    T : arb
        The period, s.
    """

    def __init__(self, p: dict[str, Any], T: Any) -> None:
        import flint
        arb, arb_mat = flint.arb, flint.arb_mat
        self.M = arb(p["mass_kg"]) + arb(p["termination_mass_kg"])
        self.b = arb(p["damping_N_s_per_m"]) + arb(p["termination_damping_N_s_per_m"])
        self.k = arb(p["termination_stiffness_N_per_m"])
        X = self.aug(T)
        self.E = arb_mat([[X[0, 0] - 1, X[0, 1]], [X[1, 0], X[1, 1] - 1]])
        self.G = (X[0, 2], X[1, 2])
        self.d = self.E.charpoly()

    def aug(self, t: Any) -> Any:
        """``exp([A, B; 0, 0] t)`` (arb_mat) for ``t`` seconds (arb)."""
        import flint
        M, b, k = self.M, self.b, self.k
        return flint.arb_mat([[0, t, 0], [-k / M * t, -b / M * t, t / M], [0, 0, 0]]).exp()

    def numerator(self, row: tuple[Any, Any] | None = None) -> Any:
        """``c adj(yI - E) Gamma = det(yI - E + Gamma c) - d(y)`` (the matrix
        determinant lemma) for the output row ``c = row`` (two arb); None: the position,
        ``c = (1, 0)``, N(y), written out (``E - Gamma c`` without multiplying by 1 and
        0: Arb would round the radius of ``Gamma * 1`` up by an ulp)."""
        import flint
        E, G = self.E, self.G
        if row is None:
            EG = flint.arb_mat([[E[0, 0] - G[0], E[0, 1]], [E[1, 0] - G[1], E[1, 1]]])
        else:
            c0, c1 = row
            EG = flint.arb_mat([[E[0, 0] - G[0] * c0, E[0, 1] - G[0] * c1],
                                [E[1, 0] - G[1] * c0, E[1, 1] - G[1] * c1]])
        return EG.charpoly() - self.d
