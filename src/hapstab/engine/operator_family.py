"""The port polynomials of a device held by *any* operator of a box, enclosed: for
every operator Z = m s + b + k/s with (m, b, k) in a box, the exact coefficients of
the port's polynomials d, N, Nt^f, D^f (:mod:`hapstab.engine.frequency`) lie in
balls computed here, and so do their derivatives in m, b and k.

The port [x, v] of the device (mass m_d, damping b_d) and the operator has
``A = [[0, 1], [-k/M, -(b_d + b)/M]]``, ``B = [0, 1/M]`` with M = m_d + m. Its
entries over the box are enclosed by outward-rounded interval arithmetic (each
entry separately: a superset), and the pipeline of
:func:`~hapstab.engine.port_poly.port_polynomials` runs in ball arithmetic
(:mod:`hapstab.engine.balls`): the ZOH pair (Phi, S) from the exponential of
``tau [[A, I], [0, 0]]``, E = A S, Gamma = S B, the
Faddeev-LeVerrier recursion (``p_k = -tr(E B_(k-1)) / k``, ``B_k = E B_(k-1) + p_k I``,
adj(yI - E) Gamma = sum_k y^(q-1-k) B_k Gamma) and the fractional-delay numerators.

Derivatives: every quantity is carried with its first derivatives in the varying
parameters (forward mode, each a ball over the box); the exponential's derivative in
direction dX is the upper-right block of ``exp([[X, dX], [0, X]])`` (Van Loan 1978),
enclosed by the same ball exponential.

References
----------
C. F. Van Loan, "Computing integrals involving the matrix exponential", IEEE Trans.
Autom. Control 23 (1978) 395-404; U. J. J. Le Verrier (1840) and D. K. Faddeev,
see F. R. Gantmacher, *The Theory of Matrices*, vol. 1, ch. IV sec. 5.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.engine.balls import Ball, ball_expm, interval_ball
from hapstab.engine.frequency import LoopResponse, PortPoly, loop_response
from hapstab.engine.port_poly import port_polynomials
from hapstab.engine.structure import FREE_SPRING, structure_of
from hapstab.errors import AnalysisError
from hapstab.models.parts import mass_spring_damper

__all__ = ["PARAMETERS", "BoxPoly", "box_port_polynomials", "family_response",
           "derivative_response"]

#: The operator's parameters, in this order everywhere (kg, N*s/m, N/m).
PARAMETERS = ("mass", "damping", "stiffness")


class TBall:
    """A ball with its first derivatives in the varying parameters (each a ball)."""

    __slots__ = ("d", "v")

    def __init__(self, v: Ball, d: list[Ball]) -> None:
        self.v, self.d = v, d

    def __add__(self, o: TBall) -> TBall:
        return TBall(self.v + o.v, [a + b for a, b in zip(self.d, o.d, strict=True)])

    def __neg__(self) -> TBall:
        return TBall(-self.v, [-a for a in self.d])

    def __sub__(self, o: TBall) -> TBall:
        return self + (-o)

    def __mul__(self, o: TBall) -> TBall:
        return TBall(self.v * o.v, [a * o.v + self.v * b for a, b in zip(self.d, o.d, strict=True)])

    def __matmul__(self, o: TBall) -> TBall:
        return TBall(self.v @ o.v, [a @ o.v + self.v @ b for a, b in zip(self.d, o.d, strict=True)])

    def __getitem__(self, key: Any) -> TBall:
        return TBall(self.v[key], [a[key] for a in self.d])

    def div_int(self, k: int) -> TBall:
        return TBall(self.v.div_int(k), [a.div_int(k) for a in self.d])

    def trace(self) -> TBall:
        return TBall(self.v.trace(), [a.trace() for a in self.d])

    def scale(self, s: float) -> TBall:
        """Times an exact number."""
        return TBall(self.v * s, [a * s for a in self.d])


@dataclass
class BoxPoly:
    """Enclosures of one port's polynomials (ascending in y) over operator boxes.

    Parameters
    ----------
    mid, rad : dict of str to (L, n) arrays
        Per polynomial (``d``, ``N``, ``Nt<f>``, ``D<f>``): midpoints and radii of
        the coefficients over each of the L boxes.
    dmid, drad : dict of str to (P, L, n) arrays
        The same for the derivatives in each varying parameter (P of them, in the
        order of ``varying``).
    varying : tuple of int
        Indices into :data:`PARAMETERS` of the parameters with a range.
    """

    mid: dict[str, np.ndarray]
    rad: dict[str, np.ndarray]
    dmid: dict[str, np.ndarray]
    drad: dict[str, np.ndarray]
    varying: tuple[int, ...]


def _dn(x: np.ndarray) -> np.ndarray:
    return np.nextafter(x, -np.inf)


def _upn(x: np.ndarray) -> np.ndarray:
    return np.nextafter(x, np.inf)


def _entries(m_d: float, b_d: float, lo: np.ndarray, hi: np.ndarray) -> dict[str, tuple]:
    """Outward-rounded intervals of the port's parameter-dependent entries and of
    their derivatives: 1/M, k/M, b_t/M, 1/M^2, k/M^2, b_t/M^2 (b_t = b_d + b)."""
    M = (_dn(m_d + lo[:, 0]), _upn(m_d + hi[:, 0]))
    bt = (_dn(b_d + lo[:, 1]), _upn(b_d + hi[:, 1]))
    k = (lo[:, 2], hi[:, 2])
    inv = (_dn(1.0 / M[1]), _upn(1.0 / M[0]))
    inv2 = (_dn(inv[0] * inv[0]), _upn(inv[1] * inv[1]))

    def times(a: tuple, b: tuple) -> tuple:          # both non-negative
        return _dn(a[0] * b[0]), _upn(a[1] * b[1])

    return {"inv": inv, "k/M": times(k, inv), "b/M": times(bt, inv), "inv2": inv2,
            "k/M2": times(k, inv2), "b/M2": times(bt, inv2)}


def _port_matrices(e: dict[str, tuple], varying: Sequence[int], L: int) -> tuple[TBall, TBall]:
    """A (L, 2, 2) and B (L, 2, 1) with their derivatives in the varying parameters."""
    ball = {k: interval_ball(*v) for k, v in e.items()}
    z = np.zeros(L)

    def mat(entries: dict[tuple[int, int], Ball], shape: tuple[int, int]) -> Ball:
        m, r = np.zeros((L, *shape)), np.zeros((L, *shape))
        for (i, j), b in entries.items():
            m[:, i, j], r[:, i, j] = b.m, b.r
        return Ball(m, r)

    A = mat({(0, 1): Ball(z + 1.0), (1, 0): -ball["k/M"], (1, 1): -ball["b/M"]}, (2, 2))
    Bv = mat({(1, 0): ball["inv"]}, (2, 1))
    dA = {0: mat({(1, 0): ball["k/M2"], (1, 1): ball["b/M2"]}, (2, 2)),
          1: mat({(1, 1): -ball["inv"]}, (2, 2)), 2: mat({(1, 0): -ball["inv"]}, (2, 2))}
    dB = {0: mat({(1, 0): -ball["inv2"]}, (2, 1))}
    zeros = Ball(np.zeros((L, 2, 1)))
    return TBall(A, [dA[p] for p in varying]), TBall(Bv, [dB.get(p, zeros) for p in varying])


def _zoh(A: TBall, tau: float) -> tuple[TBall, TBall]:
    """(Phi, S) = (e^(A tau), int_0^tau e^(A s) ds) with derivatives: the exponential
    of tau [[A, I], [0, 0]] and, per direction dA, the upper-right block of the
    exponential of [[X, dX], [0, X]]."""
    L, n = A.v.m.shape[0], A.v.m.shape[1]
    aug = Ball(np.zeros((L, 2 * n, 2 * n)))
    aug.m[:, :n, :n], aug.r[:, :n, :n] = A.v.m, A.v.r
    aug.m[:, :n, n:] = np.eye(n)
    X = aug * tau
    E = ball_expm(X)
    ders = []
    for dA in A.d:
        big = Ball(np.zeros((L, 4 * n, 4 * n)))
        for sl in (np.s_[:, :2 * n, :2 * n], np.s_[:, 2 * n:, 2 * n:]):
            big.m[sl], big.r[sl] = X.m, X.r
        dX = dA * tau
        big.m[:, :n, 2 * n:3 * n], big.r[:, :n, 2 * n:3 * n] = dX.m, dX.r
        ders.append(ball_expm(big)[:, :2 * n, 2 * n:])
    Phi = TBall(E[:, :n, :n], [d[:, :n, :n] for d in ders])
    S = TBall(E[:, :n, n:], [d[:, :n, n:] for d in ders])
    return Phi, S


def _leverrier(E: TBall, G: TBall) -> tuple[list[TBall], list[TBall]]:
    """Faddeev-LeVerrier: the characteristic polynomial det(yI - E) descending
    ``[1, p_1, ..., p_q]`` (p_0 omitted: it is 1) and the vectors v_k = B_k Gamma."""
    q = E.v.m.shape[-1]
    L = E.v.m.shape[0]
    eye = TBall(Ball(np.broadcast_to(np.eye(q), (L, q, q)).copy()),
                [Ball(np.zeros((L, q, q))) for _ in E.d])
    Bk, ps, vs = eye, [], [G]
    for k in range(1, q + 1):
        EB = E @ Bk
        pk = (-EB.trace()).div_int(k)
        ps.append(pk)
        if k < q:
            Bk = EB + _diag(pk, q)
            vs.append(Bk @ G)
    return ps, vs


def _diag(p: TBall, q: int) -> TBall:
    """p I for a scalar (per item) p."""
    def one(b: Ball) -> Ball:
        eye = np.eye(q)
        return Ball(b.m[:, None, None] * eye, b.r[:, None, None] * eye)
    return TBall(one(p.v), [one(a) for a in p.d])


def _pack(coefs: list[TBall]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Coefficient list (ascending) as arrays: mid, rad (L, n) and dmid, drad (P, L, n)."""
    mid = np.stack([c.v.m for c in coefs], axis=-1)
    rad = np.stack([c.v.r for c in coefs], axis=-1)
    P = len(coefs[0].d)
    dmid = np.stack([np.stack([c.d[p].m for c in coefs], axis=-1) for p in range(P)]) if P \
        else np.zeros((0, *mid.shape))
    drad = np.stack([np.stack([c.d[p].r for c in coefs], axis=-1) for p in range(P)]) if P \
        else np.zeros((0, *mid.shape))
    return mid, rad, dmid, drad


