"""A loop whose network drops packets, as a Markov jump linear system.

Every measured position that crosses the network (the HVE's position channel; each of
PEB's two directions, and the 4-channel loop's C_1 / C_4' terms) is a *networked term*
t. At sample k its packet is received (theta_t[k] = 1) or lost (0), and the receiver
uses the newest value it has, holding the last one it used:

    y_t[k] = x_j[k - n_t]    if received,      y_t[k] = y_t[k - 1]    if lost,

and each controller acts on its signed sum of held and local values,
``e_c[k] = sum_t s_t y_t[k]``, with ``u_c[k] = g_c K e_c[k] + (B_c / T)(e_c[k] - e_c[k-1])``
(for the HVE: ``u[k] = K y[k] + B (y[k] - y[k-1]) / T``). The closed loop at the samples
is ``s[k+1] = A_i(K) s[k]`` with ``A_i(K) = A0_i + K A1_i``, i the mode (which of the
terms were lost at k): a Markov jump linear system (MJLS), its modes driven by a Markov
chain (independent losses: every row of the transition matrix the same; bursts: the
Gilbert-Elliott chain of each term, :func:`loss_chain`).

State: the plant of each port (the engine's, discretised exactly for the ZOH), the
whole-sample delay registers of each measured port, the held value y_t[k-1] of each
networked term and the previous error e_c[k-1] of each channel.

References
----------
O. L. V. Costa, M. D. Fragoso and R. P. Marques, *Discrete-Time Markov Jump Linear
Systems*, Springer 2005, ch. 2-3 (the model x[k+1] = A_{theta_k} x[k]).
E. N. Gilbert, "Capacity of a burst-noise channel", Bell Syst. Tech. J. 39 (1960) and
E. O. Elliott, Bell Syst. Tech. J. 42 (1963) (the two-state burst-loss chain).
The loop itself: the paper, Fig. 2a (HVE) and eq. (20) (PEB).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from scipy import linalg as sla

from hapstab.engine.structure import LoopStructure, channel_ratios, structure_of
from hapstab.engine.system import build
from hapstab.errors import AnalysisError, ModelError, check_real

__all__ = ["JumpSystem", "lossy_system", "loss_chain", "NetworkedPlant", "networked_plant",
           "StateLayout", "state_layout", "source_row", "mode_matrices", "term_name"]


@dataclass(frozen=True)
class JumpSystem:
    """The loop with packet loss as a Markov jump linear system.

    Attributes
    ----------
    A0, A1 : (M, N, N) arrays
        Mode i's closed loop is ``A0[i] + K * A1[i]``; bit t of i set: term t's
        packet was lost at that sample (mode 0: every packet received).
    transition : (M, M) array
        ``transition[i, j]`` = P(mode j at k+1 | mode i at k).
    stationary : (M,) array
        The chain's stationary distribution.
    terms : tuple of str
        The networked terms (``"device position"``, ``"slave -> master"``, ...).
    period : float
        T in s.
    deflated : bool
        A rigid-body mode (z = 1 for every K and every mode, a common eigenvector) was
        removed by an exact similarity.
    """

    A0: np.ndarray
    A1: np.ndarray
    transition: np.ndarray
    stationary: np.ndarray
    terms: tuple[str, ...]
    period: float
    deflated: bool = False

    @property
    def modes(self) -> int:
        return int(self.A0.shape[0])

    @property
    def order(self) -> int:
        return int(self.A0.shape[-1])

    @property
    def independent(self) -> bool:
        """Losses independent from sample to sample (every row of the chain the same)."""
        return bool(np.all(self.transition == self.transition[:1]))

    def at(self, K: float) -> np.ndarray:
        """The mode matrices at stiffness K, (M, N, N)."""
        return self.A0 + K * self.A1


def loss_chain(loss: float, burst: float | None = None) -> np.ndarray:
    """The 2 x 2 chain of one networked term: state 0 received, 1 lost.

    Parameters
    ----------
    loss : float
        P, the long-run fraction of lost packets, in [0, 1).
    burst : float or None
        L, the mean length of a run of lost packets (Gilbert-Elliott: P(lost -> received)
        = 1/L, P(received -> lost) = q = P / (L (1 - P)), so that the stationary loss is
        P); ``None``: independent losses (q = P, 1/L = 1 - P, i.e. L = 1 / (1 - P)).

    Returns
    -------
    (2, 2) array
    """
    P = check_real("loss", loss, nonnegative=True)
    if not P < 1.0:
        raise ModelError(f"loss = {loss!r}: must be in [0, 1) (the fraction of packets lost)")
    if burst is None:
        return np.array([[1.0 - P, P], [1.0 - P, P]])
    L = check_real("burst", burst, positive=True)
    if not L >= 1.0:
        raise ModelError(f"burst = {burst!r}: the mean burst length in samples must be >= 1")
    q = P / (L * (1.0 - P))
    if q > 1.0:
        raise ModelError(f"burst = {burst!r}: with loss = {P:g} the mean burst must be at least "
                         f"P / (1 - P) = {P / (1 - P):.6g} samples (else the chain cannot lose "
                         "that many packets)")
    return np.array([[1.0 - q, q], [1.0 / L, 1.0 - 1.0 / L]])


def _zoh(Ac: np.ndarray, Bc: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation (Van Loan's block exponential)."""
    n, p = Bc.shape
    blk = np.zeros((n + p, n + p))
    blk[:n, :n], blk[:n, n:] = Ac, Bc
    E = sla.expm(blk * T)
    return E[:n, :n], E[:n, n:]


