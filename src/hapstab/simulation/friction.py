"""Coulomb friction between the sampling instants: exact stick-slip of each port under
the force held by the zero-order hold.

Model
-----
A port is one rigid body (the device with the operator / environment rigidly attached,
mass ``M = m + m_z``, state ``z = [x, v, xi...]`` of
:func:`~hapstab.engine.zoh.port_matrices`). Over a sample the net applied force ``g``
(exogenous force, spring rest offsets, minus the held controller force) is constant,
and the device's Coulomb friction f_c acts on the body's velocity:

* **sliding** (v != 0, direction ``s = sign(v)``): friction is the constant ``-s f_c``,
  so ``z' = A z + B (g - s f_c)`` is a linear ODE with a constant input, propagated
  exactly by the matrix exponential until v reaches 0;
* **at v = 0** the body sticks if the net static force ``N = g - k x - C_r xi`` (every
  force but inertia, viscous damping and friction) satisfies ``|N| <= f_c``; else it
  slides in the direction of N;
* **stuck** (v = 0, x constant): the attached impedance's internal states xi still
  relax (``xi' = A_r xi``), so N may change within the sample; the body leaves stick
  when |N| reaches f_c, in the direction of N. Without internal states (a spring,
  damper and mass) N is constant and the body stays stuck to the end of the sample.

Events (v = 0 while sliding, |N| = f_c while stuck) are located as roots of
``y(t) = c z(t) + d``, never by smoothing sign(v). The first root in the sample is
isolated by a certified subdivision: on ``[a, a + h]``, Taylor's theorem with the
derivative bound ``|y^(j+1)(t)| <= ||c~ A~^j|| e^(mu h) ||w~(a)||`` (``w = z'``, which
obeys ``w' = A w``; ``~``: a diagonal scaling of the state, ``mu`` the logarithmic
2-norm of the scaled A, made small by the scaling) proves either that y keeps its sign
on the interval, or that y is strictly monotone there (then a sign change holds
exactly one root); otherwise the interval is halved. The root is then located by
Brent's method to machine precision and v (or nothing else) is set to exactly 0.

References
----------
D. Karnopp, "Computer simulation of stick-slip friction in mechanical dynamic
systems", J. Dyn. Syst. Meas. Control 107(1), 1985 (the stick / slip switching
rule); R. P. Brent, "Algorithms for Minimization without Derivatives", 1973,
ch. 4 (the root finder).
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.engine.structure import Port
from hapstab.engine.zoh import expm_batched, port_matrices
from hapstab.errors import ModelError

__all__ = ["FrictionPort", "LoopFriction", "Segment", "Overflow", "first_zero", "MAX_EVENTS"]

#: Brent's method's relative tolerance in time: its smallest allowed value (4 eps),
#: so an event is located to machine precision.
TIME_RTOL = 4.0 * np.finfo(float).eps
#: An interval shorter than this fraction of the period is not split further: y then
#: touches 0 within rounding (a double root), and that point is taken as the event
#: (2^-44 = 5.7e-14: well above the 1e-16 resolution of a time within the sample).
H_MIN = 2.0 ** -44
#: Events in one sample beyond this are refused (a Zeno accumulation of stick-slip
#: switches that the model does not resolve); 10,000 is far beyond any physical run.
MAX_EVENTS = 10_000
#: Consecutive zero-length segments after which the body is held stuck for the rest
#: of the sample: |N| equals f_c to rounding and the switching rule cannot choose.
STALL = 3


@dataclass(frozen=True)
class Segment:
    """One stretch of a port's motion within a sample.

    Parameters
    ----------
    start_s : float
        Its start, in s after the sampling instant.
    state : (q,) array
        The port's state ``[x, v, xi...]`` there.
    mode : int
        +1 / -1 sliding in that direction, 0 stuck.
    """

    start_s: float
    state: np.ndarray
    mode: int


class _Flow:
    """``z' = A z + b g`` for a constant g: exact propagation and the data of the
    derivative bounds (module docstring).

    The matrix exponential is taken of the diagonally scaled state (the scaling of the
    bounds, e.g. ``[x, v / w]`` for a spring-mass block), whose norm is near the motion's
    own rate: scaling and squaring on the unscaled ``[[0, 1], [-w^2, 0]] t`` loses about
    ``eps ||A t||`` (1e-9 relative for 1e6 N/m on 20 g at T = 1 ms, measured against
    the closed form), the scaled one stays at rounding.
    """

    def __init__(self, A: np.ndarray, b: np.ndarray, active: np.ndarray) -> None:
        self.A, self.b, self.active = A, b, active
        self._cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        Aa = A[np.ix_(active, active)]
        best = None
        for sc in _scalings(Aa):
            At = Aa * sc[None, :] / sc[:, None]
            mu = max(0.0, float(np.linalg.eigvalsh(0.5 * (At + At.T)).max())) if At.size else 0.0
            if best is None or mu < best[0]:
                best = (mu, sc, At)
        assert best is not None
        self.mu, self.scale, self.At = best
        q = A.shape[0]
        full = np.full(q, float(best[1][0]) if best[1].size else 1.0)
        full[active] = best[1]
        self._aug = np.zeros((q + 1, q + 1))      # the scaled [[A, b], [0, 0]]
        self._aug[:q, :q] = A * full[None, :] / full[:, None]
        self._aug[:q, q] = b / full
        self._full = full

    def maps(self, t: float, cache: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """``(e^{At}, int_0^t e^{As} ds b)``."""
        hit = self._cache.get(t) if cache else None
        if hit is None:
            Ad, Bd = self.maps_many(np.array([t]))
            hit = (Ad[0], Bd[0])
            if cache:
                if len(self._cache) > 64:
                    self._cache.clear()
                self._cache[t] = hit
        return hit

    def maps_many(self, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The maps of :meth:`maps` for each time of ``ts``: (P, q, q) and (P, q)."""
        E = expm_batched(self._aug[None] * np.asarray(ts, float)[:, None, None])
        q, sc = self.A.shape[0], self._full
        return E[:, :q, :q] * sc[None, :, None] / sc[None, None, :], E[:, :q, q] * sc[None]

    def prop(self, z: np.ndarray, g: float, t: float, cache: bool = True) -> np.ndarray:
        """The state t seconds after z."""
        Ad, Bd = self.maps(t, cache)
        return Ad.dot(z) + Bd * g

    def norms(self, c: np.ndarray) -> tuple[float, float]:
        """``||c~ A~||`` and ``||c~ A~^2||`` for the output row c."""
        ct = c[self.active] * self.scale
        r1 = ct @ self.At
        return float(np.linalg.norm(r1)), float(np.linalg.norm(r1 @ self.At))


