"""Error family and the validators every model uses.

Every message names the parameter, the value received and what is allowed, so
that the CLI can print it as one line and a Python user can act on it.
"""

from __future__ import annotations

import math
import re
import warnings
from numbers import Integral, Real
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np


class HapstabError(ValueError):
    """Base class of every error hapstab raises for a user's input."""


class ArgumentTypeError(HapstabError, TypeError):
    """An argument of the wrong type (e.g. not a loop); a :class:`TypeError` too."""


class ModelError(HapstabError):
    """A model (device, impedance, controller, loop) was given invalid parameters."""


class ModelTypeError(ModelError, ArgumentTypeError):
    """A model parameter of the wrong type (a string, a complex number, a list where one
    number is wanted): both a :class:`ModelError` and a :class:`TypeError`."""


class AnalysisError(HapstabError):
    """An analysis was asked for something it cannot answer for this model."""


def _fmt(value: Any) -> str:
    return repr(value) if isinstance(value, str) else str(value)


def check_real(name: str, value: Any, *, positive: bool = False,
               nonnegative: bool = False) -> float:
    """Return ``value`` as a finite float, or raise :class:`ModelError`.

    Parameters
    ----------
    name : str
        Parameter name used in the message.
    value : Any
        The value received.
    positive, nonnegative : bool
        Require ``value > 0`` or ``value >= 0``.
    """
    if isinstance(value, bool) or not isinstance(value, Real):
        try:
            import numpy as np  # numpy scalars are Real already; arrays are not

            if isinstance(value, np.ndarray) and value.shape == ():
                value = value.item()
            else:
                raise TypeError
        except TypeError:
            raise ModelTypeError(f"{name} = {_fmt(value)!s:.60}: must be a real number "
                                 f"(got {type(value).__name__})") from None
    try:
        with warnings.catch_warnings():   # numpy's longdouble/overflow casts warn: we raise
            warnings.simplefilter("ignore")
            v = float(value)
    except OverflowError:              # an int beyond double precision (10**400)
        raise ModelError(f"{name} = {value!r:.40}: must be finite (not NaN or inf)") from None
    if not math.isfinite(v):
        raise ModelError(f"{name} = {_fmt(value)}: must be finite (not NaN or inf)")
    if positive and not v > 0:
        raise ModelError(f"{name} = {_fmt(value)}: must be > 0")
    if nonnegative and not v >= 0:
        raise ModelError(f"{name} = {_fmt(value)}: must be >= 0")
    return v


def ordered_pair(value: Any) -> tuple[Any, Any]:
    """``(lo, hi)`` from a sequence of two; a TypeError for a set, a dict or a string (they
    have no order the user gave: which end would be lo?) and a ValueError for another
    length, as unpacking gives -- the callers word the message with their parameter."""
    if isinstance(value, (set, frozenset, dict, str, bytes)):
        raise TypeError(f"{type(value).__name__}: not an ordered pair")
    lo, hi = value
    return lo, hi


def check_flag(name: str, value: Any) -> bool:
    """A switch: True or False (numpy's too), else :class:`ArgumentTypeError` naming it --
    never read by truthiness (``certify=None`` or ``"False"`` would silently switch)."""
    import numpy as np

    if not isinstance(value, (bool, np.bool_)):
        raise ArgumentTypeError(f"{name} = {value!r:.40}: must be True or False "
                                f"(got {type(value).__name__})")
    return bool(value)


def check_reals(name: str, value: Any) -> np.ndarray:
    """Return ``value`` (a number or a sequence of numbers) as a flat float array, or raise
    :class:`ModelTypeError` naming ``name`` for anything that is not real numbers (a string,
    a complex number, nested lists of different lengths).

    Finiteness and size are the caller's to check (it knows what is allowed).
    """
    import numpy as np

    def wrong() -> ModelTypeError:
        return ModelTypeError(f"{name} = {value!r:.60}: must be a real number or a sequence "
                              f"of real numbers (got {type(value).__name__})")

    if isinstance(value, (str, bytes, bool)):
        raise wrong()
    try:
        with warnings.catch_warnings():   # numpy's overflow / complex casts warn: we raise
            warnings.simplefilter("ignore")
            if np.iscomplexobj(value):
                raise TypeError
            return np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError, OverflowError):
        raise wrong() from None


