"""Delays of a sampled-data loop: whole samples and a fraction of one (t_d = (n + f) T).

The one snap rule of hapstab is :func:`split_delay`, with ``DELAY_SNAP``
(:mod:`hapstab.tolerances`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hapstab.errors import MAX_DELAY_SAMPLES, ModelError, check_real
from hapstab.tolerances import DELAY_SNAP

__all__ = ["split_delay", "delay_from_seconds", "check_fraction", "whole_delays", "DELAY_SNAP"]


def check_fraction(name: str, value: Any) -> float:
    """``value`` as the part of a delay below one sample, in [0, 1), or a ModelError.

    Parameters
    ----------
    name : str
        The parameter's name in the message.
    value : float
        The fraction of T.

    Returns
    -------
    float
    """
    v = check_real(name, value, nonnegative=True)
    if not v < 1.0:
        raise ModelError(f"{name} = {v}: must be in [0, 1) (the part of t_d/T beyond whole samples)")
    return v


def split_delay(d: float) -> tuple[int, float]:
    """Whole samples and a fraction in [0, 1) of a delay of ``d`` samples.

    Parameters
    ----------
    d : float
        Delay in samples, >= 0.

    Returns
    -------
    (int, float)
        ``n`` and ``f`` with ``d = n + f``; ``f = 0`` when ``d`` is within
        :data:`DELAY_SNAP` of a whole number (so t_d = nT gives exactly the
        integer-delay model).
    """
    n = round(d)
    if abs(d - n) <= DELAY_SNAP * max(1.0, d):
        return n, 0.0
    n = int(np.floor(d))
    return n, float(min(d - n, np.nextafter(1.0, 0.0)))


def delay_from_seconds(name: str, seconds: Any, period: float) -> tuple[int, float]:
    """Split a delay in seconds into whole samples and a fraction in [0, 1), by
    the rule of :func:`split_delay`.

    Parameters
    ----------
    name : str
        The delay's name in the error message (e.g. ``"delay_s"``).
    seconds : float
        The delay t_d in s, finite and >= 0.
    period : float
        The sampling period T in s.

    Returns
    -------
    (int, float)
        n and f with t_d = (n + f) T, 0 <= f < 1.

    Raises
    ------
    ModelError
        If ``seconds`` is negative, not finite or longer than ``MAX_DELAY_SAMPLES`` samples.
    """
    d = check_real(name, seconds, nonnegative=True) / period
    if not d <= MAX_DELAY_SAMPLES:
        # a delay given in ms without its unit (--delay-s 10 for 10 ms) fits once read so
        hint = (f"; did you mean {seconds:g}ms (= {seconds / 1e3:g} s)?"
                if d / 1e3 <= MAX_DELAY_SAMPLES and seconds < 1e3 else "")
        raise ModelError(f"{name} = {seconds!r}: {d:.4g} samples at T = {period:g} s; at most "
                         f"{MAX_DELAY_SAMPLES} (the exact model carries one state per sample)"
                         f"{hint}")
    return split_delay(d)


def whole_delays(lo_s: float, hi_s: float, period: float) -> tuple[int, int]:
    """(n_lo, n_hi) = (ceil(tau_lo / T), ceil(tau_hi / T)), a delay within
    :data:`~hapstab.tolerances.DELAY_SNAP` of a sampling instant counting as on it.

    Parameters
    ----------
    lo_s, hi_s : float
        The range of the transport delay, s (0 <= lo <= hi).
    period : float
        T in s.

    Returns
    -------
    (int, int)
    """
    lo = check_real("delay range start", lo_s, nonnegative=True)
    hi = check_real("delay range end", hi_s, nonnegative=True)
    if hi < lo:
        raise ModelError(f"delay range = {lo_s!r}:{hi_s!r}: the end must not be below the start")

    def up(t: float) -> int:
        d = t / period
        return max(0, math.ceil(d - DELAY_SNAP * max(1.0, d)))

    n_lo, n_hi = up(lo), up(hi)
    if n_hi > MAX_DELAY_SAMPLES:
        raise ModelError(f"delay range end = {hi_s!r} s: {n_hi} samples at T = {period:g} s; at "
                         f"most {MAX_DELAY_SAMPLES}")
    return n_lo, n_hi