class NetworkedPlant(NamedTuple):
    """The sampled plant and its measurements through the network, as packet loss and
    jitter both build them: structure, stiffness ratios, the built loop, T (s), the
    plant's order, its ZOH matrices, its position rows, the measured terms and which of
    them cross the network."""
    structure: LoopStructure
    ratios: tuple[float, ...]
    system: Any
    period_s: float
    n: int
    Ad: np.ndarray
    Bd: np.ndarray
    pos: np.ndarray
    terms: list[Any]
    net: list[bool]


def networked_plant(loop: Any, what: str = "packet loss") -> NetworkedPlant:
    """:class:`NetworkedPlant` of ``loop`` (refused as :func:`_check` refuses, ``what``
    naming the analysis): with one port every measurement crosses the network; with two,
    each port's reading of the other."""
    st = structure_of(loop)
    ratios = _check(st, what)
    sys = build(loop)
    T = float(sys.periods[0])
    n = sys.n_plant
    Ad, Bd = _zoh(sys.Ac, sys.Bc, T)
    terms = _networked(st)
    single = len(st.ports) == 1
    net = [single or j != st.channels[c].port for (c, j, _, _) in terms]
    return NetworkedPlant(st, ratios, sys, T, n, Ad, Bd, sys.pos[:, :n], terms, net)


def _check(st: LoopStructure, what: str = "packet loss") -> tuple[float, ...]:
    """The stiffness ratio of each channel, refusing what the model does not cover
    (``what`` names the analysis in the messages)."""
    for ch in st.channels:
        c = ch.controller
        if ch.measures != "position":
            raise AnalysisError(f"{what}: modelled for position channels only; this loop "
                                "has force channels (force gains C_2, C_3, C_5, C_6 must be 0)")
        if not c.admits("packet-loss"):
            raise AnalysisError(f"{what}: controller = {c!r}: modelled for spring-damper "
                                "controllers K + B (z - 1)/(T z) (the issue's u = K y + B (y[k] - "
                                "y[k-1]) / T); not a filtered damper or a general H(z)")
        for _, _, d in ch.terms:
            if d != int(d):
                raise AnalysisError(f"{what}: delay = {d:g} samples: modelled for whole "
                                    "samples of delay (a packet is one sample's)")
    ratios = channel_ratios(st)
    if ratios is None:
        raise AnalysisError(f"{what}: K cannot be varied on this loop (give the reference "
                            "controller a stiffness > 0)")
    return ratios


