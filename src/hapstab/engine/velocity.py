"""Filtered velocity in the characteristic function: the damper of a
:class:`~hapstab.models.controllers.FilteredSpringDamper` acts on
``(1 - z^-1)/T`` through F(z) = F_num/F_den, so its controller is

    H_j(z) = K k_j + c_j(z) / e_j(z),   c_j = beta_j (1 - z^-1) F_num,   e_j = F_den

(polynomials in z^-1). Each port's row of M is multiplied by e_j: det M becomes
``prod_j e_j`` times the unfiltered-form determinant, i.e. with X, Y_j, Delta of
:meth:`~hapstab.engine.frequency.LoopResponse.coefficients`

    F0 = X e0 e1 + Y0 c0 e1 + Y1 c1 e0 + Delta c0 c1
    F1 = (Y0 k0 + Y1 k1) e0 e1 + Delta (c0 k1 e1 + c1 k0 e0)
    F2 = Delta k0 k1 e0 e1

(one port: F0 = d e0 + T00 c0, F1 = T00 k0 e0). The filter's states are closed-loop
states, and ``z^(N - q) det M`` is still the characteristic polynomial (the extra
powers of z^-1 in e_j and c_j are the filter's states), so the count Z_out = q -
wind(det M) of the module :mod:`~hapstab.engine.frequency` holds unchanged. With
no filter, e_j = 1 and c_j = beta_j (1 - z^-1), and the formulas are exactly the
unfiltered ones, operation for operation.

* low-pass ``F = (1 - a) / (1 - a z^-1)``: c = beta (1 - a)(1 - z^-1), e = 1 - a z^-1;
* moving average of N differences: c = (beta / N)(1 - z^-N), e = 1.

Any controller affine in K, H = K P + Q (:class:`~hapstab.models.controllers.AffineController`)
is the same with H = (K a + c)/e, a = P_num Q_den, c = Q_num P_den, e = P_den Q_den
(in z^-1): the K-part then carries a_j instead of e_j,

    F1 = Y0 k0 a0 e1 + Y1 k1 a1 e0 + Delta (c0 k1 a1 + c1 k0 a0),   F2 = Delta k0 k1 a0 a1.

The filter's coefficients are those the digital controller runs (computed once in
floating point), so they carry no error of their own.

References
----------
The paper, eq. (23); F. Janabi-Sharifi, V. Hayward and C.-S. J. Chen, IEEE Trans.
Control Systems Technology 8(6), 2000 (velocity estimators of haptic devices).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from hapstab.engine.discs import Jet, const, one_minus_delay_jet, poly_jet
from hapstab.errors import AnalysisError

__all__ = ["filters_of", "filter_order", "damper_jets", "stack_filters"]

#: A channel's velocity filter in a response: None (plain backward difference),
#: ("lowpass", a per item), ("average", N) or ("affine", (a, c, e)) polynomials in z^-1.
Filter = tuple[str, Any] | None


def filters_of(controllers: Sequence[Any], T: np.ndarray) -> tuple[Filter, ...]:
    """Each channel's filter, batched over the periods ``T``; a low-pass whose pole
    underflows to 0 at every period (f_c = inf) and N = 1 are no filter."""
    out: list[Filter] = []
    for c in controllers:
        parts = c.affine_parts()
        if parts is not None:                       # K P(z) + Q(z), P and Q fixed in z
            pn, pd, qn, qd = parts
            out.append(("affine", (np.convolve(pn, qd), np.convolve(qn, pd), np.convolve(pd, qd))))
            continue
        vf = getattr(c, "velocity_filter", None)
        if vf is None or (vf.kind == "average" and vf.samples == 1):
            out.append(None)
        elif vf.kind == "average":
            out.append(("average", vf.samples))
        else:
            a = vf.pole(T)
            out.append(("lowpass", a) if np.any(a) else None)
    return tuple(out)


def filter_order(f: Filter) -> int:
    """Extra powers of z^-1 the filter adds to its row of M."""
    if f is None:
        return 0
    if f[0] == "affine":
        return max(p.size for p in f[1]) - 1
    return 1 if f[0] == "lowpass" else f[1] - 1


def damper_jets(filters: Sequence[Filter], beta: np.ndarray, idx: np.ndarray, theta: np.ndarray,
                rho: np.ndarray, b: dict[str, Jet]
                ) -> tuple[list[Jet], list[Jet | None], list[Jet | None]]:
    """Jets of c_j, e_j and a_j on the cells, channel j = port j (``None`` for e_j = 1;
    for a_j: the same as e_j)."""
    hb: list[Jet] = []
    ev: list[Jet | None] = []
    av: list[Jet | None] = []
    for j, f in enumerate(filters):
        bj = beta[idx, j]
        if f is not None and f[0] == "affine":
            a, c, e = (poly_jet(np.broadcast_to(x, (theta.size, x.size)),
                                np.zeros((theta.size, x.size)), b["zinv"]) for x in f[1])
            hb.append(c)
            ev.append(e)
            av.append(a)
            continue
        av.append(None)
        if f is None:
            hb.append(b["1-zinv"].scale(bj))
            ev.append(None)
        elif f[0] == "average":
            hb.append(one_minus_delay_jet(theta, rho, f[1]).scale(bj / f[1]))
            ev.append(None)
        else:
            a = f[1][idx]
            hb.append(b["1-zinv"].scale(bj * (1.0 - a)))
            ev.append(const(np.ones(theta.shape)) - b["zinv"].scale(a))
    return hb, ev, av


def stack_filters(all_filters: Sequence[tuple[Filter, ...]]) -> tuple[Filter, ...]:
    """The filters of stacked responses (the same kinds and N; poles concatenated)."""
    first = all_filters[0]
    out: list[Filter] = []
    for j, f in enumerate(first):
        fs = [fl[j] for fl in all_filters]
        if f is None and all(x is None for x in fs):
            out.append(None)
        elif f is not None and f[0] == "affine":
            out.append(f)     # fixed coefficients (one period: checked by loop_response)
        elif f is not None and f[0] == "average" and all(x == f for x in fs):
            out.append(f)
        elif f is not None and f[0] == "lowpass" and all(x is not None and x[0] == "lowpass"
                                                       for x in fs):
            out.append(("lowpass", np.concatenate([x[1] for x in fs])))   # type: ignore[index]
        else:
            raise AnalysisError("stack_responses: the loops differ in their velocity filters")
    return tuple(out)
