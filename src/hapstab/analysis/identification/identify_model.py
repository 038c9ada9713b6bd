"""The exact sampled model of a device driven by a held force, for identification.

The device ``m dv/dt + b v + f_c sign(v) = F`` is driven by a force held constant over
each sample (zero-order hold) and its position is read at the sampling instants.
Between two samples the motion is the closed-form solution of a linear ODE with a
constant right-hand side while the sign of the velocity does not change; Coulomb
friction's events (the velocity reaching zero, the held force then staying inside or
leaving the stick band ``|F| <= f_c``) are located exactly, in closed form.

With ``a = b / m`` and the net force ``g`` (held force minus friction), starting from
``(x0, v0)``::

    v(t) = v0 e^{-a t} + (g / m) phi1(t),     phi1(t) = (1 - e^{-a t}) / a
    x(t) = x0 + v0 phi1(t) + (g / m) phi2(t), phi2(t) = (t - phi1(t)) / a

(``phi1 -> t``, ``phi2 -> t^2 / 2`` as ``a -> 0``); the velocity reaches zero at
``t* = log1p(-v0 b / g) / a`` (``-v0 m / g`` for ``b = 0``) when ``g`` opposes ``v0``.

References
----------
G. F. Franklin, J. D. Powell and M. L. Workman, *Digital Control of Dynamic Systems*,
3rd ed., 1998, Sec. 4.3.3 (the ZOH equivalent, eq. 4.58); D. Karnopp, "Computer
simulation of stick-slip friction in mechanical dynamic systems", J. Dyn. Sys. Meas.
Control 107 (1985) 100-103 (stick while the net force stays in the stick band).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["phis", "predict"]

#: Below this a*t the series of phi2 is used: its first omitted term is (a t)^3 t^2 / 120,
#: a relative error below 1e-14 there, while the closed form (t - phi1) / a loses
#: ~eps / (a t) >= 1e-12 of its digits to cancellation.
_SERIES = 1e-4


def phis(a: float, t: float) -> tuple[float, float, float]:
    """``(e^{-a t}, phi1(t), phi2(t))`` of the module docstring, accurate for every a >= 0.

    Parameters
    ----------
    a : float
        b / m in 1/s, >= 0.
    t : float
        Time in s, >= 0.

    Returns
    -------
    tuple of float
    """
    at = a * t
    if at < _SERIES:
        e = math.exp(-at)
        return e, t * (1 - at / 2 + at * at / 6), t * t * (0.5 - at / 6 + at * at / 24)
    e = math.exp(-at)
    p1 = -math.expm1(-at) / a
    return e, p1, (t - p1) / a


def _linear(m: float, b: float, x0: float, v0: float, F: np.ndarray, T: float) -> np.ndarray:
    """Positions at the samples without friction: the exact ZOH recurrence, vectorised."""
    from scipy.signal import lfilter

    e, p1, p2 = phis(b / m, T)
    # state (x, v): x+ = x + p1 v + p2 F/m, v+ = e v + p1 F/m; x's transfer function from F
    # is (p2 z + (p1^2 - e p2)) / (m (z - 1)(z - e)) (one sample of delay: the hold)
    # lfilter's output j is then x's forced part at sample j + 1
    num = np.array([p2, p1 * p1 - e * p2]) / m
    den = np.array([1.0, -(1 + e), e])
    forced = lfilter(num, den, F[:-1])
    t = np.arange(F.size) * T
    a = b / m
    free = x0 + v0 * (t if a == 0 else -np.expm1(-a * t) / a)
    out = np.empty(F.size)
    out[0] = x0
    out[1:] = free[1:] + forced
    return out


def _slide(m: float, b: float, g: float, x: float, v: float, t: float) -> tuple[float, float]:
    """Position and velocity after ``t`` s under the constant net force ``g``."""
    e, p1, p2 = phis(b / m, t)
    return x + v * p1 + g / m * p2, v * e + g / m * p1


def _stop_time(m: float, b: float, g: float, v: float) -> float:
    """When the velocity ``v`` (opposed by ``g``) reaches zero; inf if it does not."""
    if g == 0 or (g > 0) == (v > 0):
        return math.inf
    if b == 0:
        return -v * m / g
    return math.log1p(-v * b / g) * m / b


def _one_sample(m: float, b: float, fc: float, F: float, x: float, v: float,
                T: float) -> tuple[float, float]:
    """(x, v) one sample later under the held force F, with stick-slip."""
    left = T
    for _ in range(3):          # at most: slide to a stop, (stick or) slide away
        if v == 0:
            if abs(F) <= fc:
                return x, 0.0   # sticks for the rest of the sample (F is held)
            s = 1.0 if F > 0 else -1.0
        else:
            s = 1.0 if v > 0 else -1.0
        g = F - fc * s
        ts = _stop_time(m, b, g, v) if v != 0 else math.inf
        if ts >= left:
            return _slide(m, b, g, x, v, left)
        x, _ = _slide(m, b, g, x, v, ts)
        v, left = 0.0, left - ts
    return x, v


def predict(m: float, b: float, fc: float, x0: float, v0: float, F: np.ndarray,
            T: float) -> np.ndarray:
    """The device's exact position at every sampling instant.

    Parameters
    ----------
    m, b, fc : float
        Mass (kg, > 0), viscous damping (N*s/m, >= 0), Coulomb friction (N, >= 0).
    x0, v0 : float
        Position (m) and velocity (m/s) at the first sample.
    F : (N,) array
        The force commanded at each sample, held until the next one (the last is unused).
    T : float
        Sampling period in s.

    Returns
    -------
    (N,) array
        x(k T), k = 0 ... N - 1.

    Notes
    -----
    A sample in which the device slides one way throughout takes the whole-sample
    step; the velocity's sign at its end tells (the motion under a constant force is
    monotone in v), so the events' closed forms are evaluated only in the samples that
    have one.
    """
    if fc == 0:
        return _linear(m, b, x0, v0, F, T)
    e, p1, p2 = phis(b / m, T)
    out = np.empty(F.size)
    x, v = x0, v0
    out[0] = x
    for k, f in enumerate(F[:-1].tolist()):
        if v != 0:
            g = (f - fc) / m if v > 0 else (f + fc) / m
            vn = v * e + g * p1
            if (vn > 0) == (v > 0) and vn != 0:     # slides on: no event in this sample
                x, v = x + v * p1 + g * p2, vn
                out[k + 1] = x
                continue
        x, v = _one_sample(m, b, fc, f, x, v, T)
        out[k + 1] = x
    return out
