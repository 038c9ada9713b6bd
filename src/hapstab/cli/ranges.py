"""Ranges and lists on the command line: ``start:stop[:count]`` with units, periods,
delays (the one range syntax of every command)."""

from __future__ import annotations

import math

from hapstab.cli.options import UNITS, parse_quantity
from hapstab.errors import HapstabError, ascii_float

__all__ = ["parse_range", "parse_periods", "parse_delays", "RANGE_COUNT"]

#: Points in a range given as start:stop (no count).
RANGE_COUNT = 10


def parse_range(spec: str, name: str, unit: str, *, count: bool = True,
                values: str = "> 0") -> list[float]:
    """The one range syntax of every command: ``start:stop[:count]`` (inclusive, evenly
    spaced, ``count`` default :data:`RANGE_COUNT`) or a comma list; each number may carry a
    unit (``1ms:10ms``, ``250Hz:4kHz:16``, ``20ms,50ms``).

    Parameters
    ----------
    spec : str
        The option's text.
    name : str
        The option, named in errors.
    unit : {"s", "Hz", "N/m", "N*s/m"}
        The unit of a plain number (only seconds and hertz take other units).
    count : bool
        Whether ``:count`` and comma lists are allowed (``region``'s grid size is
        ``--resolution``: there it is ``start:stop`` only).
    values : {"> 0", ">= 0", "any"}
        What each value must be (besides finite): periods and rates > 0, delays and
        stiffnesses >= 0, virtual damping either sign.

    Raises
    ------
    HapstabError
        Naming the option, the text and what is allowed.
    """
    ex = {"s": "1ms:10ms:10", "Hz": "250Hz:4kHz:16"}.get(unit, "0:900")
    allowed = (f"allowed: start:stop[:count] or a comma list, e.g. {ex}" if count
               else f"allowed: start:stop, e.g. {ex} (the grid's size is --resolution)")
    parts = spec.split(":") if ":" in spec else None
    if parts is not None and (len(parts) not in ((2, 3) if count else (2,))
                              or not all(x.strip() for x in parts)):
        raise HapstabError(f"{name} = {spec!r}: expected start:stop{'[:count]' if count else ''}; "
                           f"{allowed}")
    if parts is None and not count:
        raise HapstabError(f"{name} = {spec!r}: expected start:stop; {allowed}")
    texts = parts[:2] if parts is not None else [x for x in spec.split(",") if x.strip()]
    try:
        nums = [parse_quantity(x, unit) if unit in UNITS else _plain(x) for x in texts]
    except ValueError as e:
        raise HapstabError(f"{name} = {spec!r}: {e}; {allowed}") from None
    if not all(math.isfinite(v) for v in nums):
        raise HapstabError(f"{name} = {spec!r}: every value must be finite; {allowed}")
    if parts is not None:
        n = _count(spec, name, parts[2] if len(parts) == 3 else str(RANGE_COUNT), allowed)
        lo, hi = nums
        if not hi >= lo or (not count and not hi > lo):
            raise HapstabError(f"{name} = {spec!r}: the range is empty (stop "
                               f"{'<' if count else '<='} start); {allowed}")
        nums = [lo + (hi - lo) * i / max(n - 1, 1) for i in range(n)] if count else [lo, hi]
    if not nums:
        raise HapstabError(f"{name} = {spec!r}: the list is empty; {allowed}")
    ok = {"> 0": lambda v: v > 0, ">= 0": lambda v: v >= 0, "any": lambda v: True}[values]
    for v in nums:
        if not (math.isfinite(v) and ok(v)):
            what = "finite" if values == "any" else f"finite and {values}"
            raise HapstabError(f"{name} = {spec!r}: every value must be {what}; {allowed}")
    return nums


def _plain(text: str) -> float:
    try:
        return ascii_float(text)
    except ValueError:
        raise ValueError(f"{text.strip()!r} is not a number") from None


def _count(spec: str, name: str, text: str, allowed: str) -> int:
    try:
        c = ascii_float(text)
    except ValueError:
        raise HapstabError(f"{name} = {spec!r}: count {text!r} is not a number; {allowed}") from None
    if not (math.isfinite(c) and c.is_integer() and 1 <= c <= 100_000):
        raise HapstabError(f"{name} = {spec!r}: count must be a whole number from 1 to 100000; "
                           f"{allowed}")
    return int(c)


def parse_periods(spec: str, name: str = "--period") -> list[float]:
    """Sampling periods: :func:`parse_range` in seconds."""
    return parse_range(spec, name, "s")


def parse_delays(spec: str) -> list[int]:
    allowed = "allowed: a comma list of whole numbers of samples >= 0 (e.g. 0,10)"
    out = []
    for x in spec.split(","):
        x = x.strip()
        if not x:
            continue
        try:
            f = ascii_float(x)
        except ValueError:
            raise HapstabError(f"--delay = {spec!r}: malformed number {x!r}; {allowed}") from None
        if not (math.isfinite(f) and f.is_integer() and f >= 0):
            raise HapstabError(f"--delay = {spec!r}: {x!r} is not a whole number >= 0; {allowed}")
        out.append(int(f))
    if not out:
        raise HapstabError(f"--delay = {spec!r}: the list is empty; {allowed}")
    return out
