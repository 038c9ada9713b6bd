"""What a user describes: devices, impedances, controllers and loops. Frozen,
validated when built, SI units."""

from hapstab.models.controllers import (
    AffineController,
    Controller,
    DiscreteController,
    FilteredSpringDamper,
    SpringDamper,
    VelocityFilter,
)
from hapstab.models.fourchannel import FourChannelLoop
from hapstab.models.loops import (
                                  HapticLoop,
                                  Loop,
                                  TeleoperationLoop,
                                  delay_from_seconds,
                                  whole_delay,
)
from hapstab.models.operators import OperatorBox, operator_box
from hapstab.models.parts import (
                                  NO_IMPEDANCE,
                                  Device,
                                  Impedance,
                                  mass_spring_damper,
                                  parse_impedance,
                                  spring,
)

__all__ = ["Device", "Impedance", "NO_IMPEDANCE", "spring", "mass_spring_damper",
           "parse_impedance", "SpringDamper", "FilteredSpringDamper", "VelocityFilter",
           "AffineController", "DiscreteController", "Controller", "HapticLoop",
           "TeleoperationLoop", "FourChannelLoop", "Loop", "delay_from_seconds", "whole_delay",
           "OperatorBox", "operator_box"]
