"""What a finished sweep says: ``summary.json`` (the least and largest value of every
quantity and the point where it is, how often and where the paper's closed form
over-promises against the exact K_max) and ``kmax.png`` (K_max over two axes, the
others reduced by their minimum, maximum or median, or fixed at one of their values),
read back from the chunks."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.results import Result, jsonable
from hapstab.sweep.axes import Axis, Points, SweepError
from hapstab.sweep.heat_figure import axis_label, draw_heat_map, heat_title
from hapstab.sweep.store import read_chunk

__all__ = ["SweepResult", "summarise", "heat_map", "REDUCTIONS", "check_at", "draw_heat_map",
           "axis_label", "heat_title"]

#: How the heat map reduces, in each cell, the K_max over the axes it does not show (and
#: does not fix with ``at``): the least (the design that holds for every value of them), the
#: largest (the best value of them, e.g. the best damping), or the median.
REDUCTIONS = ("min", "max", "median")

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
    points : Points, optional
        The sweep's points (for heat maps of other axes or reductions than the summary's).
    """

    out_dir: str
    manifest: dict[str, Any] = field(repr=False)
    summary: dict[str, Any] = field(repr=False)
    computed_chunks: int = 0
    files: tuple[str, ...] = ()
    points: Points | None = field(default=None, repr=False, compare=False)

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

    def heat_map(self, x: str | None = None, y: str | None = None, reduce: str = "min",
                 at: dict[str, Any] | None = None) -> dict[str, Any] | None:
        """K_max over two axes, the others reduced cell by cell or fixed at a value.

        Parameters
        ----------
        x, y : str, optional
            The axes (names as in the sweep's ``axes``; default: the summary's heat map's).
        reduce : {"min", "max", "median"}
            How the K_max of a cell's points (over the axes not shown and not in ``at``)
            become one: ``"min"`` (the summary's), ``"max"`` (e.g. at the best damping of a
            damping axis, which ``"min"`` always shows at B = 0), ``"median"``.
        at : dict, optional
            Axis name -> one of its grid values: only the points there (a slice).

        Returns
        -------
        dict or None
            As the summary's ``heat_map`` (None: no K_max or fewer than two axes).

        Raises
        ------
        SweepError
            An unknown axis or reduction; an ``at`` value not on its axis's grid, of a
            random axis or of a shown axis.
        """
        stored = self.summary.get("heat_map")
        if stored is not None and x in (None, stored.get("x_name")) \
                and y in (None, stored.get("y_name")) and reduce == stored.get("reduce", "min") \
                and not at and not stored.get("at"):
            return stored
        if self.points is None:
            raise SweepError("heat_map: this result has no points (a SweepResult made by "
                             "hand); run hapstab.sweep on its folder again (nothing is "
                             "recomputed)")
        names = [a.name for a in self.points.axes]
        x = x or (stored.get("x_name") if stored else None) or names[0]
        y = y or (stored.get("y_name") if stored else None) or names[-1]
        for k, v in (("x", x), ("y", y)):
            if v not in names:
                raise SweepError(f"heat_map: {k} = {v!r:.40} is not an axis; axes: "
                                 f"{', '.join(names)}")
        if x == y:
            raise SweepError(f"heat_map: x = y = {x!r:.40}: two different axes")
        heat = _Heat(self.points, (x, y), reduce, at)
        paths = [os.path.join(self.out_dir, "chunks", f"chunk-{int(e['chunk']):06d}.parquet")
                 for e in self.manifest.get("finished", [])]
        for path in paths:
            heat.add(read_chunk(path, heat.columns))
        return heat.result()

    def plot(self, ax: Any = None, reduce: str = "min", at: dict[str, Any] | None = None,
             x: str | None = None, y: str | None = None) -> Any:
        """K_max over the plot's two axes (see :meth:`heat_map`: the others reduced by
        ``reduce`` or fixed by ``at``).

        Parameters
        ----------
        ax : matplotlib Axes, optional
        reduce : {"min", "max", "median"}
        at : dict, optional
            Axis name -> grid value.
        x, y : str, optional

        Returns
        -------
        matplotlib Axes
        """
        return draw_heat_map(self.heat_map(x, y, reduce, at), ax)


