"""The loop's characteristic function on the unit circle, with the delays as exact
phases: the frequency half of the one engine.

For ports j (device + attached impedance, ZOH-discretised exactly) and spring-damper
controllers H_j(z) = K k_j + beta_j (1 - z^-1) (beta_j = B_j / T) acting on
``e_i = sum_j s_ij z^-n_ij x_j((k - f_ij) T)``, write the plant of port j as
``P_j = N_j(y) / d_j(y)`` in the shifted variable ``y = z - 1`` (accurate when T is
small and every pole crowds z = 1) and the measurement with a fractional delay f as
``z^-1 Nt_j^f(y) / d_j(y)`` (modified z-transform). With

    M_ij(z, K) = delta_ij d_j(y) + (sum_terms s z^-n Ptilde_j) H_j(z),

the closed loop's characteristic polynomial is ``chi(z) = z^(N - q) det M`` exactly
(determinant identity for a feedback interconnection; q = sum_j deg d_j, N the
engine's state count), so for real K the number of closed-loop poles outside the
unit circle is

    Z_out(K) = q - wind(det M(e^{j theta}, K), theta: 0 -> 2 pi)

and det M = F0 + K F1 + K^2 F2 is evaluated at any angle in O(1) operations,
whatever the delay: ``z^-n = e^{-j n theta}`` is a phase, never n states.

Rigid-body mode: when every port is free (no spring to ground) and a constant
displacement gives every controller a zero input (PEB without operator or
environment, scaled or not: the rigid-body rule of
:func:`~hapstab.engine.structure.rigid_modes`), det M has the factor y for every K.
It is divided out exactly: each d_j = y dhat_j, and Delta = T00 T11 - T01 T10 is
divided by y analytically (divided differences of the delay phase and of the
fractional-delay numerators), which is the quotient by the common translation.

References
----------
The paper, Fig. 2a / Fig. 3, eq. (20) and (23). K. J. Astrom and B. Wittenmark,
*Computer-Controlled Systems*, 3rd ed., sec. 2.3 (ZOH sampling) and 7.7 (modified
z-transform).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.engine.arb_loop import arb_parameters
from hapstab.engine.discs import Jet, base_jets, delay_jet, poly_jet, zero
from hapstab.engine.expansion import generic_coefficients
from hapstab.engine.port_poly import COEF_REL, PortPoly, port_polynomials
from hapstab.engine.structure import (
    channel_name,
    channel_ratios,
    periods_of,
    port_is_free,
    rigid_modes,
    structure_of,
)
from hapstab.engine.two_port import two_port
from hapstab.engine.velocity import damper_jets, filter_order, filters_of, stack_filters
from hapstab.engine.zoh import port_matrices
from hapstab.errors import AnalysisError
from hapstab.models.controllers import has_stiffness
from hapstab.models.loops import HapticLoop, TeleoperationLoop, split_delay

__all__ = ["LoopResponse", "loop_response", "stack_responses", "ResponsePlan", "plan_response",
           "build_responses", "check_plan", "PortPoly", "COEF_REL", "port_polynomials"]

#: Largest ratio of port masses analysed: beyond ~1e12 the certified search's boxes
#: multiply (measured: 1e15 kg against 15 g took 0.35 GB, 1e20 kg 4.6 GB, 1e30 kg ran
#: out of memory), while no real teleoperator comes near it (grams to tonnes: 1e6).
MASS_RATIO = 1e12


@dataclass
class LoopResponse:
    """det M(e^{j theta}, K) of a batch of loops of one structure (see module doc).

    Attributes
    ----------
    terms : tuple of tuple of (j, s, n, f)
        For each channel i, the measured ports with sign, whole and fractional delay.
    ports : list of PortPoly
    k : (L, p) array
        Stiffness of each channel per unit K (k_0 = 1: K is the first port's).
    beta : (L, p) array
        B_j / T.
    scale : (L,) array
        K scale: u = K / scale is what the analysis works with (a power of two near
        min mass / T^2, so K/scale is exact).
    q : int
        Plant order (sum of deg d_j) less the rigid modes divided out.
    rigid : int
        Rigid-body modes divided out (0 or 1).
    periods : (L,) array
    """

    terms: tuple[tuple[tuple[int, float, int, float], ...], ...]
    ports: list[PortPoly]
    k: np.ndarray
    beta: np.ndarray
    scale: np.ndarray
    q: int
    rigid: int
    periods: np.ndarray
    channel_ports: tuple[int, ...] = ()
    kinds: tuple[str, ...] = ()
    gain: np.ndarray | None = None
    free: tuple[bool, ...] = ()
    filters: tuple = ()
    params: tuple = ()      # per item: arb_loop.arb_parameters (None: no ball proof)

    @property
    def size(self) -> int:
        return self.periods.size

    @property
    def simple(self) -> bool:
        """One position channel per port, channel i on port i (the HVE and PEB)."""
        return self.channel_ports == tuple(range(len(self.ports))) and \
            all(k == "position" for k in self.kinds)

    @property
    def phase_rate(self) -> int:
        """Oscillations of det M over theta in [0, pi] (round-trip delay + order)."""
        most = [0] * len(self.ports)
        for port, ch in zip(self.channel_ports, self.terms, strict=True):
            most[port] = max(most[port], *(t[2] + int(np.ceil(t[3])) for t in ch))
        return sum(most) + self.q + 2 + sum(map(filter_order, self.filters))

    # ------------------------------------------------------------------ evaluation
    def coefficients(self, idx: np.ndarray, theta: np.ndarray, rho: np.ndarray,
                     values_only: bool = False, deriv: bool = True) -> list[Jet]:
        """Jets of F0, F1, F2 (det M = F0 + u F1 + u^2 F2, u = K/scale) on the cells
        ``[theta - rho, theta + rho]`` of items ``idx`` (``values_only``: centres alone;
        and ``deriv`` False: their values alone, the derivatives ``NO_DERIV``)."""
        b = base_jets(theta, rho)
        b = {name: jet.values_only(deriv) for name, jet in b.items()} if values_only else b
        cache: dict = {}

        def pj(name: str, j: int, f: float = 0.0) -> Jet:
            key = (name, j, f)
            if key not in cache:
                pp = self.ports[j]
                arr = {"d": pp.d, "dhat": pp.dhat, "N": pp.N}.get(name)
                if arr is None:
                    arr = (pp.Nt if name == "Nt" else pp.D)[f]
                err = pp.err[name if name in ("d", "dhat", "N") else f"{name}{f}"]
                cache[key] = poly_jet(arr[idx], err[idx], b["y"])
            return cache[key]

        def measured(j: int, n: int, f: float) -> Jet:      # z^-n x_j((k - f) T) per unit force
            base = pj("N", j) if f == 0 else b["zinv"] * pj("Nt", j, f)
            return base if n == 0 else delay_jet(theta, rho, n) * base

        shape = theta.shape
        p = len(self.ports)
        if not self.simple:
            return generic_coefficients(self, idx, theta, rho, b, self._poly_of(idx, b, pj))
        hb, ev, av = damper_jets(self.filters or (None,) * p, self.beta, idx, theta, rho, b)
        ka = [e if a is None else a for a, e in zip(av, ev, strict=True)]   # K-part: a_j
        ku = [self.k[idx, j] * self.scale[idx] for j in range(p)]
        if p == 1:
            (j, s, n, f), = self.terms[0]
            T00 = measured(j, n, f).scale(s)
            return [_times(pj("d", 0), ev[0]) + T00 * hb[0], _times(T00.scale(ku[0]), ka[0]),
                    zero(shape)]
        # two ports: det(diag(d) + T diag(H)) = d0 d1 + d1 T00 H0 + d0 T11 H1 + Delta H0 H1
        # with Delta = T00 T11 - T01 T10 formed without cancellation (below); with a
        # rigid-body mode everything is divided by y (d_j = y dhat_j, Delta / y)
        T00, T11, Delta = two_port(self.terms, self.rigid, theta, rho, b, pj)
        if self.rigid:
            X = b["y"] * pj("dhat", 0) * pj("dhat", 1)
            Y0, Y1 = pj("dhat", 1) * T00, pj("dhat", 0) * T11
        else:
            X = pj("d", 0) * pj("d", 1)
            Y0, Y1 = pj("d", 1) * T00, pj("d", 0) * T11
        # filtered velocity (engine.velocity): row j times e_j; e_j = 1 leaves these the
        # unfiltered formulas operation for operation
        e0, e1 = ev
        a0, a1 = ka
        F0 = (_times(_times(X, e0), e1) + _times(Y0 * hb[0], e1) + _times(Y1 * hb[1], e0)
              + Delta * hb[0] * hb[1])
        F1 = (_times(_times(Y0.scale(ku[0]), a0), e1) + _times(_times(Y1.scale(ku[1]), a1), e0)
              + Delta * (_times(hb[0].scale(ku[1]), a1) + _times(hb[1].scale(ku[0]), a0)))
        F2 = _times(_times(Delta.scale(ku[0] * ku[1]), a0), a1)
        return [F0, F1, F2]

    def _poly_of(self, idx: np.ndarray, b: dict[str, Jet], pj: Any) -> Any:
        """Port polynomials by name for :func:`generic_coefficients`: ``d0, dhat1, N0``
        and the termination force's numerator ``R_j = -c adj(yI - E) Gamma - (m_z/M)
        z^-1 d_j`` (``Rhat_j`` = R_j / y for a free port: its constant term is 0)."""
        def poly(name: str) -> Jet:
            j = int(name[-1])
            if name.startswith(("d", "N")):
                return pj(name[:-1], j)
            pp, hat = self.ports[j], name.startswith("Rhat")
            assert pp.R is not None and pp.mz_M is not None   # a force channel measures j
            r = pp.R[:, 1:] if hat else pp.R
            e = pp.err["R"][:, 1:] if hat else pp.err["R"]
            held = (b["zinv"] * pj("dhat" if hat else "d", j)).scale(pp.mz_M[idx])
            return -(poly_jet(r[idx], e[idx], b["y"]) + held)
        return poly


def _times(a: Jet, e: Jet | None) -> Jet:
    """a e, or a itself for e = 1 (no velocity filter)."""
    return a if e is None else a * e


# ---------------------------------------------------------------------- building
@dataclass
class ResponsePlan:
    """One loop's share of a :class:`LoopResponse` before its port polynomials: what
    :func:`build_responses` needs, with the checks that need no polynomials done.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop.
    st : LoopStructure
        Its ports and channels.
    T : (L,) array
        The periods (s).
    terms : tuple
        Per channel, the measured ports (j, sign, whole delay, fraction).
    ratios : tuple of float
        Each channel's stiffness per unit K.
    pos, ctrls : list
        The position channels and their controllers.
    matrices : list of tuple
        Per port: (A, B, force row or None, m_z / M, free, fractions).
    masses : list of float
        Each port's total mass (kg).
    numbers : tuple or None
        The rows and checks of :func:`check_plan`, once it has run (then reused).
    """

    loop: Any
    st: Any
    T: np.ndarray
    terms: tuple
    ratios: tuple[float, ...]
    pos: list
    ctrls: list
    matrices: list[tuple]
    masses: list[float]
    numbers: tuple | None = None

    @property
    def filter_rate(self) -> int:
        """Powers of z^-1 the velocity filters add to det M (see LoopResponse.phase_rate)."""
        nums = self.numbers if self.numbers is not None else _numbers(self)
        return sum(map(filter_order, nums[5]))

    def key(self) -> tuple:
        """What loops must share to be one batch (see :func:`build_responses`)."""
        nums = self.numbers if self.numbers is not None else _numbers(self)
        # the expansion of several channels per port leaves out the terms of a channel
        # with no stiffness or no damping (engine.expansion): part of the structure there
        zeros = () if self.st.simple else (
            tuple(r != 0 for r in self.ratios),
            tuple(bool(np.any(nums[1][:, c])) for c in range(nums[1].shape[1])))
        return (self.terms, tuple((A.shape[0], fr, tuple(fs), force is None)
                                  for A, _b, force, _m, fr, fs in self.matrices),
                nums[4], tuple(ch.port for ch in self.st.channels),
                tuple(ch.measures for ch in self.st.channels), _filter_key(nums[5]), zeros)


def _filter_key(filters: tuple) -> tuple:
    """The velocity filters' kinds (a low-pass's pole is a number of the row)."""
    return tuple(None if f is None else ("lowpass",) if f[0] == "lowpass" else
                 ("average", f[1]) if f[0] == "average" else
                 ("affine", tuple(tuple(np.asarray(x).tolist()) for x in f[1]))
                 for f in filters)


def loop_response(loop: HapticLoop | TeleoperationLoop,
                  periods: Sequence[float] | np.ndarray | None = None) -> LoopResponse:
    """The characteristic function of ``loop`` on the unit circle for each period.

    Raises
    ------
    AnalysisError
        If a controller is not a :class:`~hapstab.models.SpringDamper` (no K to
        vary), or the master's stiffness is 0 while the slave's is not.
    """
    return build_responses([plan_response(loop, periods)])


def plan_response(loop: HapticLoop | TeleoperationLoop,
                  periods: Sequence[float] | np.ndarray | None = None) -> ResponsePlan:
    """The first half of :func:`loop_response`: the loop's structure, terms and port
    matrices, and the checks of its controllers (the errors it raises come first)."""
    st = structure_of(loop)
    T = periods_of(loop, periods)
    pos = [ch for ch in st.channels if ch.measures == "position"]
    ctrls = [ch.controller for ch in pos if has_stiffness(ch.controller)]
    if len(ctrls) != len(pos):
        raise AnalysisError("controller: critical stiffness needs SpringDamper (or "
                            "FilteredSpringDamper) controllers (a general H(z) has no stiffness "
                            "K to vary)")
    ratios = channel_ratios(st)
    if ratios is None and st.simple:
        raise AnalysisError("controllers: the master's stiffness is 0 and the slave's is not, so "
                            "K_s/K_m is undefined; give the master a stiffness > 0 to vary K")
    if ratios is None:        # several controllers per port: K names the reference one's
        ref = st.ports[st.channels[st.reference].port].name
        raise AnalysisError(f"controllers: the {ref}'s local stiffness, which K names, is 0 "
                            "while another controller's is not, so the ratios to K are "
                            f"undefined; give the {ref} a stiffness > 0 to vary K")
    terms = tuple(tuple((j, float(s), *split_delay(d)) for j, s, d in ch.terms)
                  for ch in st.channels)
    matrices, masses = _port_matrices(st, T, terms)
    return ResponsePlan(loop, st, T, terms, ratios, pos, ctrls, matrices, masses)


def build_responses(plans: Sequence[ResponsePlan]) -> LoopResponse:
    """The characteristic function of every plan's loop at each of its periods, one
    batch: the port polynomials of all items at once (plans of one :meth:`~ResponsePlan.key`).

    Parameters
    ----------
    plans : sequence of ResponsePlan
        From :func:`plan_response`, all with the same key.

    Returns
    -------
    LoopResponse
        The items of the plans in order (each plan's periods).

    Raises
    ------
    AnalysisError
        A loop outside the exact analysis's range (the first one's, in the order
        :func:`loop_response` checks them).
    """
    T = np.concatenate([pl.T for pl in plans])
    ports = _ports(plans, T)
    parts = [pl.numbers if pl.numbers is not None else _numbers(pl) for pl in plans]
    pl0 = plans[0]
    st, p = pl0.st, len(ports)
    filters = stack_filters([pt[5] for pt in parts]) if parts[0][5] else parts[0][5]
    resp = LoopResponse(pl0.terms, ports, np.concatenate([pt[0] for pt in parts]),
                        np.concatenate([pt[1] for pt in parts]),
                        np.concatenate([pt[2] for pt in parts]), parts[0][3], parts[0][4], T,
                        tuple(ch.port for ch in st.channels),
                        tuple(ch.measures for ch in st.channels),
                        np.concatenate([pt[6] for pt in parts]), parts[0][7], filters)
    if p != len(st.ports) or (p > 2 and not resp.simple):
        raise AnalysisError("loop: the exact analysis takes one or two ports")
    _check_finite(resp, [c for pl in plans for c in pl.ctrls])
    resp.params = tuple(arb_parameters(pl.loop, float(t)) for pl in plans for t in pl.T)
    return resp


def check_plan(plan: ResponsePlan) -> None:
    """The checks :func:`build_responses` makes of a plan after its polynomials, alone.

    Parameters
    ----------
    plan : ResponsePlan
        From :func:`plan_response`.

    Raises
    ------
    AnalysisError
        The loop is outside the exact analysis's range (mass ratio above 1e12, |B| T / m
        above 1e8, ...); a loop that passes may still be refused by
        :func:`build_responses` (its discretised plant or characteristic function
        overflows).
    """
    plan.numbers = _numbers(plan)


def _numbers(pl: ResponsePlan) -> tuple:
    """A plan's rows (k, beta, scale), q, rigid, filters, gain and free ports, after
    the checks :func:`loop_response` makes once the polynomials exist."""
    st, T, masses = pl.st, pl.T, pl.masses
    rigid = rigid_modes(st, float(T.max()))
    q = sum(A.shape[0] for A, *_ in pl.matrices) - rigid
    if max(masses) > MASS_RATIO * min(masses):
        names = ", ".join(f"{pt.name} mass = {m:g} kg" for pt, m in zip(st.ports, masses, strict=True))
        raise AnalysisError(f"{names}: a mass ratio above {MASS_RATIO:g} is outside the exact "
                            "analysis's range (the heavy port's response is below the light "
                            "one's by more than its certified enclosures resolve)")
    gain = np.array([[ch.controller.num[0] if ch.measures == "force" else 0.0
                      for ch in st.channels]]) * np.ones((T.size, 1))
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):    # beyond doubles:
        scale = 2.0 ** np.round(np.log2(min(masses) / T ** 2))   # refused below (m/T^2, B/T)
        beta = np.array([[getattr(c, "damping", 0.0) if ch.measures == "position" else 0.0
                          for ch, c in ((ch, ch.controller) for ch in st.channels)]]) / T[:, None]
        ratio_B = np.abs(beta).max(axis=1) * T ** 2 / min(masses) if beta.size else np.zeros(T.size)
    if not (np.all(np.isfinite(scale)) and np.all(scale > 0)):
        names = ", ".join(f"{pt.name} mass = {pt.device.mass:g} kg" for pt in st.ports)
        raise AnalysisError(f"{names}: cannot analyse at T = {T.min():g}..{T.max():g} s, the "
                            "loop's stiffness scale m/T^2 leaves double precision")
    if not np.all(ratio_B <= 1e8):
        names = ", ".join(f"{channel_name(st, ch)} virtual damping = "
                          f"{getattr(c, 'damping', 0.0):g} N*s/m"
                          for ch, c in zip(pl.pos, pl.ctrls, strict=True))
        raise AnalysisError(f"{names}: cannot analyse |B| T / m = {ratio_B.max():.3g} (at most "
                            "1e8; the loop's poles then lie beyond double precision)")
    free = tuple(port_is_free(pt, float(T.max())) for pt in st.ports)
    filters = filters_of([ch.controller for ch in st.channels], T)
    if any(f is not None and f[0] == "affine" for f in filters) and \
            not np.all(T == pl.loop.period):
        raise AnalysisError(f"period = {T.min():g}..{T.max():g} s: an AffineController's "
                            f"coefficients belong to the loop's period {pl.loop.period:g} s only")
    if any(filters) and not (len(st.ports) == len(st.channels) and
                             all(ch.port == i for i, ch in enumerate(st.channels))):
        raise AnalysisError("velocity_filter: the exact analysis takes filtered velocity with one "
                            "controller per port (HVE, PEB), not yet the 4-channel loop")
    k = np.broadcast_to(np.array(pl.ratios), (T.size, len(pl.terms))).copy()
    return k, beta, scale, q, rigid, filters, gain, free


def _port_matrices(st: Any, T: np.ndarray, terms: tuple) -> tuple[list[tuple], list[float]]:
    """Each port's (A, B, force row, m_z/M, free, fractions) and its mass: the force
    row where a force channel measures the port."""
    fracs: dict[int, set[float]] = {j: set() for j in range(len(st.ports))}
    forced = {j for ch in st.channels if ch.measures == "force" for j, _, _ in ch.terms}
    for ch in terms:
        for j, _, _, f in ch:
            if f:
                fracs[j].add(f)
    out, masses = [], []
    for j, pt in enumerate(st.ports):
        A, Bm, Cf = port_matrices(pt)
        fr = port_is_free(pt, float(T.max()))   # then the spring is dropped
        if fr:
            A, Cf = A.copy(), Cf.copy()
            A[1, 0], Cf[0, 0] = 0.0, 0.0
        M = pt.device.mass + pt.termination.mass
        masses.append(M)
        mz = pt.termination.mass
        # c = Cf + m_z A[1]: b_z - m_z b / M and k_z - m_z k / M may cancel, so their
        # rounding is bounded by the terms' magnitudes
        force = ((Cf[0] + mz * A[1], np.abs(Cf[0]) + mz * np.abs(A[1])) if j in forced
                 else None)
        out.append((A, Bm, force, mz / M, fr, sorted(fracs[j])))
    return out, masses


def _ports(plans: Sequence[ResponsePlan], T: np.ndarray) -> list[PortPoly]:
    """Each port's polynomials over every item of the plans (their own matrices)."""
    ports = []
    for j in range(len(plans[0].matrices)):
        _, _, force0, _, fr, fs = plans[0].matrices[j]
        rows = [(pl.T.size, pl.matrices[j]) for pl in plans]
        A, Bm, mz = (_rows(rows, lambda m, k=k: m[k]) for k in (0, 1, 3))
        force = None if force0 is None else (_rows(rows, lambda m: m[2][0]),
                                             _rows(rows, lambda m: m[2][1]))
        ports.append(port_polynomials(A, Bm, fr, T, fs, force, mz))
    for j, pp in enumerate(ports):
        arrays = [pp.d, pp.N, *list(pp.Nt.values()), *list(pp.D.values())]
        arrays += [pp.R] if pp.R is not None else []
        # (N vanishing for any item: its plant underflows; one row of a batch may)
        if not all(np.all(np.isfinite(a)) for a in arrays) or not np.all(np.any(pp.N, axis=1)):
            pt = plans[0].st.ports[j]
            raise AnalysisError(
                f"{pt.name} mass = {pt.device.mass:g} kg, {pt.name} damping = "
                f"{pt.device.damping:g} N*s/m at T = {T.min():g}..{T.max():g} s: cannot analyse, "
                "the discretised plant over- or underflows double precision")
    return ports


