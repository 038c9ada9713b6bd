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
    stats: dict[str, dict[str, Any]] = {}
    verdicts: dict[str, int] = {}
    over: list[tuple[float, dict[str, Any]]] = []
    n = errors = compared = 0
    heat = _Heat(points, plot) if plot else None
    axes = [a.column for a in points.axes]
    for path in paths:
        t = read_chunk(path).to_pydict()
        ids = t["point_id"]
        n += len(ids)
        errors += sum(e is not None for e in t["error"])
        for col in _numeric(quantities):
            _extremes(stats, col, t, axes)
        for v in t.get("verdict_at_K", []):
            if v is not None:
                verdicts[v] = verdicts.get(v, 0) + 1
        if "closed_form_over_promises" in t:
            flags = t["closed_form_over_promises"]
            compared += sum(f is not None for f in flags)
            for i, f in enumerate(flags):
                if f:
                    ratio = t["closed_form_N_per_m"][i] / max(t["critical_stiffness_N_per_m"][i],
                                                             1e-300)   # (0 exact: ratio inf)
                    over.append((ratio, _where(t, i, axes)))
            over = sorted(over, key=lambda r: -r[0])[:max(WORST, len(over) // 1000 + WORST)]
        if heat is not None:
            heat.add(t)
    out: dict[str, Any] = {"points": n, "errors": errors, "quantities": stats}
    if verdicts:
        out["verdicts_at_K"] = [{"verdict": v, "points": k} for v, k in sorted(verdicts.items())]
    if "closed-form" in quantities:
        count = len(over) if len(over) < WORST else None
        out["closed_form"] = {"compared": compared, "over_promises_listed": len(over[:WORST]),
                              "worst": [{"ratio": r, **w} for r, w in over[:WORST]]}
        out["closed_form"]["over_promises"] = _count_over(paths) if count is None else count
        out["closed_form"]["fraction"] = (out["closed_form"]["over_promises"] / compared
                                          if compared else None)
    if heat is not None:
        out["heat_map"] = heat.result()
    return out


def _count_over(paths: list[str]) -> int:
    return sum(sum(bool(f) for f in read_chunk(p, ["closed_form_over_promises"])
                   .column(0).to_pylist()) for p in paths)


def _numeric(quantities: tuple[str, ...]) -> list[str]:
    from hapstab.sweep.evaluate import QUANTITIES

    return [c for q in quantities for c, t in QUANTITIES[q] if t == "float64"]


def _where(t: dict[str, list[Any]], i: int, axes: list[str]) -> dict[str, Any]:
    return {"point_id": t["point_id"][i], **{a: t[a][i] for a in axes}}


def _extremes(stats: dict[str, dict[str, Any]], col: str, t: dict[str, list[Any]],
              axes: list[str]) -> None:
    vals = np.array([math.nan if v is None else v for v in t[col]], dtype=float)
    ok = ~np.isnan(vals)
    if not ok.any():
        stats.setdefault(col, {"min": None, "max": None})
        return
    s = stats.setdefault(col, {"min": None, "max": None})
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

    def add(self, t: dict[str, list[Any]]) -> None:
        K = np.array([math.nan if v is None else v for v in t["critical_stiffness_N_per_m"]],
                     dtype=float)
        ix = _cell(self.x, t[self.x.column], len(self.edges[0]))
        iy = _cell(self.y, t[self.y.column], len(self.edges[1]))
        ok = ~np.isnan(K)
        flat = self.grid.reshape(-1)          # (a view: fmin.at writes into the grid)
        np.fmin.at(flat, iy[ok] * self.grid.shape[1] + ix[ok], K[ok])   # NaN: no value yet

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
    """The cells' labels: a grid axis's values (or HEAT_CELLS bins of a long one), a random
    axis's bin centres."""
    if not a.random and len(a.values) <= HEAT_CELLS:
        return list(a.values)
    lo, hi = (a.lo, a.hi) if a.random else (float(min(a.values)), float(max(a.values)))
    if a.log or _is_log(a):
        return np.geomspace(lo, hi, HEAT_CELLS).tolist()
    return np.linspace(lo, hi, HEAT_CELLS).tolist()


def _cell(a: Axis, values: list[Any], cells: int) -> np.ndarray:
    if not a.random and len(a.values) <= HEAT_CELLS:
        index = {v: i for i, v in enumerate(a.values)}
        return np.array([index[v] for v in values], dtype=np.int64)
    v = np.asarray(values, dtype=float)
    lo, hi = (a.lo, a.hi) if a.random else (float(min(a.values)), float(max(a.values)))
    if a.log or _is_log(a):
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
    ax.figure.colorbar(mesh, ax=ax, label="K_max (N/m)")
    ax.set_xlabel(h["x"])
    ax.set_ylabel(h["y"])
    over = f", minimum over {', '.join(h['min_over'])}" if h["min_over"] else ""
    ax.set_title(f"exact K_max (N/m){over}; blank: no stable K or refused")
    return ax


heat_map = draw_heat_map
