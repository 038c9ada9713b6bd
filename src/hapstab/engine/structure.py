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
    """A device and the impedance rigidly attached to it.

    Parameters
    ----------
    device : Device
        The robot at this port (mass in kg, damping in N*s/m).
    termination : Impedance
        The operator or environment Z(s) attached to it (:data:`NO_IMPEDANCE` if none).
    name : str
        Its label in results and columns (``"device"``, ``"master"``, ``"slave"``).
    """

    device: Device
    termination: Impedance
    name: str


@dataclass(frozen=True)
class Channel:
    """The controller acting on one port: ``u_port = H(z) * sum_j sign_j z^-delay_j x_j``.

    Parameters
    ----------
    port : int
        Index of the port the force acts on.
    controller : SpringDamper or DiscreteController
        H(z).
    terms : tuple of (int, float, float)
        ``(j, sign_j, delay_j)``: the measured port, its sign and its delay in samples
        (may be fractional).
    """

    port: int
    controller: SpringDamper | DiscreteController
    terms: tuple[tuple[int, float, float], ...]  # (measured port j, sign, delay in samples)


@dataclass(frozen=True)
class LoopStructure:
    """A loop as the engine sees it: ports and one controller channel per port.

    Parameters
    ----------
    ports : tuple of Port
        The devices with their terminations.
    channels : tuple of Channel
        The controllers and what each one measures.
    """

    ports: tuple[Port, ...]
    channels: tuple[Channel, ...]


def structure_of(loop: HapticLoop | TeleoperationLoop) -> LoopStructure:
    """The HVE and PEB builders: both are a :class:`LoopStructure` for one engine.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop to describe.

    Returns
    -------
    LoopStructure
        One port for a haptic loop (``device``), two for a teleoperator (``master``,
        ``slave``, with eq. (20)'s channels).

    Raises
    ------
    TypeError
        If ``loop`` is neither kind.
    """
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
