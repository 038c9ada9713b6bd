"""A sweep's heat map drawn: K_max over two axes, the axes named with their units, a tick
for each value of a short grid axis, the title saying which reduction or slice it is."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["draw_heat_map", "heat_title", "axis_label"]

def draw_heat_map(h: dict[str, Any] | None, ax: Any = None) -> Any:
    """Draw a summary's heat map (K_max over two axes).

    Parameters
    ----------
    h : dict or None
        The summary's ``heat_map``.
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib Axes
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    if ax is None:
        _, ax = plt.subplots(figsize=(7, 5))
    if not h:
        ax.set_title("no heat map: the sweep has no [sweep.plot] axes or no K_max")
        return ax
    Z = np.array(h["critical_stiffness_N_per_m"], dtype=float)
    Z = np.where(np.isfinite(Z), Z, np.nan)
    pos = Z[np.isfinite(Z) & (Z > 0)]
    norm = LogNorm(pos.min(), pos.max()) if pos.size and pos.max() > pos.min() else None
    xs, ys = h["x_values"], h["y_values"]
    text = isinstance(xs[0], str) or isinstance(ys[0], str)
    if text:
        mesh = ax.imshow(Z, origin="lower", aspect="auto", norm=norm, cmap="viridis")
        ax.set_xticks(range(len(xs)), [str(x) for x in xs], rotation=30)
        ax.set_yticks(range(len(ys)), [str(y) for y in ys])
    else:
        mesh = ax.pcolormesh(np.asarray(xs, float), np.asarray(ys, float), Z, shading="nearest",
                             norm=norm, cmap="viridis")
        from matplotlib.ticker import NullFormatter

        ax.set_xscale("log" if h["x_log"] else "linear")
        ax.set_yscale("log" if h["y_log"] else "linear")
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_minor_formatter(NullFormatter())     # (the decades' labels only)
        for set_ticks, vals in ((ax.set_xticks, xs), (ax.set_yticks, ys)):
            if len(vals) <= 12:                           # each value the sweep took
                set_ticks([float(v) for v in vals], [f"{float(v):g}" for v in vals])
    ax.figure.colorbar(mesh, ax=ax, label="K_max (N/m)")
    ax.set_xlabel(axis_label(h["x"]))
    ax.set_ylabel(axis_label(h["y"]))
    ax.set_title(f"exact K_max (N/m){heat_title(h)}; blank: no stable K or refused")
    return ax


#: The words of a reduction in a heat map's title.
_REDUCED = {"min": "minimum", "max": "maximum", "median": "median"}


def heat_title(h: dict[str, Any]) -> str:
    """What a heat map's cells are: ``", maximum over damping (N·s/m)"``, ``", at mass =
    0.3 kg"``.

    Parameters
    ----------
    h : dict
        A summary's ``heat_map``.

    Returns
    -------
    str
    """
    reduce = h.get("reduce", "min")
    over = h.get("over", h.get("min_over", []))
    text = ""
    if over:
        text += f", {_REDUCED[reduce]} over " \
            f"{', '.join(_NAMES.get(n, n.replace('_', ' ')) for n in over)}"
    for column, v in h.get("at", {}).items():
        label = axis_label(column)
        value = f"{v:g}" if isinstance(v, float) else str(v)
        if label.endswith(")"):
            name, unit = label[:-1].rsplit(" (", 1)
            text += f", at {name} = {value} {unit}"
        else:
            text += f", at {label} = {value}"
    return text


#: A column's unit suffix -> the unit as a reader writes it.
_UNIT_SUFFIXES = (("_N_s_per_m", "N·s/m"), ("_N_per_m", "N/m"), ("_hz", "Hz"), ("_Hz", "Hz"),
                  ("_kg", "kg"), ("_samples", "samples"), ("_N", "N"), ("_s", "s"), ("_m", "m"))
#: Names that read better spelled out.
_NAMES = {"rate": "sampling rate", "period": "sampling period", "delay": "delay",
          "virtual_damping": "virtual damping B", "mass": "mass", "damping": "damping"}


def axis_label(column: str) -> str:
    """A sweep column as an axis label, name and unit: ``rate_hz`` -> ``sampling rate
    (Hz)``, ``virtual_damping_N_s_per_m`` -> ``virtual damping B (N·s/m)``.

    Parameters
    ----------
    column : str

    Returns
    -------
    str
    """
    for suffix, unit in _UNIT_SUFFIXES:
        if column.endswith(suffix) and len(column) > len(suffix):
            name = column[:-len(suffix)]
            return f"{_NAMES.get(name, name.replace('_', ' '))} ({unit})"
    return _NAMES.get(column, column.replace("_", " "))