def _scalings(A: np.ndarray) -> list[np.ndarray]:
    """Candidate diagonal scalings of the state for the bounds: none, LAPACK's balancing,
    and for a spring-mass block [[0, 1], [-w^2, .]] the one that makes it [[0, w], [-w, .]]
    (logarithmic norm 0)."""
    n = A.shape[0]
    out = [np.ones(n)]
    if n:
        with contextlib.suppress(ValueError, np.linalg.LinAlgError):   # LAPACK's refusal
            from scipy.linalg import matrix_balance  # lazily: scipy costs 0.4 s to import
            out.append(np.asarray(matrix_balance(A, permute=False, separate=True)[1][0], float))
    if n >= 2 and A[0, 1] == 1.0 and A[1, 0] < 0:
        sc = np.ones(n)
        sc[1] = math.sqrt(-A[1, 0])
        out.append(sc)
    return [s for s in out if np.all(np.isfinite(s)) and np.all(s > 0)]


#: Samples between two looks at the clock (:meth:`LoopFriction._on_time`): at most ~1 ms
#: each, so a run stops within ~0.1 s of its budget.
CLOCK_EVERY = 64


class Overflow(ArithmeticError):
    """The port's state left double precision (a growing run): the run has overflowed."""


def _derivs(flow: _Flow, z: np.ndarray, g: float, c: np.ndarray, d: float
            ) -> tuple[float, float, float, float]:
    """y, y', y'' at z and the scaled norm of w = z'.

    Raises
    ------
    Overflow
        One of them is not finite.
    """
    w = flow.A.dot(z) + flow.b * g
    ws = w[flow.active] / flow.scale     # its norm as np.linalg.norm forms it: sqrt(ws . ws)
    out = (float(c.dot(z)) + d, float(c.dot(w)), float(c.dot(flow.A.dot(w))),
           math.sqrt(ws.dot(ws)))
    if not all(map(math.isfinite, out)):
        raise Overflow
    return out


