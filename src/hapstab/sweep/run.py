"""``hapstab.sweep``: a design study of many loops, in chunks, resumable, on local
processes or a Dask cluster.

The driver checks everything before any work (the axes, the quantities, the number of
points against the budget, the first point's loop), opens the folder (refusing another
sweep's), then hands the chunks not yet finished to the workers and writes each chunk's
Parquet file as its result arrives (:func:`dask.distributed.as_completed`): the workers
return columns and need no shared file system. ``workers=1`` runs in this process,
without Dask (the single-process reference); otherwise a
:class:`dask.distributed.LocalCluster` of ``workers`` processes (one thread each), or a
client of an existing cluster (``scheduler``).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

from hapstab import progress
from hapstab.budget import BudgetError
from hapstab.errors import HapstabError
from hapstab.sweep.axes import Axis, Points, SweepError, parse_axis
from hapstab.sweep.evaluate import QUANTITIES, Spec, columns, evaluate_chunk
from hapstab.sweep.result import REDUCTIONS, SweepResult, check_at, draw_heat_map, summarise
from hapstab.sweep.store import Store

__all__ = ["sweep", "MAX_POINTS", "INSTALL", "default_chunk", "POINT_SECONDS"]

#: Points a sweep may have without asking (``--yes``; Python ``max_points=math.inf``).
MAX_POINTS = 10 ** 7
#: What installs the sweep's dependencies.
INSTALL = "pip install 'hapstab[sweep]'"
#: Seconds per point of each quantity, for the default chunk size (about, on the project's
#: machine; benchmarks/bench_sweep.py measures them): K_max 1.4-6.4 ms batched in a chunk
#: (12-85 ms one by one) on its HVE and PEB spaces, taken as 2 ms; the passivity limit and
#: a verdict ~4 ms; the best damping ~100 K_max; the network quantities as
#: benchmarks/bench_network_all.py measures them one by one (loss 0.05 s, a delay range
#: of 11 delays 0.4 s, a jitter bracket over 0:2 0.25 s; taken as 0.05, 0.1 and 0.3 s).
POINT_SECONDS = {"kmax": 2e-3, "passivity": 4e-3, "closed-form": 1e-5, "check": 4e-3,
                 "best-damping": 0.1, "loss-kmax": 0.05, "delay-range-kmax": 0.1,
                 "jitter": 0.3}
#: A chunk takes about this long: a Dask task costs ~1 ms, under 1 % of it.
CHUNK_SECONDS = 2.0
#: At most this many chunks (a larger sweep gets larger chunks: its manifest stays short).
MAX_CHUNKS = 100_000


def default_chunk(quantities: Sequence[str], points: int) -> int:
    """Points per chunk so that a chunk takes about :data:`CHUNK_SECONDS` (depends on the
    study only, never on the workers, so that a resumed sweep has the same chunks).

    Parameters
    ----------
    quantities : sequence of str
        What each point computes.
    points : int
        Points in all.

    Returns
    -------
    int
    """
    per = sum(POINT_SECONDS[q] for q in quantities) or POINT_SECONDS["kmax"]
    size = max(1, int(CHUNK_SECONDS / per))
    return max(size, -(-points // MAX_CHUNKS))


def sweep(build: Callable[[dict[str, Any]], Any], axes: Sequence[Axis] | Mapping[str, Any],
          out: str, *, fixed: Mapping[str, Any] | None = None,
          quantities: Sequence[str] = ("kmax",), samples: int | None = None, seed: int = 0,
          chunk: int | None = None, check_stiffness: float | None = None,
          damping: Mapping[str, Any] | None = None, plot: Sequence[str] | None = None,
          plot_reduce: str = "min", plot_at: Mapping[str, Any] | None = None,
          workers: int | None = None, scheduler: str | None = None, force: bool = False,
          max_points: float = MAX_POINTS, study: str | None = None) -> SweepResult:
    """Evaluate ``quantities`` at every point of a space of loops, into a folder of
    Parquet chunks, resumably.

    Parameters
    ----------
    build : callable
        ``build(options) -> loop``: the loop at one point; ``options`` is ``fixed`` and
        the point's axis values by axis name (Python scalars). Must be picklable for
        Dask (a module-level function, or anything cloudpickle takes).
    axes : sequence of Axis, or mapping
        The axes (see :func:`hapstab.sweep.axes.parse_axis`: ``{"mass": [0.1, 0.2],
        "period": "1e-3:1e-2:10:log"}``), in order: the last varies fastest.
    out : str
        The folder (``chunks/``, ``manifest.json``, ``summary.json``, ``kmax.png``).
    fixed : mapping, optional
        Options every point shares.
    quantities : sequence of str
        Of ``kmax``, ``passivity``, ``closed-form`` (adds kmax), ``check`` (needs
        ``check_stiffness``), ``best-damping``.
    samples : int, optional
        Random points instead of the grid (each axis a range ``"lo:hi[:log]"``).
    seed : int
        The random points' seed (``numpy.random.default_rng(seed)``).
    chunk : int, optional
        Points per chunk (default :func:`default_chunk`; a resumed sweep keeps its own).
    check_stiffness : float, optional
        K in N/m of the ``check`` quantity.
    damping : mapping, optional
        :func:`~hapstab.analysis.design.damping.best_damping`'s ``B_min``, ``B_max``,
        ``resolution`` for ``best-damping``.
    plot : (str, str), optional
        The heat map's x and y axes (default: the first two axes; none with one axis).
    plot_reduce : {"min", "max", "median"}
        How the heat map's cells reduce the K_max over the other axes (``"min"``: the design
        that holds for all of them; ``"max"``: their best value, e.g. of a damping axis).
        Not part of the sweep's identity: a finished sweep run again with another reduction
        recomputes nothing and redraws ``kmax.png``.
    plot_at : mapping, optional
        Axis name -> one of its grid values: the heat map of that slice only (the other
        axes not shown are reduced by ``plot_reduce``).
    workers : int, optional
        Local processes (default: every core); 1: in this process, without Dask. Not with
        ``scheduler``.
    scheduler : str, optional
        The address of a Dask scheduler to run on instead (``tcp://host:8786``).
    force : bool
        Start over in a folder that holds another sweep (or this one).
    max_points : float
        The budget of points (default :data:`MAX_POINTS`; ``math.inf``: none).
    study : str, optional
        The study file's text: its SHA-256 identifies the sweep (default: the SHA-256 of
        the arguments but ``build``, with its qualified name).

    Returns
    -------
    SweepResult

    Raises
    ------
    SweepError
        A bad axis, quantity or option; the folder holds another sweep; the sweep's
        packages are not installed.
    BudgetError
        More points than ``max_points``.
    """
    spec, plot_axes = _spec(build, axes, fixed, quantities, samples, seed, chunk,
                            check_stiffness, damping, plot, max_points)
    heat = _heat_options(spec.points, plot_axes, plot_reduce, plot_at)
    workers = _workers(workers, scheduler)
    _first_point(spec)
    _need("pyarrow")
    if workers != 1 or scheduler is not None:
        _need("dask.distributed")
    from hapstab import __version__

    identity = study if study is not None else _identity(build, spec, plot_axes)
    head = {"study_sha256": hashlib.sha256(identity.encode()).hexdigest(),
            "hapstab_version": __version__, "points": spec.points.count, "chunk": spec.chunk,
            "quantities": list(spec.quantities), "point_set": spec.points.to_dict(),
            "columns": [{"name": n, "type": t} for n, t in columns(spec)]}
    store = Store(os.fspath(out), head, columns(spec), force)
    if store.head["chunk"] != spec.chunk:                   # a resumed sweep's own chunks
        spec = _replace_chunk(spec, int(store.head["chunk"]))
    todo = store.missing()
    if todo:
        with progress.steps(sum(store.rows_of(c) for c in todo),
                               f"sweep: {len(todo)} of {store.n_chunks} chunks") as advance:
            for index, cols in _run(spec, todo, workers, scheduler):
                store.write_chunk(index, cols)
                advance(len(cols["point_id"]))
    return _finish(store, spec, plot_axes, len(todo), heat)


def _heat_options(points: Points, plot: tuple[str, str] | None, reduce: Any, at: Any
                  ) -> dict[str, Any]:
    """The heat map's reduction and slice, checked before any work."""
    if not isinstance(reduce, str) or reduce not in REDUCTIONS:
        raise SweepError(f"plot_reduce = {reduce!r:.40}: allowed: {', '.join(REDUCTIONS)}")
    if at is not None and not isinstance(at, Mapping):
        raise SweepError(f"plot_at = {at!r:.60}: a mapping axis name -> one of its values")
    if plot is None:
        if at or reduce != "min":
            raise SweepError("plot_reduce / plot_at: there is no heat map (give plot = "
                             "(x, y), two axes, and the kmax quantity)")
        return {"reduce": reduce, "at": None}
    return {"reduce": reduce, "at": check_at(points, plot, dict(at or {}))}