def summarise(paths: list[str], points: Points, quantities: tuple[str, ...],
              plot: tuple[str, str] | None, reduce: str = "min",
              at: dict[str, Any] | None = None) -> dict[str, Any]:
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
    reduce : {"min", "max", "median"}
        The heat map's reduction of the other axes.
    at : dict, optional
        The heat map's slice: axis name -> grid value.

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
    heat = _Heat(points, plot, reduce, at) if plot else None
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
    """K_max in each cell of two axes, the points of a cell reduced (min, max, median) over
    the other axes, or only those at fixed values of some; accumulated chunk by chunk."""

    def __init__(self, points: Points, plot: tuple[str, str], reduce: str = "min",
                 at: dict[str, Any] | None = None) -> None:
        if reduce not in REDUCTIONS:
            raise SweepError(f"reduce = {reduce!r:.40}: allowed: {', '.join(REDUCTIONS)}")
        by = {a.name: a for a in points.axes}
        self.x, self.y = by[plot[0]], by[plot[1]]
        self.at = check_at(points, plot, at)
        self.reduce = reduce
        self.edges = [_edges(a) for a in (self.x, self.y)]
        self.grid = np.full((len(self.edges[1]), len(self.edges[0])), np.nan)
        self.others = [a.name for a in points.axes if a.name not in plot and a.name not in
                       self.at]
        self.points = points
        self.seen: list[tuple[np.ndarray, np.ndarray]] = []     # median: (cell, K) of each chunk
        extra = {a.column for a in (self.x, self.y) if a.random} | {by[n].column for n in self.at}
        self.columns = ["point_id", "critical_stiffness_N_per_m", *sorted(extra)]

    def add(self, t: Any) -> None:
        K = _float(t, "critical_stiffness_N_per_m")
        ids = t.column("point_id").to_numpy()
        ix = self._cells(0, t, ids)
        iy = self._cells(1, t, ids)
        ok = ~np.isnan(K)
        for name, value in self.at.items():     # (the grid's own value: equal, not close)
            col = t.column(next(a.column for a in self.points.axes if a.name == name))
            ok &= np.asarray(col.to_numpy(zero_copy_only=False)) == value
        cell = iy[ok] * self.grid.shape[1] + ix[ok]
        flat = self.grid.reshape(-1)          # (a view: fmin.at writes into the grid)
        if self.reduce == "min":
            np.fmin.at(flat, cell, K[ok])     # NaN: no value yet
        elif self.reduce == "max":
            np.fmax.at(flat, cell, K[ok])
        else:
            self.seen.append((cell, K[ok]))

    def _cells(self, k: int, t: Any, ids: np.ndarray) -> np.ndarray:
        a, cells = (self.x, self.y)[k], len(self.edges[k])
        if not a.random:
            j = [b.name for b in self.points.axes].index(a.name)
            index = np.unravel_index(ids, self.points.shape)[j]     # the grid's own index
            return index if len(a.values) <= HEAT_CELLS else index * cells // len(a.values)
        return _cell(a, _float(t, a.column), cells)

    def _median(self) -> None:
        if not self.seen:
            return
        cell = np.concatenate([c for c, _ in self.seen])
        K = np.concatenate([v for _, v in self.seen])
        order = np.lexsort((K, cell))            # by cell, then by K within a cell
        cell, K = cell[order], K[order]
        first, start, count = np.unique(cell, return_index=True, return_counts=True)
        mid = (K[start + (count - 1) // 2] + K[start + count // 2]) / 2   # an even count: both
        self.grid.reshape(-1)[first] = mid

    def result(self) -> dict[str, Any]:
        if self.reduce == "median":
            self._median()
        by = {a.name: a for a in self.points.axes}
        return {"x": self.x.column, "y": self.y.column, "x_name": self.x.name,
                "y_name": self.y.name, "x_values": self.edges[0], "y_values": self.edges[1],
                "reduce": self.reduce, "over": self.others,
                "min_over": self.others if self.reduce == "min" else [],
                "at": {by[n].column: v for n, v in self.at.items()}, "at_names": list(self.at),
                "x_log": _is_log(self.x), "y_log": _is_log(self.y),
                "critical_stiffness_N_per_m": self.grid.tolist()}


def check_at(points: Points, plot: tuple[str, str], at: dict[str, Any] | None
             ) -> dict[str, Any]:
    """A heat map's slice checked: axis name -> the grid value it names.

    Parameters
    ----------
    points : Points
    plot : (str, str)
        The shown axes (not to be fixed).
    at : dict or None
        Axis name (or its column, or the command line's name with ``-``) -> a value.

    Returns
    -------
    dict
        Axis name -> the grid's own value (a float given within a relative 1e-9 of a grid
        value is that value: a value typed as 0.65 and one made by ``"0:1.3:3"`` differ in
        the last bits; grid values closer than that are not distinguished).

    Raises
    ------
    SweepError
        An unknown, shown or random axis; a value not on the axis's grid (the message lists
        the grid).
    """
    out: dict[str, Any] = {}
    if at is None:
        return out
    if not isinstance(at, dict):
        raise SweepError(f"at = {at!r:.60}: a mapping axis name -> one of its values")
    by = {a.name: a for a in points.axes} | {a.column: a for a in points.axes} \
        | {a.name.replace("_", "-"): a for a in points.axes}
    for key, value in at.items():
        a = by.get(key)
        if a is None:
            raise SweepError(f"at: {key!r:.40} is not an axis; axes: "
                             f"{', '.join(b.name.replace('_', '-') for b in points.axes)}")
        if a.name in plot:
            raise SweepError(f"at: {key!r:.40} is an axis of the heat map; fix another one")
        if a.random:
            raise SweepError(f"at: {key!r:.40} is a random axis (no grid value to fix); "
                             f"reduce it instead (reduce = {', '.join(REDUCTIONS)})")
        out[a.name] = _grid_value(a, key, value)
    return out


def _grid_value(a: Axis, key: str, value: Any) -> Any:
    listed = ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in a.values[:12])
    listed += ", ..." if len(a.values) > 12 else ""
    if a.dtype == "string":
        if value in a.values:
            return value
    elif not isinstance(value, bool) and isinstance(value, (int, float)) \
            and math.isfinite(value):
        vals = np.asarray(a.values, dtype=float)
        j = int(np.argmin(np.abs(vals - value)))
        if abs(vals[j] - value) <= 1e-9 * max(abs(vals[j]), abs(value)):   # see check_at
            return a.values[j]
    raise SweepError(f"at: {key} = {value!r:.40}: not a value of the axis; its values: "
                     f"{listed}")


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


heat_map = draw_heat_map
