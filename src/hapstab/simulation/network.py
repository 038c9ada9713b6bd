"""A network between the device and the controller in simulation: a varying delay and
lost packets, from a measured trace or drawn at random.

**The model** is the analyses' (:mod:`hapstab.analysis.network.jitter_modes` and
:mod:`hapstab.analysis.network.jump`). Every position that crosses the network (the
HVE's device position; each direction of PEB, independently) is sampled at kT and sent
in its own packet. The packet of sample j takes a transport delay of ``delta_j`` whole
samples (it arrives at sample j + delta_j) or is lost. At sample k the controller uses
the *newest* sample that has arrived, y[k] = x[k - d_k] with
d_k = k - max{j : packet j arrived at or before k}: its age grows by at most one per
sample (d_{k+1} <= d_k + 1) and falls at once when a fresher packet arrives. When
nothing newer has arrived, the receiver holds the value it used: y[k] = y[k-1]. With a
constant transport delay n this is exactly the loss model of :mod:`.jump`
(y[k] = x[k - n] if the packet of sample k - n arrived, else y[k-1]): packet k - n lost
leaves sample k - n - 1 the newest, which is what was used at k - 1. The controller acts
on what it uses, its own state (the spring-damper's previous value y[k-1]) included.
The history before the run is at rest: the samples j < 0 arrive with the largest delay
``hi`` of the network (so the first samples see what a constant delay hi shows).

**Simulation.** The loop is built with the delay ``hi`` (the engine's shift registers
then hold x[k-1] ... x[k-hi] of each networked port) and stepped sample by sample
(:func:`hapstab.simulation.stepper.step_nonlinear`); at each sample the entry the
controller reads, the register of x[k - hi], is replaced in what the controller
*measures* by the value the network delivers (register d_k, the position itself for
d_k = 0, or the held value). The physical registers are untouched.

A trace file is read by :func:`hapstab.simulation.network_trace.read_trace` (its format
there and in docs/guide/networks.md).

References
----------
The models: :mod:`hapstab.analysis.network.jitter_modes` (newest sample arrived,
Jungers 2009), :mod:`hapstab.analysis.network.jump` (hold the last value; Costa,
Fragoso & Marques 2005). J.-H. Ryu, J. Artigas and C. Preusche, "A passive bilateral
control scheme for a teleoperator with time-varying communication delay",
Mechatronics 20(7):812-823, 2010 (TDPA with the energies sent with the packets).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.errors import MAX_DELAY_SAMPLES, ModelError, check_real

__all__ = ["Network", "trace", "from_ages", "network_options", "NetworkLine", "tdpa_rows",
           "network_loop", "wire"]


@dataclass(frozen=True, eq=False)
class Network:
    """The network of a simulation: a trace, or random delays and losses.

    Attributes
    ----------
    delay_samples : (m, n) int array or None
        A trace: the transport delay of the packet of each sample 0..n-1, one row per
        direction (one row: every direction the same).
    arrived : (m, n) bool array or None
        A trace: whether that packet arrived.
    jitter : (lo, hi) or None
        Random mode: each packet's transport delay uniform on the whole samples
        lo..hi, independently.
    loss : float
        Random mode: each packet is lost with this probability, independently.
    seed : int
        Random mode: the seed of :func:`numpy.random.default_rng` (same seed, same run).
    source : str or None
        Where a trace came from (a file name), for the record.
    """

    delay_samples: np.ndarray | None = None
    arrived: np.ndarray | None = None
    jitter: tuple[int, int] | None = None
    loss: float = 0.0
    seed: int = 0
    source: str | None = None

    @property
    def hi(self) -> int:
        """The largest transport delay, samples."""
        if self.jitter is not None:
            return self.jitter[1]
        assert self.delay_samples is not None
        return int(self.delay_samples.max())

    def to_dict(self) -> dict[str, Any]:
        if self.jitter is not None:
            return {"mode": "random", "jitter_samples": list(self.jitter), "loss": self.loss,
                    "seed": self.seed}
        assert self.delay_samples is not None and self.arrived is not None
        return {"mode": "trace", "source": self.source, "rows": int(self.delay_samples.shape[1]),
                "delay_samples_range": [int(self.delay_samples.min()), self.hi],
                "lost_fraction": float(1.0 - self.arrived.mean())}

    def schedule(self, n_terms: int, M: int) -> tuple[np.ndarray, np.ndarray]:
        """Transport delays and arrivals of the packets of samples 0..M, (n_terms, M+1).

        Parameters
        ----------
        n_terms : int
            The networked signals of the loop.
        M : int
            Samples of the run.

        Returns
        -------
        (delays, arrived) : (n_terms, M+1) int and bool arrays

        Raises
        ------
        ModelError
            A trace shorter than the run, or with more directions than the loop has.
        """
        if self.jitter is not None:
            rng = np.random.default_rng(self.seed)
            lo, hi = self.jitter
            d, a = np.zeros((n_terms, M + 1), int), np.zeros((n_terms, M + 1), bool)
            for t in range(n_terms):          # each direction independently, in order
                d[t] = rng.integers(lo, hi + 1, size=M + 1)
                a[t] = rng.random(M + 1) >= self.loss
            return d, a
        assert self.delay_samples is not None and self.arrived is not None
        n = self.delay_samples.shape[1]
        if n < M + 1:
            raise ModelError(f"network: the trace has {n} rows (samples 0..{n - 1}); the run "
                             f"needs {M + 1} (samples 0..{M}): give a longer trace or a "
                             f"duration of at most {n - 1} samples")
        rows = self.delay_samples.shape[0]
        if rows not in (1, n_terms):
            raise ModelError(f"network: the trace has {rows} directions; this loop has "
                             f"{n_terms} networked signals (allowed: 1, or {n_terms})")
        take = np.arange(n_terms) if rows == n_terms else np.zeros(n_terms, int)
        return self.delay_samples[take, :M + 1], self.arrived[take, :M + 1]


def _whole(name: str, v: Any) -> int:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer, float)) \
            or not float(v) == math.floor(float(v)) or not 0 <= float(v) <= MAX_DELAY_SAMPLES:
        raise ModelError(f"{name} = {v!r}: must be a whole number of samples in "
                         f"[0, {MAX_DELAY_SAMPLES}]")
    return int(v)


def network_options(network: Any) -> Network | None:
    """A :class:`Network` from what ``simulate(..., network=...)`` received: None, a
    Network, or a dict with ``jitter=(lo, hi)`` (whole samples), ``loss`` and ``seed``,
    or ``delay_samples`` (and ``arrived``) for a trace.

    Parameters
    ----------
    network : None, Network or dict
        What ``simulate`` received.

    Returns
    -------
    Network or None

    Raises
    ------
    ModelError
        Anything else, naming the field.
    """
    if network is None or (isinstance(network, Network) and _checked(network)):
        return network
    if not isinstance(network, dict):
        raise ModelError(f"network = {network!r}: allowed: None, a Network, or a dict with "
                         "jitter=(lo, hi), loss, seed (random) or delay_samples, arrived (trace)")
    unknown = set(network) - {"jitter", "loss", "seed", "delay_samples", "arrived", "source"}
    if unknown:
        raise ModelError(f"network: unknown field(s) {sorted(unknown)}; allowed: jitter, loss, "
                         "seed, delay_samples, arrived, source")
    if "delay_samples" in network:
        if set(network) & {"jitter", "loss", "seed"}:
            raise ModelError("network: a trace (delay_samples) or random delays (jitter, loss, "
                             "seed), not both")
        d = np.atleast_2d(np.asarray(network["delay_samples"]))
        a = network.get("arrived")
        a = np.ones(d.shape, bool) if a is None else np.atleast_2d(np.asarray(a))
        return trace(d, a, network.get("source"))
    jit = network.get("jitter", (0, 0))
    try:
        lo, hi = jit
    except (TypeError, ValueError):
        raise ModelError(f"network jitter = {jit!r}: must be (lo, hi), whole samples") from None
    net = Network(jitter=(_whole("jitter lo", lo), _whole("jitter hi", hi)),
                  loss=check_real("network loss", network.get("loss", 0.0)),
                  seed=network.get("seed", 0))
    _checked(net)
    return net


def _checked(net: Network) -> bool:
    if net.jitter is not None:
        lo, hi = net.jitter
        if not lo <= hi:
            raise ModelError(f"network jitter = {lo}:{hi}: need lo <= hi (whole samples)")
        P = check_real("loss", net.loss, nonnegative=True)
        if not P < 1.0:
            raise ModelError(f"loss = {net.loss!r}: must be in [0, 1) (the fraction of packets "
                             "lost)")
        if isinstance(net.seed, bool) or not isinstance(net.seed, (int, np.integer)) \
                or net.seed < 0:
            raise ModelError(f"seed = {net.seed!r}: must be a whole number >= 0")
    elif net.delay_samples is None or net.arrived is None:
        raise ModelError("network: give jitter (random) or delay_samples (a trace)")
    return True


def trace(delay_samples: Any, arrived: Any = None, source: str | None = None) -> Network:
    """A trace network from arrays (one row per direction, one column per sample).

    Parameters
    ----------
    delay_samples : array of int
        Each packet's transport delay, samples, (n,) or (m, n).
    arrived : array of bool or 0 / 1, optional
        Whether it arrived (default: every one).
    source : str, optional
        Where it came from, for the record.

    Returns
    -------
    Network

    Raises
    ------
    ModelError
        Delays not whole samples >= 0, arrivals not 0 / 1, or shapes that differ.
    """
    try:
        if isinstance(delay_samples, (str, bytes)) or np.iscomplexobj(delay_samples):
            raise TypeError
        d = np.atleast_2d(np.asarray(delay_samples, dtype=float))
    except (TypeError, ValueError, OverflowError):
        raise ModelError(f"network trace: delay_samples = {delay_samples!r:.60}: must be an "
                         "array of whole samples (a row per direction)") from None
    a = np.ones(d.shape, bool) if arrived is None else np.atleast_2d(np.asarray(arrived))
    if d.ndim != 2 or d.shape[1] < 1 or a.shape != d.shape:
        raise ModelError(f"network trace: delay_samples of shape {d.shape} and arrived of shape "
                         f"{a.shape}: need the same shape (directions, samples)")
    bad = ~(np.isfinite(d) & (d == np.floor(d)) & (d >= 0) & (d <= MAX_DELAY_SAMPLES))
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise ModelError(f"network trace: delay_samples[{r}][{c}] = {d[r, c]!r}: must be a whole "
                         f"number of samples in [0, {MAX_DELAY_SAMPLES}]")
    if a.dtype != bool:
        okv = np.isin(a, (0, 1))
        if not okv.all():
            r, c = np.argwhere(~okv)[0]
            raise ModelError(f"network trace: arrived[{r}][{c}] = {a[r, c]!r}: must be 1 or 0")
        a = a.astype(bool)
    return Network(delay_samples=d.astype(int), arrived=a, source=source)


def from_ages(ages: Any) -> Network:
    """The trace whose newest-arrived ages are ``ages`` (one row per direction).

    An age sequence with d_{k+1} <= d_k + 1 is produced by letting sample j arrive at
    the first k with k - d_k >= j (:mod:`hapstab.analysis.network.jitter_modes`); a
    sample no k reaches is sent with the largest age (it arrives after the sequence).

    Parameters
    ----------
    ages : sequence of int, or (m, n) array
        The age d_k used at each sample, one row per direction.

    Returns
    -------
    Network
        A trace (every packet arrives).

    Raises
    ------
    ModelError
        An age sequence that rises by more than one per sample, or not whole >= 0.
    """
    A = np.atleast_2d(np.asarray(ages))
    out = np.zeros(A.shape, int)
    for t, row in enumerate(A):
        checked = trace(row).delay_samples      # checks whole >= 0
        assert checked is not None
        d = checked[0]
        jump = np.flatnonzero(np.diff(d) > 1)
        if jump.size:
            k = int(jump[0]) + 1
            raise ModelError(f"ages[{k}] = {d[k]} after {d[k - 1]}: the newest sample that has "
                             "arrived ages by at most one per sample (d_(k+1) <= d_k + 1)")
        n = d.size
        newest = np.arange(n) - d             # nondecreasing
        first = np.searchsorted(newest, np.arange(n), side="left")   # first k with newest >= j
        out[t] = np.where(first < n, first - np.arange(n), d.max())
    return trace(out)


class NetworkLine:
    """The network in the stepping: replaces, in what the controller measures, the
    register each networked signal is read from by the value the network delivers.

    Parameters
    ----------
    network : Network
    targets : sequence of int
        Per networked signal, the state entry the controller reads (x[k - hi]).
    sources : sequence of sequence of int
        Per signal, the state entry of x[k - d] for d = 0..n, n = max(hi, 1) (at k = 0
        the age is at most n, so a value is read before any is held).
    M : int
        Samples of the run.
    """

    def __init__(self, network: Network, targets: Any, sources: Any, M: int) -> None:
        self.network = network
        self.targets = np.asarray(targets, int)
        m, hi = self.targets.size, network.hi
        delay, arrived = network.schedule(m, M)
        j = np.arange(M + 1)
        best = np.full((m, M + 1), np.iinfo(np.int64).min // 2)
        for t in range(m):
            at = j + delay[t]
            ok = arrived[t] & (at <= M)
            np.maximum.at(best[t], at[ok], j[ok])
        hist = np.minimum(j - hi, -1)            # the history: sample j < 0 arrives at j + hi
        newest = np.maximum.accumulate(np.maximum(best, hist[None, :]), axis=1)
        self.age = j[None, :] - newest           # (m, M+1): the age used at each sample
        src = np.asarray(sources, int)           # (m, n + 1), n = max(hi, 1) registers
        n = src.shape[1] - 1
        self.src = np.where(self.age <= n, np.take_along_axis(
            src, np.minimum(self.age, n), axis=1), -1)
        self.newest = newest
        self.held = np.zeros(m)

    def reset(self) -> None:
        """Forget the held values (a new run through the same delays and losses)."""
        self.held = np.zeros(self.targets.size)

    def __call__(self, k: int, sm: np.ndarray) -> None:
        """Put the delivered values into the measured state ``sm`` at sample k (in place).

        Parameters
        ----------
        k : int
            The sample.
        sm : (N,) array
            What the controller measures.
        """
        s = self.src[:, k]
        fresh = s >= 0
        self.held[fresh] = sm[s[fresh]]           # read every source before writing
        sm[self.targets] = self.held

    def summary(self) -> dict[str, Any]:
        """The ages the controller used (samples) and how often it re-used the value of
        the sample before (nothing newer had arrived)."""
        same = np.diff(self.newest, axis=1) == 0
        return {"age_samples_range": [int(self.age.min()), int(self.age.max())],
                "held_fraction": float(same.mean()) if same.size else 0.0}


def tdpa_rows(line: NetworkLine, port_of_term: Any, n_ports: int) -> np.ndarray | None:
    """Per port and sample, the row of the other port's input energy its PO may use:
    the newest sample of the other's position it has (the energies travel with the
    positions, Ryu, Artigas & Preusche 2010), at least one sample old.

    Parameters
    ----------
    line : NetworkLine
    port_of_term : sequence of (int, int)
        (controller port, source port) of each networked signal.
    n_ports : int

    Returns
    -------
    (p, M+1) int array, or None for one port
    """
    if n_ports < 2:
        return None
    k = np.arange(line.newest.shape[1])
    rows = np.full((n_ports, k.size), -1)
    for t, (dst, _src) in enumerate(port_of_term):
        rows[dst] = np.minimum(line.newest[t], k - 1)
    return rows


def network_loop(net: Network, loop: Any) -> Any:
    """The loop to build for a run with ``net``: every networked delay ``max(hi, 1)``
    whole samples (the registers the network reads); refuses what is not modelled.

    Parameters
    ----------
    net : Network
    loop : HapticLoop or TeleoperationLoop

    Returns
    -------
    HapticLoop or TeleoperationLoop

    Raises
    ------
    ModelError
        A 4-channel loop (force channels), or a scaled teleoperator.
    """
    if getattr(loop, "force_gains", None) is not None:
        raise ModelError("network: simulated for hve and peb (position channels); the 4-channel "
                         "loop's force channels are not (allowed: network=None)")
    n = max(net.hi, 1)
    if len(loop.controllers) == 2:
        return loop.replace(delay_samples=n, delay_backward_samples=n, fractional_delay=0.0,
                            fractional_delay_backward=None)
    return loop.with_whole_delay(n)


def wire(net: Network, loop: Any, sysm: Any, roles: Any, M: int) -> tuple[Any, NetworkLine,
                                                                          list]:
    """The roles of the state for a run through ``net`` and its :class:`NetworkLine`.

    ``loop`` is :func:`network_loop`'s. The controller states become controller rows
    (updated from what the controller measured, the network's values), no longer
    copies of a register; the registers of each port are x[k-1] ... x[k-n].

    Parameters
    ----------
    net : Network
    loop : HapticLoop or TeleoperationLoop
        :func:`network_loop`'s.
    sysm : SampledSystem
        ``build(loop)``.
    roles : Roles
        :func:`hapstab.simulation.stepper.roles_of`'s.
    M : int
        Samples of the run.

    Returns
    -------
    (roles, line, terms): terms are (controller port, source port) of each networked
    signal.
    """
    from hapstab.engine.structure import structure_of

    st = structure_of(loop)
    npl, p, n = sysm.n_plant, sysm.n_ports, max(net.hi, 1)
    pos_idx = np.argmax(sysm.pos, axis=1)
    A = roles.A
    reg = lambda j, lag: int(pos_idx[j]) if lag == 0 else npl + j * n + lag - 1  # noqa: E731
    for j in range(p):                         # the layout this relies on, checked
        ok = np.array_equal(A[reg(j, 1)], sysm.pos[j]) and all(
            A[reg(j, lag + 1), reg(j, lag)] == 1.0 for lag in range(1, n))
        if not ok:
            raise ModelError("network: this loop's delay registers are not the plain shift "
                             "registers the network reads (allowed: hve, peb)")
    terms = [(ch.port, j) for ch in st.channels for (j, _s, _d) in ch.terms
             if p == 1 or j != ch.port]
    targets = [reg(j, n) for (_c, j) in terms]
    sources = [[reg(j, lag) for lag in range(n + 1)] for (_c, j) in terms]
    phys = np.zeros(sysm.order, bool)
    phys[:npl + p * n] = True
    pe = np.concatenate([pos_idx, npl + np.arange(p * n)]).astype(int)
    port = np.concatenate([np.arange(p), np.repeat(np.arange(p), n)]).astype(int)
    order = np.argsort(pe)
    roles = dataclasses.replace(roles, physical=phys, pos_entries=pe[order], pos_port=port[order])
    return roles, NetworkLine(net, targets, sources, M), terms
