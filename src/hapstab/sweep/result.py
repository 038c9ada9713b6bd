"""What a finished sweep says: ``summary.json`` (the least and largest value of every
quantity and the point where it is, how often and where the paper's closed form
over-promises against the exact K_max) and ``kmax.png`` (K_max over two axes, the
others reduced by their minimum), read back from the chunks."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.results import Result, jsonable
from hapstab.sweep.axes import Axis, Points
from hapstab.sweep.store import read_chunk

__all__ = ["SweepResult", "summarise", "heat_map"]

#: Cells of the heat map along an axis at most (a longer grid axis is binned).
HEAT_CELLS = 200
#: The over-promising points listed in the summary (the worst first).
WORST = 20
#: N/m: the ratio of a closed form to an exact K_max of 0 is taken against this (huge).
TINY = 1e-300  # not a tolerance: a floor that keeps the ratio finite


@dataclass(frozen=True)
class SweepResult(Result):
    """A sweep's results: where they are and what they say.

    Parameters
    ----------
    out_dir : str
        The folder (``chunks/``, ``manifest.json``, ``summary.json``, ``kmax.png``).
    manifest : dict
        ``manifest.json``: the study's SHA-256, the points, the chunks and their SHA-256.
    summary : dict
        ``summary.json``: per quantity its least and largest value and where.
    computed_chunks : int
        Chunks this call computed (the others were finished before: a resumed sweep).
    files : tuple of str
        The files of the summary (``summary.json``, ``kmax.png`` if drawn).
    """

    out_dir: str
    manifest: dict[str, Any] = field(repr=False)
    summary: dict[str, Any] = field(repr=False)
    computed_chunks: int = 0
    files: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The manifest (without the chunk list) and the summary, strict JSON.

        Returns
        -------
        dict
        """
        head = {k: v for k, v in self.manifest.items() if k != "finished"}
        return jsonable({"out_dir": self.out_dir, "computed_chunks": self.computed_chunks,
                         "files": list(self.files), "manifest": head, "summary": self.summary})

    def table(self, columns: list[str] | None = None) -> Any:
        """Every row, read from the chunks.

        Parameters
        ----------
        columns : list of str, optional
            Only these columns.

        Returns
        -------
        pyarrow.Table
            Sorted by point id.
        """
        import pyarrow as pa

        paths = [os.path.join(self.out_dir, "chunks", f"chunk-{int(e['chunk']):06d}.parquet")
                 for e in self.manifest.get("finished", [])]
        return pa.concat_tables([read_chunk(p, columns) for p in paths])

    def plot(self, ax: Any = None) -> Any:
        """K_max over the plot's two axes (the others reduced by the minimum).

        Parameters
        ----------
        ax : matplotlib Axes, optional

        Returns
        -------
        matplotlib Axes
        """
        return draw_heat_map(self.summary.get("heat_map"), ax)


def summarise(paths: list[str], points: Points, quantities: tuple[str, ...],
              plot: tuple[str, str] | None) -> dict[str, Any]:
    """The summary of the finished chunks ``paths``, read one at a time.

    Parameters
    ----------
    paths : list of str
        The chunk files.
    points : Points
        The sweep's points (for the heat map's axes).
    quantities : tuple of str
        What was computed.
    plot : (str, str) or None
        The heat map's axes (axis names), or None for none.

    Returns
    -------
    dict
        ``points``, ``errors``, per quantity column ``{min, max, where_min, where_max}``,
        ``closed_form`` (over-promises: count, fraction, the worst points),
        ``verdicts_at_K`` (check: each verdict and its number of points), and
        ``heat_map`` (its grid) with ``plot``.
    """
    import pyarrow.compute as pc

    stats: dict[str, dict[str, Any]] = {}
    verdicts: dict[str, int] = {}
    worst: list[tuple[float, dict[str, Any]]] = []
    n = errors = inapplicable = compared = over = 0
    heat = _Heat(points, plot) if plot else None
    axes = [a.column for a in points.axes]
    for path in paths:
        t = read_chunk(path)
        n += t.num_rows
        errors += t.num_rows - t.column("error").null_count
        if "not_applicable" in t.column_names:
            inapplicable += t.num_rows - t.column("not_applicable").null_count
        for col in _numeric(quantities):
            _extremes(stats, col, t, axes)
        if "verdict_at_K" in t.column_names:
            for v in pc.value_counts(t.column("verdict_at_K")).to_pylist():
                if v["values"] is not None:
                    verdicts[v["values"]] = verdicts.get(v["values"], 0) + int(v["counts"])
        if "closed_form_over_promises" in t.column_names:
            flags = t.column("closed_form_over_promises")
            compared += len(flags) - flags.null_count
            hit = np.flatnonzero(pc.fill_null(flags, False).to_numpy(zero_copy_only=False))
            over += hit.size
            cf, K = _float(t, "closed_form_N_per_m"), _float(t, "critical_stiffness_N_per_m")
            ratio = cf[hit] / np.maximum(K[hit], TINY)
            for r, i in sorted(zip(-ratio, hit, strict=True))[:WORST]:
                worst.append((float(-r), _where(t, int(i), axes)))
            worst = sorted(worst, key=lambda r: -r[0])[:WORST]
        if heat is not None:
            heat.add(t)
    out: dict[str, Any] = {"points": n, "errors": errors, "not_applicable": inapplicable,
                           "quantities": stats}
    if verdicts:
        out["verdicts_at_K"] = [{"verdict": v, "points": k} for v, k in sorted(verdicts.items())]
    if "closed-form" in quantities:
        out["closed_form"] = {"compared": compared, "over_promises": over,
                              "fraction": over / compared if compared else None,
                              "over_promises_listed": len(worst),
                              "worst": [{"ratio": r, **w} for r, w in worst]}
    if heat is not None:
        out["heat_map"] = heat.result()
    return out


