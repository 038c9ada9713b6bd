"""The loop's characteristic function in ball arithmetic (python-flint's Arb): the
rigorous half of the one engine, on which every certified verdict rests.

The loop is given by plain numbers (:func:`arb_parameters`): per port the device's
mass and damping and its termination's mass, damping and spring; per channel the
controller's stiffness per unit K, its virtual damping B and the measured ports
(sign, whole delay in samples); the sampling period. Each number is a double and is
taken as exact. From them, in balls of ``prec`` bits:

* the ZOH of each port, ``[Phi, Gamma; 0, 1] = exp([A, B; 0, 0] T)`` by Arb's
  matrix exponential (``arb_mat.exp``, rigorous error bounds), ``E = Phi - I``;
* the port polynomials in ``y = z - 1``: ``d(y) = det(yI - E)`` (``charpoly``) and
  ``N(y) = C adj(yI - E) Gamma = det(yI - E + Gamma C) - d(y)`` (C reads the
  position; the identity is the matrix determinant lemma);
* with ``H_j = K k_j + h_j``, ``h_j = beta_j (1 - z^-1)``, ``beta_j = B_j / T`` and
  ``S_ij = s_ij z^-n_ij`` the measurement matrix, the characteristic function

      det M(z, K) = det(diag(d_j) + S diag(N_j H_j)) = P(z, K) + w(z) Q(z, K),

  where ``w = z^-n`` is the whole delay as an exact phase and P, Q are delay-free
  polynomials of degree <= 2 in K. One port (HVE): ``P = d_0``, ``Q = s N_0 H_0``,
  ``w = z^-n``. Two ports whose own positions are read undelayed (PEB, eq. 20):
  ``P = (d_0 + s_00 N_0 H_0)(d_1 + s_11 N_1 H_1)``, ``Q = -s_01 s_10 N_0 N_1 H_0 H_1``,
  ``w = z^-(n_01 + n_10)`` (the round trip).

For real K the closed loop has ``Z_out(K) = q - wind(det M(e^{j theta}, K))`` poles
outside the unit circle (``q`` = the ports' total order; see
:mod:`hapstab.engine.frequency` for the determinant identity). Every value is a ball
that contains the exact value of the function of the given doubles, for every
theta and K in the argument balls, so an exclusion (0 not in the ball) is a proof.

References
----------
F. Johansson, "Arb: efficient arbitrary-precision midpoint-radius interval
arithmetic", IEEE Trans. Computers 66 (2017) 1281-1292. The paper, Fig. 2a / Fig. 3,
eq. (20) and (23); K. J. Astrom and B. Wittenmark, *Computer-Controlled Systems*,
3rd ed., sec. 2.3 (ZOH sampling).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hapstab.engine.arb_base import (
    BASE_RATIO,
    NEGLIGIBLE_DAMPING,
    PortZoh,
    base_point,
    damping_scale,
    k_scale,
)
from hapstab.engine.arb_forms import (
    Dual,
    accuracy_bits,
    box_balls,
    dpoly_k,
    exclusion_test,
    poly_k,
    preconditioned_excludes,
)
from hapstab.engine.arb_kernel import KernelPolys, kernel_polys, poly_kernel

__all__ = ["ArbLoop", "arb_parameters", "working_precision", "PREC", "poly_k", "dpoly_k", "Dual",
           "base_point", "k_scale", "damping_scale", "BASE_RATIO", "NEGLIGIBLE_DAMPING",
           "preconditioned_excludes"]

#: Working precision in bits. The port polynomials cancel: with E ~ T^2/m the
#: coefficients are 1e-35 of the unit terms for a 1e29 kg device at T = 1 ms
#: (116 bits); 320 bits keep more than 150 bits after that. :class:`ArbLoop` checks
#: the relative accuracy it got and raises the precision if needed.
PREC = 320
#: Bits of relative accuracy the port polynomials must keep (else the precision is
#: doubled): far more than any exclusion needs, so the balls are never the bottleneck.
MIN_BITS = 80
#: Most angle kernels (:meth:`ArbLoop.kernel`) kept at once (memory; a proof of a
#: long delay visits a few thousand pieces of [0, pi]).
KERNEL_CACHE = 20000


class working_precision:
    """Run with Arb's (global) precision at ``prec`` bits, restored afterwards (a
    context manager; a class, not a generator: the proof enters it a few times per
    box, and a generator's context costs ~2 us, a tenth of a box)."""

    __slots__ = ("ctx", "old", "prec")

    def __init__(self, prec: int) -> None:
        import flint  # cached after the first import: a dict lookup
        self.ctx, self.prec, self.old = flint.ctx, prec, 0

    def __enter__(self) -> None:
        self.old = self.ctx.prec
        if self.old != self.prec:       # setting it costs ~1 us; nested uses often agree
            self.ctx.prec = self.prec

    def __exit__(self, *exc: object) -> None:
        if self.old != self.prec:
            self.ctx.prec = self.old


