"""``hapstab sweep STUDY.toml --out DIR``: a study file's ``[sweep]`` over millions of
loops, in Parquet chunks, resumable, on local processes or a Dask cluster.

The study file is the one of ``hapstab run`` (kind, title, [loop] with the command
line's option names) with a ``[sweep]`` table::

    [sweep]
    quantities = ["kmax", "passivity", "closed-form", "check", "best-damping"]
    chunk = 2000                         # points per chunk (default: about 2 s of work)

    [sweep.axes]                         # loop options by their command-line names
    mass = [0.1, 0.3, 1.0]               # a list
    rate = "250Hz:4kHz:16:log"           # lo:hi:count, log-spaced; units as on the CLI
    delay = "0:20:5"                     # whole samples stay whole

    [sweep.random]                       # instead of the grid: random points
    samples = 100000                     # (each axis then "lo:hi" or "lo:hi:log")
    seed = 1

    [sweep.plot]                         # the heat map of K_max
    x = "rate"
    y = "delay"
    reduce = "min"                       # the other axes: "min" (default), "max", "median"
    at = { mass = 0.3 }                  # or a slice: only the points at these values

    [sweep.check]
    stiffness = 250                      # N/m, for the "check" quantity

    [sweep.best-damping]                 # best_damping's window
    min-damping = 0
    max-damping = 20
    resolution = 32

Everything is checked before any work (tomllib, nothing evaluated): one line naming the
file, the line and the key, exit code 2.
"""

from __future__ import annotations

import functools
import math
import os
import sys
from typing import Any

import click

from hapstab.cli.options import ARGV, LOOP_KINDS, IntRange, provenance
from hapstab.cli.study import (
    ALTERNATIVES,
    BASE,
    OUTPUT_KEYS,
    Study,
    StudyError,
    load_study,
    option_spellings,
    study_defaults,
)
from hapstab.cli.sweep_keys import NETWORK_KEYS, at_value, network_value
from hapstab.results import dumps

if sys.version_info >= (3, 11):
    import tomllib
else:                                    # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[import-not-found,unused-ignore]

__all__ = ["sweep_cmd", "build_loop", "column_of", "plan"]

#: The [sweep] table's keys, and its sub-tables' keys.
KEYS = {"quantities", "chunk", "axes", "random", "plot", "check", "best-damping", "network"}
#: The network's parameters (sweep.evaluate.NETWORK), as an axis or in [sweep.network]:
#: study key -> (name, whole samples, the least value, the largest or None).
SUB = {"random": {"samples", "seed"}, "plot": {"x", "y", "reduce", "at"},
       "check": {"stiffness"}, "network": set(NETWORK_KEYS),
       "best-damping": {"min-damping", "max-damping", "resolution"}}
#: Options of ``kmax`` that are not the loop's: neither an axis nor a [loop] key here.
NOT_LOOP = {"method", "approximation", "operator_damping_min", "environment_damping_min",
            "loss", "burst", "delay_range", "certify", "cert_path"}


def column_of(name: str) -> str:
    """The column of a loop option, with its SI unit (``mass`` -> ``mass_kg``).

    Parameters
    ----------
    name : str
        The option's parameter name.

    Returns
    -------
    str
    """
    fixed = {"period": "period_s", "rate": "rate_hz", "delay": "delay_samples",
             "delay_forward": "delay_forward_samples", "delay_backward": "delay_backward_samples"}
    if name in fixed:
        return fixed[name]
    for end, unit in (("mass", "_kg"), ("damping", "_N_s_per_m"), ("friction", "_N")):
        if name.endswith(end):
            return name + unit
    return name


def build_loop(kind: str, options: dict[str, Any]) -> Any:
    """The loop the command line would build from ``options`` (picklable with
    :func:`functools.partial`, for the workers).

    Parameters
    ----------
    kind : {"hve", "peb", "4ch"}
    options : dict
        Every option of the kind's loop, by parameter name.

    Returns
    -------
    HapticLoop or TeleoperationLoop
    """
    return LOOP_KINDS[kind](dict(options), 1.0)


