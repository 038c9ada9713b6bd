"""det M of a two-port loop with any channels: several controllers per port, force
channels, each term with its own whole delay (Lawrence's 4-channel architecture).

With ports j (``x_j = N_j/d_j (-u_j)``, termination force ``Ft_j = R_j/d_j (-u_j)``),
each channel c on port i adds ``H_c(z) s z^-n`` times the measured numerator to
``W_ij``: ``H_c = K k_c + beta_c (1 - z^-1)`` for a position channel, a constant gain
for a force channel. Then

    det M = (d_0 + W_00)(d_1 + W_11) - W_01 W_10

is expanded symbolically into products of port polynomials (``d_j, N_j, R_j``), powers
of h = 1 - z^-1 and of K, each with a scalar coefficient and a delay phase
``z^-n``. Products of the same polynomials and the same powers are grouped and their
phases combined as ``sum_n c_n z^-n = z^-n0 [sum c - sum c_n (1 - z^-(n - n0))]``: the
``(1 - z^-m)`` are evaluated without cancellation, so PEB gains (C_1 = C_s,
C_4' = C_m) give the K^2 coefficient ``N_0 N_1 (1 - w)`` as PEB's own analysis does,
and exactly 0 without delay. A coefficient sum that is 0 in floating point is 0 (the
model means the gains as given: the rigid-body rule forms the same products).

Rigid-body mode: every group then carries a factor y = z - 1 (h = y z^-1, a free
port's d_j = y dhat_j and R_j = y Rhat_j), or its coefficients sum to 0 and
``(1 - z^-m)/y = z^-m G_m`` divides instead; it is divided out exactly.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from typing import Any

import numpy as np

from hapstab.engine.discs import (
    EPS_OP,
    Jet,
    const,
    delay_jet,
    geometric_sum_jet,
    one_minus_delay_jet,
    zero,
)
from hapstab.errors import AnalysisError

__all__ = ["generic_coefficients"]

#: A term: (power of K, coefficient per item, power of h, delay, port polynomials).
Term = tuple[int, np.ndarray, int, int, tuple[str, ...]]


def _entries(resp: Any, idx: np.ndarray) -> dict[tuple[int, int], list[Term]]:
    """The terms of every W_ij (items ``idx``); u = K / scale carries the scale."""
    W: dict[tuple[int, int], list[Term]] = defaultdict(list)
    for c, (port, kind, terms) in enumerate(zip(resp.channel_ports, resp.kinds, resp.terms,
                                                strict=True)):
        for j, s, n, f in terms:
            if f:
                raise AnalysisError("fractional delay: a loop with several channels per port "
                                    "takes whole samples of delay only")
            if kind == "force":
                W[port, j].append((0, s * resp.gain[idx, c], 0, n, (f"R{j}",)))
                continue
            k, beta = resp.k[idx, c], resp.beta[idx, c]
            if np.any(k):
                W[port, j].append((1, s * k * resp.scale[idx], 0, n, (f"N{j}",)))
            if np.any(beta):
                W[port, j].append((0, s * beta, 1, n, (f"N{j}",)))
    return W


def _groups(W: dict[tuple[int, int], list[Term]], ones: np.ndarray) -> dict:
    """Group the products of det M by (K power, h power, polynomials): delay -> list of
    coefficient arrays."""
    P0 = [(0, ones, 0, 0, ("d0",))] + W[0, 0]
    P1 = [(0, ones, 0, 0, ("d1",))] + W[1, 1]
    out: dict = defaultdict(lambda: defaultdict(list))
    for sign, left, right in ((1.0, P0, P1), (-1.0, W[0, 1], W[1, 0])):
        for ka, ca, ha, na, fa in left:
            for kb, cb, hb, nb, fb in right:
                out[ka + kb, ha + hb, tuple(sorted(fa + fb))][na + nb].append(sign * (ca * cb))
    return out


def _coefficient(parts: list[np.ndarray]) -> Jet:
    """Sum of products: exact when they cancel to 0 (the model's gains as given),
    else the sum's rounding (EPS_OP per term on the sum of magnitudes) in the radius."""
    total = np.sum(parts, axis=0)
    if len(parts) == 1:
        return const(total)
    mag = np.sum(np.abs(parts), axis=0)
    return const(total, np.where(total == 0.0, 0.0, len(parts) * EPS_OP * mag))


def generic_coefficients(resp: Any, idx: np.ndarray, theta: np.ndarray, rho: np.ndarray,
                         b: dict[str, Jet], poly: Callable[[str], Jet]) -> list[Jet]:
    """Jets of F0, F1, F2 (det M = F0 + u F1 + u^2 F2) for any two-port structure.

    Parameters
    ----------
    resp : LoopResponse
        Its ``channel_ports``, ``kinds``, ``terms``, ``k``, ``beta``, ``gain``,
        ``scale``, ``free`` and ``rigid``.
    idx, theta, rho : arrays
        Items and cells, as :meth:`LoopResponse.coefficients`.
    b : dict of Jet
        :func:`~hapstab.engine.discs.base_jets` of the cells.
    poly : callable
        ``poly(name)`` -> the jet of a port polynomial: ``d0, N0, R0, dhat0, Rhat0``, ...

    Returns
    -------
    list of Jet
        F0, F1, F2.

    Raises
    ------
    AnalysisError
        A fractional delay, or a rigid-body mode that a group cannot carry (the
        rigid-body rule and the structure disagree).
    """
    shape = theta.shape
    groups = _groups(_entries(resp, idx), np.ones(idx.size))
    F = [zero(shape), zero(shape), zero(shape)]
    for (kpow, hpow, names), by_delay in groups.items():
        value = _group_value(resp, theta, rho, b, poly, hpow, names, by_delay)
        F[kpow] = F[kpow] + value
    return F


def _group_value(resp: Any, theta: np.ndarray, rho: np.ndarray, b: dict[str, Jet],
                 poly: Callable[[str], Jet], hpow: int, names: tuple[str, ...],
                 by_delay: dict[int, list[np.ndarray]]) -> Jet:
    """sum_n c_n z^-n h^hpow prod(polynomials), divided by y with a rigid-body mode."""
    names_l, hpow_l, divided = list(names), hpow, not resp.rigid
    if resp.rigid and hpow_l:
        hpow_l, divided = hpow_l - 1, True
        extra = b["zinv"]                          # h / y = z^-1
    else:
        extra = None
    if resp.rigid and not divided:
        for nm in names_l:
            if nm[0] in "dR" and resp.free[int(nm[-1])]:
                names_l[names_l.index(nm)] = nm[:-1] + "hat" + nm[-1]
                divided = True
                break
    mono = extra
    for nm in names_l:
        mono = poly(nm) if mono is None else mono * poly(nm)
    for _ in range(hpow_l):
        mono = b["1-zinv"] if mono is None else mono * b["1-zinv"]
    phases = _phases(theta, rho, by_delay, divided)
    return phases if mono is None else phases * mono


def _phases(theta: np.ndarray, rho: np.ndarray, by_delay: dict[int, list[np.ndarray]],
            divided: bool) -> Jet:
    """sum_n c_n z^-n without cancellation; over y when not ``divided`` (then the c_n
    must sum to exactly 0)."""
    n0 = min(by_delay)
    total = _coefficient([c for parts in by_delay.values() for c in parts])
    if not divided and (np.any(total.vc != 0) or np.any(total.vr != 0)):
        raise AnalysisError("rigid-body mode: a term of det M has no factor z - 1; the "
                            "rigid-body rule and the loop's channels disagree")
    out = total if divided else None
    for n, parts in by_delay.items():
        if n == n0:
            continue
        m, c = n - n0, _coefficient(parts)
        if divided:
            part = c * one_minus_delay_jet(theta, rho, m)
        else:                                       # (1 - z^-m) / y = z^-m G_m
            part = c * delay_jet(theta, rho, m) * geometric_sum_jet(theta, rho, m)
        out = -part if out is None else out - part
    if out is None:
        return zero(theta.shape)
    return out if n0 == 0 else out * delay_jet(theta, rho, n0)