def arb_parameters(loop: Any, period_s: float | None = None) -> dict[str, Any] | None:
    """The plain numbers :class:`ArbLoop` needs, or None if the loop's structure is
    outside what the ball-arithmetic core covers (then the float-enclosure core of
    :mod:`hapstab.analysis.exact.crossings` answers alone, and says so).

    Covered: one or two ports whose terminations are mass-spring-dampers (no internal
    states), one spring-damper position controller per port (no velocity filter),
    whole delays, the own position read undelayed on two ports, no rigid-body mode.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop.
    period_s : float, optional
        The sampling period (default the loop's).

    Returns
    -------
    dict or None
        ``period_s``, ``ports`` (``mass_kg``, ``damping_N_s_per_m``,
        ``termination_mass_kg``, ``termination_damping_N_s_per_m``,
        ``termination_stiffness_N_per_m``), ``channels`` (``stiffness_ratio``,
        ``damping_N_s_per_m``, ``terms`` as ``[port, sign, delay_samples]``).
    """
    from hapstab.engine.structure import channel_ratios, rigid_modes, structure_of
    from hapstab.models.controllers import SpringDamper
    from hapstab.models.loops import split_delay
    try:
        st = structure_of(loop)
    except Exception:       # not a loop the exact core takes at all
        return None
    T = float(loop.period if period_s is None else period_s)
    ratios = channel_ratios(st)
    if ratios is None or not st.simple or len(st.ports) not in (1, 2) or \
            rigid_modes(st, T) or ratios[0] != 1.0:
        return None
    ports = []
    for pt in st.ports:
        z = pt.termination
        if z.state_space()[0].shape[0]:
            return None
        ports.append({"mass_kg": float(pt.device.mass),
                      "damping_N_s_per_m": float(pt.device.damping),
                      "termination_mass_kg": float(z.mass),
                      "termination_damping_N_s_per_m": float(z.damping),
                      "termination_stiffness_N_per_m": float(z.stiffness)})
    chans: list[dict[str, Any]] = []
    for i, ch in enumerate(st.channels):
        if type(ch.controller) is not SpringDamper:
            return None
        terms = []
        for j, s, dly in ch.terms:
            n, f = split_delay(dly)
            if f or (len(st.ports) == 2 and j == i and n):
                return None
            terms.append([int(j), float(s), int(n)])
        chans.append({"stiffness_ratio": float(ratios[i]),
                      "damping_N_s_per_m": float(ch.controller.damping), "terms": terms})
    if len(ports) == 1 and len(chans[0]["terms"]) != 1:
        return None
    if len(ports) == 2 and any(len(c["terms"]) != 2 for c in chans):
        return None
    return {"period_s": T, "ports": ports, "channels": chans}


@dataclass
class _Port:
    d: Any          # acb_poly in y
    N: Any          # acb_poly in y
    order: int
    dd: Any = None  # d'(y), N'(y): the derivatives, formed once
    dN: Any = None

    def __post_init__(self) -> None:
        self.dd, self.dN = self.d.derivative(), self.N.derivative()


