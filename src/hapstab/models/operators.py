"""An uncertain operator: a box of mass-spring-damper hands, Z = m s + b + k/s with
m, b and k each in a range (or fixed), and presets from published measurements.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.errors import ModelError, check_real, ordered_pair
from hapstab.models.parts import mass_spring_damper

__all__ = ["OperatorBox", "operator_box", "PRESETS"]

_UNITS = {"mass": "kg", "damping": "N*s/m", "stiffness": "N/m"}


@dataclass(frozen=True)
class OperatorBox:
    """Every operator Z(s) = m s + b + k/s with (m, b, k) in a box.

    Parameters
    ----------
    mass : (float, float)
        Operator mass range in kg (lo <= hi, both >= 0); equal ends fix it.
    damping : (float, float)
        Operator damping range in N*s/m (>= 0).
    stiffness : (float, float)
        Operator stiffness range in N/m (>= 0).
    label : str
        What the box describes (a preset's name, or ``"custom"``).
    source : str
        Where the ranges come from (a citation for a preset).
    """

    mass: tuple[float, float]
    damping: tuple[float, float]
    stiffness: tuple[float, float]
    label: str = "custom"
    source: str = ""

    def __post_init__(self) -> None:
        for name in ("mass", "damping", "stiffness"):
            object.__setattr__(self, name, _range(f"operator {name}", getattr(self, name),
                                                  _UNITS[name]))

    @property
    def lo(self) -> np.ndarray:
        """The lower corner (m, b, k)."""
        return np.array([self.mass[0], self.damping[0], self.stiffness[0]])

    @property
    def hi(self) -> np.ndarray:
        """The upper corner (m, b, k)."""
        return np.array([self.mass[1], self.damping[1], self.stiffness[1]])

    @property
    def varying(self) -> tuple[str, ...]:
        """The names of the parameters with a range."""
        return tuple(n for n, a, b in zip(("mass", "damping", "stiffness"), self.lo, self.hi,
                                          strict=True) if b > a)

    def operator(self, mass: float, damping: float, stiffness: float) -> Any:
        """The impedance of one operator of the box (checked to lie in it).

        Parameters
        ----------
        mass, damping, stiffness : float
            kg, N*s/m, N/m.

        Returns
        -------
        Impedance
            m s + b + k/s.

        Raises
        ------
        ModelError
            A value outside the box.
        """
        p = np.array([mass, damping, stiffness], float)
        if np.any(p < self.lo) or np.any(p > self.hi):
            raise ModelError(f"operator (m, b, k) = {tuple(p.tolist())}: outside the box "
                             f"{self.describe()}")
        return mass_spring_damper(*p)

    def describe(self) -> str:
        """The box in words, with units."""
        parts = []
        for name in ("mass", "damping", "stiffness"):
            a, b = getattr(self, name)
            parts.append(f"{name} {a:g}" + (f"..{b:g}" if b > a else "") + f" {_UNITS[name]}")
        return ", ".join(parts)

    def to_dict(self) -> dict[str, Any]:
        """The box as JSON-ready values (units in the keys)."""
        return {"label": self.label, "mass_kg": list(self.mass),
                "damping_N_s_per_m": list(self.damping), "stiffness_N_per_m": list(self.stiffness),
                "source": self.source}


def _range(name: str, value: Any, unit: str) -> tuple[float, float]:
    """A (lo, hi) pair of finite numbers >= 0 (a single number fixes it)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = (value, value)
    try:
        lo, hi = ordered_pair(value)
    except (TypeError, ValueError):
        raise ModelError(f"{name} = {value!r:.60}: must be a (lo, hi) pair or one number "
                         f"in {unit}") from None
    lo = check_real(f"{name} (lower end)", lo, nonnegative=True)
    hi = check_real(f"{name} (upper end)", hi, nonnegative=True)
    if hi < lo:
        raise ModelError(f"{name} = ({lo:g}, {hi:g}) {unit}: the lower end must not exceed the "
                         "upper end")
    return (lo, hi)


#: The published measurement behind ``arm-grasp`` (see :func:`operator_box`).
VAN_BEEK_2015 = (
    "F. E. van Beek, W. M. Bergmann Tiest, W. Mugge and A. M. L. Kappers, 'Haptic "
    "perception of force magnitude and its relation to postural arm dynamics in 3D', "
    "Sci. Rep. 5, 18004 (2015), doi:10.1038/srep18004, Fig. 3: a mass-damper-spring fit "
    "to the arm of a participant holding the handle of a HapticMaster under stochastic "
    "position perturbations gave M = 0.554 kg, B = 6.45 N s/m, K = 135 N/m (one trial; "
    "the paper reports that the parameters vary with direction and participant). The "
    "preset spans a factor of 2 either side of that trial: hapstab's choice, not a "
    "published range")

#: Presets: name -> (mass, damping, stiffness ranges, citation).
PRESETS: dict[str, tuple[tuple[float, float], tuple[float, float], tuple[float, float], str]] = {
    "arm-grasp": ((0.554 / 2, 0.554 * 2), (6.45 / 2, 6.45 * 2), (135.0 / 2, 135.0 * 2),
                  VAN_BEEK_2015),
}


def operator_box(name: str | None = None, *, mass: Any = None, damping: Any = None,
                 stiffness: Any = None) -> OperatorBox:
    """A box of operators: a preset by name, or ranges (a preset's ranges may be
    overridden one by one).

    Parameters
    ----------
    name : str, optional
        A preset (see :data:`PRESETS` and the References).
    mass, damping, stiffness : (float, float) or float, optional
        Ranges in kg, N*s/m, N/m; required without a preset.

    Returns
    -------
    OperatorBox

    Raises
    ------
    ModelError
        An unknown preset, a missing or malformed range.

    Notes
    -----
    ``"arm-grasp"``: mass 0.277..1.108 kg, damping 3.225..12.9 N*s/m, stiffness
    67.5..270 N/m, a factor of 2 either side of a published fit of an arm holding a
    haptic handle (van Beek et al. 2015, below). That fit is one trial of one
    participant (M = 0.554 kg, B = 6.45 N s/m, K = 135 N/m); the factor of 2 is
    hapstab's choice to cover directions and people, not a published range. Give
    your own ranges where you have measurements of your users.

    References
    ----------
    F. E. van Beek, W. M. Bergmann Tiest, W. Mugge and A. M. L. Kappers, "Haptic
    perception of force magnitude and its relation to postural arm dynamics in 3D",
    Sci. Rep. 5, 18004 (2015), doi:10.1038/srep18004, Fig. 3 (caption: "For this
    trial, the model yielded the following values: M = 0.554 kg, B = 6.45 Ns/m,
    K = 135 N/m").
    """
    if name is not None:
        if name not in PRESETS:
            raise ModelError(f"operator box = {name!r}: unknown preset; allowed: "
                             f"{', '.join(sorted(PRESETS))}")
        m, b, k, src = PRESETS[name]
        return OperatorBox(m if mass is None else mass, b if damping is None else damping,
                           k if stiffness is None else stiffness,
                           name if mass is None and damping is None and stiffness is None
                           else f"{name} (modified)", src)
    missing = [n for n, v in (("mass", mass), ("damping", damping), ("stiffness", stiffness))
               if v is None]
    if missing:
        raise ModelError(f"operator box: {', '.join(missing)} not given; give a range for each "
                         "of mass, damping and stiffness (or a preset name)")
    return OperatorBox(mass, damping, stiffness)
