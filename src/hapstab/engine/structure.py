"""A loop as ports and channels: the one place where the loop kinds differ.

A loop is a set of *ports* (a device with the impedance rigidly attached to it)
and one discrete controller per port acting on a signed sum of delayed position
samples (``e_i = sum_j s_ij z^-n_ij x_j``).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from hapstab.errors import ModelError, check_period
from hapstab.models.controllers import DiscreteController, SpringDamper
from hapstab.models.loops import HapticLoop, TeleoperationLoop, require_loop, split_delay
from hapstab.models.parts import Device, Impedance

__all__ = ['Port', 'Channel', 'LoopStructure', 'structure_of', 'split_delay', 'port_is_free',
           'periods_of',
           'rigid_modes', 'FREE_SPRING']


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


def rigid_modes(structure: LoopStructure, period_s: float) -> int:
    """The rigid-body rule (its one definition): the modes at z = 1 that no controller
    moves. A constant displacement x of the ports with no spring to ground that gives
    every controller a zero input (``S x = 0``, ``S_ij`` the sum of channel i's signs on
    port j) is an equilibrium for every K: a common translation of PEB's free master
    and slave (x = [1, 1]), or x = [1, alpha] with position scaling alpha.

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
        otherwise the rank of the signs (and grounded ports) in exact rational arithmetic.
    """
    p = len(structure.ports)
    free = [port_is_free(pt, period_s) for pt in structure.ports]
    S = np.zeros((len(structure.channels), p))
    for i, ch in enumerate(structure.channels):
        for j, sign, _ in ch.terms:
            S[i, j] += sign
    if S.shape == (2, 2) and all(free) and np.any(S):
        # the products as the exact core forms them (a0 a1 == c0 c1): a scaled pair's
        # signs alpha beta, -beta, -alpha, 1 carry alpha beta rounded once, and the model
        # means the exact product, whose translation [1, alpha] is the rigid mode
        return int(S[0, 0] * S[1, 1] == S[0, 1] * S[1, 0])
    rows = [[Fraction(0)] * p for _ in structure.channels]
    for r, ch in zip(rows, structure.channels, strict=True):
        for j, sign, _ in ch.terms:
            r[j] += Fraction(sign)
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
        T = np.atleast_1d(np.asarray(periods, dtype=float)).ravel()
    except (TypeError, ValueError):
        raise ModelError(f"periods = {periods!r}: must be numbers (s)") from None
    if T.size == 0:
        raise ModelError("periods: the list is empty; give at least one period")
    return np.array([check_period("period", float(t)) for t in T])


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
    if isinstance(loop, HapticLoop):
        return LoopStructure(
            (Port(loop.device, loop.operator, "device"),),
            (Channel(0, loop.controller, ((0, 1.0, loop.delay_in_samples),)),))
    if isinstance(loop, TeleoperationLoop):
        fwd, bwd = loop.forward_delay_in_samples, loop.backward_delay_in_samples
        a, b = loop.position_scale, loop.force_scale       # eq. (20) when both are 1
        return LoopStructure(
            (Port(loop.master, loop.operator, "master"), Port(loop.slave, loop.environment, "slave")),
            (Channel(0, loop.master_controller, ((0, b * a, 0.0), (1, -b, bwd))),
             Channel(1, loop.slave_controller, ((1, 1.0, 0.0), (0, -a, fwd)))))
    require_loop(loop)
    raise AssertionError("unreachable: require_loop accepts only the two kinds above")