def _float(t: Any, col: str) -> np.ndarray:
    """A float column as an array, null as NaN."""
    return np.asarray(t.column(col).to_numpy(zero_copy_only=False), dtype=float)


def _numeric(quantities: tuple[str, ...]) -> list[str]:
    from hapstab.sweep.evaluate import QUANTITIES

    return [c for q in quantities for c, t in QUANTITIES[q] if t == "float64"]


def _where(t: Any, i: int, axes: list[str]) -> dict[str, Any]:
    return {"point_id": t.column("point_id")[i].as_py(),
            **{a: t.column(a)[i].as_py() for a in axes}}


def _extremes(stats: dict[str, dict[str, Any]], col: str, t: Any, axes: list[str]) -> None:
    vals = _float(t, col)
    s = stats.setdefault(col, {"min": None, "max": None})
    ok = ~np.isnan(vals)
    if not ok.any():
        return
    lo = int(np.flatnonzero(ok)[np.argmin(vals[ok])])
    hi = int(np.flatnonzero(ok)[np.argmax(vals[ok])])
    if s["min"] is None or vals[lo] < s["min"]:
        s["min"], s["where_min"] = float(vals[lo]), _where(t, lo, axes)
    if s["max"] is None or vals[hi] > s["max"]:
        s["max"], s["where_max"] = float(vals[hi]), _where(t, hi, axes)


class _Heat:
    """The minimum of K_max in each cell of two axes, accumulated chunk by chunk."""

    def __init__(self, points: Points, plot: tuple[str, str]) -> None:
        by = {a.name: a for a in points.axes}
        self.x, self.y = by[plot[0]], by[plot[1]]
        self.edges = [_edges(a) for a in (self.x, self.y)]
        self.grid = np.full((len(self.edges[1]), len(self.edges[0])), np.nan)
        self.others = [a.name for a in points.axes if a.name not in plot]
        self.points = points

    def add(self, t: Any) -> None:
        K = _float(t, "critical_stiffness_N_per_m")
        ids = t.column("point_id").to_numpy()
        ix = self._cells(0, t, ids)
        iy = self._cells(1, t, ids)
        ok = ~np.isnan(K)
        flat = self.grid.reshape(-1)          # (a view: fmin.at writes into the grid)
        np.fmin.at(flat, iy[ok] * self.grid.shape[1] + ix[ok], K[ok])   # NaN: no value yet

    def _cells(self, k: int, t: Any, ids: np.ndarray) -> np.ndarray:
        a, cells = (self.x, self.y)[k], len(self.edges[k])
        if not a.random:
            j = [b.name for b in self.points.axes].index(a.name)
            index = np.unravel_index(ids, self.points.shape)[j]     # the grid's own index
            return index if len(a.values) <= HEAT_CELLS else index * cells // len(a.values)
        return _cell(a, _float(t, a.column), cells)

    def result(self) -> dict[str, Any]:
        return {"x": self.x.column, "y": self.y.column, "x_values": self.edges[0],
                "y_values": self.edges[1], "min_over": self.others,
                "x_log": _is_log(self.x), "y_log": _is_log(self.y),
                "critical_stiffness_N_per_m": self.grid.tolist()}


def _is_log(a: Axis) -> bool:
    return a.log or (len(a.values) > 2 and a.dtype != "string"
                     and float(a.values[0]) > 0 and not np.allclose(np.diff(a.values), np.diff(
                         a.values)[0], rtol=1e-9))   # a geometric grid: equal steps fail


def _edges(a: Axis) -> list[Any]:
    """The cells' labels: a grid axis's values (a long one: the first value of each of its
    HEAT_CELLS bins of indices), a random axis's bin centres."""
    if not a.random:
        n = len(a.values)
        return list(a.values) if n <= HEAT_CELLS else \
            [a.values[-(-k * n // HEAT_CELLS)] for k in range(HEAT_CELLS)]
    if a.log:
        return np.geomspace(a.lo, a.hi, HEAT_CELLS).tolist()
    return np.linspace(a.lo, a.hi, HEAT_CELLS).tolist()


def _cell(a: Axis, v: np.ndarray, cells: int) -> np.ndarray:
    """The bins of a random axis's values."""
    lo, hi = a.lo, a.hi
    if a.log:
        v, lo, hi = np.log(v), math.log(lo), math.log(hi)
    u = (v - lo) / (hi - lo) if hi > lo else np.zeros_like(v)
    return np.clip(np.rint(u * (cells - 1)).astype(np.int64), 0, cells - 1)


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
    over = f", minimum over {', '.join(h['min_over'])}" if h["min_over"] else ""
    ax.set_title(f"exact K_max (N/m){over}; blank: no stable K or refused")
    return ax


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


heat_map = draw_heat_map