def box_port_polynomials(device_mass: float, device_damping: float, lo: np.ndarray,
                         hi: np.ndarray, period: float, fractions: Sequence[float]) -> BoxPoly:
    """Enclosures of the port polynomials of a device held by every operator of each box.

    Parameters
    ----------
    device_mass, device_damping : float
        The device's mass (kg) and damping (N*s/m).
    lo, hi : (L, 3) arrays
        Each box's lower and upper operator mass (kg), damping (N*s/m) and stiffness
        (N/m), all >= 0 with device mass + operator mass > 0.
    period : float
        T in s.
    fractions : sequence of float
        Fractional delays f of the measurements of this port (Nt^f, D^f).

    Returns
    -------
    BoxPoly
        Balls of the coefficients of d, N, Nt<f>, D<f> (as in
        :class:`hapstab.engine.frequency.PortPoly`) and of their derivatives in the
        parameters whose range has width in some box.
    """
    lo, hi = np.atleast_2d(np.asarray(lo, float)), np.atleast_2d(np.asarray(hi, float))
    L = lo.shape[0]
    varying = tuple(int(p) for p in np.flatnonzero(np.any(hi > lo, axis=0)))
    A, Bv = _port_matrices(_entries(device_mass, device_damping, lo, hi), varying, L)
    _, S = _zoh(A, period)
    E, G = A @ S, S @ Bv
    ps, vs = _leverrier(E, G)
    q = E.v.m.shape[-1]
    one = TBall(Ball(np.ones(L)), [Ball(np.zeros(L)) for _ in varying])
    d = [ps[q - 1 - j] for j in range(q)] + [one]              # ascending
    N = [vs[q - 1 - j][:, 0, 0] for j in range(q)]
    out = {"d": d, "N": N}
    for f in fractions:
        Phf, Sf = _zoh(A, (1.0 - f) * period)
        Gf = (Sf @ Bv)[:, 0, 0]
        cphi = Phf[:, 0:1, :]                                   # (L, 1, q)
        part = [(cphi @ vs[q - 1 - j])[:, 0, 0] for j in range(q)]
        nt = [Gf * c for c in d]
        nt = [nt[j] + part[j] if j < q else nt[j] for j in range(q + 1)]
        onepy = [N[j] if j == 0 else (N[j] + N[j - 1] if j < q else N[q - 1])
                 for j in range(q + 1)]
        out[f"Nt{f}"] = nt
        out[f"D{f}"] = [nt[j] - onepy[j] for j in range(1, q + 1)]
    mid, rad, dmid, drad = {}, {}, {}, {}
    for name, coefs in out.items():
        mid[name], rad[name], dmid[name], drad[name] = _pack(coefs)
    return BoxPoly(mid, rad, dmid, drad, varying)


