"""Independent event-driven reference for Coulomb friction in the sampled loops (no
hapstab code).

Written from the physics: each port is one body of mass M (device plus the operator's
or environment's mass) with viscous damping b, a spring k relaxed at ``rest``, an
optional Maxwell element (a spring k_m in series with a damper b_m: its force F_m
obeys ``F_m' = k_m v - (k_m / b_m) F_m``) and Coulomb friction f_c:

``M v' = g - b v - k (x - rest) - F_m - f_c sign(v)``, ``g = f_ext - u`` held over the
sample (zero-order hold).

Between samples each port is integrated by :func:`scipy.integrate.solve_ivp` (DOP853,
rtol 1e-12) with a terminal event where v crosses 0 while sliding; there the body
sticks if the static force ``N = g - k (x - rest) - F_m`` has ``|N| <= f_c``, else it
slides the other way; while stuck (v = 0, x fixed) only F_m relaxes, and terminal
events where N crosses +-f_c end the stick. Extra integrated states give the energy
friction and viscosity dissipate. The controllers (Fig. 2a, Fig. 3 of Miandashti &
Tavakoli 2014; ``u = K e + B (e - e_prev) / T``), the delay (whole or fractional
samples, read from the recorded continuous trajectory), the encoder, the unilateral
wall and saturation act at the sampling instants, as in ``simref.py``.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["Body", "Track", "acceleration", "advance", "hve_run", "peb_run"]

#: solve_ivp's relative tolerance (the brief's); the absolute one is this times the
#: state's scale (1e-12 of a mm, a mm/s, a mN: far below every compared difference)
RTOL = 1e-12
ATOL = 1e-12


@dataclass
class Body:
    """One port: mass M (kg), damping b (N s/m), spring k (N/m) relaxed at ``rest`` (m),
    Coulomb friction fc (N), optional Maxwell element (km N/m in series with bm N s/m)."""

    M: float
    b: float = 0.0
    k: float = 0.0
    fc: float = 0.0
    rest: float = 0.0
    km: float = 0.0
    bm: float = math.inf

    @property
    def relax(self) -> float:
        return 0.0 if self.km == 0 else self.km / self.bm

    def static(self, y: np.ndarray, g: float) -> float:
        """Every force on the body but inertia, viscous damping and friction."""
        return g - self.k * (y[0] - self.rest) - y[2]


@dataclass
class Track:
    """A port's continuous trajectory, piece by piece: (t0, t1, callable or constant)."""

    starts: list = field(default_factory=list)
    pieces: list = field(default_factory=list)

    def add(self, t0: float, fn) -> None:
        self.starts.append(t0)
        self.pieces.append(fn)

    def x(self, t: float, x_before: float) -> float:
        if not self.starts or t < self.starts[0]:
            return x_before
        i = bisect.bisect_right(self.starts, t) - 1
        fn = self.pieces[i]
        return float(fn(t)[0]) if callable(fn) else float(fn[0])


def _rhs(body: Body, g: float, sigma: int):
    def f(t, y):
        x, v, Fm = y[0], y[1], y[2]
        if sigma == 0:
            return [0.0, 0.0, -body.relax * Fm, 0.0, 0.0]
        a = (g - body.b * v - body.k * (x - body.rest) - Fm - sigma * body.fc) / body.M
        return [v, a, body.km * v - body.relax * Fm, sigma * body.fc * v, body.b * v * v]
    return f


def _events(body: Body, g: float, sigma: int):
    if sigma:
        def stop(t, y):
            return y[1]
        stop.terminal, stop.direction = True, -sigma
        return [stop]

    def up(t, y):
        return body.static(y, g) - body.fc

    def down(t, y):
        return body.static(y, g) + body.fc
    up.terminal, up.direction = True, 1
    down.terminal, down.direction = True, -1
    return [up, down]


def _mode(body: Body, y: np.ndarray, g: float) -> int:
    if y[1] != 0:
        return 1 if y[1] > 0 else -1
    N = body.static(y, g)
    return 0 if abs(N) <= body.fc else (1 if N > 0 else -1)


def advance(body: Body, y: np.ndarray, g: float, t0: float, T: float, track: Track | None
            ) -> tuple[np.ndarray, int]:
    """The state ``[x, v, F_m, E_friction, E_viscous]`` T seconds after t0, g held, and
    the mode (+-1 sliding, 0 stuck) just before then."""
    t, y = t0, np.array(y, float)
    sigma = _mode(body, y, g)
    scale = np.maximum(np.abs(y), 1e-3)                  # (m, m/s, N, J, J) scales
    for _ in range(1000):
        if t >= t0 + T:
            break
        if sigma == 0 and body.km == 0:                   # nothing moves: stuck to the end
            if track is not None:
                track.add(t, y.copy())
            break
        sol = solve_ivp(_rhs(body, g, sigma), (t, t0 + T), y, method="DOP853", rtol=RTOL,
                        atol=ATOL * scale, events=_events(body, g, sigma), dense_output=True)
        if track is not None:
            track.add(t, sol.sol)
        hit = [i for i, te in enumerate(sol.t_events) if te.size]
        if not hit:
            y, t = sol.y[:, -1], t0 + T
            break
        i = min(hit, key=lambda i: sol.t_events[i][0])
        t, y = float(sol.t_events[i][0]), sol.y_events[i][0].copy()
        if sigma:
            y[1] = 0.0
            N = body.static(y, g)
            sigma = 0 if abs(N) <= body.fc else (1 if N > 0 else -1)
        else:
            sigma = 1 if i == 0 else -1
    return y, sigma


