"""One chunk of a sweep: its points' loops, K_max of them all in one batch
(:func:`~hapstab.analysis.exact.many.critical_stiffness_many`), and the other quantities
point by point. A worker runs :func:`evaluate_chunk` and returns the chunk's columns; it
writes nothing (the driver does), so workers need no shared file system.

A point whose loop is refused (a model error) is a row with its one-line message in the
``error`` column and no quantities; a quantity that does not apply to a point (the
paper's closed form of a 4-channel loop, the sampled-data passivity at a fractional
delay) is empty (NaN or null) with the reason in ``not_applicable``, which is not an
error; a quantity whose analysis refuses the point otherwise (the passivity limit of a
filtered damper) says why in ``error``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from hapstab import progress
from hapstab.analysis.table import quantities
from hapstab.errors import HapstabError
from hapstab.sweep.axes import Points, ids_of

__all__ = ["Spec", "QUANTITIES", "columns", "evaluate_chunk", "OVER_PROMISE_REL"]

#: The quantities a sweep may ask for -> their columns (name, type), from the one table
#: of analyses (:data:`hapstab.analysis.table.TABLE`). "closed-form" needs K_max and adds it.
QUANTITIES: dict[str, tuple[tuple[str, str], ...]] = quantities()
#: The network's parameters (issue 30): axes or fixed values of a sweep, never the loop's
#: (taken out of a point's options before its loop is built) -> their defaults. ``loss``
#: (probability) and ``burst`` (mean burst length, samples; None: independent) for
#: "loss-kmax"; ``delay_range_width`` and ``jitter_width`` (whole samples) make the range
#: [n, n + width] from the point's own delay n for "delay-range-kmax" and "jitter".
NETWORK = {"loss": 0.0, "burst": None, "delay_range_width": 0, "jitter_width": 0}
#: A closed form over-promises where it allows K > K_max (1 + 1e-6) + 1e-12 N/m: the
#: rule of :func:`hapstab.audit` (K_max agrees to ~1e-9; 1e-12 N/m keeps an exact 0 of
#: both from counting).
OVER_PROMISE_REL, OVER_PROMISE_ABS = 1e-6, 1e-12  # audit's rule (see above)


@dataclass(frozen=True)
class Spec:
    """What every chunk of one sweep evaluates (sent to the workers).

    Parameters
    ----------
    build : callable
        ``build(options) -> loop``: the loop at a point (its stiffness is not used).
    fixed : dict
        The options every point shares (the axes' values are added to them).
    points : Points
        The points.
    quantities : tuple of str
        Keys of :data:`QUANTITIES`, in the order of their columns.
    chunk : int
        Points per chunk.
    check_stiffness : float or None
        K of the ``check`` quantity, N/m.
    damping : dict
        ``best_damping``'s options (``B_min``, ``B_max``, ``resolution``).
    """

    build: Callable[[dict[str, Any]], Any]
    fixed: dict[str, Any]
    points: Points
    quantities: tuple[str, ...]
    chunk: int
    check_stiffness: float | None = None
    damping: dict[str, Any] = field(default_factory=dict)


def columns(spec: Spec) -> list[tuple[str, str]]:
    """Every column of the sweep's rows, in order: the point id, the axes, the
    quantities, ``error``.

    Parameters
    ----------
    spec : Spec

    Returns
    -------
    list of (str, str)
        (name, type), the type one of ``int64``, ``float64``, ``string``, ``bool``.
    """
    out = [("point_id", "int64")] + [(a.column, a.dtype) for a in spec.points.axes]
    for q in spec.quantities:
        out += list(QUANTITIES[q])
    return [*out, ("not_applicable", "string"), ("error", "string")]


def evaluate_chunk(spec: Spec, chunk: int) -> dict[str, list[Any]]:
    """The rows of chunk number ``chunk``, as columns.

    Parameters
    ----------
    spec : Spec
    chunk : int
        From 0.

    Returns
    -------
    dict
        Column name -> list of values (one per point, in point order), for every column
        of :func:`columns`.
    """
    with progress.listening(None):          # (a point's own progress is not the sweep's)
        return _evaluate(spec, chunk)


def _evaluate(spec: Spec, chunk: int) -> dict[str, list[Any]]:
    start, stop = ids_of(chunk, spec.chunk, spec.points.count)
    values = spec.points.values(start, stop)
    n = stop - start
    out: dict[str, list[Any]] = {name: [None] * n for name, _ in columns(spec)}
    out["point_id"] = list(range(start, stop))
    for a in spec.points.axes:
        out[a.column] = values[a.name].tolist()
    errors: list[list[str]] = [[] for _ in range(n)]
    loops: list[Any] = [None] * n
    nets: list[dict[str, Any]] = [{} for _ in range(n)]
    for i in range(n):
        opts = {**spec.fixed, **{a.name: out[a.column][i] for a in spec.points.axes}}
        nets[i] = {k: opts.pop(k, d) for k, d in NETWORK.items()}
        try:
            loops[i] = spec.build(opts)
        except HapstabError as e:
            errors[i].append(_line(e))
    good = [i for i in range(n) if loops[i] is not None]
    if "kmax" in spec.quantities:
        _kmax(loops, good, out, errors)
    na: list[list[str]] = [[] for _ in range(n)]
    for i in good:
        if loops[i] is not None:
            _others(spec, loops[i], i, out, errors[i], na[i])
            for q in spec.quantities:
                if q in NETWORK_QUANTITIES:
                    _network(q, loops[i], nets[i], i, out, errors[i], na[i])
    out["not_applicable"] = ["; ".join(e) if e else None for e in na]
    out["error"] = ["; ".join(e) if e else None for e in errors]
    return out


def _kmax(loops: list[Any], good: list[int], out: dict[str, list[Any]],
          errors: list[list[str]]) -> None:
    """K_max of every good point in one batch; a loop the core refuses gets its message
    (and no quantities)."""
    from hapstab.analysis.exact.many import critical_stiffness_many

    results = critical_stiffness_many([loops[i] for i in good], errors="return")
    for i, r in zip(good, results, strict=True):
        if isinstance(r, HapstabError):
            errors[i].append(_line(r))
            loops[i] = None
            continue
        out["critical_stiffness_N_per_m"][i] = float(r.critical_stiffness)
        out["reason"][i] = r.reason
        out["crossing_frequency_hz"][i] = float(r.crossing_frequency_hz)


def _others(spec: Spec, loop: Any, i: int, out: dict[str, list[Any]], errors: list[str],
            na: list[str]) -> None:
    """The quantities other than K_max, at one point; one that does not apply there (the
    sampled-data passivity at a fractional delay, no closed form for the loop) is said in
    ``na``, not counted as an error."""
    q = spec.quantities
    if "passivity" in q:
        frac = _fractional(loop)
        if frac:
            na.append(f"passivity: derived for whole samples of delay; this point has {frac}")
            out["passivity_kmax_N_per_m"][i] = math.nan
        else:
            out["passivity_kmax_N_per_m"][i] = _try(errors, "passivity",
                                                    lambda: _passivity(loop))
    if "closed-form" in q:
        eq, K = _closed_form(loop, errors, na)
        exact = out["critical_stiffness_N_per_m"][i]
        out["closed_form_equation"][i] = eq
        out["closed_form_N_per_m"][i] = K
        out["closed_form_over_promises"][i] = (
            None if not (math.isfinite(K) and exact is not None and math.isfinite(exact))
            else bool(K > exact * (1 + OVER_PROMISE_REL) + OVER_PROMISE_ABS))
    if "check" in q:
        def verdict() -> str:
            from hapstab.analysis.exact.core import stability

            return str(stability(loop.with_stiffness(spec.check_stiffness)).verdict)

        out["verdict_at_K"][i] = _try(errors, "check", verdict, None)
    if "best-damping" in q:
        res = _try(errors, "best-damping", lambda: _best(loop, spec.damping), None)
        if res is not None:
            out["best_damping_B_N_s_per_m"][i] = float(res.damping)
            out["best_damping_K_N_per_m"][i] = float(res.critical_stiffness)


def _loss(loop: Any, net: dict[str, Any]) -> tuple[float, ...]:
    from hapstab.analysis.network import loss_critical_stiffness

    return (float(loss_critical_stiffness(loop, net["loss"], net["burst"]).critical_stiffness),)


def _delay_range(loop: Any, net: dict[str, Any]) -> tuple[float, ...]:
    from hapstab.analysis.network import delay_range_critical_stiffness

    n = int(loop.delay_in_samples)
    r = delay_range_critical_stiffness(loop, n, n + int(net["delay_range_width"]),
                                       seconds=False)
    return float(r.critical_stiffness), float(r.worst_delay_samples)


def _jitter(loop: Any, net: dict[str, Any]) -> tuple[float, ...]:
    from hapstab.analysis.network import jitter

    n = int(loop.delay_in_samples)
    r = jitter(loop, (n, n + int(net["jitter_width"])))
    return float(r.stable_up_to), float(r.unstable_from)


#: The network quantities -> the analysis giving their columns (in QUANTITIES' order) from
#: the loop and the point's network parameters (:data:`NETWORK`).
NETWORK_QUANTITIES: dict[str, Callable[[Any, dict[str, Any]], tuple[float, ...]]] = {
    "loss-kmax": _loss, "delay-range-kmax": _delay_range, "jitter": _jitter}


def _network(q: str, loop: Any, net: dict[str, Any], i: int, out: dict[str, list[Any]],
             errors: list[str], na: list[str]) -> None:
    """One network quantity at one point: its columns, or NaN with why (a fractional
    delay: the ranges start at whole samples; an analysis that refuses the point)."""
    cols = [c for c, _ in QUANTITIES[q]]
    if q != "loss-kmax" and _fractional(loop):
        na.append(f"{q}: its range starts at the point's whole-sample delay; this point has "
                  f"{_fractional(loop)}")
        values: Any = None
    else:
        values = _try(errors, q, lambda: NETWORK_QUANTITIES[q](loop, net), None)
    for j, c in enumerate(cols):
        out[c][i] = math.nan if values is None else values[j]


def _passivity(loop: Any) -> float:
    from hapstab.analysis.methods import critical_stiffness

    return float(critical_stiffness(loop, method="passivity").critical_stiffness)


def _fractional(loop: Any) -> str:
    """The loop's fractional delays in words ("t_d = 2.5 T"), or "" when every delay is a
    whole number of samples."""
    parts = [(name, getattr(loop, attr, 0) or 0) for name, attr in
             (("t_d", "fractional_delay"), ("backward t_d", "fractional_delay_backward"))]
    n = float(getattr(loop, "delay_in_samples", 0.0))
    return ", ".join(f"{name} = {n:g} T" if name == "t_d" else f"a fractional {name}"
                     for name, f in parts if f)


def _closed_form(loop: Any, errors: list[str], na: list[str]) -> tuple[str, float]:
    """The paper's condition for the loop (eq. 13 / 18 / 29 / 34) and its K, or ("", NaN)
    with the reason (in ``na``) where none applies."""
    from hapstab.analysis.conditions.closed_forms import EQUATION, paper_condition

    try:
        cond = paper_condition(loop)
    except HapstabError as e:
        na.append(f"closed-form: {_line(e)}")
        return "", math.nan
    K = _try(errors, "closed-form", lambda: float(cond.function(loop).critical_stiffness))
    return EQUATION.get(cond.key, cond.key), K


def _best(loop: Any, options: dict[str, Any]) -> Any:
    from hapstab.analysis.design.damping import best_damping

    return best_damping(loop, **options)


def _try(errors: list[str], what: str, f: Callable[[], Any], empty: Any = math.nan) -> Any:
    try:
        return f()
    except HapstabError as e:
        errors.append(f"{what}: {_line(e)}")
        return empty


def _line(e: BaseException) -> str:
    return " ".join(str(e).split())

