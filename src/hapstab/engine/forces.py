"""Force measurement for the state-space engine: the force a port's termination applies
to its device just before a sample (kT^-), its delay registers and the held forces it
needs.

With the actuator force u and the exogenous force f held over the previous sample
(ZOH), port j's acceleration just before the sample is ``a = A[1, :] s + (f_old -
u_old) / M`` (:func:`~hapstab.engine.zoh.port_matrices`: M the device's mass plus the
termination's m_z), and the termination's force on the device is

``F_term(kT^-) = f_old - m_z a - Cf s
             = -(Cf + m_z A[1, :]) s + (m_z / M) u_old + (1 - m_z / M) f_old``.

So every port a force channel measures gets two states, ``u_old[k+1] = u[k]`` (its
total controller force, whose stiffness part enters through B1 C1 like the plant
rows) and ``f_old[k+1] = f_ext[k]`` (an exogenous input row), and a delayed force
measurement gets shift registers ``r_0[k+1] = F_term[k]``, ``r_l[k+1] = r_{l-1}[k]``.
These states come after every other state, so loops without force channels keep
their layout.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hapstab.engine.structure import LoopStructure, split_delay
from hapstab.errors import ModelError

__all__ = ['ForceLayout', 'force_layout', 'termination_rows', 'force_selector', 'held_states']


@dataclass(frozen=True)
class ForceLayout:
    """Where the force-measurement states live (port -> state index)."""

    u_old: dict[int, int] = field(default_factory=dict)   # controller force held over k-1
    f_old: dict[int, int] = field(default_factory=dict)   # exogenous force held over k-1
    off_r: dict[int, int] = field(default_factory=dict)   # first register of F_term
    depth: dict[int, int] = field(default_factory=dict)   # registers of F_term
    N: int = 0                                             # the closed loop's order


def force_layout(st: LoopStructure, N0: int) -> ForceLayout:
    """The force states of ``st``, placed after the first ``N0`` states.

    Parameters
    ----------
    st : LoopStructure
        The loop.
    N0 : int
        The number of states before them (plant, registers, controllers, fractions).

    Returns
    -------
    ForceLayout
        For every measured port (in port order): u_old, f_old, then its registers.

    Raises
    ------
    ModelError
        A force measured with a fractional delay.
    """
    depth: dict[int, int] = {}
    for ch in st.channels:
        if ch.measures != "force":
            continue
        for j, _, d in ch.terms:
            n, f = split_delay(d)
            if f:
                raise ModelError(f"delay = {d:g} samples on the force of port {j}: a force "
                                 "is measured at the samples only; allowed: whole samples")
            depth[j] = max(depth.get(j, 0), n)
    u_old, f_old, off_r = {}, {}, {}
    N = N0
    for j in sorted(depth):
        u_old[j], f_old[j], off_r[j] = N, N + 1, N + 2
        N += 2 + depth[j]
    return ForceLayout(u_old, f_old, off_r, dict(sorted(depth.items())), N)


def termination_rows(st: LoopStructure, fl: ForceLayout, Ac: np.ndarray, Cf: np.ndarray,
                     off_p: np.ndarray) -> np.ndarray:
    """``F_term_j(kT^-) = R_j s`` for every measured port j (zero rows for the others).

    Parameters
    ----------
    st : LoopStructure
        The loop (its ports' masses).
    fl : ForceLayout
        Where u_old and f_old live.
    Ac, Cf : arrays
        The continuous plant of all ports and each termination's force from it
        (:func:`~hapstab.engine.system.build`'s plant).
    off_p : array of int
        First plant state of each port.

    Returns
    -------
    (p, N) array
        In N per unit state.
    """
    R = np.zeros((len(st.ports), fl.N))
    for j in fl.u_old:
        pt = st.ports[j]
        mz, M = pt.termination.mass, pt.device.mass + pt.termination.mass
        sl = slice(off_p[j], off_p[j + 1])
        R[j, sl] = -(Cf[j, sl] + mz * Ac[off_p[j] + 1, sl])
        R[j, fl.u_old[j]] = mz / M
        R[j, fl.f_old[j]] = 1.0 - mz / M
    return R


def force_selector(fl: ForceLayout, R: np.ndarray, j: int, n: int) -> np.ndarray:
    """The row giving ``F_term_j[k - n]`` from the state (register n-1 for n > 0).

    Parameters
    ----------
    fl : ForceLayout
        The registers.
    R : (p, N) array
        :func:`termination_rows`.
    j, n : int
        The port and the delay in samples.

    Returns
    -------
    (N,) array
    """
    if n == 0:
        return R[j]
    row = np.zeros(fl.N)
    row[fl.off_r[j] + n - 1] = 1.0
    return row


def held_states(A0: np.ndarray, B_ext: np.ndarray, B1: np.ndarray, Fu0: np.ndarray,
                fl: ForceLayout, R: np.ndarray) -> None:
    """The rows of u_old, f_old and the force registers (in place).

    Parameters
    ----------
    A0, B_ext, B1 : (P, N, N), (P, N, p), (P, N, p) arrays
        The closed loop's fixed part, exogenous input and K input.
    Fu0 : (P, p, N) array
        The fixed part of each port's controller force (its K-part is ``+1`` in B1).
    fl : ForceLayout
        Where the states live.
    R : (p, N) array
        :func:`termination_rows`.
    """
    for j, u in fl.u_old.items():
        A0[:, u, :] = Fu0[:, j, :]
        B1[:, u, j] = 1.0
        B_ext[:, fl.f_old[j], j] = 1.0
        r0 = fl.off_r[j]
        for step in range(fl.depth[j]):
            if step == 0:
                A0[:, r0, :] = R[j]
            else:
                A0[:, r0 + step, r0 + step - 1] = 1.0
