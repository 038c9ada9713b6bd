"""Independent per-sample reference simulator of the paper's two loops (no hapstab code).

Written from the physics of Fig. 2a (HVE) and Fig. 3 / eq. (19)-(21) (PEB) of
Miandashti & Tavakoli 2014, for long reference runs of nonlinear loops:

* each device with its termination (a spring-damper acting on the device's own
  position and velocity) is discretised exactly for the zero-order hold: the
  augmented matrix exponential of ``[x, v, g]`` with ``g`` the held input (net
  force plus the constant ``k * rest`` of the spring), computed once by
  :func:`scipy.linalg.expm` and unpacked into Python floats;
* the sampler, the delay line (a list of past positions), the encoder
  quantisation, the spring-damper controller ``u = K e + B (e - e_prev) / T``
  (eq. 23, backward difference), the unilateral wall and the actuator saturation
  act at the sampling instants, in plain float arithmetic (no numpy per sample).

The history before t = 0 is at rest at the initial positions; so is the
controller's previous error (``e[-1] = e[0]``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

__all__ = ["hve_run", "peb_run", "zoh", "quantize"]

#: |x| beyond this ends a run: the rest of the output is inf (overflow guard).
BLOWUP = 1e150


def zoh(mass: float, damping: float, stiffness: float, period: float) -> tuple[float, ...]:
    """Exact ZOH of ``m a = g - damping v - stiffness x`` over one period.

    Parameters
    ----------
    mass, damping, stiffness, period : float
        Total mass, total damping, spring stiffness (rest at 0) and T.

    Returns
    -------
    tuple of 6 floats
        ``(a11, a12, a21, a22, b1, b2)``: ``x+ = a11 x + a12 v + b1 g`` and
        ``v+ = a21 x + a22 v + b2 g`` with ``g`` held over the period.
    """
    M = np.zeros((3, 3))
    M[0, 1] = 1.0
    M[1, 0] = -stiffness / mass
    M[1, 1] = -damping / mass
    M[1, 2] = 1.0 / mass
    E = expm(M * period)
    return tuple(float(a) for a in (E[0, 0], E[0, 1], E[1, 0], E[1, 1], E[0, 2], E[1, 2]))


def quantize(x: float, resolution: float | None, quantizer: str = "floor") -> float:
    """The encoder: ``floor`` (a count, Δ floor(x/Δ)) or ``nearest`` (half away from zero).

    Parameters
    ----------
    x : float
    resolution : float or None
        Δ; None returns ``x`` unchanged.
    quantizer : {"floor", "nearest"}

    Returns
    -------
    float
    """
    if resolution is None:
        return x
    if quantizer == "floor":
        return resolution * math.floor(x / resolution)
    return math.copysign(resolution * math.floor(abs(x) / resolution + 0.5), x)


def _check(n_samples: int, delay: int, resolution: float | None, quantizer: str) -> tuple[int, int]:
    """Validate the common arguments; return (n_samples, delay) as ints."""
    n, d = int(n_samples), int(delay)
    if n != n_samples or n < 1 or d != delay or d < 0:
        raise ValueError(f"n_samples = {n_samples!r}, delay = {delay!r}: need whole n >= 1, d >= 0")
    if quantizer not in ("floor", "nearest"):
        raise ValueError(f"quantizer = {quantizer!r}: 'floor' or 'nearest'")
    if resolution is not None and not resolution > 0:
        raise ValueError(f"resolution = {resolution!r}: must be > 0")
    return n, d


def _forces(force, n: int, name: str) -> list[float]:
    """The held exogenous force as a list of n Python floats (None: zeros)."""
    if force is None:
        return [0.0] * n
    f = np.asarray(force, float).ravel()
    if f.size != n:
        raise ValueError(f"{name}: {f.size} values; need n_samples = {n}")
    return f.tolist()


def _finish(cols: list[list[float]], lengths: tuple[int, ...]) -> list[np.ndarray]:
    """Lists to arrays, padded with inf to ``lengths`` after an early stop."""
    out = []
    for c, ln in zip(cols, lengths, strict=True):
        a = np.full(ln, np.inf)
        a[:len(c)] = c
        out.append(a)
    return out


def hve_run(*, mass: float, damping: float, op_stiffness: float, op_damping: float,
            K: float, B: float, period: float, delay: int, x0: float, force,
            n_samples: int, wall: float | None = None, wall_pulls: bool = False,
            resolution: float | None = None, quantizer: str = "floor",
            saturation: float | None = None, rest: float | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """Simulate the HVE of Fig. 2a sample by sample, exact between samples.

    ``m a = f_ext - u - b v - k_op (x - rest) - b_op v``; the controller reads
    ``e[k] = q(x[k - delay]) - wall`` and commands
    ``u[k] = K e[k] + B (e[k] - e[k-1]) / T``, held over the sample.

    Parameters
    ----------
    mass, damping : float
        Device m (> 0) and b.
    op_stiffness, op_damping : float
        Operator spring k_op and damper b_op on the handle.
    K, B, period : float
        Virtual stiffness, virtual damping (any sign) and T.
    delay : int
        Whole samples n >= 0 between the sampler and the controller.
    x0 : float
        Initial position (at rest; the history is at rest at x0).
    force : array of n_samples or None
        Operator's exogenous force f_ext[k], held over [t_k, t_k+1).
    n_samples : int
    wall : float, optional
        Unilateral wall: u = 0 unless the measured penetration e[k] > 0.
    wall_pulls : bool
        If False (default), in contact u = max(u, 0): the wall only pushes out.
    resolution : float, optional
        Encoder step Δ.
    quantizer : {"floor", "nearest"}
        See :func:`quantize`.
    saturation : float, optional
        |u| <= saturation (applied after the wall rule).
    rest : float, optional
        Rest position of the operator spring (default x0).

    Returns
    -------
    x : (n_samples + 1,) array
        Positions at the sampling instants (inf after |x| > 1e150).
    u : (n_samples,) array
        Controller forces held over each sample (inf after an overflow stop).
    """
    n, d = _check(n_samples, delay, resolution, quantizer)
    f = _forces(force, n, "force")
    a11, a12, a21, a22, b1, b2 = zoh(mass, damping + op_damping, op_stiffness, period)
    bias = op_stiffness * (x0 if rest is None else rest)
    mode = 0 if resolution is None else (1 if quantizer == "floor" else 2)
    res = resolution or 1.0
    off = 0.0 if wall is None else float(wall)
    has_wall, pushes = wall is not None, not wall_pulls
    clip = saturation is not None
    sat = float(saturation) if clip else 0.0
    K, BT = float(K), float(B) / period
    x, v = float(x0), 0.0
    xs, us = [x], []
    e_prev = quantize(x, resolution, quantizer) - off
    for k in range(n):
        xd = xs[k - d] if k >= d else x0
        if mode == 1:
            xd = res * math.floor(xd / res)
        elif mode == 2:
            xd = math.copysign(res * math.floor(abs(xd) / res + 0.5), xd)
        e = xd - off
        u = K * e + BT * (e - e_prev)
        e_prev = e
        if has_wall and (e <= 0.0 or (pushes and u < 0.0)):
            u = 0.0
        if clip:
            u = sat if u > sat else (-sat if u < -sat else u)
        g = f[k] - u + bias
        x, v = a11 * x + a12 * v + b1 * g, a21 * x + a22 * v + b2 * g
        us.append(u)
        xs.append(x)
        if not abs(x) <= BLOWUP:
            xs[-1] = math.inf
            break
    return tuple(_finish([xs, us], (n + 1, n)))


def peb_run(*, master: tuple[float, float], slave: tuple[float, float],
            op: tuple[float, float], env: tuple[float, float], K: float, B: float,
            period: float, delay: int, xm0: float, xs0: float = 0.0, force_m,
            n_samples: int, resolution: float | None = None, quantizer: str = "floor",
            saturation: float | None = None, rest_m: float | None = None,
            rest_s: float | None = None, force_s=None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Simulate the PEB teleoperator of Fig. 3 / eq. (19)-(21) sample by sample.

    Eq. (20) with C_m = C_s = K + B (z - 1)/(T z): each controller reads its own
    robot's position undelayed and the other's ``delay`` samples late,
    ``e_m[k] = q(x_m[k]) - q(x_s[k - n])``, ``e_s[k] = q(x_s[k]) - q(x_m[k - n])``,
    and commands ``u = K e + B (e - e_prev) / T``. The robots:
    ``m_m a = f_h - u_m - b_m v - k_op (x_m - rest_m) - b_op v`` and
    ``m_s a = f_e - u_s - b_s v - k_env (x_s - rest_s) - b_env v``.

    Parameters
    ----------
    master, slave : (mass, damping)
        Robots' m and b.
    op, env : (stiffness, damping)
        Operator's and environment's spring-damper.
    K, B, period : float
        Controller stiffness, virtual damping (both ports) and T.
    delay : int
        One-way delay n >= 0 in whole samples, the same in each direction.
    xm0, xs0 : float
        Initial positions (at rest; histories at rest there).
    force_m : array of n_samples or None
        Operator's exogenous force f_h[k] on the master, held.
    n_samples : int
    resolution : float, optional
        Encoder step Δ (both robots).
    quantizer : {"floor", "nearest"}
    saturation : float, optional
        |u_m|, |u_s| <= saturation.
    rest_m, rest_s : float, optional
        Spring rest positions (defaults xm0, xs0).
    force_s : array of n_samples or None
        Environment's exogenous force f_e[k] on the slave (default none).

    Returns
    -------
    xm, xs : (n_samples + 1,) arrays
        Positions at the sampling instants (inf after |x| > 1e150).
    um, us : (n_samples,) arrays
        Controller forces held over each sample.
    """
    n, d = _check(n_samples, delay, resolution, quantizer)
    fm, fs = _forces(force_m, n, "force_m"), _forces(force_s, n, "force_s")
    p11, p12, p21, p22, p1, p2 = zoh(master[0], master[1] + op[1], op[0], period)
    r11, r12, r21, r22, r1, r2 = zoh(slave[0], slave[1] + env[1], env[0], period)
    cm = op[0] * (xm0 if rest_m is None else rest_m)
    cs = env[0] * (xs0 if rest_s is None else rest_s)
    mode = 0 if resolution is None else (1 if quantizer == "floor" else 2)
    res = resolution or 1.0
    clip = saturation is not None
    sat = float(saturation) if clip else 0.0
    K, BT = float(K), float(B) / period
    xm, vm, xs, vs = float(xm0), 0.0, float(xs0), 0.0
    XM, XS, UM, US = [xm], [xs], [], []
    qm0, qs0 = quantize(xm, resolution, quantizer), quantize(xs, resolution, quantizer)
    em_prev, es_prev = qm0 - qs0, qs0 - qm0
    for k in range(n):
        am, as_ = xm, xs                                    # own positions, undelayed
        bm, bs = (XM[k - d], XS[k - d]) if k >= d else (xm0, xs0)   # the other's, delayed
        if mode == 1:
            am, as_ = res * math.floor(am / res), res * math.floor(as_ / res)
            bm, bs = res * math.floor(bm / res), res * math.floor(bs / res)
        elif mode == 2:
            am = math.copysign(res * math.floor(abs(am) / res + 0.5), am)
            as_ = math.copysign(res * math.floor(abs(as_) / res + 0.5), as_)
            bm = math.copysign(res * math.floor(abs(bm) / res + 0.5), bm)
            bs = math.copysign(res * math.floor(abs(bs) / res + 0.5), bs)
        em, es = am - bs, as_ - bm
        um = K * em + BT * (em - em_prev)
        us = K * es + BT * (es - es_prev)
        em_prev, es_prev = em, es
        if clip:
            um = sat if um > sat else (-sat if um < -sat else um)
            us = sat if us > sat else (-sat if us < -sat else us)
        gm, gs = fm[k] - um + cm, fs[k] - us + cs
        xm, vm = p11 * xm + p12 * vm + p1 * gm, p21 * xm + p22 * vm + p2 * gm
        xs, vs = r11 * xs + r12 * vs + r1 * gs, r21 * xs + r22 * vs + r2 * gs
        UM.append(um)
        US.append(us)
        XM.append(xm)
        XS.append(xs)
        if not (abs(xm) <= BLOWUP and abs(xs) <= BLOWUP):
            XM[-1] = XS[-1] = math.inf
            break
    return tuple(_finish([XM, XS, UM, US], (n + 1, n + 1, n, n)))