def plan(study: Study, root: click.Group, yes: bool, reduce: str | None = None,
         at: tuple[str, ...] = ()) -> dict[str, Any]:
    """The arguments of :func:`hapstab.sweep.run.sweep` from a study, every key checked.

    Parameters
    ----------
    study : Study
    root : click.Group
        The ``hapstab`` group (the loop options are ``kmax <kind>``'s).
    yes : bool
        No budget of points.
    reduce : str, optional
        ``--reduce``: the heat map's reduction (instead of ``[sweep.plot] reduce``).
    at : tuple of str
        ``--at NAME=VALUE``: the heat map's slice (instead of ``[sweep.plot] at``).

    Returns
    -------
    dict

    Raises
    ------
    StudyError
        One line naming the file, the line and the key.
    """
    table = tomllib.loads(study.text).get("sweep")
    if not isinstance(table, dict):
        raise StudyError(f"{study.path}: no [sweep] table: nothing to sweep; e.g. [sweep.axes] "
                         "mass = [0.1, 0.3]")
    _known(study, table, KEYS, "sweep")
    for sub, keys in SUB.items():
        if sub in table:
            if not isinstance(table[sub], dict):
                raise StudyError(f"{study.where(sub, 'sweep')}sweep.{sub}: must be a table "
                                 f"([sweep.{sub}])")
            _known(study, table[sub], keys, f"sweep.{sub}")
    kmax = root.commands["kmax"]
    assert isinstance(kmax, click.Group)
    cmd = kmax.commands[study.kind]
    params = {p.name: p for p in cmd.params if isinstance(p, click.Option) and p.name
              and p.name not in NOT_LOOP and p.name not in ("as_json",)}
    fixed = {name: p.default for name, p in params.items()}
    loop = study_defaults(study, cmd, "kmax", BASE, [], run=False)    # not [run.kmax]
    for name in loop:
        if name in NOT_LOOP:
            raise StudyError(f"{study.where(name, 'loop')}{name.replace('_', '-')}: not a loop "
                             "option (hapstab sweep computes its [sweep] quantities)")
    fixed.update(loop)
    from hapstab.sweep.evaluate import NETWORK

    fixed.update(NETWORK)
    for key, value in table.get("network", {}).items():
        try:
            fixed[NETWORK_KEYS[key][0]] = network_value(key, value)
        except ValueError as e:
            raise StudyError(f"{study.where(key, 'sweep.network')}sweep.network.{e}") from None
    random = table.get("random")
    if random is not None:
        _random(study, random)                  # (before the axes, which depend on it)
    axes = _axes(study, table.get("axes"), params, random is not None)
    for a in axes:
        fixed.pop(a.name, None)         # (a network axis's default too)
        for x, y in ALTERNATIVES:
            if a.name in (x, y):
                other = y if a.name == x else x
                if other in [b.name for b in axes]:
                    raise StudyError(f"{study.where(a.name, 'sweep.axes')}sweep.axes: "
                                     f"{x.replace('_', '-')} and {y.replace('_', '-')}: give one")
                if other in ("rate", "delay_s"):      # (the builder prefers them when set)
                    fixed[other] = None
    settings = _settings(study, table, random, axes)
    settings.update(_heat(study, table.get("plot"), axes, params, reduce, at,
                          settings.get("plot")))
    return {"build": functools.partial(build_loop, study.kind), "axes": axes, "fixed": fixed,
            **settings, "max_points": math.inf if yes else None}


