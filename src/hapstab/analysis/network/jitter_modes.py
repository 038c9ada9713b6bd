"""A loop whose delay varies from sample to sample, as a switched linear system, and the
admissible periodic delay patterns.

**The model (newest sample arrived).** Every position that crosses the network (the
HVE's device position; each direction of PEB, independently) is sampled at kT and sent;
its packet takes a transport delay of any whole number of samples in [lo, hi], packet by
packet, arriving in any order. At sample k the controller uses the *newest* sample of
that position that has arrived, x[k - d_k]: its age d_k is then in [lo, hi] (sample
k - hi has arrived, no sample newer than k - lo can have), and since what had arrived at
k is still there at k + 1,

    d_{k+1} <= d_k + 1:

the age grows by at most one per sample (it grows by exactly one when nothing newer
arrived: the controller re-uses the sample it used at k, never an older one) and may
fall by any amount at once (a fresh packet). Conversely every sequence with
lo <= d_k <= hi and d_{k+1} <= d_k + 1 is produced by some transport delays in
[lo, hi] (let sample j arrive at the first k with k - d_k >= j): these are the
*admissible* sequences. The controller is the spring-damper on what it uses,
``u[k] = K y[k] + (B / T)(y[k] - y[k-1])`` with ``y[k] = x[k - d_k]`` (y[k-1] the value
it used at k-1, kept in the state; PEB: each controller on its signed sum of its own
position and the other's, as in :mod:`.jump`).

The closed loop at the samples is ``s[k+1] = A_{d_k}(K) s[k]``, one mode per delay (per
pair of delays for PEB), ``A_d(K) = A0_d + K A1_d``, on a state holding the plant
(the engine's realisation, ZOH exact), hi past positions of every networked port and the
previous error of each controller: the matrices are :mod:`.jump`'s, with every packet
received and the delay of each networked term set to d.

References
----------
R. M. Jungers, *The Joint Spectral Radius: Theory and Applications*, Springer 2009
(switched systems x[k+1] = A_{sigma_k} x[k]; rho(A_{s_p} ... A_{s_1})^(1/p) of any
product is a lower bound of the joint spectral radius, and with a periodic pattern it
is the growth rate of that pattern). X. Dai, "A Gel'fand-type spectral radius formula
and stability of linear constrained switching systems", Linear Algebra Appl. 436 (2012)
(the same with the switching constrained by a graph, here d_{k+1} <= d_k + 1).
The loop: the paper, Fig. 2a (HVE) and eq. (20) (PEB).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from hapstab.analysis.network.jump import (
    mode_matrices,
    networked_plant,
    rigid_householder,
    source_row,
    state_layout,
    term_name,
)
from hapstab.errors import AnalysisError, ModelError

__all__ = ["JitterModes", "jitter_modes", "patterns", "pattern_rates",
           "MAX_PATTERNS", "at_lo"]

#: The most periodic patterns the lower bound enumerates (all lengths together): the
#: longest length is the largest whose patterns still fit (a bound on the work, which
#: is patterns x length matrix products and one eigenvalue solve per pattern and K).
MAX_PATTERNS = 4000


@dataclass(frozen=True)
class JitterModes:
    """The loop with a time-varying delay as a switched linear system.

    Attributes
    ----------
    A0, A1 : (M, N, N) arrays
        Mode i's closed loop is ``A0[i] + K * A1[i]``.
    delays : tuple of tuple of int
        Mode i's delay (samples) of each networked term.
    B0, B1 : (N, m) arrays
        The input of r_t, the jitter of term t, at the nominal mode (every delay lo):
        ``A_d = A_lo + sum_t (B0 + K B1)[:, t] (c_{t,d_t} - c_{t,lo})``.
    C : (m, N) array
        ``w_t[k] = x_t[k - lo] - x_t[k - lo - 1]`` (the nominal measurement's backward
        difference) of each networked term; zero rows when hi = lo.
    nominal : int
        The mode with every delay lo.
    lo, hi : int
        The range of delays, samples.
    terms : tuple of str
        The networked terms.
    period : float
        T in s.
    deflated : bool
        A rigid-body mode (z = 1 for every K and mode) was removed by an exact similarity.
    """

    A0: np.ndarray
    A1: np.ndarray
    delays: tuple[tuple[int, ...], ...]
    B0: np.ndarray
    B1: np.ndarray
    C: np.ndarray
    nominal: int
    lo: int
    hi: int
    terms: tuple[str, ...]
    period: float
    deflated: bool = False

    @property
    def order(self) -> int:
        return int(self.A0.shape[-1])

    def at(self, K: float) -> np.ndarray:
        """The mode matrices at stiffness K, (M, N, N)."""
        return self.A0 + K * self.A1


def at_lo(loop, lo: int):
    """The loop with every networked delay lo (whole samples, no fractional part).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
    lo : int
        Samples.

    Returns
    -------
    HapticLoop or TeleoperationLoop
    """
    if len(loop.controllers) == 2:
        return loop.replace(delay_samples=lo, delay_backward_samples=lo, fractional_delay=0.0,
                            fractional_delay_backward=None)
    return loop.with_whole_delay(lo)


def jitter_modes(loop, lo: int, hi: int) -> JitterModes:
    """The mode matrices of ``loop`` with each networked delay anywhere in [lo, hi].

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controllers (its own delay is replaced by the range).
    lo, hi : int
        Whole samples, 0 <= lo <= hi.

    Returns
    -------
    JitterModes
    """
    if getattr(loop, "force_gains", None) is not None:
        raise AnalysisError("jitter: modelled for hve and peb (the 4-channel loop's force "
                            "channels are not)")
    if not (isinstance(lo, int) and isinstance(hi, int) and 0 <= lo <= hi):
        raise ModelError(f"delay range = {lo!r}:{hi!r}: whole samples, 0 <= start <= end")
    st, ratios, sys, T, n, Ad, Bd, pos, terms, net = networked_plant(at_lo(loop, lo), "jitter")
    nets = [i for i, is_net in enumerate(net) if is_net]
    # hi registers: x[k - 1] ... x[k - hi] (w's x[k - lo - 1] is one when hi > lo)
    deep = [(c, j, s, hi if is_net else d) for (c, j, s, d), is_net in zip(terms, net,
                                                                               strict=True)]
    none = [False] * len(terms)
    lay = state_layout(st, n, deep, none)
    parts = (Ad, Bd, pos, ratios, T)

    def mode(ds: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        at = list(terms)
        for h, i in enumerate(nets):
            c, j, s, _ = terms[i]
            at[i] = (c, j, s, ds[h])
        return mode_matrices(st, lay, parts, at, none, 0)

    delays = tuple(itertools.product(range(lo, hi + 1), repeat=len(nets)))
    mats = [mode(ds) for ds in delays]
    A0, A1 = np.array([a for a, _ in mats]), np.array([b for _, b in mats])
    B0, B1, C = (np.zeros((lay.N, len(nets))), np.zeros((lay.N, len(nets))),
                 np.zeros((len(nets), lay.N)))
    for h, i in enumerate(nets):
        if hi == lo:
            break
        _, j, _, _ = terms[i]
        up = tuple(lo + (g == h) for g in range(len(nets)))
        a0, a1 = mode(up)
        col = lay.off_r[j] + lo                 # the register of x_j[k - lo - 1]
        B0[:, h], B1[:, h] = a0[:, col] - A0[0][:, col], a1[:, col] - A1[0][:, col]
        C[h] = source_row(lay, pos, j, lo) - source_row(lay, pos, j, lo + 1)
    deflated = False
    if sys.rigid_modes:
        H = rigid_householder(A0, A1, lay, pos)
        if H is not None:
            A0, A1 = (H @ A0 @ H)[:, 1:, 1:], (H @ A1 @ H)[:, 1:, 1:]
            B0, B1, C = (H @ B0)[1:], (H @ B1)[1:], (C @ H)[:, 1:]
            deflated = True
    names = tuple(term_name(st, terms[i][0], terms[i][1]) for i in nets)
    return JitterModes(A0, A1, delays, B0, B1, C, 0, lo, hi, names, T, deflated)


def _walks(lo: int, hi: int, p: int) -> list[tuple[int, ...]]:
    """Every cyclically admissible sequence of length p over [lo, hi] whose first entry is
    its minimum (each closed walk has such a rotation): depth-first, entries >= the first,
    each at most one above the one before (a Catalan number of them per start)."""
    out: list[tuple[int, ...]] = []

    def grow(seq: list[int]) -> None:
        if len(seq) == p:
            out.append(tuple(seq))                # closing seq[-1] -> seq[0] <= seq[-1] + 1
            return
        for v in range(seq[0], min(hi, seq[-1] + 1) + 1):
            grow([*seq, v])

    for s0 in range(lo, hi + 1):
        grow([s0])
    return out


def _canonical(seq: tuple) -> bool:
    """seq is the least of its rotations and not a repetition of a shorter pattern."""
    p = len(seq)
    return all(seq < seq[i:] + seq[:i] for i in range(1, p))


def patterns(lo: int, hi: int, terms: int, max_length: int,
             budget: int = MAX_PATTERNS) -> list[tuple[tuple[int, ...], ...]]:
    """Every admissible periodic delay pattern of length <= ``max_length`` (one per
    rotation class, primitive ones only: a repeated pattern has its root's growth rate),
    lengths added while the total stays within ``budget``.

    Parameters
    ----------
    lo, hi : int
        The range of delays, samples.
    terms : int
        Networked terms (1: HVE, 2: PEB, each with its own delay).
    max_length : int
        The longest pattern, samples (>= 1).
    budget : int
        The most patterns (the constant ones are always there, even beyond it).

    Returns
    -------
    list of tuple of tuple of int
        Each pattern: the delays of every term at each sample of a period.
    """
    # the constant delays always (the budget may stop the lengths after them)
    out: list[tuple[tuple[int, ...], ...]] = [
        tuple([d]) for d in itertools.product(range(lo, hi + 1), repeat=terms)]
    for p in range(2, max_length + 1):
        walks = _walks(lo, hi, p)
        rot = sorted({w[i:] + w[:i] for w in walks for i in range(p)})
        if len(rot) ** terms > budget * p * 4:        # far beyond: do not even form them
            break
        new = [tuple(zip(*combo, strict=True)) for combo in itertools.product(rot, repeat=terms)]
        new = [q for q in new if _canonical(q)]
        if len(out) + len(new) > budget:
            break
        out += new
    return out


def pattern_rates(mats: np.ndarray, index: dict[tuple[int, ...], int],
                  pats: list[tuple[tuple[int, ...], ...]]) -> np.ndarray:
    """rho(A_{d_p} ... A_{d_1})^(1/p) of every pattern, the mode matrices ``mats`` at
    one K (``index``: delays -> mode).

    Parameters
    ----------
    mats : (M, N, N) array
    index : dict
    pats : list of patterns

    Returns
    -------
    array of float, one per pattern
    """
    rates = np.zeros(len(pats))
    by_len: dict[int, list[int]] = {}
    for i, q in enumerate(pats):
        by_len.setdefault(len(q), []).append(i)
    for p, which in by_len.items():
        idx = np.array([[index[d] for d in pats[i]] for i in which])
        prod = mats[idx[:, 0]]
        for s in range(1, p):
            prod = mats[idx[:, s]] @ prod
        rho = np.abs(np.linalg.eigvals(prod)).max(axis=1)
        rates[which] = rho ** (1.0 / p)
    return rates
