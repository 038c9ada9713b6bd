"""A loop as ports and channels: the one place where the loop kinds differ.

A loop is a set of *ports* (a device with the impedance rigidly attached to it)
and one discrete controller per port acting on a signed sum of delayed position
samples (``e_i = sum_j s_ij z^-n_ij x_j``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np

from hapstab.errors import PERIOD_RANGE, ModelError, check_period
from hapstab.models.controllers import (
    Controller,
    DiscreteController,
    has_stiffness,
    stiffness_ratios,
)
from hapstab.models.fourchannel import FourChannelLoop
from hapstab.models.loops import HapticLoop, TeleoperationLoop, require_loop, split_delay
from hapstab.models.parts import Device, Impedance

__all__ = ['Port', 'Channel', 'LoopStructure', 'structure_of', 'split_delay', 'port_is_free',
           'periods_of',
           'rigid_modes', 'FREE_SPRING', 'channel_ratios', 'position_gains', 'own_stiffness']


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
    controller : SpringDamper, FilteredSpringDamper or DiscreteController
        H(z).
    terms : tuple of (int, float, float)
        ``(j, sign_j, delay_j)``: the measured port, its sign and its delay in samples
        (may be fractional for positions).
    measures : {"position", "force"}
        What the terms sample: the ports' positions, or the force each port's
        termination applies to its device just before the sample (kT^-; whole delays).
        A port may have several channels; their forces add.
    """

    port: int
    controller: Controller
    terms: tuple[tuple[int, float, float], ...]  # (measured port j, sign, delay in samples)
    measures: str = "position"


@dataclass(frozen=True)
class LoopStructure:
    """A loop as the engine sees it: ports and one controller channel per port.

    Parameters
    ----------
    ports : tuple of Port
        The devices with their terminations.
    channels : tuple of Channel
        The controllers and what each one measures.
    reference : int
        The position channel whose stiffness K names (:func:`channel_ratios`).
    """

    ports: tuple[Port, ...]
    channels: tuple[Channel, ...]
    reference: int = 0

    @property
    def simple(self) -> bool:
        """One position channel per port, channel i on port i (the HVE and PEB)."""
        return all(ch.port == i and ch.measures == "position"
                   for i, ch in enumerate(self.channels)) and \
            len(self.channels) == len(self.ports)


#: A spring to ground with k T^2 / m below this moves the port's pole at z = 1 by
#: less than double precision can see (about sqrt(1e-20) = 1e-10 in angle, on
#: numbers near 1): the port counts as free and the spring is dropped.
FREE_SPRING = 1e-20


def port_is_free(port: Port, period_s: float) -> bool:
    """Whether nothing ties the port to ground at this sampling period.

    Parameters
    ----------
    port : Port
        The device and its termination.
    period_s : float
        The (largest) sampling period in s.

    Returns
    -------
    bool
        ``k T^2 / m < FREE_SPRING`` for the termination's spring k and the port's mass m.
    """
    mass = port.device.mass + port.termination.mass
    return bool(port.termination.stiffness * float(period_s) ** 2 / mass < FREE_SPRING)


def channel_ratios(structure: LoopStructure) -> tuple[float, ...] | None:
    """Each channel's stiffness per unit K: the one rule by which every analysis varies K.

    K is the stiffness of the reference channel (``structure.reference``); every other
    position channel keeps its stiffness ratio to it
    (:func:`~hapstab.models.controllers.stiffness_ratios`); force channels have none (0).

    Parameters
    ----------
    structure : LoopStructure
        The loop.

    Returns
    -------
    tuple of float or None
        One ratio per channel; ``None`` when K cannot be varied: a position channel is
        not a :class:`SpringDamper`, or the reference stiffness is 0 while another is not.
    """
    chs = structure.channels
    pos = [i for i, ch in enumerate(chs) if ch.measures == "position"]
    if not all(has_stiffness(chs[i].controller) for i in pos):
        return None
    order = [structure.reference] + [i for i in pos if i != structure.reference]
    ratios = stiffness_ratios([chs[i].controller.stiffness for i in order])  # type: ignore[union-attr]
    if ratios is None:
        return None
    out = [0.0] * len(chs)
    for i, r in zip(order, ratios, strict=True):
        out[i] = r
    return tuple(out)