def _heat(study: Study, plot: Any, axes: list[Any], params: dict[str, click.Option],
          reduce: str | None, at: tuple[str, ...], shown: Any) -> dict[str, Any]:
    """The heat map's reduction and slice: [sweep.plot] reduce / at, or --reduce / --at
    (which redraw a finished sweep without changing its study); values with units."""
    from hapstab.sweep.result import REDUCTIONS

    plot = plot or {}
    out: dict[str, Any] = {}
    if reduce is None and "reduce" in plot:
        reduce = plot["reduce"]
        if not isinstance(reduce, str) or reduce not in REDUCTIONS:
            raise StudyError(f"{study.where('reduce', 'sweep.plot')}sweep.plot.reduce = "
                             f"{reduce!r:.40}: allowed: {', '.join(REDUCTIONS)}")
    if reduce is not None:
        out["plot_reduce"] = reduce
    given: dict[str, tuple[Any, str]] = {}
    if at:
        for item in at:
            key, eq, value = item.partition("=")
            if not eq or not key.strip() or not value.strip():
                raise StudyError(f"--at {item!r:.40}: give NAME=VALUE, e.g. --at damping=0.5")
            if key.strip() in given:
                raise StudyError(f"--at {key.strip()}: given twice; a slice has one value an axis")
            given[key.strip()] = (value.strip(), f"--at {key.strip()}")
    elif "at" in plot:
        if not isinstance(plot["at"], dict) or not plot["at"]:
            raise StudyError(f"{study.where('at', 'sweep.plot')}sweep.plot.at = "
                             f"{plot['at']!r:.40}: a table axis = value, e.g. at = "
                             "{ mass = 0.3 }")
        for key, value in plot["at"].items():
            given[key] = (value, f"{study.where('at', 'sweep.plot')}sweep.plot.at.{key}")
    by = {a.name.replace("_", "-"): a for a in axes} | {a.name: a for a in axes}
    values = {}
    for key, (value, where) in given.items():
        a = by.get(key)
        if a is None:
            raise StudyError(f"{where}: not an axis of the sweep; axes: "
                             f"{', '.join(b.name.replace('_', '-') for b in axes)}")
        try:
            values[key] = at_value(a, value, params)
        except click.BadParameter as e:
            raise StudyError(f"{where} = {value!r:.40}: {e.message}") from None
        except ValueError as e:                 # a network axis's value (loss, ...)
            raise StudyError(f"{where} = {value!r:.40}: {e}") from None
    if values:
        from hapstab.sweep.axes import Points, SweepError
        from hapstab.sweep.result import check_at

        where = "--at" if at else f"{study.where('at', 'sweep.plot')}sweep.plot.at"
        if shown is None and len(axes) < 2:
            raise StudyError(f"{where}: no heat map to slice (it needs two axes)")
        try:
            check_at(Points(tuple(axes)), shown or (axes[0].name, axes[1].name), values)
        except SweepError as e:
            raise StudyError(f"{where}: {str(e).removeprefix('at: ')}") from None
        out["plot_at"] = values
    return out


def _known(study: Study, table: dict[str, Any], keys: set[str], where: str) -> None:
    for key in table:
        if key not in keys:
            raise StudyError(f"{study.where(key, where)}{where}.{key}: unknown key; allowed: "
                             f"{', '.join(sorted(keys))}")


def _axes(study: Study, axes: Any, params: dict[str, click.Option], random: bool) -> list[Any]:
    from hapstab.sweep.axes import SweepError, parse_axis

    if not isinstance(axes, dict) or not axes:
        raise StudyError(f"{study.where('axes', 'sweep')}sweep.axes: give at least one axis "
                         "([sweep.axes] with a loop option = a list or \"lo:hi:count\")")
    names = option_spellings(params)
    out = []
    seen: dict[str, str] = {}
    for key, spec in axes.items():
        where = study.where(key, "sweep.axes")
        if key.replace("_", "-") in NETWORK_KEYS:
            net, integer, _, _ = NETWORK_KEYS[key.replace("_", "-")]
            try:
                out.append(parse_axis(net, spec, integer=integer, random=random,
                                      convert=functools.partial(network_value,
                                                                key.replace("_", "-")),
                                      column=net + ("_samples" if integer else ""),
                                      where=f"sweep.axes.{key}"))
            except SweepError as e:
                raise StudyError(f"{where}{e}") from None
            continue
        name = names.get(key.replace("-", "_"))
        if name is None or key in OUTPUT_KEYS:
            raise StudyError(f"{where}sweep.axes.{key}: not a loop option of {study.kind}; "
                             f"allowed: {', '.join(sorted(k.replace('_', '-') for k in names))}")
        if name in seen:            # m and mass: one option twice (was "axes: ..." unplaced)
            raise StudyError(f"{where}sweep.axes.{key}: the option of sweep.axes.{seen[name]} "
                             "again; give it once")
        seen[name] = key
        p = params[name]
        integer = type(p.type).__name__ == "Delay"
        text = isinstance(p.type, click.types.StringParamType)

        def convert(v: Any, p: click.Option = p) -> Any:
            try:
                return p.type.convert(v, p, None)
            except click.BadParameter as e:
                raise ValueError(e.message) from None

        try:
            out.append(parse_axis(name, spec, column=column_of(name), convert=convert,
                                  integer=integer, text=text, random=random,
                                  where=f"sweep.axes.{key}"))
        except SweepError as e:
            raise StudyError(f"{where}{e}") from None
    return out


