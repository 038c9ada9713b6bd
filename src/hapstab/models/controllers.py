"""The discrete controllers: the spring-damper of eq. (23) and any H(z).

References
----------
N. Miandashti and M. Tavakoli, "Stability of Sampled-Data, Delayed Haptic
Interaction and Teleoperation", IEEE Haptics Symposium 2014 (the paper).
Equation and figure numbers below are the paper's.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.errors import ModelError, check_real
from hapstab.models.parts import _poly

__all__ = ['SpringDamper', 'DiscreteController', 'Controller', 'spring_damper', 'stiffness_ratios']


# ----------------------------------------------------------------------- controllers
@dataclass(frozen=True)
class SpringDamper:
    """Virtual spring-damper H(z) = K + B (z - 1) / (T z)  (eq. 23).

    Parameters
    ----------
    stiffness : float
        K in N/m, >= 0 (default 0: for ``critical_stiffness``, which varies K, only B
        matters, ``SpringDamper(damping=B)``).
    damping : float
        Virtual damping B in N*s/m (backward difference): any finite real.
        B < 0 is used in practice to cancel a device's own damping or friction;
        it subtracts from the device's damping (Colgate-Schenkel's passivity
        condition is b > KT/2 + |B|), and with |B| large enough the loop is
        unstable for every K > 0, which the analyses report with a reason.

    Raises
    ------
    ModelError
        If K is negative or not finite, or B is not finite.
    """

    stiffness: float = 0.0
    damping: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "stiffness", check_real("stiffness", self.stiffness, nonnegative=True))
        object.__setattr__(self, "damping", check_real("virtual damping", self.damping))

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        """(num, den) of H(z) in z, highest power first."""
        K, B, T = self.stiffness, self.damping, period
        return np.array([K * T + B, -B]) / T, np.array([1.0, 0.0])

    def with_stiffness(self, K: float) -> SpringDamper:
        return dataclasses.replace(self, stiffness=K)

    def to_dict(self) -> dict[str, Any]:
        """The controller as JSON-ready values, units in the keys."""
        return {"type": "spring-damper", "stiffness_N_per_m": self.stiffness,
                "virtual_damping_N_s_per_m": self.damping}


@dataclass(frozen=True)
class DiscreteController:
    """Any proper discrete transfer function H(z) = num(z)/den(z) (highest power first).
    It has no stiffness parameter, so :func:`critical_stiffness` does not apply.

    Parameters
    ----------
    num : sequence of float
        Numerator coefficients in z, highest power first; force in N per m of input.
    den : sequence of float
        Denominator coefficients in z, highest power first, not all zero; the degree
        of ``num`` must not exceed that of ``den`` (proper).

    Raises
    ------
    ModelError
        If a coefficient is not finite, the denominator is zero or H is improper.
    """

    num: tuple[float, ...]
    den: tuple[float, ...]

    def __post_init__(self) -> None:
        num, den = _poly("controller numerator", self.num), _poly("controller denominator", self.den)
        if not np.any(den):
            raise ModelError(f"controller denominator = {list(self.den)}: must not be zero")
        if num.size > den.size:
            raise ModelError(
                f"controller = ({list(self.num)})/({list(self.den)}): must be proper "
                "(numerator degree <= denominator degree)")
        object.__setattr__(self, "num", tuple(map(float, num)))
        object.__setattr__(self, "den", tuple(map(float, den)))

    def to_dict(self) -> dict[str, Any]:
        """The controller as JSON-ready values: H(z) = num/den, highest power first."""
        return {"type": "discrete", "num": list(self.num), "den": list(self.den)}

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.num), np.array(self.den)


Controller = SpringDamper | DiscreteController


def spring_damper(controller: Controller, name: str = "controller") -> SpringDamper:
    """``controller`` itself if it is a :class:`SpringDamper` (the only controller with a
    stiffness K to vary).

    Parameters
    ----------
    controller : SpringDamper or DiscreteController
        The controller to vary K of.
    name : str
        Its name in the error message (``"controller"``, ``"master_controller"``, ...).

    Raises
    ------
    ModelError
        If it is not a :class:`SpringDamper`.
    """
    if not isinstance(controller, SpringDamper):
        raise ModelError(f"{name}: a SpringDamper is needed to vary the stiffness")
    return controller


def stiffness_ratios(stiffnesses: Sequence[float]) -> tuple[float, ...] | None:
    """The one K_s/K_m convention: each controller's stiffness per unit K.

    K is the first controller's (the master's) stiffness; every other controller
    keeps its ratio to it, so equal stiffnesses (the paper's C_m = C_s) stay equal.
    Every loop builder, the engine and the frequency-domain analyses vary K by this
    rule and by no other.

    Parameters
    ----------
    stiffnesses : sequence of float
        The controllers' stiffnesses in N/m, first the one that K names.

    Returns
    -------
    tuple of float or None
        ``k_i`` with ``k_0 = 1`` (all ones when every stiffness is 0); ``None`` when
        the ratio is undefined: the first stiffness is 0 and another is not.
    """
    ks = [float(k) for k in stiffnesses]
    if ks[0] > 0:
        return tuple(k / ks[0] for k in ks)
    return None if any(k > 0 for k in ks) else tuple(1.0 for _ in ks)
