"""One exact model of any loop: its structure (ports and channels), the exact
zero-order-hold discretisation, the closed loop at the sampling instants
(:mod:`~hapstab.engine.system`) and its frequency response on the unit circle
(:mod:`~hapstab.engine.frequency`)."""

from hapstab.engine.structure import (
           Channel,
           LoopStructure,
           Port,
           split_delay,
           structure_of,
)
from hapstab.engine.system import SampledSystem, build
from hapstab.engine.zoh import discretize, expm_batched, port_matrices

__all__ = ["Port", "Channel", "LoopStructure", "structure_of", "split_delay", "port_matrices",
           "expm_batched", "discretize", "SampledSystem", "build"]
