"""The two-port determinant of the position-error structure (eq. 20), formed
without cancellation: the part of :meth:`~hapstab.engine.frequency.LoopResponse.coefficients`
that PEB and scaled PEB share.

References
----------
The paper, eq. (20); K. J. Astrom and B. Wittenmark, *Computer-Controlled Systems*,
3rd ed., sec. 7.7 (modified z-transform).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hapstab.engine.discs import (
    Jet,
    delay_jet,
    geometric_sum_jet,
    one_minus_delay_jet,
    zero,
)
from hapstab.errors import AnalysisError

__all__ = ["two_port"]


def two_port(terms: tuple, rigid: int, theta: np.ndarray, rho: np.ndarray, b: dict[str, Jet],
             pj: Any) -> tuple[Jet, Jet, Jet]:
    """T00, T11 and Delta = T00 T11 - T01 T10 (or Delta / y with a rigid mode) for
    the position-error structure: channel i measures its own port undelayed (sign
    a_i) and the other port with delay n_i + f_i (sign c_i); eq. (20) has a_i = 1,
    c_i = -1, position/force scaling a_0 = alpha beta, c_0 = -beta, c_1 = -alpha.

    With P_j^f = N_j + e_j, e_j = z^-1 y D_j^f (module doc) and w the round-trip
    phase: Delta = (a0 a1 - c0 c1) N0 N1 + c0 c1 Delta_1 with Delta_1 = N0 N1 (1 - w)
    - w (e0 N1 + N0 e1 + e0 e1), and (1 - w)/y = w G_n (a geometric sum), e_j / y =
    z^-1 D_j^f: no cancellation, so F2 = Delta k0 k1 is 0 without delay, exactly.
    A rigid mode needs a0 a1 = c0 c1 (the rigid-body rule), so Delta / y = c0 c1
    Delta_1 / y.
    """
    own, cross = [], []
    for i, ch in enumerate(terms):
        mine = [t for t in ch if t[0] == i]
        other = [t for t in ch if t[0] != i]
        if len(ch) != 2 or len(mine) != 1 or mine[0][2:] != (0, 0.0) or not mine[0][1] \
                or not other[0][1]:
            raise AnalysisError("two-port loop: only the position-error structure of eq. (20) "
                                "is supported by the exact analysis")
        own.append(mine[0])
        cross.append(other[0])
    a0a1, c0c1 = own[0][1] * own[1][1], cross[0][1] * cross[1][1]
    N0, N1 = pj("N", 0), pj("N", 1)
    n_rt = cross[0][2] + cross[1][2]
    # e_j / y of port j measured by the other channel (channel 1 measures port 0)
    fr = {0: cross[1][3], 1: cross[0][3]}
    ey = {j: (b["zinv"] * pj("D", j, fr[j]) if fr[j] else None) for j in (0, 1)}
    w = delay_jet(theta, rho, n_rt) if n_rt else None
    if rigid:
        base = zero(theta.shape) if not n_rt else N0 * N1 * w * geometric_sum_jet(theta, rho, n_rt)
        corr = zero(theta.shape)
        if ey[0] is not None:
            corr = corr + ey[0] * N1
        if ey[1] is not None:
            corr = corr + N0 * ey[1]
        if ey[0] is not None and ey[1] is not None:
            corr = corr + ey[0] * ey[1] * b["y"]
        delta = base - (corr if w is None else w * corr)
    else:
        base = zero(theta.shape) if not n_rt else N0 * N1 * one_minus_delay_jet(theta, rho, n_rt)
        corr = zero(theta.shape)
        e: dict[int, Jet | None] = {}
        for j in (0, 1):
            ej = ey[j]
            e[j] = None if ej is None else ej * b["y"]
        if e[0] is not None:
            corr = corr + e[0] * N1
        if e[1] is not None:
            corr = corr + N0 * e[1]
        if e[0] is not None and e[1] is not None:
            corr = corr + e[0] * e[1]
        delta = base - (corr if w is None else w * corr)
    if c0c1 != 1.0:
        delta = delta.scale(c0c1)
    if a0a1 != c0c1:
        delta = delta + (N0 * N1).scale(a0a1 - c0c1)
    T00 = N0 if own[0][1] == 1.0 else N0.scale(own[0][1])
    T11 = N1 if own[1][1] == 1.0 else N1.scale(own[1][1])
    return T00, T11, delta
