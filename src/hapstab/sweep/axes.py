"""The points of a sweep: axes (lists, linear or log-spaced ranges, or random samples
with a seed) and their one deterministic order.

Order. A grid is the Cartesian product of its axes in the order they are given, the
**last axis varying fastest** (C order, as :func:`itertools.product`): point ``i`` has
the indices ``numpy.unravel_index(i, shape)``. Random samples are drawn with
``numpy.random.default_rng(seed)``: point ``i`` takes the row ``i`` of
``default_rng(seed).random((samples, len(axes)))`` (uniform in [0, 1)), mapped onto each
axis (linearly, or in log for a log axis; an integer axis takes the whole numbers
lo...hi with equal probability). A chunk of points is made without making the others:
the generator is advanced to the chunk's first row (PCG64's ``advance``: one 64-bit draw
per uniform double), so a chunk's values do not depend on the chunk size or on which
worker makes them. A point's id is its index.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.errors import HapstabError, ascii_float

__all__ = ["SweepError", "Axis", "Points", "parse_axis", "ids_of", "chunks_of"]


class SweepError(HapstabError):
    """A sweep that cannot be run as given (the message names the key or parameter)."""


@dataclass(frozen=True)
class Axis:
    """One axis of a sweep.

    Parameters
    ----------
    name : str
        The parameter it sets (the key the loop builder receives).
    column : str
        Its column in the results (with its SI unit, e.g. ``period_s``).
    values : tuple
        A grid axis's values, in order (empty for a random axis).
    lo, hi : float
        A random axis's range (NaN for a grid axis).
    log : bool
        A random axis sampled uniformly in log (lo > 0).
    integer : bool
        The values are whole numbers (int64 column).
    spec : str
        The axis as it was given (for the manifest).
    """

    name: str
    column: str
    values: tuple[Any, ...] = ()
    lo: float = math.nan
    hi: float = math.nan
    log: bool = False
    integer: bool = False
    spec: str = ""

    @property
    def random(self) -> bool:
        """Whether the axis is sampled (not a grid)."""
        return not self.values

    @property
    def dtype(self) -> str:
        """``"int64"``, ``"float64"`` or ``"string"``."""
        if self.integer:
            return "int64"
        if self.values and isinstance(self.values[0], str):
            return "string"
        return "float64"

    def to_dict(self) -> dict[str, Any]:
        """The axis for the manifest.

        Returns
        -------
        dict
        """
        d: dict[str, Any] = {"name": self.name, "column": self.column, "spec": self.spec,
                             "dtype": self.dtype}
        if self.random:
            d.update(lo=self.lo, hi=self.hi, log=self.log)
        else:
            d.update(count=len(self.values))
        return d

    def from_uniform(self, u: np.ndarray) -> np.ndarray:
        """Map uniform draws in [0, 1) onto the axis (random axes)."""
        if self.integer and self.log:   # log-uniform over [lo, hi + 1), whole numbers
            a, b = math.log(self.lo), math.log(self.hi + 1)
            return np.minimum(np.floor(np.exp(a + u * (b - a))).astype(np.int64), int(self.hi))
        if self.integer:
            lo, hi = int(self.lo), int(self.hi)
            return np.minimum(lo + np.floor(u * (hi - lo + 1)).astype(np.int64), hi)
        if self.log:
            a, b = math.log(self.lo), math.log(self.hi)
            return np.minimum(np.exp(a + u * (b - a)), self.hi)
        if not math.isfinite(self.hi - self.lo):    # -1e308:1e308: the width overflows
            return self.lo * (1 - u) + self.hi * u
        return np.minimum(self.lo + u * (self.hi - self.lo), self.hi)


@dataclass(frozen=True)
class Points:
    """The points of a sweep: a grid over ``axes``, or ``samples`` random points.

    Parameters
    ----------
    axes : tuple of Axis
        In order (the last one varies fastest on a grid).
    samples : int or None
        Random points (None: the grid).
    seed : int
        The random generator's seed.
    """

    axes: tuple[Axis, ...]
    samples: int | None = None
    seed: int = 0

    def __len__(self) -> int:
        return self.count

    @property
    def count(self) -> int:
        """How many points (a Python int: 10^12 is counted, never built)."""
        if self.samples is not None:
            return int(self.samples)
        return math.prod(len(a.values) for a in self.axes)

    @property
    def shape(self) -> tuple[int, ...]:
        """The grid's shape (one entry per axis)."""
        return tuple(len(a.values) for a in self.axes)

    def values(self, start: int, stop: int) -> dict[str, np.ndarray]:
        """Every axis's values at the points ``start ... stop - 1``.

        Parameters
        ----------
        start, stop : int
            Point ids, ``0 <= start <= stop <= count``.

        Returns
        -------
        dict
            Axis name -> array of ``stop - start`` values.
        """
        ids = np.arange(start, stop, dtype=np.int64)
        if self.samples is None:
            idx = np.unravel_index(ids, self.shape) if self.axes else ()
            return {a.name: np.asarray(a.values, dtype=_np_dtype(a))[i]
                    for a, i in zip(self.axes, idx, strict=True)}
        bits = np.random.PCG64(self.seed)
        bits.advance(start * len(self.axes))        # one 64-bit draw per double
        u = np.random.Generator(bits).random((stop - start, len(self.axes)))
        return {a.name: a.from_uniform(u[:, j]) for j, a in enumerate(self.axes)}

    def to_dict(self) -> dict[str, Any]:
        """The point set for the manifest.

        Returns
        -------
        dict
        """
        return {"count": self.count, "order": "grid, last axis fastest" if self.samples is None
                else "random rows of default_rng(seed)", "samples": self.samples,
                "seed": self.seed, "axes": [a.to_dict() for a in self.axes]}