def _networked(st: LoopStructure) -> list[tuple[int, int, float, int]]:
    """(channel, port j, sign, delay) of every term of every channel (which of them are
    networked is decided by :func:`lossy_system`: a term that measures another port, or
    any term of a one-port loop, whose position crosses to the virtual environment)."""
    out = []
    for c, ch in enumerate(st.channels):
        for j, s, d in ch.terms:
            out.append((c, j, float(s), int(d)))
    return out


@dataclass(frozen=True)
class StateLayout:
    """Where each part of a mode's state starts: the plant's ``n_plant`` states, then
    each port's delay registers (from ``off_r[j]``), the held networked values (from
    ``off_h``) and the controllers' previous errors (from ``off_e``); ``N`` in all."""

    n_plant: int
    off_r: list[int]          # first register of each port
    off_h: int                # first held value
    off_e: int                # first previous error
    N: int


def state_layout(st: LoopStructure, n_plant: int, terms: list, net: list[bool]) -> StateLayout:
    """The state's layout for the structure ``st``: as many registers per port as its
    deepest delay among ``terms`` (channel, port, gain, delay), one held value per
    networked term (``net``) and one previous error per channel."""
    p = len(st.ports)
    depth = [0] * p
    for (_, j, _, d) in terms:
        depth[j] = max(depth[j], d)
    off_r = list(n_plant + np.concatenate([[0], np.cumsum(depth)]).astype(int))
    off_h = off_r[-1]
    off_e = off_h + sum(net)
    return StateLayout(n_plant, off_r, off_h, off_e, off_e + len(st.channels))


def source_row(lay: StateLayout, pos: np.ndarray, j: int, d: int) -> np.ndarray:
    """Row selecting x_j[k - d] from the state."""
    r = np.zeros(lay.N)
    if d == 0:
        r[:lay.n_plant] = pos[j]
    else:
        r[lay.off_r[j] + d - 1] = 1.0
    return r


def mode_matrices(st: LoopStructure, lay: StateLayout, parts: tuple, terms: list, net: list[bool],
          lost: int) -> tuple[np.ndarray, np.ndarray]:
    """(A0_i, A1_i) of the mode whose lost terms are the set bits of ``lost``."""
    Ad, Bd, pos, ratios, T = parts
    N, n, p = lay.N, lay.n_plant, len(st.ports)
    E = np.zeros((len(st.channels), N))
    A0 = np.zeros((N, N))
    h = 0
    for (c, j, s, d), is_net in zip(terms, net, strict=True):
        y = source_row(lay, pos, j, d)
        if is_net:
            if lost >> h & 1:
                y = np.zeros(N)
                y[lay.off_h + h] = 1.0
            A0[lay.off_h + h] = y                 # the held value y_t[k] for k + 1
            h += 1
        E[c] += s * y
    F0, F1 = np.zeros((p, N)), np.zeros((p, N))
    for c, ch in enumerate(st.channels):
        BT = getattr(ch.controller, "damping", 0.0) / T
        prev = np.zeros(N)
        prev[lay.off_e + c] = 1.0
        F0[ch.port] += BT * (E[c] - prev)
        F1[ch.port] += ratios[c] * E[c]
        A0[lay.off_e + c] = E[c]
    A0[:n, :n] = Ad
    A0[:n] -= Bd @ F0
    for j in range(p):
        for step in range(lay.off_r[j + 1] - lay.off_r[j]):
            r = lay.off_r[j] + step
            A0[r] = source_row(lay, pos, j, step)    # x_j[k - step] is x_j[k+1 - (step + 1)]
    A1 = np.zeros((N, N))
    A1[:n] = -Bd @ F1
    return A0, A1


