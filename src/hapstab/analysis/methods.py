"""Front door of the analyses: ``critical_stiffness(loop, method=...)`` and ``boundary``.

A method is a function ``f(loop, **options) -> CriticalStiffnessResult`` over the
same models; :data:`METHODS` is the one table of them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from hapstab import progress
from hapstab.analysis.conditions.circle import critical_stiffness_circle
from hapstab.analysis.conditions.circle import kmax_parts as circle_parts
from hapstab.analysis.conditions.closed_forms import CLOSED_FORMS, TABLE
from hapstab.analysis.conditions.passivity import critical_stiffness_passivity
from hapstab.analysis.conditions.passivity import kmax_parts as passivity_parts
from hapstab.analysis.exact.core import exact_critical_stiffness, exact_kmax_batch
from hapstab.analysis.teleoperation.twoport import critical_stiffness_llewellyn
from hapstab.errors import (
    MAX_DELAY_SAMPLES,
    PERIOD_RANGE,
    AnalysisError,
    ArgumentTypeError,
    check_delay,
    check_period,
    check_real,
    check_reals,
)
from hapstab.models.loops import HapticLoop, TeleoperationLoop, require_loop
from hapstab.models.parts import friction_note
from hapstab.results import BoundaryResult, CriticalStiffnessResult
from hapstab.simulation.search import critical_stiffness_simulation

__all__ = ["critical_stiffness", "boundary", "METHODS", "AFFINE_PARTS", "methods_for"]

#: method name -> function
METHODS: dict[str, Callable[..., CriticalStiffnessResult]] = {
    "exact": exact_critical_stiffness,
    **CLOSED_FORMS,
    "circle": critical_stiffness_circle,
    "passivity": critical_stiffness_passivity,
    "llewellyn": critical_stiffness_llewellyn,
    "simulation": critical_stiffness_simulation,
}
#: Methods whose K_max is the least PSD limit over frequency of a matrix affine in K:
#: method -> its ``kmax_parts(loop) -> (parts, oscillations)`` (each module's); a K-B
#: region's overlay takes every row from them at once
#: (:func:`~hapstab.analysis.conditions.frequency_grid.affine_kmax_rows`).
AFFINE_PARTS: dict[str, Callable[..., Any]] = {"circle": circle_parts,
                                               "passivity": passivity_parts}
#: Methods for one loop kind only (besides the closed forms derived for one).
ONLY = {"llewellyn": ("peb", "4ch")}

def methods_for(kind: Any) -> list[str]:
    """Method names that apply to loops of ``kind``: every method but the closed
    forms derived for the other kind.

    Parameters
    ----------
    kind : {"hve", "peb", "4ch"} or a loop
        The loop kind (haptic virtual environment, position-error-based or
        4-channel teleoperator), or a loop, whose kind is taken.

    Returns
    -------
    list of str
        Names accepted by :func:`critical_stiffness` for that kind.
    """
    kind = getattr(kind, "kind", kind)
    if not isinstance(kind, str) or kind not in ("hve", "peb", "4ch"):
        raise AnalysisError(f"kind = {kind!r}: allowed: 'hve', 'peb', '4ch' or a loop")
    other = {c.key for c in TABLE if c.kind != kind} | {m for m, k in ONLY.items()
                                                       if kind not in k}
    return [m for m in METHODS if m not in other]


def order_estimate(loop: HapticLoop | TeleoperationLoop, delay_samples: float) -> int:
    """About how many states the exact model of ``loop`` with ``delay_samples`` of delay
    has (each channel's delay registers, two per port, a few for controllers), without
    building it: for cost estimates."""
    ports = len(loop.controllers)
    return int(ports * (delay_samples + 4) + 2)


def _resolve(method: str) -> Callable[..., CriticalStiffnessResult]:
    if not isinstance(method, str):
        raise ArgumentTypeError(f"method = {method!r:.40}: must be a string; allowed: "
                                f"{', '.join(METHODS)}")
    if method not in METHODS:
        raise AnalysisError(f"method = {method!r}: unknown; allowed: {', '.join(METHODS)}")
    return METHODS[method]


def critical_stiffness(loop: HapticLoop | TeleoperationLoop, method: str = "exact",
                       **options: Any) -> CriticalStiffnessResult:
    """Largest K such that the loop is stable for every K in (0, K_max].

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Everything but K is held fixed (B, T, n, impedances). For teleoperation
        K is the master's stiffness and K_s/K_m is kept (equal in the paper).
    method : str
        ``"exact"`` (default): the exact sampled-data loop, see
        :mod:`hapstab.analysis.exact`; ``"circle"`` (the paper's circle criterion, eq. 15/30;
        option ``approximation="forward"|"backward"|"tustin"``), ``"passivity"``
        (exact sampled-data passivity, Colgate-Schenkel), ``"simulation"`` (the
        paper's simulation search); or a closed form: ``"colgate"`` (eq. 1/13),
        ``"gil"`` (eq. 2), ``"eq18"``, ``"gil2004"`` for the HVE and ``"eq29"``,
        ``"eq34"`` for PEB.
    **options
        Passed to the method.

    Returns
    -------
    CriticalStiffnessResult
        Of the friction-free loop: with a device's Coulomb friction its ``note`` says
        so, once (:func:`~hapstab.models.parts.friction_note`).

    Raises
    ------
    AnalysisError
        Unknown method, or a method that does not apply to this loop.
    """
    f = _resolve(method)
    _check_options(method, f, options)
    res = f(loop, **options)
    note = friction_note(loop)      # a linear method: the friction-free loop
    return dataclasses.replace(res, note=note) if note else res


def _check_options(method: str, f: Callable[..., Any], options: dict[str, Any]) -> None:
    """Refuse an option the method does not take, naming it and the ones it does."""
    import inspect

    params = inspect.signature(f).parameters
    if any(p.kind is p.VAR_KEYWORD for p in params.values()):
        return
    allowed = [n for n, p in list(params.items())[1:]
               if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)]
    for name in options:
        if name not in allowed:
            raise ArgumentTypeError(f"{name} = {options[name]!r:.40}: not an option of method "
                                    f"{method!r}; it takes: {', '.join(allowed) or 'none'}")


def boundary(loop: HapticLoop | TeleoperationLoop, periods: Sequence[float] | np.ndarray,
             delays: Sequence[int] | np.ndarray = (0,), method: str = "exact", *,
             delays_s: Sequence[float] | np.ndarray | None = None,
             axis: str = "period", **options: Any) -> BoundaryResult:
    """K_max over a grid of sampling periods and delays (the curves of Fig. 5 / 6), or
    over sampling rates at fixed delays in seconds (the question about one's own device:
    how stiff at 500 Hz, 1 kHz, 4 kHz with 20 ms of network delay?).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Template: its own period and delay (fractional and backward parts too) are
        replaced by the grid's, equal in both directions.
    periods : array of float
        Sampling periods T in s (> 0).
    delays : array of int
        Delays n in whole samples (t_d = n T at each T); ignored with ``delays_s``.
    method : str
        As for :func:`critical_stiffness`; ``"exact"`` is vectorised over T.
    delays_s : array of float, optional
        Delays in seconds (>= 0), each held fixed over the periods: at each T the loop
        has t_d / T samples of delay, fractional parts modelled exactly.
    axis : {"period", "rate"}
        What the result's plot puts on its horizontal axis (T in ms, or 1/T in Hz).
    **options
        Passed to the method at every grid point (e.g. ``approximation`` for
        ``"circle"``); ``"exact"`` takes ``certify`` (default True: every point proved
        in ball arithmetic, as :func:`critical_stiffness`; False: the float search
        alone, not proved, and 5-25x faster over a grid: 4 delays x 60 periods take
        0.8 s against 4.3 s for the paper's HVE, 0.4 s against 9.3 s for its PEB).
        ``max_memory`` / ``max_seconds``: the
        budget of the whole grid (see :mod:`hapstab.budget`).

    Returns
    -------
    BoundaryResult
        ``critical_stiffness[i, j]`` for ``delays[i]`` (or ``delays_s[i]``), ``periods[j]``.
    """
    require_loop(loop)
    T = _periods(periods)
    rows = _delay_rows(delays, delays_s)
    if not isinstance(axis, str) or axis not in ("period", "rate"):
        raise AnalysisError(f"axis = {axis!r}: allowed: 'period', 'rate'")
    limits = options.pop("max_memory", None), options.pop("max_seconds", None)
    _check_options(method, _resolve(method), options)
    samples = max(rows) / T.min() + 1 if delays_s is not None else max(rows)
    if samples > MAX_DELAY_SAMPLES + 1:
        raise AnalysisError(f"delays_s = {max(rows):g} s: at T = {T.min():g} s that is "
                            f"{samples - 1:.4g} samples; at most {MAX_DELAY_SAMPLES} (the exact "
                            "model carries one state per sample of delay)")
    _charge_boundary(loop, T, len(rows), samples, method, options, limits)
    out = np.empty((len(rows), T.size))
    with progress.steps(out.size, f"boundary, {method}: {out.size} points") as advance:
        for i, d in enumerate(rows):
            if delays_s is None and method == "exact":     # batched over the periods
                tmpl = loop.with_whole_delay(int(d), float(T[0]))
                out[i] = [r.kmax for r in exact_kmax_batch(tmpl, T, intervals=False,
                                                          certify=options.get("certify", True))]
                advance(T.size)
                continue
            f = _resolve(method)
            for j, t in enumerate(T):
                at = _at(loop, float(t), d, delays_s is not None)
                out[i, j] = f(at, **options).critical_stiffness
                advance(1)
    unit = "s" if delays_s is not None else "samples"
    return BoundaryResult(T, np.array(rows), out, method, loop.kind, unit, axis)


def _periods(periods: Any) -> np.ndarray:
    if isinstance(periods, bool):
        raise ArgumentTypeError(f"periods = {periods!r}: must be numbers (s)")
    T = check_reals("periods", periods)       # not a string, a complex number, ...
    if T.size == 0:
        raise AnalysisError("periods: the range is empty; give at least one period")
    lo, hi = PERIOD_RANGE     # every period, by the models' own rule, vectorised (10^7 in ms)
    for t in T[~((T >= lo) & (T <= hi))][:1]:
        check_period("period", float(t))       # the first bad one, with the models' message
    return T


#: Above this many whole delays (an integer array), they are checked vectorised.
MANY_DELAYS = 1000


def _delay_rows(delays: Any, delays_s: Any) -> list[Any]:
    """Whole samples, or seconds (>= 0, finite) when ``delays_s`` is given."""
    if delays_s is None:
        given = np.atleast_1d(delays)
        if given.size > MANY_DELAYS and given.dtype.kind in "iu":    # vectorised, as periods
            for n in given[(given < 0) | (given > MAX_DELAY_SAMPLES)][:1]:
                check_delay("delay", n)
        rows: list[Any] = (given.tolist() if given.size > MANY_DELAYS and given.dtype.kind in "iu"
                           else [check_delay("delay", n) for n in given])
        what = "delays"
    else:
        rows = [check_real("delays_s", d, nonnegative=True)
                for d in check_reals("delays_s", delays_s)]
        what = "delays_s"
    if not rows:
        raise AnalysisError(f"{what}: the list is empty; give at least one delay")
    return rows


def _at(loop: Any, T: float, delay: Any, seconds: bool) -> Any:
    """The template at period T with the row's delay (whole samples, or seconds)."""
    return loop.replace(period=T).with_delay_s(delay) if seconds else \
        loop.with_whole_delay(int(delay), T)


def _charge_boundary(loop: Any, T: np.ndarray, n_rows: int, samples: float, method: str,
                     options: dict[str, Any], limits: tuple[Any, Any]) -> None:
    """The grid's cost, from its longest delay in samples (see :mod:`hapstab.budget`)."""
    from hapstab import budget

    if method == "simulation":
        from hapstab.simulation.search import search_cost

        longest = loop.with_whole_delay(math.ceil(samples), float(T.min()))
        budget.check(search_cost(longest, n_rows * T.size, options.get("n_samples", 2000)),
                     *limits)
        return
    points = n_rows * T.size
    what = f"boundary: {points} points ({n_rows} delays x {T.size} periods), {method!r}"
    if method in ("exact", "circle", "passivity"):   # per point: grows with the loop
        cost = budget.exact_points_cost(what, T.size, order_estimate(loop, samples))
        cost = budget.Cost(what, cost.memory_bytes, cost.seconds * n_rows)
    else:                                              # a closed form: a formula per point
        cost = budget.Cost(what, 1e3 * points, 1e-4 * points)  # measured: 44,000 in 0.6 s
    budget.check(cost, *limits)
