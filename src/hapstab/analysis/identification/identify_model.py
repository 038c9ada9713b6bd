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
    k, n, size = 0, F.size - 1, RUN
    while k < n:
        if v != 0:
            r, x, v = _run(F[k:min(n, k + size)], m, fc, e, p1, p2, x, v, out[k + 1:])
            k += r
            if r == size:               # slid through the whole batch: a longer one next
                size = min(2 * size, MAX_RUN)
                continue
            size = RUN
            if k >= n:
                break
        elif abs(F[k]) <= fc:           # stuck while the held force stays in the band
            stay = np.abs(F[k:n]) <= fc
            r = int(np.argmin(stay)) if not stay.all() else n - k
            out[k + 1:k + 1 + r] = x
            k += r
            continue
        x, v = _one_sample(m, b, fc, float(F[k]), x, v, T)   # an event
        out[k + 1] = x
        k += 1
    return out


#: Samples a sliding run is first stepped at once (:func:`_run`), and the most: a run
#: that reaches its end is stepped on twice as far; an event starts again at RUN (a choice
#: of batch size, not a tolerance: every sample's step is the same either way).
RUN = 32
MAX_RUN = 4096


def _run(F: np.ndarray, m: float, fc: float, e: float, p1: float, p2: float, x: float,
         v: float, out: np.ndarray) -> tuple[int, float, float]:
    """The samples of ``F`` (held forces) over which the device slides on one way from
    ``(x, v)``, v != 0, stepped at once: their positions into ``out``; returns (how many,
    x and v after them). A sample whose step would end at or past v = 0 ends the run
    (:func:`_one_sample` locates its event). Bit for bit the one-sample steps of
    :func:`_predict_stepwise`: v+ = e v + p1 g is ``lfilter``'s recurrence (the same two
    products, summed once), and x+ = (x + p1 v) + p2 g a running sum of the products
    interleaved (``cumsum`` adds in order)."""
    from scipy.signal import lfilter
    g = (F - fc) / m if v > 0 else (F + fc) / m
    vn = lfilter([p1], [1.0, -e], g, zi=[e * v])[0]
    slides = (vn > 0) if v > 0 else (vn < 0)
    r = int(np.argmin(slides)) if not slides.all() else F.size
    if r == 0:
        return 0, x, v
    terms = np.empty(2 * r + 1)
    terms[0], terms[1], terms[3::2] = x, v * p1, vn[:r - 1] * p1
    terms[2::2] = g[:r] * p2
    xs = np.cumsum(terms)[2::2]
    out[:r] = xs
    return r, float(xs[-1]), float(vn[r - 1])


def _predict_stepwise(m: float, b: float, fc: float, x0: float, v0: float, F: np.ndarray,
                      T: float) -> np.ndarray:
    """:func:`predict` with friction one sample at a time (the reference its runs are
    tested against)."""
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
