"""Sample-by-sample stepping of the sampled-data loop with nonlinear elements at the
sampling instants, the consistent initial state, and exact dense output.

The closed-loop state of :func:`hapstab.engine.build` is split by *role*, read off
the matrices themselves (not from the engine's layout):

* **physical** rows hold true physical quantities: the plant states, sampled
  positions between samples (fractional delays: rows driven by the held force) and
  pure copies of position entries (the delay registers). They evolve with the
  open-loop map and the force actually applied: ``A_free s + G (f - u)`` with
  ``A_free = A_cl + G F_u``.
* the **position entries** among them (device positions, registers, fractional
  samples) are what the controller reads; the measurement (encoder quantisation,
  wall offset) is applied when they are read. Quantisation is memoryless, so a
  register that stores the true position and is quantised when read gives exactly
  what a register of quantised samples gives.
* the **held forces** (``sysm.held_u``, ``held_f``: the controller and exogenous
  force of the previous sample, kept for a force measurement at kT^-) take the force
  actually applied (after saturation) and the exogenous force.
* the remaining rows (controller states, force registers) are updated from the
  measured state.

Without nonlinear elements this is exactly ``s[k+1] = A_cl s[k] + G f[k]``.

References
----------
The paper, Fig. 2a and Fig. 3 (sampler, ZOH, delay, discrete controller).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.engine.system import SampledSystem
from hapstab.engine.zoh import discretize
from hapstab.errors import ModelError, check_reals
from hapstab.models.loops import HapticLoop, TeleoperationLoop

__all__ = ["Roles", "roles_of", "initial_state", "step_nonlinear", "dense_output"]


@dataclass(frozen=True)
class Roles:
    """Which closed-loop state entries are what (see the module docstring)."""

    A: np.ndarray          # A_cl (N, N)
    G: np.ndarray          # exogenous input (N, p)
    Fu: np.ndarray         # controller force u = Fu s (p, N)
    A_free: np.ndarray     # A_cl + G Fu
    pos_entries: np.ndarray   # indices of position entries
    pos_port: np.ndarray      # their port
    physical: np.ndarray      # bool mask (N,)
    E: np.ndarray | None      # controller input selectors (p, N); None: several per port
    held_u: np.ndarray        # (port, state) pairs of the held controller forces (h, 2)
    held_f: np.ndarray        # (port, state) pairs of the held exogenous forces (h, 2)


def roles_of(loop: HapticLoop | TeleoperationLoop, sysm: SampledSystem) -> Roles:
    """Classify the state entries of ``sysm`` (at the loop's own stiffness)."""
    A, G, Fu = sysm.closed_loop()[0], sysm.B_ext[0], sysm.force_matrix()[0]
    N, npl = sysm.order, sysm.n_plant
    A_free = A + G @ Fu
    pos_idx = np.argmax(sysm.pos, axis=1)
    plant_port = np.searchsorted(pos_idx, np.arange(npl), side="right") - 1
    port_of = {int(i): j for j, i in enumerate(pos_idx)}
    held = [_held(h) for h in (sysm.held_u, sysm.held_f)]
    skip = {int(i) for h in held for i in h[:, 1]}
    changed = True
    while changed:                       # registers chain: copy of a copy of a position
        changed = False
        for i in range(npl, N):
            if i in port_of or i in skip:
                continue
            if np.any(G[i]):             # a position sampled between samples (fractional delay)
                cols = np.flatnonzero(A_free[i, :npl])
                if cols.size:
                    port_of[i], changed = int(plant_port[cols[0]]), True
                continue
            nz = np.flatnonzero(A[i])
            if nz.size == 1 and A[i, nz[0]] == 1.0 and int(nz[0]) in port_of:
                port_of[i], changed = port_of[int(nz[0])], True
    pe = np.array(sorted(port_of), dtype=int)
    phys = np.zeros(N, bool)
    phys[:npl] = True
    phys[pe] = True
    return Roles(A, G, Fu, A_free, pe, np.array([port_of[i] for i in pe], dtype=int), phys,
                 None if sysm.E is None else np.asarray(sysm.E), held[0], held[1])


def _held(h: np.ndarray | None) -> np.ndarray:
    """(port, state) pairs of a held-force index array (-1: the port has none)."""
    if h is None:
        return np.zeros((0, 2), dtype=int)
    ports = np.flatnonzero(np.asarray(h) >= 0)
    return np.stack([ports, np.asarray(h)[ports]], axis=1).astype(int)


def initial_state(sysm: SampledSystem, roles: Roles, x0: Any, v0: Any, full: Any,
                  measure: Callable[[np.ndarray], np.ndarray],
                  held_force: np.ndarray | None = None) -> np.ndarray:
    """The initial closed-loop state: given in full, or the plant at (x0, v0) with a
    history at rest at x0 (every stored position x0 of its port; the exogenous force
    held over the previous sample ``held_force`` (p,), default 0; controller states,
    held controller forces and force registers the fixed point of their own update).

    Raises
    ------
    ModelError
        Wrong sizes or non-finite values.
    """
    p, N, npl = sysm.n_ports, sysm.order, sysm.n_plant
    if full is not None:
        s = check_reals("initial_state", full)
        if s.size != N or not np.all(np.isfinite(s)):
            raise ModelError(f"initial_state: {s.size} values; need {N} finite values "
                             f"(plant {npl}, then delay registers and controller states)")
        return s
    pos_idx = np.argmax(sysm.pos, axis=1)
    s = np.zeros(N)
    vals = []
    for nm, val in (("initial_position", x0), ("initial_velocity", v0)):
        v = check_reals(nm, val)
        a = np.broadcast_to(v, (p,)) if v.size in (1, p) else None
        if a is None or not np.all(np.isfinite(a)):
            raise ModelError(f"{nm} = {val!r}: must be one finite number or one per port ({p})")
        vals.append(a)
    s[roles.pos_entries] = vals[0][roles.pos_port]
    s[pos_idx + 1] = vals[1]
    ctrl = ~roles.physical
    if roles.held_f.size:
        hf = np.zeros(p) if held_force is None else np.asarray(held_force, float)
        s[roles.held_f[:, 1]] = hf[roles.held_f[:, 0]]
        ctrl[roles.held_f[:, 1]] = False
    if ctrl.any():
        sm = measure(s)
        Acc = roles.A[np.ix_(ctrl, ctrl)]
        rhs = roles.A[np.ix_(ctrl, ~ctrl)] @ sm[~ctrl]
        s[ctrl] = np.linalg.lstsq(np.eye(int(ctrl.sum())) - Acc, rhs, rcond=None)[0]
    return s


def step_nonlinear(roles: Roles, s0: np.ndarray, F: np.ndarray, M: int,
                   measure: Callable[[np.ndarray], np.ndarray], has_wall: bool,
                   sat: float | None, wall_pulls: bool = False,
                   adjust: Callable[[int, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
                   | None = None,
                   between: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None
                   = None, network: Callable[[int, np.ndarray], None] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Step M samples with the nonlinear elements at the sampling instants.

    The wall (port 0) acts only on a penetration it sees, and then only pushes
    (``u >= 0``) unless ``wall_pulls``; saturation clips each port's force; then
    ``adjust(k, u, s, measured s)``, if given, returns the force to apply (the
    passivity controller of :mod:`hapstab.simulation.tdpa`).
    ``between(k, s, g, nxt)``, if given, replaces what the linear step put in ``nxt``
    for the motion between samples k and k+1 under the held net force ``g = F[k] - u``
    (Coulomb friction, :class:`~hapstab.simulation.friction.LoopFriction`).
    ``network(k, sm)``, if given, puts what the network delivers at sample k into the
    measured state ``sm`` (in place, :class:`~hapstab.simulation.network.NetworkLine`).

    Returns
    -------
    S : (M+1, N) states, U : (M+1, p) applied controller forces, C : (M+1,) wall
    contact flags (None without a wall). Rows after an overflow are inf / nan.
    """
    # integer indices (not the boolean masks: a mask's scatter costs several times
    # more per sample) and the held forces' (state, port) columns, formed once
    ph, ct = np.flatnonzero(roles.physical), np.flatnonzero(~roles.physical)
    Af, Gp, Ac = roles.A_free[ph], roles.G[ph], roles.A[ct]
    hu_s, hu_p = roles.held_u[:, 1], roles.held_u[:, 0]
    hf_s, hf_p = roles.held_f[:, 1], roles.held_f[:, 0]
    Fu = roles.Fu
    E0 = roles.E[0] if roles.E is not None else np.zeros(s0.size)   # the wall's (HVE) reading
    S = np.empty((M + 1, s0.size))
    U = np.empty((M + 1, Fu.shape[0]))
    C = np.zeros(M + 1, bool) if has_wall else None
    s = s0.copy()
    # a run that leaves double precision ends as overflowed (below): its products
    # overflow on the way, as the linear recurrence's do (propagate_linear), silently
    with np.errstate(over="ignore", invalid="ignore"):
        # ndarray.dot, not @: the same BLAS product (bit for bit) at half the call overhead on
        # these small vectors; np.minimum/np.maximum for np.clip likewise (the same values)
        for k in range(M + 1):
            S[k] = s
            sm = measure(s)
            if network is not None:
                network(k, sm)
            u = Fu.dot(sm)
            if C is not None:                # has_wall
                C[k] = c = bool(E0.dot(sm) > 0)   # the wall pushes only on penetration it sees
                if not c:
                    u[0] = 0.0
                elif not wall_pulls and u[0] < 0:
                    u[0] = 0.0               # a wall pushes out; its damper must not pull in
            if sat is not None:
                u = np.minimum(np.maximum(u, -sat), sat)
            if adjust is not None:
                u = adjust(k, u, s, sm)
            U[k] = u
            if k == M:
                break
            nxt = np.empty_like(s)
            Fk = F[k]
            nxt[ph] = Af.dot(s) + Gp.dot(Fk - u)
            nxt[ct] = Ac.dot(sm)
            nxt[hu_s] = u[hu_p]                  # the force actually applied
            nxt[hf_s] = Fk[hf_p]
            if between is not None:
                between(k, s, Fk - u, nxt)
            s = nxt
            # s . s is finite when every entry is, unless it overflows (|s| > 1e154): then
            # the entries themselves are looked at
            if not math.isfinite(s.dot(s)) and not np.isfinite(s).all():
                S[k + 1:] = np.inf
                U[k + 1:] = np.nan
                break
    return S, U, C


def dense_output(sysm: SampledSystem, S: np.ndarray, G: np.ndarray, T: float, m: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact plant trajectory at m points per sample: the held net force G[k]
    (exogenous minus controller) acts on the plant from its sampled state.

    Returns
    -------
    t (M m + 1,), positions (M m + 1, p), velocities (M m + 1, p)
    """
    npl = sysm.n_plant
    pos_idx = np.argmax(sysm.pos, axis=1)
    taus = T * np.arange(1, m) / m
    Adt, Bdt = discretize(sysm.Ac, sysm.Bc, taus)
    Pk = S[:-1, :npl]
    inner = np.einsum("inj,kj->kin", Adt, Pk) + np.einsum("inj,kj->kin", Bdt, G)
    M = Pk.shape[0]
    allp = np.concatenate([Pk[:, None, :], inner], axis=1).reshape(M * m, npl)
    allp = np.vstack([allp, S[-1:, :npl]])
    t = np.concatenate([(np.arange(M)[:, None] * T + np.r_[0.0, taus][None, :]).ravel(), [M * T]])
    return t, allp[:, pos_idx], allp[:, pos_idx + 1]