def _spec(build: Any, axes: Any, fixed: Any, quantities: Any, samples: Any, seed: Any,
          chunk: Any, check_stiffness: Any, damping: Any, plot: Any, max_points: Any
          ) -> tuple[Spec, tuple[str, str] | None]:
    """Every argument checked, and the points counted (never built) against the budget."""
    if not callable(build):
        raise SweepError(f"build = {build!r:.60}: must be a function options -> loop")
    if samples is not None and (isinstance(samples, bool) or not isinstance(samples, int)
                                or samples < 1):
        raise SweepError(f"samples = {samples!r}: must be a whole number >= 1")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SweepError(f"seed = {seed!r}: must be a whole number >= 0")
    if isinstance(axes, Mapping):
        axes = [parse_axis(k, v, random=samples is not None) for k, v in axes.items()]
    axes = tuple(axes)
    if not axes or not all(isinstance(a, Axis) for a in axes):
        raise SweepError("axes: give at least one axis (a mapping name -> values or range)")
    if samples is not None and not all(a.random for a in axes):
        raise SweepError("axes: with samples every axis is a range \"lo:hi\" or \"lo:hi:log\"")
    if samples is None and any(a.random for a in axes):
        raise SweepError("axes: a random axis (lo:hi) needs samples")
    _unique([a.name for a in axes], "axis")
    _unique([a.column for a in axes], "column")
    qs = _quantities(quantities)
    points = Points(axes, samples, seed)
    limit = _max_points(max_points)
    if points.count > limit:
        shape = " x ".join(str(len(a.values)) for a in axes) if samples is None else "samples"
        raise BudgetError(f"sweep: {points.count:.4g} points ({shape}): more than the budget "
                          f"of {limit:.4g}; run it anyway with --yes (Python: "
                          "max_points=math.inf)")
    if "check" in qs and check_stiffness is None:
        raise SweepError("check: give the stiffness K ([sweep.check] stiffness = ..., Python: "
                         "check_stiffness=)")
    if check_stiffness is not None and not (isinstance(check_stiffness, (int, float))
                                            and math.isfinite(check_stiffness)
                                            and check_stiffness >= 0):
        raise SweepError(f"check_stiffness = {check_stiffness!r}: must be a number >= 0 (N/m)")
    size = chunk if chunk is not None else default_chunk(qs, points.count)
    if isinstance(size, bool) or not isinstance(size, int) or size < 1:
        raise SweepError(f"chunk = {chunk!r}: must be a whole number of points >= 1")
    plot_axes = _plot(plot, axes, qs)
    spec = Spec(build, dict(fixed or {}), points, qs, size,
                None if check_stiffness is None else float(check_stiffness), dict(damping or {}))
    return spec, plot_axes