def first_zero(flow: _Flow, z0: np.ndarray, g: float, c: np.ndarray, d: float, tau: float,
               bounds: tuple[float, float], h_min: float, start_up: bool = False
               ) -> tuple[float | None, np.ndarray]:
    """The first t in (0, tau] where ``y = c z(t) + d`` reaches 0, y >= 0 at t = 0.

    Parameters
    ----------
    flow : _Flow
        The dynamics, input ``g`` held.
    z0 : (q,) array
        The state at t = 0.
    g : float
        The constant input (N).
    c, d : (q,) array, float
        The output ``y = c z + d``.
    tau : float
        The end of the search (s).
    bounds : (float, float)
        ``flow.norms(c)``.
    h_min : float
        The shortest interval that is split (s).
    start_up : bool
        y starts at 0 and is known to rise (a slide that has just begun): a slope
        that rounding made slightly negative is read as 0.

    Returns
    -------
    (t or None, state)
        The event time and the state there; ``(None, z(tau))`` without an event.
    """
    n1, n2 = bounds
    a, za, h = 0.0, z0, tau
    ya, y1, y2, nw = _derivs(flow, za, g, c, d)
    if start_up and ya == 0:
        y1 = max(y1, 0.0)
    if ya < 0 or (ya == 0 and (y1 < 0 or (y1 == 0 and y2 <= 0))):
        return 0.0, z0                     # y is 0 and heading down: the event is now
    while True:
        h = min(h, tau - a)
        grow = math.exp(min(flow.mu * h, 700.0)) * nw
        c2, c3 = n1 * grow, n2 * grow      # |y''|, |y'''| on [a, a + h]
        if not math.isfinite(c2 + c3):
            raise Overflow
        if ya > 0:                         # y >= ya + y1 s - c2 s^2 / 2, concave in s
            clear = ya + y1 * h - 0.5 * c2 * h * h > 0
        else:                              # y / s >= y1 + y2 s / 2 - c3 s^2 / 6
            clear = y1 >= 0 and y1 + 0.5 * y2 * h - c3 * h * h / 6.0 > 0
        sg = 1.0 if (y1 > 0 or (y1 == 0 and y2 > 0)) else -1.0
        mono = not clear and sg * y1 >= 0 and sg * (y1 + y2 * h) - 0.5 * c3 * h * h > 0
        if clear or mono:
            zb = flow.prop(za, g, h)
            yb = float(c @ zb) + d
            if yb <= 0:                    # one crossing (or rounding at a touch)
                if yb == 0 or ya == 0:
                    return a + h, zb
                return _locate(flow, za, g, c, d, a, h, tau)
            if a + h >= tau:
                return None, zb
            a, za, h = a + h, zb, 2.0 * h
            ya, y1, y2, nw = _derivs(flow, za, g, c, d)
        elif h > h_min:
            h *= 0.5
        else:                              # y touches 0 within rounding: an event here
            return a, za


def _locate(flow: _Flow, za: np.ndarray, g: float, c: np.ndarray, d: float, a: float, h: float,
            tau: float) -> tuple[float, np.ndarray]:
    """The one root of y on (a, a + h], where y(a) > 0 > y(a + h): Brent's method."""
    from scipy.optimize import brentq  # lazily: scipy costs 0.4 s to import
    t = brentq(lambda s: float(c @ flow.prop(za, g, s, cache=False)) + d, 0.0, h,
               xtol=TIME_RTOL * tau, rtol=TIME_RTOL)
    return a + t, flow.prop(za, g, t, cache=False)