def acceleration(body: Body, y: np.ndarray, g: float, sigma: int) -> float:
    """The body's acceleration in mode sigma (0 while stuck)."""
    if sigma == 0:
        return 0.0
    return (g - body.b * y[1] - body.k * (y[0] - body.rest) - y[2] - sigma * body.fc) / body.M


def _q(x: float, res: float | None, how: str) -> float:
    if res is None:
        return x
    if how == "floor":
        return res * math.floor(x / res)
    return math.copysign(res * math.floor(abs(x) / res + 0.5), x)


def hve_run(body: Body, *, K: float, B: float, T: float, delay: float, x0: float, v0: float,
            force, n: int, wall: float | None = None, wall_pulls: bool = False,
            resolution: float | None = None, quantizer: str = "floor",
            saturation: float | None = None, track: bool = False,
            force_feedback: tuple[float, float, float] | None = None):
    """The HVE of Fig. 2a with friction. ``delay`` in samples (may be fractional: the
    controller reads q(x(kT - delay T)), x0 before t = 0). ``force_feedback = (c, m_z,
    b_z)`` subtracts ``c F_h`` from u: F_h the force the operator (mass m_z, damper b_z
    and the body's spring) applies to the device just before the sample, ``F_h = f_old -
    m_z a - b_z v - k (x - rest)`` (a the acceleration just before, f_old the force held
    over the last sample; at rest before t = 0). Returns positions, velocities (n + 1,),
    forces u (n,), friction and viscous energies (n + 1,) and the track."""
    tr = Track()
    y = np.array([x0, v0, 0.0, 0.0, 0.0])
    X, V, U, EF, EV = [x0], [v0], [], [0.0], [0.0]
    f_old, accel = 0.0, 0.0
    off = 0.0 if wall is None else wall
    e_prev = _q(x0, resolution, quantizer) - off
    for k in range(n):
        t = k * T
        xd = x0 if k < delay else (X[k - int(delay)] if delay == int(delay)
                                   else tr.x(t - delay * T, x0))
        e = _q(xd, resolution, quantizer) - off
        u = K * e + B * (e - e_prev) / T
        e_prev = e
        if force_feedback is not None:
            c, mz, bz = force_feedback
            Fh = f_old - mz * accel - bz * y[1] - body.k * (y[0] - body.rest)
            u -= c * Fh
        if wall is not None and (e <= 0 or (not wall_pulls and u < 0)):
            u = 0.0
        if saturation is not None:
            u = min(max(u, -saturation), saturation)
        y, sigma = advance(body, y, float(force[k]) - u, t, T, tr)
        f_old, accel = float(force[k]), acceleration(body, y, float(force[k]) - u, sigma)
        X.append(y[0]), V.append(y[1]), U.append(u), EF.append(y[3]), EV.append(y[4])
    out = [np.array(a) for a in (X, V, U, EF, EV)]
    return (*out, tr) if track else tuple(out)


def peb_run(master: Body, slave: Body, *, K: float, B: float, T: float, delay: int,
            xm0: float, xs0: float, force_m, force_s, n: int,
            resolution: float | None = None, quantizer: str = "floor",
            saturation: float | None = None):
    """The PEB teleoperator of Fig. 3 / eq. (20) with friction on both robots:
    ``e_m = q(x_m[k]) - q(x_s[k - n])``, ``e_s = q(x_s[k]) - q(x_m[k - n])``. Returns
    (Xm, Xs, Um, Us, EFm, EFs)."""
    ym = np.array([xm0, 0.0, 0.0, 0.0, 0.0])
    ys = np.array([xs0, 0.0, 0.0, 0.0, 0.0])
    XM, XS, UM, US, FM, FS = [xm0], [xs0], [], [], [0.0], [0.0]
    qm0, qs0 = _q(xm0, resolution, quantizer), _q(xs0, resolution, quantizer)
    em_prev, es_prev = qm0 - qs0, qs0 - qm0
    for k in range(n):
        bm, bs = (XM[k - delay], XS[k - delay]) if k >= delay else (xm0, xs0)
        qm, qs = _q(XM[k], resolution, quantizer), _q(XS[k], resolution, quantizer)
        em = qm - _q(bs, resolution, quantizer)
        es = qs - _q(bm, resolution, quantizer)
        um = K * em + B * (em - em_prev) / T
        us = K * es + B * (es - es_prev) / T
        em_prev, es_prev = em, es
        if saturation is not None:
            um = min(max(um, -saturation), saturation)
            us = min(max(us, -saturation), saturation)
        ym = advance(master, ym, float(force_m[k]) - um, k * T, T, None)[0]
        ys = advance(slave, ys, float(force_s[k]) - us, k * T, T, None)[0]
        XM.append(ym[0]), XS.append(ys[0]), UM.append(um), US.append(us)
        FM.append(ym[3]), FS.append(ys[3])
    return tuple(np.array(a) for a in (XM, XS, UM, US, FM, FS))