def _unique(names: list[str], what: str) -> None:
    for n in names:
        if names.count(n) > 1:
            raise SweepError(f"axes: {what} {n!r} given twice")


def _quantities(quantities: Any) -> tuple[str, ...]:
    if isinstance(quantities, str) or not isinstance(quantities, Sequence) or not quantities:
        raise SweepError(f"quantities = {quantities!r:.60}: a non-empty list of "
                         f"{', '.join(QUANTITIES)}")
    for q in quantities:
        if q not in QUANTITIES:
            raise SweepError(f"quantities: {q!r:.40} is not one; allowed: {', '.join(QUANTITIES)}")
    want = set(quantities) | ({"kmax"} if "closed-form" in quantities else set())
    return tuple(q for q in QUANTITIES if q in want)


def _max_points(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
        raise SweepError(f"max_points = {v!r}: must be a number > 0 (math.inf: no limit)")
    return float(v)


def _plot(plot: Any, axes: tuple[Axis, ...], qs: tuple[str, ...]) -> tuple[str, str] | None:
    names = [a.name for a in axes]
    if plot is None:
        return (names[0], names[1]) if len(names) >= 2 and "kmax" in qs else None
    if isinstance(plot, str) or len(plot) != 2 or plot[0] == plot[1]:
        raise SweepError(f"plot = {plot!r:.60}: two different axes (x, y)")
    if "kmax" not in qs:
        raise SweepError("plot: the heat map is of K_max; add \"kmax\" to the quantities")
    for p in plot:
        if p not in names:
            raise SweepError(f"plot: {p!r:.40} is not an axis; axes: {', '.join(names)}")
    return plot[0], plot[1]


def _workers(workers: Any, scheduler: Any) -> int:
    if workers is None:
        return os.cpu_count() or 1
    most = 4 * (os.cpu_count() or 1)      # (more local processes than that only compete)
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= most:
        raise SweepError(f"--workers = {workers!r}: must be a whole number 1...{most} (4 times "
                         "this machine's cores; a cluster: --scheduler)")
    if scheduler is not None:
        raise SweepError("--workers and --scheduler: give one of them (a scheduler's cluster "
                         "has its own workers)")
    return workers


def _first_point(spec: Spec) -> None:
    """Build the first point's loop: a bad fixed option fails before any work."""
    first = spec.points.values(0, 1)
    opts = {**spec.fixed, **{k: v.tolist()[0] for k, v in first.items()}}
    try:
        spec.build(opts)
    except HapstabError as e:
        shown = ", ".join(f"{a.column} = {opts[a.name]!r}" for a in spec.points.axes)
        raise type(e)(f"{e} (the first point: {shown})") from None


def _need(module: str) -> None:
    try:
        __import__(module)
    except ImportError:
        raise SweepError(f"hapstab sweep needs {module.split('.')[0]}: {INSTALL}") from None


def _identity(build: Any, spec: Spec, plot: Any) -> str:
    name = f"{getattr(build, '__module__', '')}.{getattr(build, '__qualname__', repr(build))}"
    return json.dumps({"build": name, "fixed": spec.fixed, "points": spec.points.to_dict(),
                       "values": [list(map(str, a.values)) for a in spec.points.axes],
                       "quantities": spec.quantities, "check": spec.check_stiffness,
                       "damping": spec.damping, "plot": plot}, sort_keys=True, default=str)


def _replace_chunk(spec: Spec, chunk: int) -> Spec:
    import dataclasses

    return dataclasses.replace(spec, chunk=chunk)


def _run(spec: Spec, todo: list[int], workers: int, scheduler: str | None
         ) -> Iterator[tuple[int, dict[str, list[Any]]]]:
    """(chunk, columns) as they finish."""
    if workers == 1 and scheduler is None:
        for c in todo:
            yield c, evaluate_chunk(spec, c)
        return
    from hapstab.sweep.cluster import on_dask

    yield from on_dask(spec, todo, workers, scheduler)


def _finish(store: Store, spec: Spec, plot: tuple[str, str] | None, computed: int,
            heat: dict[str, Any]) -> SweepResult:
    """The summary and the heat map, then the final manifest."""
    from hapstab.outputs import Outputs, figure_to
    from hapstab.results import dumps

    summary = summarise(store.chunk_paths(), spec.points, spec.quantities, plot,
                        heat["reduce"], heat["at"])
    files = ["summary.json"] + (["kmax.png"] if plot else [])
    with Outputs() as out:
        with out.open(os.path.join(store.folder, "summary.json"), "--out") as fh:
            fh.write(dumps(summary) + "\n")
        if plot:
            figure_to(out, _Drawn(summary), os.path.join(store.folder, "kmax.png"), "--out")
    manifest = store.write_manifest(now=True, files=files)
    return SweepResult(store.folder, manifest, summary, computed, tuple(files), spec.points)


class _Drawn:
    """The summary's heat map as something with ``plot()`` (for figure_to)."""

    def __init__(self, summary: dict[str, Any]) -> None:
        self.summary = summary

    def plot(self, ax: Any = None) -> Any:
        return draw_heat_map(self.summary.get("heat_map"), ax)

