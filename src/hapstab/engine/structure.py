"""A loop as ports and channels: the one place where the loop kinds differ.

A loop is a set of *ports* (a device with the impedance rigidly attached to it)
and one discrete controller per port acting on a signed sum of delayed position
samples (``e_i = sum_j s_ij z^-n_ij x_j``).
"""

from __future__ import annotations

from dataclasses import dataclass

from hapstab.models.controllers import DiscreteController, SpringDamper
from hapstab.models.loops import HapticLoop, TeleoperationLoop, split_delay
from hapstab.models.parts import Device, Impedance

__all__ = ['Port', 'Channel', 'LoopStructure', 'structure_of', 'split_delay']


@dataclass(frozen=True)
class Port:
    """A device and the impedance rigidly attached to it."""

    device: Device
    termination: Impedance
    name: str


@dataclass(frozen=True)
class Channel:
    """The controller acting on one port: ``u_port = H(z) * sum_j sign_j z^-delay_j x_j``."""

    port: int
    controller: SpringDamper | DiscreteController
    terms: tuple[tuple[int, float, float], ...]  # (measured port j, sign, delay in samples)


@dataclass(frozen=True)
class LoopStructure:
    ports: tuple[Port, ...]
    channels: tuple[Channel, ...]


def structure_of(loop: HapticLoop | TeleoperationLoop) -> LoopStructure:
    """The HVE and PEB builders: both are a :class:`LoopStructure` for one engine."""
    if isinstance(loop, HapticLoop):
        return LoopStructure(
            (Port(loop.device, loop.operator, "device"),),
            (Channel(0, loop.controller, ((0, 1.0, loop.delay_in_samples),)),))
    if isinstance(loop, TeleoperationLoop):
        fwd, bwd = loop.forward_delay_in_samples, loop.backward_delay_in_samples
        return LoopStructure(
            (Port(loop.master, loop.operator, "master"), Port(loop.slave, loop.environment, "slave")),
            (Channel(0, loop.master_controller, ((0, 1.0, 0.0), (1, -1.0, bwd))),   # eq. (20)
             Channel(1, loop.slave_controller, ((1, 1.0, 0.0), (0, -1.0, fwd)))))
    raise TypeError(f"not a loop: {loop!r}")
