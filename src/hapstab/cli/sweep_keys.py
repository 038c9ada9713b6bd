"""The network keys of a sweep (``[sweep.network]`` and network axes: loss, burst, delay-range
width, jitter width) and the value of a heat map's slice on any axis."""

from __future__ import annotations

import math
from typing import Any

import click

from hapstab.errors import ascii_float

__all__ = ["NETWORK_KEYS", "network_value", "at_value"]

#: network key -> (name, whole number?, lowest, highest (excluded) or None)
NETWORK_KEYS = {"loss": ("loss", False, 0.0, 1.0), "burst": ("burst", False, 1.0, None),
                "delay-range-width": ("delay_range_width", True, 0, None),
                "jitter-width": ("jitter_width", True, 0, None)}


def network_value(key: str, value: Any) -> Any:
    """A network parameter's value, checked against its range (NETWORK_KEYS); a
    ValueError naming what is allowed."""
    _, integer, low, high = NETWORK_KEYS[key]
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if ok and integer:
        ok = float(value).is_integer()
    if not ok or value < low or (high is not None and value >= high):
        allowed = (f"a whole number of samples >= {low}" if integer else
                   f"a number in [{low:g}, {high:g})" if high is not None else
                   f"a number >= {low:g}")
        raise ValueError(f"{key} = {value!r:.40}: allowed: {allowed}")
    return int(value) if integer else float(value)


def at_value(a: Any, value: Any, params: dict[str, click.Option]) -> Any:
    """A slice's value on axis ``a``, read by its option's type (a network axis -- loss,
    burst, delay-range-width -- by the [sweep.network] reader: it has no loop option)."""
    if a.dtype == "string":
        return value
    if a.name not in params:
        key = next(k for k, v in NETWORK_KEYS.items() if v[0] == a.name)
        return network_value(key, ascii_float(value) if isinstance(value, str) else value)
    p = params[a.name]
    return p.type.convert(value, p, None)