def _np_dtype(a: Axis) -> Any:
    return {"int64": np.int64, "float64": np.float64, "string": object}[a.dtype]


def parse_axis(name: str, spec: Any, *, column: str | None = None,
               convert: Callable[[Any], Any] = float, integer: bool = False,
               text: bool = False, random: bool = False, where: str = "") -> Axis:
    """An axis from its spec: a list of values, ``"lo:hi:count"`` (evenly spaced,
    inclusive), ``"lo:hi:count:log"`` (log-spaced); with ``random``, ``"lo:hi"`` or
    ``"lo:hi:log"`` (sampled by :class:`Points`).

    Parameters
    ----------
    name : str
        The parameter the axis sets.
    spec : list or str
        The values, or a range.
    column : str, optional
        Its column (default: ``name``).
    convert : callable
        Turns one value or range end into the parameter's value (e.g. with its unit:
        ``"4kHz"`` -> 4000.0); raises ValueError or HapstabError with the reason.
    integer : bool
        A parameter of whole numbers (a delay in samples).
    text : bool
        A parameter that is a string (an impedance): a list only.
    random : bool
        The sweep samples random points: ranges have no count.
    where : str
        The key as the message names it (default ``name``).

    Returns
    -------
    Axis

    Raises
    ------
    SweepError
        An empty list, a bad value, lo > hi, count < 1, a log range with lo <= 0.
    """
    key = where or name
    col = column or name
    if isinstance(spec, (list, tuple)):
        if random:
            raise SweepError(f"{key} = {_short(spec)}: with [sweep.random] an axis is a range "
                             "\"lo:hi\" or \"lo:hi:log\", not a list")
        if not spec:
            raise SweepError(f"{key} = []: an empty axis has no points; give at least one value")
        vals = tuple(_one(key, v, convert, integer, text) for v in spec)
        return Axis(name, col, vals, integer=integer, spec=_short(spec))
    if not isinstance(spec, str):
        raise SweepError(f"{key} = {_short(spec)}: must be a list or a range string "
                         f"(\"lo:hi:count\" or \"lo:hi:count:log\")")
    if text:
        raise SweepError(f"{key} = {spec!r}: a list of values (this option is not a number)")
    parts = spec.split(":")
    log = len(parts) > 2 - random and parts[-1].strip().lower() == "log"
    if log:
        parts = parts[:-1]
    want = 2 if random else 3
    form = "\"lo:hi\" or \"lo:hi:log\"" if random else "\"lo:hi:count\" or \"lo:hi:count:log\""
    if len(parts) != want:
        raise SweepError(f"{key} = {spec!r}: a range is {form}")
    lo, hi = (_one(key, p, convert, integer, False) for p in parts[:2])
    if lo > hi:
        raise SweepError(f"{key} = {spec!r}: lo = {lo:g} > hi = {hi:g}; give lo <= hi")
    if log and not lo > 0:
        raise SweepError(f"{key} = {spec!r}: a log range needs lo > 0 (got {lo:g})")
    if random:
        return Axis(name, col, (), float(lo), float(hi), log, integer, spec)
    count = _count(key, spec, parts[2])
    grid = np.geomspace(lo, hi, count) if log else np.linspace(lo, hi, count)
    if count == 1:
        grid = np.array([lo])
    if integer:
        whole = np.rint(grid).astype(np.int64)
        if len(set(whole.tolist())) < count:
            raise SweepError(f"{key} = {spec!r}: {count} whole numbers from {lo} to {hi} "
                             f"repeat; give count <= {int(hi - lo) + 1}")
        return Axis(name, col, tuple(int(v) for v in whole), integer=True, spec=spec)
    return Axis(name, col, tuple(float(v) for v in grid), log=log, spec=spec)