def _settings(study: Study, table: dict[str, Any], random: Any, axes: list[Any]) -> dict[str, Any]:
    """quantities, chunk, samples, seed, plot, check_stiffness, damping; types checked."""
    out: dict[str, Any] = {}
    q = table.get("quantities", ["kmax"])
    if not isinstance(q, list) or not q or not all(isinstance(x, str) for x in q):
        raise StudyError(f"{study.where('quantities', 'sweep')}sweep.quantities = {q!r:.60}: a "
                         "non-empty list of strings")
    from hapstab.sweep.evaluate import QUANTITIES

    for x in q:
        if x not in QUANTITIES:
            raise StudyError(f"{study.where('quantities', 'sweep')}sweep.quantities: {x!r:.40} "
                             f"is not one; allowed: {', '.join(QUANTITIES)}")
    out["quantities"] = q
    out["chunk"] = _int(study, table, "chunk", "sweep", 1)
    if random is not None:
        out.update(_random(study, random))
    plot = table.get("plot")
    if plot is not None:
        for k in ("x", "y"):
            v = plot.get(k)
            names = {a.name: a for a in axes} | {a.name.replace("_", "-"): a for a in axes}
            if not isinstance(v, str) or v not in names:
                raise StudyError(f"{study.where(k, 'sweep.plot')}sweep.plot.{k} = {v!r:.40}: "
                                 f"an axis; allowed: {', '.join(a.name.replace('_', '-') for a in axes)}")
        out["plot"] = (names[plot["x"]].name, names[plot["y"]].name)
    check = table.get("check", {})
    if "stiffness" in check:
        out["check_stiffness"] = _number(study, check, "stiffness", "sweep.check", 0.0)
    elif "check" in q:
        raise StudyError(f"{study.where('quantities', 'sweep')}sweep.quantities: \"check\" needs "
                         "[sweep.check] stiffness = K (N/m)")
    bd = table.get("best-damping", {})
    damping = {}
    for key, name, low in (("min-damping", "B_min", None), ("max-damping", "B_max", None),
                           ("resolution", "resolution", 2)):
        if key in bd:
            damping[name] = (_int(study, bd, key, "sweep.best-damping", 2) if low
                             else _number(study, bd, key, "sweep.best-damping", None))
    # as best-damping's command line (the window was accepted and every row refused)
    for key, name, bad, allowed in (("max-damping", "B_max", lambda v: not v > 0, "> 0"),
                                    ("min-damping", "B_min", lambda v: v > 0, "<= 0 (the search "
                                     "always includes B = 0)"),
                                    ("resolution", "resolution", lambda v: v > 2000, "<= 2000")):
        if name in damping and bad(damping[name]):
            raise StudyError(f"{study.where(key, 'sweep.best-damping')}sweep.best-damping."
                             f"{key} = {damping[name]!r}: must be {allowed}")
    out["damping"] = damping
    return out


def _random(study: Study, random: dict[str, Any]) -> dict[str, Any]:
    """[sweep.random]: samples and seed."""
    if "samples" not in random:
        raise StudyError(f"{study.where('random', 'sweep')}sweep.random.samples: missing; "
                         "give the number of random points")
    return {"samples": _int(study, random, "samples", "sweep.random", 1),
            "seed": _int(study, random, "seed", "sweep.random", 0) or 0}


def _int(study: Study, table: dict[str, Any], key: str, where: str, low: int) -> int | None:
    v = table.get(key)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int) or v < low:
        raise StudyError(f"{study.where(key, where)}{where}.{key} = {v!r:.40}: must be a whole "
                         f"number >= {low}")
    return v


def _number(study: Study, table: dict[str, Any], key: str, where: str, low: float | None) -> float:
    v = table.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or (low is not None and v < low):
        raise StudyError(f"{study.where(key, where)}{where}.{key} = {v!r:.40}: must be a finite "
                         f"number{f' >= {low:g}' if low is not None else ''}")
    return float(v)