# ------------------------------------------------------------------ the family's response
def family_response(loop: Any, lo: np.ndarray, hi: np.ndarray) -> tuple[LoopResponse, BoxPoly]:
    """The characteristic function of ``loop`` with its operator replaced by every
    operator of each box: one item per box, whose operator port's coefficients are
    the boxes' midpoints and whose error bounds cover every operator of the box (the
    larger of the ball's radius and the floating-point bound the exact core gives
    the box's centre).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The operator is at port 0 (the device, or the master); spring-damper
        controllers.
    lo, hi : (L, 3) arrays
        Each box's operator mass (kg), damping (N*s/m) and stiffness (N/m) ranges.

    Returns
    -------
    resp : LoopResponse
        One item per box (:func:`hapstab.engine.frequency.loop_response`'s layout).
    poly : BoxPoly
        The enclosures, with the derivatives in the varying parameters.

    Raises
    ------
    AnalysisError
        A loop whose exact analysis is not the one- or two-port position structure,
        or a teleoperator whose slave is free while an operator of the box is (the
        common translation is then a pole at z = 1 for some operators and not others).
    """
    st = structure_of(loop)
    if not st.simple:
        raise AnalysisError("operator box: the robust analysis takes the HVE and PEB "
                            "(one position controller per port)")
    lo, hi = np.atleast_2d(lo), np.atleast_2d(hi)
    L = lo.shape[0]
    centres = 0.5 * (lo + hi)
    template = loop_response(loop.replace(operator=mass_spring_damper(*centres[0])))
    if any(template.filters):
        raise AnalysisError("controller: the robust analysis takes spring-dampers on the plain "
                            "backward difference, not yet a filtered velocity or an "
                            "AffineController")
    T = float(template.periods[0])
    dev = st.ports[0].device
    others = [pt.device.mass + pt.termination.mass for pt in st.ports[1:]]
    if template.free[1:] and all(template.free[1:]) and np.any(
            lo[:, 2] * T ** 2 / (dev.mass + hi[:, 0]) < FREE_SPRING):
        raise AnalysisError(f"operator stiffness = {lo[:, 2].min():g} N/m with a free slave "
                            "(no environment spring): some operators of the box leave the "
                            "teleoperator free (a rigid-body mode); give the operator a "
                            "stiffness range above 0 or the environment a spring")
    fr = sorted(template.ports[0].Nt)
    bp = box_port_polynomials(dev.mass, dev.damping, lo, hi, T, fr)
    errs = []
    for m, b, k in centres:              # the exact core's own allowance at each centre
        M = dev.mass + m                 # (engine.zoh.port_matrices of this port)
        A = np.array([[0.0, 1.0], [-k / M, -(dev.damping + b) / M]])
        errs.append(port_polynomials(A, np.array([[0.0], [1.0 / M]]), False, np.array([T]), fr).err)
    err = {n: np.maximum(bp.rad[n], np.concatenate([e[n] for e in errs])) for n in bp.mid}
    err["dhat"] = np.zeros((L, 0))
    p0 = PortPoly(bp.mid["d"], np.zeros((L, 0)), bp.mid["N"],
                  {f: bp.mid[f"Nt{f}"] for f in fr}, {f: bp.mid[f"D{f}"] for f in fr}, err)
    masses = np.minimum(dev.mass + centres[:, 0], min(others, default=np.inf))
    scale = 2.0 ** np.round(np.log2(masses / T ** 2))
    tile = lambda a: np.repeat(a[:1], L, axis=0)  # noqa: E731
    ports = [p0] + [PortPoly(tile(pp.d), tile(pp.dhat), tile(pp.N),
                             {f: tile(v) for f, v in pp.Nt.items()},
                             {f: tile(v) for f, v in pp.D.items()},
                             {k: tile(v) for k, v in pp.err.items()}) for pp in template.ports[1:]]
    resp = LoopResponse(template.terms, ports, tile(template.k), tile(template.beta), scale,
                        template.q, 0, tile(template.periods), template.channel_ports,
                        template.kinds, None if template.gain is None else tile(template.gain),
                        (False, *template.free[1:]))
    return resp, bp


def derivative_response(resp: LoopResponse, poly: BoxPoly, p: int) -> LoopResponse:
    """The characteristic function's derivative in the p-th varying parameter: det M is
    linear in the operator port's polynomials (each term of the determinant has one
    factor from that port's column), so it is det M with that port's coefficients
    replaced by their derivatives (enclosed over each box).

    Parameters
    ----------
    resp : LoopResponse
        From :func:`family_response`.
    poly : BoxPoly
        Its enclosures.
    p : int
        Index into ``poly.varying``.

    Returns
    -------
    LoopResponse
        Items as ``resp``'s; F0, F1, F2 of it are the derivatives of resp's.
    """
    pp = resp.ports[0]
    fr = sorted(pp.Nt)
    mid = {n: poly.dmid[n][p] for n in poly.dmid}
    err = {n: poly.drad[n][p] for n in poly.drad}
    err["dhat"] = pp.err["dhat"]
    p0 = PortPoly(mid["d"], pp.dhat, mid["N"], {f: mid[f"Nt{f}"] for f in fr},
                  {f: mid[f"D{f}"] for f in fr}, err)
    return dataclasses.replace(resp, ports=[p0, *resp.ports[1:]])
