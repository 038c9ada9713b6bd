"""The angle kernel of the proof's exclusion as precomputed ball polynomials
(certificate version 4): what :meth:`~hapstab.engine.arb_loop.ArbLoop.exclusion` needs
of an angle piece, by a few C-level polynomial evaluations instead of forward-mode
derivatives over Python objects (:class:`~hapstab.engine.arb_forms.Dual`, versions 1-3).

Each coefficient in K of P and Q (module doc of :mod:`~hapstab.engine.arb_loop`) is a
polynomial in ``v = 1 - z^-1`` (the controllers' damping terms, ``h_j = beta_j v``)
whose coefficients are polynomials in ``y = z - 1`` (the ports' d_j, N_j), formed once
per loop in balls:

    P_i(theta) = sum_m v^m p_im(y),   Q_i(theta) = sum_m v^m q_im(y),   m = 0, 1, 2.

One port: ``P_0 = d``, ``Q_0 = v s beta N``, ``Q_1 = s k N``. Two ports: with
``a_j = d_j + v s_j beta_j N_j``, ``b_j = s_j k_j N_j``, ``c = s_2 N_0 N_1``:
``P = [a_0 a_1, a_0 b_1 + a_1 b_0, b_0 b_1]``, ``Q = c [v^2 beta_0 beta_1,
v (beta_0 k_1 + beta_1 k_0), k_0 k_1]``. Without delay (w = 1) det M's coefficients
``P_i + Q_i`` are formed as polynomials themselves, so terms that cancel cancel in
their coefficients; the K^2 one, ``(s_0 s_1 + s_2) k_0 k_1 N_0 N_1``, is exactly 0 when
the signs cancel (the position-error structure), not a ball around 0. On an angle ball the kernel is each
function's value at the centre and its derivative over the ball,
``d/dtheta = sum_m (m v^(m-1) v' p_im + v^m p_im' y')`` with ``y' = j z`` and
``v' = j z^-1``: the same functions and the same mean-value forms as versions 1-3,
evaluated by Arb's polynomial evaluation; the balls differ in their rounding, so a
certificate says which evaluation its gap pieces were proved with (its version), and
the checker uses that one.

References
----------
F. Johansson, "Arb: efficient arbitrary-precision midpoint-radius interval
arithmetic", IEEE Trans. Computers 66 (2017) 1281-1292 (``acb_poly`` evaluation);
R. E. Moore, R. B. Kearfott and M. J. Cloud, *Introduction to Interval Analysis*,
SIAM 2009, sec. 6.1 (the mean-value form).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["KernelPolys", "kernel_polys", "poly_kernel"]

#: A function of the angle: its polynomials in y per power of v (None: exactly 0).
VPoly = list


@dataclass
class KernelPolys:
    """The coefficients in K (K^0, K^1, K^2) of P and Q, and of det M = P + Q without
    delay (``F``, else None), as :data:`VPoly` (module doc), with the derivatives in y
    (``dP``, ``dQ``, ``dF``)."""

    P: list[VPoly]
    Q: list[VPoly]
    F: list[VPoly] | None
    n_phase: int

    def __post_init__(self) -> None:
        def deriv(f: VPoly) -> VPoly:
            return [None if p is None else p.derivative() for p in f]
        self.dP = [deriv(f) for f in self.P]
        self.dQ = [deriv(f) for f in self.Q]
        self.dF = None if self.F is None else [deriv(f) for f in self.F]
        self.nonzero = _nonzero(self.P, self.Q, self.F)


def _nonzero(P: list[VPoly], Q: list[VPoly], F: list[VPoly] | None) -> tuple:
    """Which coefficients of :func:`poly_kernel`'s lists ``(Pm, Qm, Fm, Pd, Qd, Fd)`` may
    be nonzero: False where the function is exactly 0 (its :data:`VPoly` all None; det
    M's where P's and Q's both are), so that the kernel's entry is an exact zero ball
    (:func:`~hapstab.engine.arb_forms.exclusion_test` skips it)."""
    def nz(fs: list[VPoly]) -> tuple[bool, ...]:
        return tuple(any(p is not None for p in f) for f in fs)
    p, q = nz(P), nz(Q)
    f = nz(F) if F is not None else tuple(a or b for a, b in zip(p, q, strict=True))
    return p, q, f, p, q, f


def _add(a: VPoly, b: VPoly) -> VPoly:
    n = max(len(a), len(b))
    a, b = a + [None] * (n - len(a)), b + [None] * (n - len(b))
    return [x if y is None else y if x is None else x + y for x, y in zip(a, b, strict=True)]


def _mul(a: VPoly, b: VPoly) -> VPoly:
    out: VPoly = [None] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            if x is not None and y is not None:
                out[i + j] = x * y if out[i + j] is None else out[i + j] + x * y
    return out


def kernel_polys(ports: list[Any], s: list[Any], k: list[Any], beta: list[Any],
                 n_phase: int) -> KernelPolys:
    """P and Q as :data:`VPoly` (module doc) from the port polynomials d_j, N_j in y
    (``ports``: objects with ``d`` and ``N`` acb_poly), the signs ``s``, the stiffness
    ratios ``k`` and ``beta_j = B_j / T`` (acb), at the precision in force."""
    import flint
    acb_poly = flint.acb_poly

    def const(c: Any) -> VPoly:
        return [None if c == 0 else acb_poly([c])]
    h = [[None, None if b == 0 else acb_poly([b])] for b in beta]
    kk = [const(x) for x in k]
    if len(ports) == 1:
        d, sN = [ports[0].d], [ports[0].N * s[0]]
        P: list[VPoly] = [d, [None], [None]]
        Q: list[VPoly] = [_mul(sN, h[0]), _mul(sN, kk[0]), [None]]
    else:
        sN = [[ports[j].N * s[j]] for j in range(2)]
        a = [_add([ports[j].d], _mul(sN[j], h[j])) for j in range(2)]
        b = [_mul(sN[j], kk[j]) for j in range(2)]
        c = [ports[0].N * ports[1].N * s[2]]
        P = [_mul(a[0], a[1]), _add(_mul(a[0], b[1]), _mul(a[1], b[0])), _mul(b[0], b[1])]
        Q = [_mul(c, _mul(h[0], h[1])), _mul(c, _add(_mul(h[0], kk[1]), _mul(h[1], kk[0]))),
             _mul(c, _mul(kk[0], kk[1]))]
    F = [_add(p, q) for p, q in zip(P, Q, strict=True)] if n_phase == 0 else None
    if F is not None and len(ports) == 2:
        # the K^2 coefficient (s_0 s_1 + s_2) k_0 k_1 N_0 N_1 as one product: exactly 0
        # when the signs cancel (the position-error structure), not a ball around 0
        lead = (s[0] * s[1] + s[2]) * k[0] * k[1]
        F[2] = [None] if lead.is_zero() else [ports[0].N * ports[1].N * lead]
    return KernelPolys(P, Q, F, n_phase)


def _value(f: VPoly, y: Any, vp: list[Any], zero: Any) -> Any:
    """sum_m v^m f_m(y), with ``vp`` the powers of v (``zero`` when f is 0)."""
    out = None
    for m, p in enumerate(f):
        if p is not None:
            term = p(y) if m == 0 else vp[m] * p(y)
            out = term if out is None else out + term
    return zero if out is None else out


def _slope(f: VPoly, df: VPoly, y: Any, vp: list[Any], jz: Any, jzi: Any, zero: Any) -> Any:
    """d/dtheta of sum_m v^m f_m(y) over the ball (``jz = y'``, ``jzi = v'``; ``zero``
    when f is 0)."""
    out = None
    for m, (p, dp) in enumerate(zip(f, df, strict=True)):
        if p is None:
            continue
        term = dp(y) * jz if m == 0 else vp[m] * dp(y) * jz + (m * vp[m - 1]) * jzi * p(y)
        out = term if out is None else out + term
    return zero if out is None else out


def poly_kernel(sp: KernelPolys, theta: Any) -> tuple:
    """The kernel on the angle ball ``theta`` (arb), at the precision in force:
    ``(Pm, Qm, Fm, Pd, Qd, Fd)``, lists of 3 acb, the coefficients of K^0..K^2 of P,
    Q, det M at the ball's centre and of their d/dtheta over the ball, as
    :meth:`~hapstab.engine.arb_loop.ArbLoop.kernel` gives them in versions 1-3."""
    import flint
    acb, arb = flint.acb, flint.arb
    zero = acb(0)
    jm, jt = acb(0, arb(theta.mid())), acb(0, theta)
    ym, y = jm.expm1(), jt.expm1()
    vm, v = -(-jm).expm1(), -(-jt).expm1()           # 1 - z^-1
    vpm, vp = [acb(1), vm, vm * vm], [acb(1), v, v * v]
    j = acb(0, 1)
    jz, jzi = j * (1 + y), j * (1 - v)                 # y' = j z, v' = j / z
    Pm = [_value(f, ym, vpm, zero) for f in sp.P]
    Qm = [_value(f, ym, vpm, zero) for f in sp.Q]
    Pd = [_slope(f, df, y, vp, jz, jzi, zero) for f, df in zip(sp.P, sp.dP, strict=True)]
    Qd = [_slope(f, df, y, vp, jz, jzi, zero) for f, df in zip(sp.Q, sp.dQ, strict=True)]
    if sp.F is not None and sp.dF is not None:
        Fm = [_value(f, ym, vpm, zero) for f in sp.F]
        Fd = [_slope(f, df, y, vp, jz, jzi, zero) for f, df in zip(sp.F, sp.dF, strict=True)]
        return Pm, Qm, Fm, Pd, Qd, Fd
    n = sp.n_phase
    wm, w = (-jm * n).exp(), (-jt * n).exp()
    Fm = [p + wm * q for p, q in zip(Pm, Qm, strict=True)]
    Qv = [_value(f, y, vp, zero) for f in sp.Q]
    dw = w * acb(0, -n)
    Fd = [pd + dw * q + w * qd for pd, q, qd in zip(Pd, Qv, Qd, strict=True)]
    return Pm, Qm, Fm, Pd, Qd, Fd