def _count(key: str, spec: str, text: str) -> int:
    try:
        f = ascii_float(text)
    except ValueError:
        f = math.nan
    if not (math.isfinite(f) and f.is_integer()):
        raise SweepError(f"{key} = {spec!r}: count {text.strip()!r} must be a whole number >= 1")
    if f < 1:
        raise SweepError(f"{key} = {spec!r}: count = {int(f)}: must be >= 1")
    if f > MAX_AXIS:        # (10^8 values took 18 s and ran out of memory before the budget)
        raise SweepError(f"{key} = {spec!r}: count = {int(f)}: at most {MAX_AXIS} values an "
                         "axis (the points of a sweep are at most 10^7 by default)")
    return int(f)


#: The most values one axis takes: a sweep's default budget of points (sweep.run's
#: MAX_POINTS), built as a tuple of numbers before the points are counted.
MAX_AXIS = 10 ** 7
#: The largest whole number an integer axis takes: whole numbers are exact in doubles up
#: to 2^53 (its values are read as numbers first; its column is int64).
INT_MAX = 2 ** 53


def _one(key: str, value: Any, convert: Callable[[Any], Any], integer: bool, text: bool) -> Any:
    """One value of an axis, converted; whole numbers for an integer axis."""
    if isinstance(value, (list, dict, tuple, bool)):
        raise SweepError(f"{key}: value {_short(value)} must be a number or a string")
    if text:
        if not isinstance(value, str):
            raise SweepError(f"{key}: value {value!r} must be a string")
        try:
            convert(value)
        except (ValueError, HapstabError) as e:
            raise SweepError(f"{key}: value {value!r}: {e}") from None
        return value
    try:
        v = convert(value.strip() if isinstance(value, str) else value)
    except OverflowError:
        raise SweepError(f"{key}: value {_short(value)}: beyond double precision "
                         "(at most ~1.8e308)") from None
    except (ValueError, TypeError, HapstabError) as e:
        raise SweepError(f"{key}: value {_short(value)}: {e}") from None
    if integer:
        if not (math.isfinite(float(v)) and float(v).is_integer()):
            raise SweepError(f"{key}: value {value!r}: must be a whole number")
        if abs(int(v)) > INT_MAX:
            raise SweepError(f"{key}: value {_short(value)}: must be a whole number of at most "
                             f"{INT_MAX} in size (2^53, whole in double precision)")
        return int(v)
    if not math.isfinite(float(v)):
        raise SweepError(f"{key}: value {value!r}: must be finite")
    return float(v)


def _short(x: Any) -> str:
    s = repr(x)
    return s if len(s) <= 60 else s[:57] + "..."


def ids_of(chunk: int, size: int, count: int) -> tuple[int, int]:
    """The point ids ``[start, stop)`` of chunk number ``chunk`` of ``size`` points.

    Parameters
    ----------
    chunk : int
        The chunk's number (from 0).
    size : int
        Points per chunk.
    count : int
        Points in all.

    Returns
    -------
    (int, int)
    """
    start = chunk * size
    return start, min(start + size, count)


def chunks_of(count: int, size: int) -> int:
    """How many chunks ``count`` points make, ``size`` a chunk.

    Parameters
    ----------
    count : int
        Points in all.
    size : int
        Points per chunk.

    Returns
    -------
    int
    """
    return -(-count // size)