def own_stiffness(structure: LoopStructure) -> float:
    """The loop's own K: the stiffness of its reference channel (N/m).

    Parameters
    ----------
    structure : LoopStructure
        The loop, with spring-damper position controllers.

    Returns
    -------
    float

    Raises
    ------
    ModelError
        The reference controller is not a :class:`SpringDamper`.
    """
    c = structure.channels[structure.reference].controller
    if not has_stiffness(c):
        raise ModelError("controller: a SpringDamper is needed to vary the stiffness")
    return c.stiffness


def position_gains(structure: LoopStructure) -> np.ndarray:
    """``S_ij``: the constant-displacement gain of port i's controllers on port j's
    position per unit K, as the exact core forms it (the rigid-body rule's matrix).

    For the HVE and PEB (one channel per port) the signs alone: a channel's stiffness
    scales its whole row, which leaves the null space alone. With several channels per
    port each sign is weighted by its channel's stiffness ratio (a damper-only channel
    exerts no force at a constant displacement); force channels measure nothing there.
    """
    p = len(structure.ports)
    ratios = None if structure.simple else channel_ratios(structure)
    S = np.zeros((p, p))
    for c, ch in enumerate(structure.channels):
        if ch.measures != "position":
            continue
        for j, sign, _ in ch.terms:
            S[ch.port, j] += sign if ratios is None else ratios[c] * sign
    return S


def rigid_modes(structure: LoopStructure, period_s: float) -> int:
    """The rigid-body rule (its one definition): the modes at z = 1 that no controller
    moves. A constant displacement x of the ports with no spring to ground that gives
    every controller a zero force (``S x = 0``, :func:`position_gains`) is an
    equilibrium for every K: a common translation of PEB's free master and slave
    (x = [1, 1]), or x = [1, alpha] with position scaling alpha.

    Parameters
    ----------
    structure : LoopStructure
        The loop.
    period_s : float
        The (largest) sampling period in s (see :func:`port_is_free`).

    Returns
    -------
    int
        The dimension of that set of displacements (0 or 1 for the loops hapstab builds):
        for two free ports, whether ``S00 S11 == S01 S10`` as the exact core computes it;
        otherwise the rank of S (and grounded ports) in exact rational arithmetic.
    """
    p = len(structure.ports)
    free = [port_is_free(pt, period_s) for pt in structure.ports]
    S = position_gains(structure)
    if S.shape == (2, 2) and all(free) and np.any(S):
        # the products as the exact core forms them (a0 a1 == c0 c1): a scaled pair's
        # signs alpha beta, -beta, -alpha, 1 carry alpha beta rounded once, and the model
        # means the exact product, whose translation [1, alpha] is the rigid mode
        return int(S[0, 0] * S[1, 1] == S[0, 1] * S[1, 0])
    rows = [[Fraction(float(v)) for v in row] for row in S]
    for j in range(p):
        if not free[j]:                          # a grounded port cannot move
            rows.append([Fraction(int(i == j)) for i in range(p)])
    return p - _rank(rows)


def _rank(rows: list[list[Fraction]]) -> int:
    """Rank of a small matrix, exactly (Gaussian elimination on fractions)."""
    m = [list(r) for r in rows]
    rank, cols = 0, len(m[0]) if m else 0
    for c in range(cols):
        piv = next((i for i in range(rank, len(m)) if m[i][c] != 0), None)
        if piv is None:
            continue
        m[rank], m[piv] = m[piv], m[rank]
        for i in range(len(m)):
            if i != rank and m[i][c] != 0:
                f = m[i][c] / m[rank][c]
                m[i] = [a - f * b for a, b in zip(m[i], m[rank], strict=True)]
        rank += 1
    return rank