def rigid_householder(A0: np.ndarray, A1: np.ndarray, lay: StateLayout, pos: np.ndarray
                      ) -> np.ndarray | None:
    """The similarity H (H = H^T = H^-1) whose first column is the rigid-body mode (every
    position, register and held value 1, velocities and previous errors 0), when that is
    an exact eigenvector at z = 1 of every mode for every K; else None."""
    v = np.zeros(lay.N)
    v[:lay.n_plant] = pos.sum(axis=0)
    v[lay.n_plant:lay.off_e] = 1.0
    scale = max(1.0, float(np.abs(A0).max()))
    # 1e-12 relative: the eigenvector equation holds to rounding of the matrices' entries
    if not (np.abs(A0 @ v - v).max() <= 1e-12 * scale and np.abs(A1 @ v).max()
            # a floor against division by zero / rounding, far below the answer's own accuracy
            <= 1e-12 * max(1.0, float(np.abs(A1).max()))):
        return None
    u = v / np.linalg.norm(v)
    w = u.copy()
    w[0] -= 1.0
    if not np.any(w):
        return np.eye(lay.N)
    return np.eye(lay.N) - 2.0 * np.outer(w, w) / (w @ w)       # H u = e1, H = H^T = H^-1


def _deflate(A0: np.ndarray, A1: np.ndarray, lay: StateLayout, pos: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, bool]:
    """Remove the rigid-body mode (:func:`rigid_householder`) by an exact similarity, as
    the exact core divides it out."""
    H = rigid_householder(A0, A1, lay, pos)
    if H is None:
        return A0, A1, False
    return (H @ A0 @ H)[:, 1:, 1:], (H @ A1 @ H)[:, 1:, 1:], True


def lossy_system(loop, loss: float, burst: float | None = None) -> JumpSystem:
    """The loop with packet loss on every networked term, as a Markov jump linear system.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controllers, whole-sample delays; K is varied as everywhere
        (the master's stiffness, K_s / K_m kept).
    loss : float
        P in [0, 1): each networked term's long-run fraction of lost packets.
    burst : float, optional
        Mean burst length L (samples) of a Gilbert-Elliott chain; ``None``: independent
        losses. Each networked term has its own chain, independent of the others.

    Returns
    -------
    JumpSystem
    """
    st, ratios, sys, T, n, Ad, Bd, pos, terms, net = networked_plant(loop)
    lay = state_layout(st, n, terms, net)
    m = sum(net)
    mats = [mode_matrices(st, lay, (Ad, Bd, pos, ratios, T), terms, net, i) for i in range(2 ** m)]
    A0, A1 = np.array([a for a, _ in mats]), np.array([b for _, b in mats])
    deflated = False
    if sys.rigid_modes:
        A0, A1, deflated = _deflate(A0, A1, lay, pos)
    chain = loss_chain(loss, burst)
    Pi = np.ones((1, 1))
    for _ in range(m):
        Pi = np.kron(chain, Pi)                    # term t is bit t of the mode index
    stat = _stationary(Pi)
    names = tuple(term_name(st, c, j) for (c, j, _, _), is_net in zip(terms, net, strict=True)
                  if is_net)
    return JumpSystem(A0, A1, Pi, stat, names, T, deflated)


def _stationary(Pi: np.ndarray) -> np.ndarray:
    w, V = np.linalg.eig(Pi.T)
    v = np.real(V[:, int(np.argmin(np.abs(w - 1.0)))])
    return v / v.sum()


def term_name(st: LoopStructure, c: int, j: int) -> str:
    """The words for channel c's term in port j's position: ``"device position"``, or
    ``"slave -> master"`` when it crosses from one port to another."""
    src, dst = st.ports[j].name, st.ports[st.channels[c].port].name
    return f"{src} position" if src == dst else f"{src} -> {dst}"
