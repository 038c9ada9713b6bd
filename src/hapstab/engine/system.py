"""The one engine: the exact discrete-time model of a sampled-data loop.

A loop is a set of *ports* (a device with the impedance rigidly attached to it)
and discrete controllers (channels), each acting on its port with a signed sum of
delayed position samples (``e_c = sum_j s_cj z^-n_cj x_j``) or of delayed samples of
the forces the terminations apply (:mod:`hapstab.engine.forces`); a port's channels
add.  The continuous part of each port is
discretised exactly for a zero-order hold (matrix exponential), the delays are
shift registers and each controller is realised in state space.  The closed loop
at the sampling instants is then ``s[k+1] = A_cl s[k] + B_ext f_ext[k]``.

For spring-damper controllers the stiffness enters only the controller's direct
feed-through, so ``A_cl(K) = A0 + K * B1 @ C1`` with ``B1`` and ``C1`` of one column
and row per port (K varied by :func:`~hapstab.engine.structure.channel_ratios`); the
analyses rely on this affine structure.

Everything is batched over sampling periods: arrays carry a leading axis P.

References
----------
The paper, Fig. 2a (HVE) and Fig. 3 / eq. (19)-(21) (PEB); H(z) of eq. (23).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from hapstab.engine.forces import (
    ForceLayout,
    force_layout,
    force_selector,
    held_states,
    termination_rows,
)
from hapstab.engine.structure import (
    LoopStructure,
    channel_name,
    channel_ratios,
    periods_of,
    rigid_modes,
    structure_of,
)
from hapstab.engine.zoh import discretize, port_matrices
from hapstab.errors import ModelError
from hapstab.models.controllers import has_stiffness
from hapstab.models.loops import HapticLoop, TeleoperationLoop, split_delay

__all__ = ['SampledSystem', 'build']


@dataclass
class SampledSystem:
    """The exact sampled-data closed loop, batched over P sampling periods.

    Attributes
    ----------
    periods : (P,) array
    A0, B1, C1 : arrays
        ``A_cl(K) = A0 + K * B1 @ C1`` with K the common stiffness of the
        spring-damper controllers (zero columns for controllers without one).
    stiffness : (P,) array
        The loops' own K; ``A_cl = A0 + stiffness * B1 @ C1``.
    B_ext : (P, N, p)
        Exogenous force on each port, held over the sample.
    F_u0, F_u1 : (P, p, N)
        Controller force of each port from the state, ``u = (F_u0 + K F_u1) s``
        (:meth:`force_matrix`), in N.
    pos, vel : (p, N)
        Selectors of each port's position and velocity.
    Ac, Bc : (np, np), (np, p)
        Continuous plant (all ports), state = the first ``np`` closed-loop states.
    Cf : (p, np)
        Each port's termination force (N) from the plant state.
    n_plant : int
        ``np``, the number of plant states.
    labels : list of str
        The ports' names (``device``; ``master``, ``slave``).
    varies_with_K : bool
        False when K cannot be varied (a position controller without a stiffness, or
        a reference stiffness of 0 with another > 0): then ``B1 @ C1`` is zero.
    E : (p, N) or None
        The controller input of each port, ``e_i = E_i s`` (delays included), when
        every port has one position channel (``LoopStructure.simple``: the HVE, PEB);
        ``None`` otherwise (see ``E_channels``).
    E_channels : (C, N) or None
        The input of each channel (positions, or termination forces at kT^-).
    held_u, held_f : (p,) int arrays or None
        The state holding each port's controller / exogenous force of the previous
        sample (-1: none); only ports whose force a channel measures have them.
    fractional : tuple of (int, float, int)
        ``(port j, fraction f, state)`` of each fractional-delay state
        ``x_j(kT - fT)`` (its registers follow it).
    fixed_reason : str
        Why K cannot be varied (empty when it can).
    rigid_modes : int
        Modes at z = 1 that no controller moves (the rigid-body rule,
        :func:`~hapstab.engine.structure.rigid_modes`): 0 or 1.
    """

    periods: np.ndarray
    A0: np.ndarray
    B1: np.ndarray
    C1: np.ndarray
    stiffness: np.ndarray
    B_ext: np.ndarray
    F_u0: np.ndarray
    F_u1: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    Ac: np.ndarray
    Bc: np.ndarray
    Cf: np.ndarray
    n_plant: int
    labels: list[str] = field(default_factory=list)
    varies_with_K: bool = True
    E: np.ndarray | None = None
    fixed_reason: str = ""
    rigid_modes: int = 0
    E_channels: np.ndarray | None = None
    held_u: np.ndarray | None = None
    held_f: np.ndarray | None = None
    fractional: tuple[tuple[int, float, int], ...] = ()

    @property
    def order(self) -> int:
        return self.A0.shape[-1]

    @property
    def n_ports(self) -> int:
        return self.pos.shape[0]

    def A1(self) -> np.ndarray:
        return self.B1 @ self.C1

    def closed_loop(self, K: np.ndarray | float | None = None) -> np.ndarray:
        """A_cl at stiffness K (default: the loop's own), shape (P, N, N)."""
        K = self.stiffness if K is None else np.broadcast_to(np.asarray(K, float), self.periods.shape)
        return self.A0 + K[:, None, None] * (self.B1 @ self.C1)

    def force_matrix(self, K: np.ndarray | float | None = None) -> np.ndarray:
        """F_u at stiffness K: the controller force of each port, ``u = F_u s``."""
        K = self.stiffness if K is None else np.broadcast_to(np.asarray(K, float), self.periods.shape)
        return self.F_u0 + K[:, None, None] * self.F_u1


@dataclass(frozen=True)
class _Layout:
    """Where each part of the closed-loop state lives (see :func:`build`)."""

    off_p: np.ndarray                       # plant block of each port
    n_plant: int
    depth: list[int]                        # whole-sample registers of each port
    off_r: np.ndarray                       # first register of each port
    off_c: np.ndarray                       # controller states of each channel
    frac: dict[tuple[int, float], int]      # (port, fraction) -> registers after it
    off_f: dict[tuple[int, float], int]     # (port, fraction) -> its state
    N: int
    force: ForceLayout                      # held forces and force registers (last)


def _plant(st: LoopStructure, T: np.ndarray) -> tuple[np.ndarray, ...]:
    """Continuous (Ac, Bc, Cf) of all ports, block-diagonal, their ZOH (Ad, Bd)
    for each period, and the offset of each port's block."""
    cont = [port_matrices(pt) for pt in st.ports]
    off_p = np.concatenate([[0], np.cumsum([a.shape[0] for a, _, _ in cont])]).astype(int)
    n_plant, p = int(off_p[-1]), len(st.ports)
    Ac, Bc, Cf = np.zeros((n_plant, n_plant)), np.zeros((n_plant, p)), np.zeros((p, n_plant))
    for i, (a, b, cf) in enumerate(cont):
        sl = slice(off_p[i], off_p[i + 1])
        Ac[sl, sl], Bc[sl, i], Cf[i, sl] = a, b[:, 0], cf[0]
    Ad, Bd = discretize(Ac, Bc, T)
    return Ac, Bc, Cf, Ad, Bd, off_p


def _layout(st: LoopStructure, off_p: np.ndarray, qs: list[int]) -> _Layout:
    """Offsets of the delay registers, the controller states (``qs`` per channel)
    and the fractional-delay states.

    A term's delay is d = n + f samples. The whole part is shift registers of x_j
    (register l of port j holds x_j[k-1-l]). A fractional part f > 0 is a state
    r = x_j(kT - fT), exact from the previous sample and the force held over it
    (ZOH), with its own registers (after the controller states, so the layout of
    integer-delay loops is unchanged). Force measurements come last
    (:func:`~hapstab.engine.forces.force_layout`).
    """
    p, n_plant = len(st.ports), int(off_p[-1])
    depth = [0] * p
    frac: dict[tuple[int, float], int] = {}
    for ch in st.channels:
        for j, _, d in ch.terms if ch.measures == "position" else ():
            n, f = split_delay(d)
            if f == 0.0:
                depth[j] = max(depth[j], n)
            else:
                frac[(j, f)] = max(frac.get((j, f), 0), n)
    off_r = n_plant + np.concatenate([[0], np.cumsum(depth)]).astype(int)
    off_c = int(off_r[-1]) + np.concatenate([[0], np.cumsum(qs)]).astype(int)
    off_f: dict[tuple[int, float], int] = {}
    N = int(off_c[-1])
    for key in sorted(frac):
        off_f[key] = N
        N += 1 + frac[key]
    fl = force_layout(st, N)
    return _Layout(off_p, n_plant, depth, off_r, off_c, frac, off_f, fl.N, fl)


def _selectors(st: LoopStructure, lay: _Layout, R: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position and velocity selectors (p, N), and the error selectors E (C, N) of the
    channels: e_c = E_c s, the signed sum of delayed positions (or of the delayed
    termination forces ``R s``, :func:`~hapstab.engine.forces.termination_rows`)
    each controller acts on."""
    p, N = len(st.ports), lay.N
    pos, vel = np.zeros((p, N)), np.zeros((p, N))
    for i in range(p):
        pos[i, lay.off_p[i]], vel[i, lay.off_p[i] + 1] = 1.0, 1.0
    E = np.zeros((len(st.channels), N))
    for c, ch in enumerate(st.channels):
        for j, sgn, d in ch.terms:
            n, f = split_delay(d)
            if ch.measures == "force":
                E[c] += sgn * force_selector(lay.force, R, j, n)
            elif f:
                E[c, lay.off_f[(j, f)] + n] += sgn     # r itself (n = 0) or register n-1
            elif n == 0:
                E[c] += sgn * pos[j]
            else:
                E[c, lay.off_r[j] + n - 1] += sgn
    return pos, vel, E


def _controllers(st: LoopStructure, parts: Sequence[tuple[np.ndarray, ...]], lay: _Layout,
                 E: np.ndarray, P: int, ratios: Sequence[float]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """The controllers' forces u = F_u0 s + K F_u1 s (each port's channels added, the
    K-part of channel c scaled by ``ratios[c]``), their own state updates (the
    controller rows of A0) and each channel's K-part per unit K, (P, N)."""
    p, N = len(st.ports), lay.N
    Fu0, Fu1, A0 = np.zeros((P, p, N)), np.zeros((P, p, N)), np.zeros((P, N, N))
    krows = []
    for c, (ch, (Ah, Bh, Ch, Dfix, Dk, ChK)) in enumerate(zip(st.channels, parts, strict=True)):
        i = ch.port
        cs = slice(lay.off_c[c], lay.off_c[c + 1])
        Fu0[:, i, cs] = Ch[:, 0, :]
        Fu0[:, i, :] += Dfix[:, None] * E[c]
        kr = Dk[:, None] * E[c]
        kr[:, cs] += ChK[:, 0, :]
        krows.append(kr)
        Fu1[:, i, :] += ratios[c] * kr
        A0[:, cs, cs] = Ah
        A0[:, cs, :] += Bh[:, :, :1] * E[c][None, None, :]
    return Fu0, Fu1, A0, krows


def _registers(A0: np.ndarray, pos: np.ndarray, lay: _Layout) -> None:
    """The whole-sample shift registers of each port's position (in place)."""
    for j, depth in enumerate(lay.depth):
        if depth:
            A0[:, lay.off_r[j], :] = pos[j]
            for step in range(1, depth):
                A0[:, lay.off_r[j] + step, lay.off_r[j] + step - 1] = 1.0


def _fractional(A0: np.ndarray, B_ext: np.ndarray, B1: np.ndarray, Fu0: np.ndarray,
                Ac: np.ndarray, Bc: np.ndarray, T: np.ndarray,
                lay: _Layout) -> dict[tuple[int, float], np.ndarray]:
    """The fractional-delay states and their registers (in place); returns the
    held force's gain Gamma of each, for the K-part."""
    gam_of: dict[tuple[int, float], np.ndarray] = {}
    for (j, f), r0 in lay.off_f.items():
        # r[k+1] = x_j((k+1)T - fT) = C (Phi x_j[k] + Gamma (f_ext - u)[k]) over (1 - f)T
        pl = slice(lay.off_p[j], lay.off_p[j + 1])
        Phi, Gam = discretize(Ac[pl, pl], Bc[pl, j:j + 1], (1.0 - f) * T)
        A0[:, r0, pl] = Phi[:, 0, :]
        A0[:, r0, :] -= Gam[:, 0, 0][:, None] * Fu0[:, j, :]
        B_ext[:, r0, j] = Gam[:, 0, 0]
        B1[:, r0, j] = -Gam[:, 0, 0]
        gam_of[(j, f)] = Gam[:, 0, 0]
        for step in range(1, lay.frac[(j, f)] + 1):
            A0[:, r0 + step, r0 + step - 1] = 1.0
    return gam_of


@dataclass
class _KPart:
    """The stiffness part of the loop: u = F_u0 s + K F_u1 s, A(K) = A0 + K B1 C1."""

    A0: np.ndarray
    Fu0: np.ndarray
    Fu1: np.ndarray
    C1: np.ndarray
    K_own: np.ndarray
    varies: bool
    fixed_reason: str


def _stiffness(st: LoopStructure, k: _KPart, Bd: np.ndarray, lay: _Layout,
               gam_of: dict[tuple[int, float], np.ndarray], krows: list[np.ndarray]) -> _KPart:
    """Which K the loop varies: the reference channel's stiffness, every other
    position channel's kept in ratio (:func:`~hapstab.engine.structure.channel_ratios`,
    already applied to the K-part by :func:`_controllers`); or none (a general H(z),
    or a reference stiffness of 0 with another > 0), when every spring-damper's own
    stiffness is folded into the fixed part."""
    sd = [has_stiffness(ch.controller) for ch in st.channels]
    pos = [ch.measures == "position" for ch in st.channels]
    ref = st.channels[st.reference].controller
    if channel_ratios(st) is not None:
        k.K_own[:] = ref.stiffness        # type: ignore[union-attr]
        return k
    if not all(s for s, q in zip(sd, pos, strict=True) if q):
        k.fixed_reason = ("controller: critical stiffness needs SpringDamper controllers (a "
                          "general H(z) has no stiffness K to vary)")
    else:
        k.fixed_reason = ("controllers: the stiffness K names is 0 and another controller's "
                          "is not, so their ratio is undefined; give it a stiffness > 0 to "
                          "vary K")
        if st.simple:
            k.fixed_reason = ("controllers: the master's stiffness is 0 and the slave's is not, "
                              "so K_s/K_m is undefined; give the master a stiffness > 0 to "
                              "vary K")
    k.varies, k.K_own = False, np.zeros_like(k.K_own)
    if not any(sd):
        return k
    # no ratio to keep: the loop is exact with every channel's own K folded into the
    # fixed part, and K cannot be varied
    own = np.zeros_like(k.Fu1)
    for c, ch in enumerate(st.channels):
        if sd[c]:
            own[:, ch.port, :] += ch.controller.stiffness * krows[c]    # type: ignore[union-attr]
    k.Fu0 = k.Fu0 + own
    k.A0[:, :lay.n_plant, :] -= Bd @ own
    for (j, f), r0 in lay.off_f.items():
        k.A0[:, r0, :] -= gam_of[(j, f)][:, None] * own[:, j, :]
    for j, u in lay.force.u_old.items():
        k.A0[:, u, :] += own[:, j, :]
    k.Fu1, k.C1 = np.zeros_like(k.Fu1), np.zeros_like(k.C1)
    return k


def _check_finite(st: LoopStructure, T: np.ndarray, arrays: list[np.ndarray]) -> None:
    """Refuse a model that overflowed double precision, naming its parameters."""
    with np.errstate(all="ignore"):
        if all(np.all(np.isfinite(a)) for a in arrays):
            return
    ports = "; ".join(f"{pt.name} mass {pt.device.mass:g} kg, damping {pt.device.damping:g} N*s/m"
                      for pt in st.ports)
    ctrls = "; ".join(f"{channel_name(st, ch)} stiffness K = {ch.controller.stiffness:g} N/m, "
                      f"{channel_name(st, ch)} virtual damping B = "
                      f"{getattr(ch.controller, 'damping', 0.0):g} N*s/m"
                      if has_stiffness(ch.controller) else "H(z)"
                      for ch in st.channels)
    raise ModelError(f"period = {T.min():g} s: the sampled model overflows double precision with "
                     f"{ports}; controllers {ctrls}")


def build(loop: HapticLoop | TeleoperationLoop,
          periods: Sequence[float] | np.ndarray | None = None, *,
          max_memory: float | None = None, max_seconds: float | None = None) -> SampledSystem:
    """Assemble the exact closed loop of ``loop`` for each sampling period.

    The state is: each port's plant (ZOH), the whole-sample delay registers, the
    controller states, the fractional-delay states with their registers, then for
    every port whose force a channel measures its held forces and force registers
    (:mod:`hapstab.engine.forces`).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop; its structure (:func:`~hapstab.engine.structure.structure_of`)
        is all the engine reads.
    periods : array of float, optional
        Sampling periods (s); defaults to ``[loop.period]``. Everything else
        (devices, impedances, controllers, delays in samples) is the loop's.
    max_memory, max_seconds : float, optional
        Budget in bytes and seconds (default :mod:`hapstab.budget`'s): the matrices of
        every period (:func:`hapstab.budget.build_cost`) are estimated first and
        refused above it.

    Returns
    -------
    SampledSystem

    Raises
    ------
    BudgetError
        Over the budget, before any work.
    """
    st = structure_of(loop)
    T = periods_of(loop, periods)
    P = T.size
    from hapstab import budget

    budget.check(budget.build_cost(P, len(st.ports) * (loop.delay_in_samples + 4) + 2),
                 max_memory, max_seconds)
    Ac, Bc, Cf, Ad, Bd, off_p = _plant(st, T)
    parts = [ch.controller.realisation(T) for ch in st.channels]
    lay = _layout(st, off_p, [pa[0].shape[1] for pa in parts])
    R = termination_rows(st, lay.force, Ac, Cf, off_p)
    pos, vel, E = _selectors(st, lay, R)
    ratios = channel_ratios(st) or (1.0,) * len(st.channels)
    Fu0, Fu1, A0, krows = _controllers(st, parts, lay, E, P, ratios)
    n, p = lay.n_plant, len(st.ports)
    A0[:, :n, :n] = Ad
    A0[:, :n, :] -= Bd @ Fu0
    _registers(A0, pos, lay)
    B_ext, B1 = np.zeros((P, lay.N, p)), np.zeros((P, lay.N, p))
    B_ext[:, :n, :], B1[:, :n, :] = Bd, -Bd
    gam_of = _fractional(A0, B_ext, B1, Fu0, Ac, Bc, T, lay)
    held_states(A0, B_ext, B1, Fu0, lay.force, R)
    # C1 rows: the K-part of each port's force; same for every period
    k = _stiffness(st, _KPart(A0, Fu0, Fu1, Fu1.copy(), np.zeros(P), True, ""), Bd, lay, gam_of,
                   krows)
    _check_finite(st, T, [k.A0, k.C1, k.Fu0, B_ext, B1])
    held = [np.array([d.get(j, -1) for j in range(p)]) if d else None
            for d in (lay.force.u_old, lay.force.f_old)]
    return SampledSystem(periods=T, A0=k.A0, B1=B1, C1=k.C1, stiffness=k.K_own, B_ext=B_ext,
                         F_u0=k.Fu0, F_u1=k.Fu1, pos=pos, vel=vel, Ac=Ac, Bc=Bc, Cf=Cf,
                         n_plant=n, labels=[pt.name for pt in st.ports], varies_with_K=k.varies,
                         E=E if st.simple else None, fixed_reason=k.fixed_reason,
                         rigid_modes=rigid_modes(st, float(T.max())), E_channels=E,
                         held_u=held[0], held_f=held[1],
                         fractional=tuple((j, f, r0) for (j, f), r0 in lay.off_f.items()))
