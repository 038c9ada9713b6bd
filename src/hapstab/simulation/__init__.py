"""Time-domain simulation, exact between samples, and the verdict on a run."""

from hapstab.simulation.growth import BoundednessVerdict
from hapstab.simulation.inputs import force_samples
from hapstab.simulation.network import Network, from_ages
from hapstab.simulation.network_trace import NetworkTraceError, read_trace
from hapstab.simulation.propagate import propagate_linear
from hapstab.simulation.result import SimulationResult
from hapstab.simulation.run import quantize, simulate
from hapstab.simulation.search import critical_stiffness_simulation
from hapstab.simulation.tdpa import TDPA

__all__ = ["simulate", "SimulationResult", "BoundednessVerdict", "force_samples",
           "critical_stiffness_simulation", "propagate_linear", "quantize", "TDPA", "Network",
           "NetworkTraceError", "read_trace", "from_ages"]