def _whole(value: Real) -> bool:
    """``value`` is finite and whole as a float (numpy's longdouble has no ``__trunc__``;
    one that underflows, 1e-4940, is not whole: it is not 0 either)."""
    try:
        with warnings.catch_warnings():   # longdouble -> float casts warn: we decide
            warnings.simplefilter("ignore")
            f = float(value)
            exact = f == value
    except (OverflowError, TypeError, ValueError):
        return False
    return bool(exact) and math.isfinite(f) and f.is_integer()


#: A number as a user types it: ASCII digits, an optional sign, point and exponent, or
#: nan / inf (refused as not finite by the callers, with their own message).
_ASCII_NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?"
                           r"|[-+]?(?:nan|inf|infinity)", re.ASCII | re.IGNORECASE)


def ascii_float(text: Any) -> float:
    """A number from text: ASCII decimal digits only, surrounding blanks ignored.

    Python's :func:`float` also takes other scripts' digits (mathematical bold, fullwidth, Arabic-Indic) and
    digit separators (``'1_000'``); a number on the command line or in a study is the
    plain decimal spelling (what every other tool reads the same way).

    Raises
    ------
    ValueError
        Not such a number (the callers word the message with their parameter).
    """
    t = str(text).strip(" \t\r\n")
    if not _ASCII_NUMBER.fullmatch(t):
        raise ValueError(f"{t!r} is not a number (ASCII decimal digits only)")
    return float(t)


def check_delay(name: str, value: Any) -> int:
    """Return a whole, non-negative number of samples, or raise :class:`ModelError`."""
    if isinstance(value, bool):
        raise ModelError(f"{name} = {value}: must be a whole number of samples >= 0")
    if isinstance(value, Integral):
        v = int(value)
    elif isinstance(value, Real) and _whole(value):
        v = int(float(value))        # whole and finite: exact below 2**53, refused above
    else:
        raise ModelError(
            f"{name} = {_fmt(value)}: must be a whole number of samples >= 0 "
            "(the delay is n*T with integer n)"
        )
    if v < 0:
        raise ModelError(f"{name} = {v}: must be a whole number of samples >= 0")
    if v > MAX_DELAY_SAMPLES:
        raise ModelError(f"{name} = {v}: at most {MAX_DELAY_SAMPLES} samples (the exact model "
                         "carries one state per sample of delay; use a longer period)")
    return v


#: The exact model has one state per sample of delay: beyond this it is slow and large.
MAX_DELAY_SAMPLES = 100_000

#: Sampling periods the model represents (validated down to 10 us; below 1e-7 s the
#: dynamics between samples drown in rounding).
PERIOD_RANGE = (1e-7, 1e3)


def check_period(name: str, value: Any) -> float:
    """A sampling period in seconds within :data:`PERIOD_RANGE`."""
    v = check_real(name, value, positive=True)
    lo, hi = PERIOD_RANGE
    if not lo <= v <= hi:
        raise ModelError(f"{name} = {v:g}: must be between {lo:g} s and {hi:g} s")
    return v


def check_poly(name: str, coeffs: Any) -> np.ndarray:
    """Finite real polynomial coefficients, highest power first, leading zeros
    dropped (all-zero gives [0.]); else :class:`ModelError` naming ``name``."""
    import numpy as np

    try:
        if isinstance(coeffs, (str, bytes)) or np.iscomplexobj(coeffs):
            raise TypeError             # (a complex array would be cast, its imaginary parts lost)
        with warnings.catch_warnings():   # numpy's overflow casts warn: the check below refuses
            warnings.simplefilter("ignore")
            a = np.atleast_1d(np.asarray(coeffs, dtype=float)).ravel()
    except (TypeError, ValueError, OverflowError):
        raise ModelError(f"{name} = {coeffs!r:.80}: must be a sequence of real coefficients"
                         ) from None
    if a.size == 0 or not np.all(np.isfinite(a)):
        raise ModelError(f"{name} = {coeffs!r}: must be finite real coefficients, highest power first")
    nz = np.flatnonzero(a)
    return a[nz[0]:] if nz.size else np.zeros(1)