def _rows(rows: list[tuple[int, tuple]], part: Any) -> np.ndarray:
    """One part of each plan's port matrices, repeated for each of its periods."""
    return np.concatenate([np.broadcast_to(part(m), (n, *np.shape(part(m)))) for n, m in rows])


def _check_finite(resp: LoopResponse, ctrls) -> None:
    """Refuse parameters whose characteristic function overflows (e.g. B = 1e300)."""
    th = np.array([0.0, 1.0, np.pi])
    idx = np.repeat(np.arange(resp.size), th.size)
    F = resp.coefficients(idx, np.tile(th, resp.size), np.zeros(idx.size), values_only=True)
    with np.errstate(all="ignore"):
        top = [np.abs(f.vc) * u for f, u in zip(F, (1.0, 1e10, 1e20), strict=True)]   # up to u = U_HI
    if not all(np.all(np.isfinite(t)) for t in top):
        damp = [getattr(c, "damping", 0.0) for c in ctrls]
        raise AnalysisError(f"virtual damping = {damp} N*s/m, stiffness = "
                            f"{[c.stiffness for c in ctrls]} N/m: cannot analyse these "
                            "parameters, the loop's characteristic function overflows double "
                            "precision")


def stack_responses(resps: Sequence[LoopResponse]) -> LoopResponse:
    """Concatenate responses of one structure (same terms and port orders)."""
    r0 = resps[0]
    for r in resps:
        if r.terms != r0.terms or r.q != r0.q or [pp.d.shape for pp in r.ports][1:] != \
                [pp.d.shape for pp in r0.ports][1:]:
            raise AnalysisError("stack_responses: the loops differ in structure")
    cat = np.concatenate
    ports = []
    for j in range(len(r0.ports)):
        ps = [r.ports[j] for r in resps]
        ports.append(PortPoly(cat([x.d for x in ps]), cat([x.dhat for x in ps]),
                              cat([x.N for x in ps]),
                              {f: cat([x.Nt[f] for x in ps]) for f in ps[0].Nt},
                              {f: cat([x.D[f] for x in ps]) for f in ps[0].D},
                              {k: cat([x.err[k] for x in ps]) for k in ps[0].err},
                              None if ps[0].R is None else cat([x.R for x in ps]),
                              None if ps[0].mz_M is None else cat([x.mz_M for x in ps])))
    return LoopResponse(r0.terms, ports, cat([r.k for r in resps]), cat([r.beta for r in resps]),
                        cat([r.scale for r in resps]), r0.q, r0.rigid,
                        cat([r.periods for r in resps]), r0.channel_ports, r0.kinds,
                        cat([r.gain for r in resps]), r0.free,
                        stack_filters([r.filters for r in resps]) if r0.filters else (),
                        tuple(x for r in resps for x in (r.params or (None,) * r.size)))