def periods_of(loop: HapticLoop | TeleoperationLoop, periods: object = None) -> np.ndarray:
    """The sampling periods to build for: the loop's own, or ``periods`` checked.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (its period is the default).
    periods : sequence of float, optional
        Periods in s, each within :data:`~hapstab.errors.PERIOD_RANGE`.

    Returns
    -------
    (P,) array of float

    Raises
    ------
    ModelError
        An empty list, or a period that is not a number in range.
    """
    require_loop(loop)
    if periods is None:
        return np.array([float(loop.period)])
    try:
        with np.errstate(over="ignore"):     # (a longdouble beyond a double: inf, refused)
            T = np.atleast_1d(np.asarray(periods, dtype=float)).ravel()
    except (TypeError, ValueError, OverflowError):     # (OverflowError: Fraction(10**400))
        raise ModelError(f"periods = {periods!r}: must be numbers (s)") from None
    if T.size == 0:
        raise ModelError("periods: the list is empty; give at least one period")
    lo, hi = PERIOD_RANGE
    bad = ~((T >= lo) & (T <= hi))           # (vectorised: 10^7 periods are checked in ms)
    for t in T[bad][:1]:
        check_period("period", float(t))     # the first bad one, refused with its message
    return T.copy()


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
    ArgumentTypeError
        If ``loop`` is neither kind (a :class:`TypeError`).
    """
    require_loop(loop)
    return _BUILDERS[loop.kind](loop)


def _haptic(loop: HapticLoop) -> LoopStructure:
    """Fig. 2a: one device, the virtual environment on its delayed position."""
    return LoopStructure(
        (Port(loop.device, loop.operator, "device"),),
        (Channel(0, loop.controller, ((0, 1.0, loop.delay_in_samples),)),))


def _teleoperation(loop: TeleoperationLoop) -> LoopStructure:
    """Fig. 3 / eq. (20): PEB, with position and force scaling."""
    fwd, bwd = loop.forward_delay_in_samples, loop.backward_delay_in_samples
    a, b = loop.position_scale, loop.force_scale       # eq. (20) when both are 1
    return LoopStructure(
        (Port(loop.master, loop.operator, "master"), Port(loop.slave, loop.environment, "slave")),
        (Channel(0, loop.master_controller, ((0, b * a, 0.0), (1, -b, bwd))),
         Channel(1, loop.slave_controller, ((1, 1.0, 0.0), (0, -a, fwd)))))


def _four_channel(loop: FourChannelLoop) -> LoopStructure:
    """Lawrence's architecture as channels: u = -F_c (the force a controller resists
    with), so u_m = C_m x_m - C_4' z^-n_b x_s - C_6 Ft_m - C_2 z^-n_b Ft_s and
    u_s = C_s x_s - C_1 z^-n_f x_m - C_3 z^-n_f Ft_m - C_5 Ft_s, Ft_j the force of
    port j's termination on its device (F_h = Ft_m, F_e = -Ft_s). Force channels with a
    gain of 0 are left out."""
    fwd, bwd = loop.forward_delay_in_samples, loop.backward_delay_in_samples
    cm, cs, c1, c4 = loop.position_controllers
    chans = [Channel(0, cm, ((0, 1.0, 0.0),)), Channel(0, c4, ((1, -1.0, bwd),)),
             Channel(1, cs, ((1, 1.0, 0.0),)), Channel(1, c1, ((0, -1.0, fwd),))]
    for port, gain, j, d in ((0, loop.master_force_feedback, 0, 0.0),
                             (0, loop.force_to_master, 1, bwd),
                             (1, loop.force_to_slave, 0, fwd),
                             (1, loop.slave_force_feedback, 1, 0.0)):
        if gain != 0.0:
            chans.append(Channel(port, DiscreteController((gain,), (1.0,)), ((j, -1.0, d),),
                                 "force"))
    return LoopStructure(
        (Port(loop.master, loop.operator, "master"), Port(loop.slave, loop.environment, "slave")),
        tuple(chans), reference=2 * loop.stiffness_reference)


#: The one builder of each loop kind (the loop's ``kind`` names it).
_BUILDERS: dict[str, Callable[[Any], LoopStructure]] = {
    "hve": _haptic, "peb": _teleoperation, "4ch": _four_channel}


def channel_name(structure: LoopStructure, channel: Channel) -> str:
    """A channel in a message: its port's name, or Lawrence's C4 / C1 for a position
    controller that reads only the other port (the 4-channel loop's transmitted ones).

    Parameters
    ----------
    structure : LoopStructure
        The loop.
    channel : Channel
        One of its channels.

    Returns
    -------
    str
    """
    if len(structure.ports) == 2 and channel.measures == "position" and \
            all(j != channel.port for j, _, _ in channel.terms):
        return "C4" if channel.port == 0 else "C1"
    return structure.ports[channel.port].name
