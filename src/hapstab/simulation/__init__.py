"""Time-domain simulation, exact between samples, and the verdict on a run."""

from hapstab.simulation.growth import BoundednessVerdict
from hapstab.simulation.result import SimulationResult
from hapstab.simulation.run import (
                                    critical_stiffness_simulation,
                                    force_samples,
                                    propagate_linear,
                                    quantize,
                                    simulate,
)

__all__ = ["simulate", "SimulationResult", "BoundednessVerdict", "force_samples",
           "critical_stiffness_simulation", "propagate_linear", "quantize"]
