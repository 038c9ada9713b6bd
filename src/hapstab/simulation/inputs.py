"""Exogenous forces: the specs a user gives (step, pulse, sine, callable, array),
sampled and held like the controller's output; and whether a force still grows.

References
----------
The paper, Fig. 2a, Fig. 3 and Section 5.
"""

from __future__ import annotations

import math
from itertools import pairwise
from numbers import Real
from typing import Any

import numpy as np

from hapstab.errors import ModelError, check_real

__all__ = ['ForceSpec', 'force_samples']

#: Slack (s) on a force's edge times: an edge at t0 = k T starts at sample k although
#: k * T and t0 differ by rounding (~1e-16 t); 1e-12 s is far above that for runs up to
#: ~1e3 s, and far below any sampling period (>= 1e-7 s): it never moves an edge a sample.
_EDGE = 1e-12


ForceSpec = Any  # None | float | "step:F[,t0]" | "pulse:F,width[,t0]" | "sine:F,Hz" | callable | array


def force_samples(spec: ForceSpec, times: np.ndarray, name: str = "force") -> np.ndarray:
    """Exogenous force at each sampling instant, held over the sample (ZOH).

    Parameters
    ----------
    spec : None, float, str, callable or array
        ``None`` (no force); a number F (step of F N at t = 0); ``"step:F[,t0]"``;
        ``"pulse:F,width[,t0]"`` (F N for ``width`` s from ``t0``); ``"sine:F,Hz"``;
        a callable ``f(t)``; or an array with one value per sample.
    times : (M,) array
        Sampling instants t_k = k T.
    name : str
        Parameter name for messages.

    Returns
    -------
    (M,) array

    Raises
    ------
    ModelError
        A malformed spec or an array of the wrong length.

    Notes
    -----
    The force is sampled at t_k and held, like the controller's output; a sine is
    therefore seen with the hold's half-sample lag.
    """
    M = times.size
    allowed = "allowed: a number, step:F[,t0], pulse:F,width[,t0], sine:F,Hz, a callable or an array"
    if spec is None:
        return np.zeros(M)
    if isinstance(spec, Real) and not isinstance(spec, bool):      # a Fraction, a Decimal too
        return np.full(M, check_real(name, spec))
    if isinstance(spec, str):
        kind, _, args = spec.strip().lower().partition(":")
        try:
            v = [float(a) for a in args.split(",")] if args else []
        except ValueError:
            raise ModelError(f"{name} = {spec!r}: malformed number; {allowed}") from None
        if not all(math.isfinite(x) for x in v):
            raise ModelError(f"{name} = {spec!r}: numbers must be finite; {allowed}")
        if kind == "step" and len(v) in (1, 2):
            t0 = v[1] if len(v) == 2 else 0.0
            return np.where(times >= t0 - _EDGE, v[0], 0.0)
        if kind == "pulse" and len(v) in (2, 3) and v[1] > 0:
            t0 = v[2] if len(v) == 3 else 0.0
            return np.where((times >= t0 - _EDGE) & (times < t0 + v[1] - _EDGE), v[0], 0.0)
        if kind == "sine" and len(v) == 2 and v[1] >= 0:
            return v[0] * np.sin(2 * np.pi * v[1] * times)
        raise ModelError(f"{name} = {spec!r}: not understood; {allowed}")
    if callable(spec):
        return _called(spec, times, name)
    try:
        if np.iscomplexobj(spec):       # (its imaginary part would be dropped silently)
            raise TypeError
        a = np.asarray(spec, dtype=float).ravel()
    except (TypeError, ValueError, OverflowError):
        raise ModelError(f"{name} = {spec!r:.80}: {allowed}") from None
    if a.size != M or not np.all(np.isfinite(a)):
        raise ModelError(f"{name}: array of {a.size} values; need {M} finite values (one per sample)")
    return a


def _called(f: Any, times: np.ndarray, name: str) -> np.ndarray:
    """``f(t)`` at every instant; a failure or a value that is not a finite number is an
    error naming the force and the time at which it happened."""
    out = np.empty(times.size)
    for k, t in enumerate(times):
        try:
            v = float(f(float(t)))
        except Exception as e:   # the user's function failed: say where, as their error
            raise ModelError(f"{name}: the function raised {type(e).__name__} at t = {t:.6g} s "
                             f"({e})") from e
        if not math.isfinite(v):
            raise ModelError(f"{name}: the function returned {v} at t = {t:.6g} s; forces "
                             "must be finite")
        out[k] = v
    return out


def force_grows(F: np.ndarray) -> bool:
    """Whether the exogenous force still grows at the end of the run: its largest
    size per tenth of the run rises in every tenth of the second half (a ramp, a
    growing sine; not a step, a pulse or a sine, however late they start)."""
    M = F.shape[0]
    if M < 10 or not np.any(F):
        return False
    tenths = np.linspace(0, M, 11).astype(int)
    peaks = np.array([np.abs(F[a:b]).max() for a, b in pairwise(tenths)])
    return bool(np.all(np.diff(peaks[4:]) > 0))