@click.command("sweep", short_help="A study's [sweep] over many loops, in resumable chunks.")
@click.argument("study_path", metavar="STUDY.toml")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Folder of results: chunks/*.parquet, manifest.json, summary.json, kmax.png. "
                   "Rerun the same command to resume.")
@click.option("--workers", type=IntRange(1, 4096), default=None,
              help="Local worker processes (default: every core); 1: in this process, "
                   "without Dask.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run on an existing Dask cluster (tcp://host:8786) instead.")
@click.option("--force", is_flag=True, help="Start over in a folder holding another sweep.")
@click.option("--reduce", type=click.Choice(["min", "max", "median"]), default=None,
              help="The heat map's cells: the least (default), largest or median K_max over "
                   "the axes it does not show (max: e.g. at the best damping). Rerun a "
                   "finished sweep with it to redraw kmax.png; nothing is recomputed.")
@click.option("--at", "at", multiple=True, metavar="NAME=VALUE",
              help="The heat map of one slice: only the points at this value of an axis "
                   "(one of its values, units as in the study), e.g. --at damping=0.5; "
                   "repeatable.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (manifest, summary).")
def sweep_cmd(study_path: str, out_dir: str, workers: int | None, scheduler: str | None,
              force: bool, reduce: str | None, at: tuple[str, ...], as_json: bool) -> None:
    """Evaluate a study file's [sweep] quantities (K_max and its reason, the passivity
    limit, the paper's closed form, the verdict at K, the best damping) at every point of
    its axes, into Parquet chunks written as they finish; rerun to resume."""
    from hapstab.sweep.cluster import check_address
    from hapstab.sweep.run import sweep

    study = load_study(study_path, "STUDY.toml")
    root = click.get_current_context().find_root().command
    assert isinstance(root, click.Group)
    args = plan(study, root, "--yes" in ARGV.get(), reduce, at)
    if args["max_points"] is None:
        del args["max_points"]
    if scheduler is not None:
        scheduler = check_address(scheduler)
    if not out_dir.strip():
        raise StudyError(f"--out = {out_dir!r}: must be a folder path (it is empty)")
    with _bar(as_json):
        res = sweep(out=out_dir, workers=workers, scheduler=scheduler, force=force,
                    study=study.text, **args)
    if as_json:
        click.echo(dumps({**res.to_dict(), **provenance()}))
    else:
        _table(res)


def _bar(quiet: bool) -> Any:
    """A progress bar with points done, points per second and the time left, on a
    terminal's stderr (nothing with --json or when piped)."""
    import contextlib

    from hapstab import progress

    if quiet or not sys.stderr.isatty():
        return progress.listening(None)

    @contextlib.contextmanager
    def listener(what: str, total: int) -> Any:
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeRemainingColumn,
        )

        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TextColumn("{task.fields[rate]} points/s"), TimeRemainingColumn(),
                      transient=True, console=Console(stderr=True)) as prog:
            task = prog.add_task(what, total=total, rate="-")

            def advance(k: int) -> None:
                prog.advance(task, k)
                speed = prog.tasks[0].speed
                prog.update(task, rate=f"{speed:.4g}" if speed else "-")

            yield advance

    return progress.listening(listener)


def _table(res: Any) -> None:
    from rich.markup import escape
    from rich.table import Table

    from hapstab.cli.options import console, fmt

    m, s = res.manifest, res.summary
    t = Table(title=escape(f"sweep: {m['points']} points in {m['chunks']} chunks of "
                           f"{m['chunk']} ({res.computed_chunks} computed now)"))
    for c in ("quantity", "min", "where", "max", "where"):
        t.add_column(c)
    for col, st in s["quantities"].items():
        if st["min"] is None:
            continue
        t.add_row(col, fmt(st["min"]), escape(_where(st["where_min"])), fmt(st["max"]),
                  escape(_where(st["where_max"])))
    con = console()
    con.print(t)
    cf = s.get("closed_form")
    if cf:
        con.print(escape(f"the paper's closed form over-promises at {cf['over_promises']} of "
                         f"{cf['compared']} points"))
    if s["errors"]:
        con.print(escape(f"{s['errors']} points carry a message in the error column"))
    if s.get("not_applicable"):
        con.print(escape(f"{s['not_applicable']} points have a quantity that does not apply "
                         "there (the not_applicable column; not errors)"))
    con.print(escape(f"wrote {os.path.join(res.out_dir, 'chunks')}/ and "
                     f"{', '.join(res.files)} to {res.out_dir}"))


def _where(w: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}" for k, v in w.items())