class ArbLoop:
    """det M(e^{j theta}, K) = P + w Q of a loop in ball arithmetic (module doc).

    Parameters
    ----------
    params : dict
        From :func:`arb_parameters` (or a certificate's ``loop`` entry).
    prec : int
        Starting precision in bits (raised until the port polynomials keep
        :data:`MIN_BITS` bits).

    Attributes
    ----------
    q : int
        The ports' total order.
    n_phase : int
        The whole delay carried by the phase w = z^-n_phase.
    prec : int
        The precision used.
    """

    def __init__(self, params: dict[str, Any], prec: int = PREC) -> None:
        self.params = params
        self._kernels: dict[Any, tuple] = {}
        self._skernels: dict[Any, tuple] = {}
        self._polys: KernelPolys | None = None
        while True:
            with working_precision(prec):
                ok = self._build(params)
            if ok or prec >= 4096:
                break
            prec *= 2
        self.prec = prec
        self.accurate = ok

    # -------------------------------------------------------------- building
    def _build(self, params: dict[str, Any]) -> bool:
        import flint
        acb, arb = flint.acb, flint.arb
        T = arb(params["period_s"])
        self.ports = [self._port(p, T) for p in params["ports"]]
        self.q = sum(p.order for p in self.ports)
        ch = params["channels"]
        # complex balls throughout: python-flint multiplies acb by acb several times
        # faster than acb by arb (the same product)
        self.k = [acb(arb(c["stiffness_ratio"])) for c in ch]
        self.beta = [acb(arb(c["damping_N_s_per_m"]) / T) for c in ch]
        if len(self.ports) == 1:
            (_j, s, n), = ch[0]["terms"]
            self.n_phase, self.s = int(n), [acb(s)]
        else:
            own = [next(t for t in c["terms"] if t[0] == i) for i, c in enumerate(ch)]
            cross = [next(t for t in c["terms"] if t[0] != i) for i, c in enumerate(ch)]
            self.n_phase = int(cross[0][2] + cross[1][2])
            self.s = [acb(own[0][1]), acb(own[1][1]), acb(-cross[0][1] * cross[1][1])]
        return all(accuracy_bits(p.d) >= MIN_BITS and accuracy_bits(p.N) >= MIN_BITS for p in self.ports)

    @staticmethod
    def _port(p: dict[str, Any], T: Any) -> _Port:
        import flint
        z = PortZoh(p, T)
        return _Port(flint.acb_poly(z.d), flint.acb_poly(z.numerator()), 2)

    # -------------------------------------------------------------- evaluation
    def parts(self, theta: Any, deriv: bool = False) -> tuple[list[Any], list[Any], Any]:
        """Coefficients in K of P and Q, and the phase w, on the ball ``theta``.

        Parameters
        ----------
        theta : arb
            An angle or a ball of angles (rad/sample).
        deriv : bool
            Return :class:`Dual` numbers (value, d/dtheta) instead of acb.

        Returns
        -------
        P, Q : list of 3 acb (or Dual)
            ``P = P[0] + K P[1] + K^2 P[2]`` (K in N/m), the same for Q.
        w : acb (or Dual)
            ``z^-n_phase`` on the ball.
        """
        with working_precision(self.prec):
            return self._parts(theta, deriv)

    def _parts(self, theta: Any, deriv: bool) -> tuple[list[Any], list[Any], Any]:
        """:meth:`parts` at the precision already set."""
        import flint
        acb = flint.acb
        jt = acb(0, theta)
        y = jt.expm1()
        omz = -(-jt).expm1()                 # 1 - z^-1
        w = (-jt * self.n_phase).exp() if self.n_phase else acb(1)
        if deriv:
            j = acb(0, 1)
            yd = Dual(y, j * (1 + y))
            omzd = Dual(omz, j * (1 - omz))
            wd = Dual(w, -j * self.n_phase * w)
            dN = [(Dual(p.d(y), p.dd(y) * yd.d), Dual(p.N(y), p.dN(y) * yd.d))
                  for p in self.ports]
            return self._combine(dN, [omzd * b for b in self.beta], wd)
        dN = [(p.d(y), p.N(y)) for p in self.ports]
        return self._combine(dN, [omz * b for b in self.beta], w)

    def _combine(self, dN: list, h: list, w: Any) -> tuple[list[Any], list[Any], Any]:
        """P, Q from the port polynomials' values and h_j (acb or Dual alike)."""
        zero = 0 * h[0]
        if len(self.ports) == 1:
            (d, N), = dN
            sN = N * self.s[0]
            return [d, zero, zero], [sN * h[0], sN * self.k[0], zero], w
        (d0, N0), (d1, N1) = dN
        a0, b0 = d0 + N0 * h[0] * self.s[0], N0 * (self.s[0] * self.k[0])
        a1, b1 = d1 + N1 * h[1] * self.s[1], N1 * (self.s[1] * self.k[1])
        c = N0 * N1 * self.s[2]
        P = [a0 * a1, a0 * b1 + a1 * b0, b0 * b1]
        Q = [c * h[0] * h[1], c * (h[0] * self.k[1] + h[1] * self.k[0]),
             c * (self.k[0] * self.k[1])]
        return P, Q, w

    def kernel(self, theta: Any, key: Any = None, polys: bool = False) -> tuple:
        """What :meth:`box` needs of the angle alone, as coefficients in K: P, Q and
        det M = P + w Q at the ball's centre, and the values and d/dtheta over the ball
        (det M's combined before any K enters, so that terms of P and w Q that cancel
        -- the K^2 terms of a two-port loop without delay -- cancel in the
        coefficients, not in the balls). None of it depends on K, so the boxes of one
        theta piece at many K-ranges share it (cached by ``key``, the piece's ends as
        the caller names them, and served only for the same ball; None: not cached).

        Parameters
        ----------
        theta : arb
            A ball of angles (rad/sample).
        key : hashable, optional
            The cache key of this ball (e.g. the piece's ends (a, b)).
        polys : bool
            By precomputed ball polynomials (:mod:`~hapstab.engine.arb_kernel`,
            certificate version 4; a few times faster) instead of forward-mode
            derivatives (versions 1-3, and the argument-principle counts): the same
            functions, balls that differ in their rounding.

        Returns
        -------
        tuple
            ``(Pm, Qm, Fm, Pd, Qd, Fd)``: lists of 3 acb, the coefficients of K^0..K^2
            of P, Q, det M at the centre and of their d/dtheta over the ball.
        """
        return self.kernel_entry(theta, key, polys)[1]

    def kernel_entry(self, theta: Any, key: Any, polys: bool) -> tuple:
        """:meth:`kernel`'s cache entry: ``(theta, kernel, nonzero flags)``, the ball it
        was made for (the one given, or an equal one cached), the kernel and, with
        ``polys``, :class:`~hapstab.engine.arb_kernel.KernelPolys`'s ``nonzero``."""
        cache = self._skernels if polys else self._kernels
        if key is not None:
            got = cache.get(key)
            # the kernel holds the ball's centre: it serves only the very ball it was made
            # for (the same ends formed at another precision have another centre, and a
            # centre of one with the radius of the other misses a sliver of the piece)
            if got is not None and (got[0] is theta or (got[0].mid() == theta.mid()
                                                        and got[0].rad() == theta.rad())):
                return got
        import flint
        arb = flint.arb
        with working_precision(self.prec):
            if polys:
                kern = poly_kernel(self.kernel_polys, theta)
            else:
                Pm, Qm, wm = self._parts(arb(theta.mid()), False)
                Pt, Qt, wt = self._parts(theta, True)
                Fm = [p + wm * q for p, q in zip(Pm, Qm, strict=True)]
                Pd, Qd = [p.d for p in Pt], [q.d for q in Qt]
                Fd = [p + wt.d * q.v + wt.v * dq for p, q, dq in zip(Pd, Qt, Qd, strict=True)]
                kern = (Pm, Qm, Fm, Pd, Qd, Fd)
        entry = (theta, kern, self.kernel_polys.nonzero if polys else None)
        if key is not None:
            if len(cache) >= KERNEL_CACHE:
                cache.clear()
            cache[key] = entry
        return entry

    @property
    def kernel_polys(self) -> KernelPolys:
        """P and Q as ball polynomials (:mod:`~hapstab.engine.arb_kernel`), formed once,
        at the loop's precision."""
        if self._polys is None:
            with working_precision(self.prec):
                self._polys = kernel_polys(self.ports, self.s, self.k, self.beta, self.n_phase)
        return self._polys

    def box(self, theta: Any, K: Any, key: Any = None, polys: bool = False) -> tuple[Any, Any, Any]:
        """Balls of P, Q and det M = P + w Q over the balls ``theta`` x ``K``, in the
        centred (mean-value) form: the value at the centre plus the radii times the
        derivatives over the box, so the overestimation is of second order. Each is a
        polynomial in K with coefficients from :meth:`kernel`.

        Parameters
        ----------
        theta, K : arb
            Balls of angles and of stiffnesses (N/m).
        key : hashable, optional
            Cache key of the angle's :meth:`kernel` (the same ball every time).
        polys : bool
            As :meth:`kernel`.

        Returns
        -------
        P, Q, F : acb
        """
        kern = self.kernel(theta, key, polys)
        with working_precision(self.prec):
            return box_balls(kern, theta, K)[:3]

    def exclusion(self, theta: Any, K: Any, key: Any = None,
                  polys: bool = False) -> tuple[str | None, float, float]:
        """Whether det M has no zero on the box ``theta`` x ``K``, by the tests a
        certificate names, in order (:func:`~hapstab.engine.arb_forms.exclusion_test`):
        ``"P"`` (|P| > |Q|: then |det M| >= |P| - |Q| > 0 whatever the delay's phase),
        ``"Q"`` (|Q| > |P|), ``"F"`` (0 not in det M's ball), ``"N"`` (0 not in the
        preconditioned ball); the balls are :meth:`box`'s (``polys``: as :meth:`kernel`).

        Returns
        -------
        how : {"P", "Q", "F", "N"} or None
            The test that excludes the box (None: none does).
        spread_theta, spread_K : float
            With ``how`` None: upper bounds of |d det M/d theta| rad(theta) and
            |d det M/dK| rad(K) over the box, the widths of det M's ball due to each
            (to choose a split); else 0.
        """
        _t, kern, nz = self.kernel_entry(theta, key, polys)
        with working_precision(self.prec):
            return exclusion_test(kern, theta, K, nz)

    def box_derivatives(self, theta: Any, K: Any, key: Any = None,
                        polys: bool = False) -> tuple[Any, Any, Any]:
        """det M at the box's centre and its derivatives over the box, as :meth:`box`
        forms them: ``(F_c, dF/dtheta, dF/dK)`` (acb), for the preconditioned test
        (:func:`preconditioned_excludes`)."""
        kern = self.kernel(theta, key, polys)
        with working_precision(self.prec):
            return box_balls(kern, theta, K)[3:]


    def krawczyk_excludes(self, theta: Any, K: Any, box: tuple[float, float, float, float],
                          kern0: tuple | None = None) -> bool:
        """Whether det M has no zero on ``box`` = (a, b, K_a, K_b) by the iterated
        Krawczyk operator from the balls ``theta`` x ``K`` that hold it (certificate
        version 5's test ``"I"``, :mod:`~hapstab.engine.arb_krawczyk`), on the angle
        kernel of ball polynomials at the loop's precision; ``kern0``: that kernel on
        ``theta``, formed already."""
        from hapstab.engine.arb_krawczyk import krawczyk_excludes

        def kernel_at(t: Any) -> tuple:
            return self.kernel_entry(t, None, True)[1]
        with working_precision(self.prec):
            return krawczyk_excludes(kernel_at, theta, K, box, kern0)

    @property
    def degree(self) -> int:
        """The degree of :meth:`polynomial` in z: the closed loop's number of states."""
        e = len(self.ports)
        return self.n_phase + e + self.q

    def polynomial(self, K: Any) -> Any:
        """The closed loop's characteristic polynomial chi(z) = z^(n + e) det M(z, K) in
        balls (acb_poly in z; n = :attr:`n_phase`, e the number of ports), monic of
        degree :attr:`degree`: its roots are the closed-loop poles.

        With ``G_j(z) = z H_j = K k_j z + beta_j (z - 1)`` and the port polynomials in
        ``y = z - 1`` composed with ``z - 1``: one port, ``chi = z^(n+1) d + s N G``;
        two ports, ``chi = z^n (z d_0 + s_0 N_0 G_0)(z d_1 + s_1 N_1 G_1) +
        s_2 N_0 N_1 G_0 G_1`` (module doc's P, Q and w = z^-n, times z^(n+2)). The
        z^(n+e) adds roots at z = 0 only, so the roots outside the unit circle are the
        zeros of det M there. Monic: d_j is monic of degree 2 in y and every other
        term has a lower degree.

        Parameters
        ----------
        K : float or arb
            Stiffness (N/m).

        Returns
        -------
        acb_poly
        """
        import flint
        acb, acb_poly = flint.acb, flint.acb_poly
        with working_precision(self.prec):
            Kc = acb(K)
            y, z = acb_poly([-1, 1]), acb_poly([0, 1])
            dz = [p.d(y) for p in self.ports]
            nz = [p.N(y) for p in self.ports]
            G = [z * (Kc * k) + (z - 1) * b for k, b in zip(self.k, self.beta, strict=True)]
            if len(self.ports) == 1:
                return z ** (self.n_phase + 1) * dz[0] + nz[0] * G[0] * self.s[0]
            a = [z * dz[j] + nz[j] * G[j] * self.s[j] for j in range(2)]
            return z ** self.n_phase * a[0] * a[1] + nz[0] * nz[1] * G[0] * G[1] * self.s[2]

    def value(self, theta: Any, K: Any) -> Any:
        """det M on the balls ``theta`` (arb) and ``K`` (arb, N/m): an acb ball."""
        import flint
        acb = flint.acb
        with working_precision(self.prec):
            P, Q, w = self._parts(theta, False)
            Kc = acb(K)
            return poly_k(P, Kc) + w * poly_k(Q, Kc)

    def dvalue_dk(self, theta: Any, K: Any) -> Any:
        """d det M / dK on the balls (for Newton's method and the crossing's direction)."""
        import flint
        acb = flint.acb
        with working_precision(self.prec):
            P, Q, w = self._parts(theta, False)
            Kc = acb(K)
            return P[1] + 2 * Kc * P[2] + w * (Q[1] + 2 * Kc * Q[2])