class FrictionPort:
    """One port with Coulomb friction, advanced exactly over one sample.

    Parameters
    ----------
    port : Port
        The device (with ``coulomb_friction`` > 0) and its termination.
    period : float
        T in s.

    Raises
    ------
    ModelError
        The port's model overflows (see :func:`~hapstab.engine.zoh.port_matrices`).
    """

    def __init__(self, port: Port, period: float) -> None:
        A, B, _ = port_matrices(port)
        q = A.shape[0]
        self.q, self.T = q, float(period)
        self.fc = float(port.device.coulomb_friction)
        self.mass = port.device.mass + port.termination.mass
        self.net = self.mass * A[1]          # N = net z + g at v = 0
        self.h_min = H_MIN * self.T
        idx = np.arange(q)
        active = idx if np.any(A[:, 0]) else idx[1:]     # x matters only through a spring
        self.slide = _Flow(A, B[:, 0], active)
        self.ev = np.zeros(q)
        self.ev[1] = 1.0
        self.slide_bounds = self.slide.norms(self.ev)
        self.stick: _Flow | None = None
        if q > 2:                            # internal states relax while it sticks
            As = A.copy()
            As[:2] = 0.0
            self.stick = _Flow(As, np.zeros(q), idx[2:])
            self.stick_bounds = self.stick.norms(self.net)

    def mode(self, z: np.ndarray, g: float) -> int:
        """+1 / -1 sliding, 0 stuck, from the state (v) and the held force g."""
        if z[1] != 0:
            return 1 if z[1] > 0 else -1
        N = float(self.net @ z) + g
        return 0 if abs(N) <= self.fc else (1 if N > 0 else -1)

    def advance(self, z0: np.ndarray, g: float) -> tuple[np.ndarray, float, list[Segment], float]:
        """The state one period after z0 under the held force g (N).

        Returns
        -------
        (state, dissipated, segments, friction)
            The state at the next sample, the energy friction dissipated (J), the
            sample's segments, and the friction force on the body just before the
            next sample (N; while stuck, the force that holds it).
        """
        z, t, mode, stalls = np.array(z0, float), 0.0, self.mode(z0, g), 0
        segs, diss = [Segment(0.0, z, mode)], 0.0
        for _ in range(MAX_EVENTS):
            rem = self.T - t
            if rem <= 0:
                break
            if stalls >= STALL:              # |N| = f_c to rounding: held stuck
                mode = 0
                segs.append(Segment(t, z, mode))
                if self.stick is not None:
                    z = self.stick.prop(z, 0.0, rem, cache=False)
                break
            if mode == 0:
                if self.stick is None:
                    break
                te, zn, mode = self._unstick(z, g, rem)
                if te is None:
                    z = zn
                    break
            else:
                te, zn = first_zero(self.slide, z, g - mode * self.fc, mode * self.ev, 0.0, rem,
                                    self.slide_bounds, self.h_min, start_up=z[1] == 0)
                diss += self.fc * abs(zn[0] - z[0])
                if te is None:
                    z = zn
                    break
                zn = zn.copy()
                zn[1] = 0.0
                N = float(self.net @ zn) + g
                mode = 0 if abs(N) <= self.fc else (1 if N > 0 else -1)
            stalls = stalls + 1 if te == 0 else 0
            t, z = t + te, zn
            segs.append(Segment(t, z, mode))
        else:
            raise ModelError(f"coulomb_friction = {self.fc:g} N: more than {MAX_EVENTS} "
                             "stick-slip events in one sample (the switching accumulates)")
        return z, diss, segs, self._friction_force(z, g, mode)

    def _unstick(self, z: np.ndarray, g: float, rem: float
                 ) -> tuple[float | None, np.ndarray, int]:
        """While stuck: when |N| reaches f_c (and which way it then slides)."""
        assert self.stick is not None
        hits, end = [], z
        for sgn in (1, -1):                  # y = f_c - sgn N >= 0 while stuck
            te, zn = first_zero(self.stick, z, 0.0, -sgn * self.net, self.fc - sgn * g, rem,
                                self.stick_bounds, self.h_min)
            if te is None:
                end = zn
            else:
                hits.append((te, sgn, zn))
        if not hits:
            return None, end, 0
        te, sgn, zn = min(hits, key=lambda hit: hit[0])
        return te, zn, sgn

    def _friction_force(self, z: np.ndarray, g: float, mode: int) -> float:
        """Friction on the body at the end of the sample (N)."""
        if mode:
            return -mode * self.fc
        return -(float(self.net @ z) + g)

    def state_at(self, segs: list[Segment], g: float, t: float) -> np.ndarray:
        """The port's state t seconds into the sample whose segments are ``segs``."""
        seg = segs[0]
        for s in segs[1:]:
            if s.start_s <= t:
                seg = s
        dt = t - seg.start_s
        if seg.mode:
            return self.slide.prop(seg.state, g - seg.mode * self.fc, dt, cache=False)
        if self.stick is None or dt == 0:
            return seg.state
        return self.stick.prop(seg.state, 0.0, dt, cache=False)


class LoopFriction:
    """The ports of a loop that have Coulomb friction, advanced between samples (the
    ``between`` hook of :func:`~hapstab.simulation.stepper.step_nonlinear`), with what
    the dense output and the energy bookkeeping need.

    Parameters
    ----------
    ports : sequence of Port
        The loop's ports (:func:`~hapstab.engine.structure.structure_of`).
    sysm : SampledSystem
        Its sampled model (plant layout, fractional-delay states, held forces).
    samples : int
        The run's length M.
    seconds : float
        The time budget (:func:`hapstab.budget.seconds_allowed`): the run's cost was
        estimated at a typical ~30 us per port and sample, but stick-slip events at every
        sample cost up to ~1 ms each (each event's time is located on the exact flow), so
        the stepping itself stops with :class:`~hapstab.budget.BudgetError` once it has
        run this long (a budgeted stop; ``math.inf``: never).
    """

    def __init__(self, ports: Any, sysm: Any, samples: int, seconds: float = math.inf) -> None:
        T = float(sysm.periods[0])
        self.samples, self.seconds, self.start = samples, seconds, time.monotonic()
        pos_idx = np.argmax(sysm.pos, axis=1)
        p = len(ports)
        self.T, self.ports = T, []
        for j, pt in enumerate(ports):
            if pt.device.coulomb_friction > 0:
                fp = FrictionPort(pt, T)
                self.ports.append((j, fp, slice(int(pos_idx[j]), int(pos_idx[j]) + fp.q)))
        # x_j((k+1)T - fT) is the position (1 - f) T into sample k
        self.frac = {j: [((1.0 - f) * T, row) for jj, f, row in sysm.fractional if jj == j]
                     for j in range(p)}
        hu = sysm.held_u
        self.held = {j: int(hu[j]) for j in range(p) if hu is not None and hu[j] >= 0}
        self.dissipated = np.zeros((samples + 1, p))
        self.modes = np.zeros((samples, p), np.int8)
        self.events: dict[tuple[int, int], list[Segment]] = {}

    def __call__(self, k: int, s: np.ndarray, g: np.ndarray, nxt: np.ndarray) -> None:
        """Replace the linear step's plant rows of the friction ports in ``nxt`` (and
        their fractional-delay states) by the exact stick-slip motion over sample k
        under the held net force ``g`` (p,); a measured port's held controller force
        takes the friction force too (the termination's force at kT^- sees the
        acceleration friction leaves)."""
        if k % CLOCK_EVERY == 0:
            self._on_time(k)
        self.dissipated[k + 1] = self.dissipated[k]
        for j, fp, sl in self.ports:
            gj = float(g[j])
            try:
                if not (np.isfinite(s[sl]).all() and math.isfinite(gj)):
                    raise Overflow
                with np.errstate(over="ignore", invalid="ignore"):
                    z, diss, segs, phi = fp.advance(s[sl], gj)
            except Overflow:                 # the stepper ends the run as overflowed
                nxt[sl] = np.inf
                continue
            nxt[sl] = z
            for tau, row in self.frac[j]:
                nxt[row] = fp.state_at(segs, gj, tau)[0]
            if j in self.held:
                nxt[self.held[j]] -= phi
            self.dissipated[k + 1, j] += diss
            self.modes[k, j] = segs[0].mode
            if len(segs) > 1:
                self.events[(k, j)] = segs

    def _on_time(self, k: int) -> None:
        """Stop the run (BudgetError) once it has taken longer than its budget."""
        took = time.monotonic() - self.start
        if took <= self.seconds:
            return
        from hapstab.budget import BudgetError

        whole = took * self.samples / max(k, 1)
        raise BudgetError(
            f"a simulation of {self.samples} samples with Coulomb friction: {k} samples took "
            f"{took:.0f} s (budget {self.seconds:.0f} s; the stick-slip events of every "
            f"sample are located one by one), about {whole:.0f} s for the whole run; run it "
            "anyway with --yes (Python: max_seconds= or hapstab.budget.unlimited())")

    def dense(self, X: np.ndarray, V: np.ndarray, S: np.ndarray, G: np.ndarray,
              m: int) -> None:
        """Overwrite, in place, the friction ports' columns of the dense output
        (``X``, ``V``: (M m + 1, p), m points per sample, from the sampled states ``S``
        and held net forces ``G`` (M, p)) with their exact stick-slip motion."""
        taus = self.T * np.arange(1, m) / m
        M = S.shape[0] - 1
        for j, fp, sl in self.ports:
            Z, sig = S[:-1, sl], self.modes[:M, j].astype(float)
            Ad, Bd = fp.slide.maps_many(taus)
            inner = np.einsum("inj,kj->kin", Ad, Z) \
                + Bd[None, :, :] * (G[:, j] - sig * fp.fc)[:, None, None]
            stuck = sig == 0
            if fp.stick is None:
                inner[stuck] = Z[stuck][:, None, :]
            else:
                As = fp.stick.maps_many(taus)[0]
                inner[stuck] = np.einsum("inj,kj->kin", As, Z[stuck])
            for (k, jj), segs in self.events.items():
                if jj == j:
                    inner[k] = [fp.state_at(segs, float(G[k, j]), tau) for tau in taus]
            allz = np.concatenate([Z[:, None, :], inner], axis=1).reshape(M * m, fp.q)
            X[:-1, j], V[:-1, j] = allz[:, 0], allz[:, 1]
            X[-1, j], V[-1, j] = S[-1, sl][0], S[-1, sl][1]
