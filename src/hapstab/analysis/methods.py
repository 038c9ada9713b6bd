"""Front door of the analyses: ``critical_stiffness(loop, method=...)`` and ``boundary``.

A method is a function ``f(loop, **options) -> CriticalStiffnessResult`` over the
same models; :data:`METHODS` is the one table of them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from hapstab.analysis.circle import critical_stiffness_circle
from hapstab.analysis.closed_forms import CLOSED_FORMS, TABLE
from hapstab.analysis.exact.core import exact_critical_stiffness, exact_kmax_batch
from hapstab.analysis.passivity import critical_stiffness_passivity
from hapstab.errors import AnalysisError, check_delay, check_period
from hapstab.models.loops import HapticLoop, TeleoperationLoop, require_loop
from hapstab.results import BoundaryResult, CriticalStiffnessResult
from hapstab.simulation.search import critical_stiffness_simulation

__all__ = ["critical_stiffness", "boundary", "METHODS", "methods_for"]

#: method name -> function
METHODS: dict[str, Callable[..., CriticalStiffnessResult]] = {
    "exact": exact_critical_stiffness,
    **CLOSED_FORMS,
    "circle": critical_stiffness_circle,
    "passivity": critical_stiffness_passivity,
    "simulation": critical_stiffness_simulation,
}

def methods_for(kind: Any) -> list[str]:
    """Method names that apply to loops of ``kind``: every method but the closed
    forms derived for the other kind.

    Parameters
    ----------
    kind : {"hve", "peb"} or a loop
        The loop kind (haptic virtual environment or position-error-based
        teleoperator), or a loop, whose kind is taken.

    Returns
    -------
    list of str
        Names accepted by :func:`critical_stiffness` for that kind.
    """
    kind = getattr(kind, "kind", kind)
    if kind not in ("hve", "peb"):
        raise AnalysisError(f"kind = {kind!r}: allowed: 'hve', 'peb' or a loop")
    other = {c.key for c in TABLE if c.kind != kind}
    return [m for m in METHODS if m not in other]


def order_estimate(loop: HapticLoop | TeleoperationLoop, delay_samples: float) -> int:
    """About how many states the exact model of ``loop`` with ``delay_samples`` of delay
    has (each channel's delay registers, two per port, a few for controllers), without
    building it: for cost estimates."""
    ports = len(loop.controllers)
    return int(ports * (delay_samples + 4) + 2)


def _resolve(method: str) -> Callable[..., CriticalStiffnessResult]:
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
        :mod:`hapstab.exact`; ``"circle"`` (the paper's circle criterion, eq. 15/30;
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

    Raises
    ------
    AnalysisError
        Unknown method, or a method that does not apply to this loop.
    """
    return _resolve(method)(loop, **options)


def boundary(loop: HapticLoop | TeleoperationLoop, periods: Sequence[float] | np.ndarray,
             delays: Sequence[int] | np.ndarray = (0,), method: str = "exact",
             **options: Any) -> BoundaryResult:
    """K_max over a grid of sampling periods and delays (the curves of Fig. 5 / 6).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Template: its own period and delay (fractional and backward parts too) are
        replaced by the grid's: delays[i] whole samples, equal in both directions.
    periods : array of float
        Sampling periods T in s (> 0).
    delays : array of int
        Delays n in samples (t_d = n T at each T).
    method : str
        As for :func:`critical_stiffness`; ``"exact"`` is vectorised over T.
    **options
        Passed to the method at every grid point (e.g. ``approximation`` for
        ``"circle"``); ``"exact"`` takes none and ignores them.

    Returns
    -------
    BoundaryResult
        ``critical_stiffness[i, j]`` for ``delays[i]``, ``periods[j]``.
    """
    require_loop(loop)
    try:
        T = np.atleast_1d(np.asarray(periods, dtype=float)).ravel()
    except (TypeError, ValueError):
        raise AnalysisError(f"periods = {periods!r}: must be numbers (s)") from None
    if T.size == 0:
        raise AnalysisError("periods: the range is empty; give at least one period")
    for t in T:   # every period, by the models' own rule (not only the first, which builds the loop)
        check_period("period", float(t))
    ns = [check_delay("delay", n) for n in np.atleast_1d(delays)]
    if not ns:
        raise AnalysisError("delays: the list is empty; give at least one delay")
    from hapstab import budget

    limits = options.pop("max_memory", None), options.pop("max_seconds", None)
    if method == "simulation":
        from hapstab.simulation.search import search_cost

        longest = loop.with_whole_delay(max(ns), float(T.min()))
        budget.check(search_cost(longest, len(ns) * T.size, options.get("n_samples", 2000)),
                     *limits)
    else:
        points = len(ns) * T.size
        what = f"boundary: {points} points ({len(ns)} delays x {T.size} periods), {method!r}"
        states = order_estimate(loop, max(ns))
        if method in ("exact", "circle", "passivity"):   # per point: grows with the loop
            cost = budget.exact_points_cost(what, T.size, states)
            cost = budget.Cost(what, cost.memory_bytes, cost.seconds * len(ns))
        else:                                              # a closed form: a formula per point
            cost = budget.Cost(what, 1e3 * points, 1e-4 * points)  # measured: 44,000 in 0.6 s
        budget.check(cost, *limits)
    out = np.empty((len(ns), T.size))
    for i, n in enumerate(ns):
        # the grid's delay replaces the template's, in both directions, whole samples
        tmpl = loop.with_whole_delay(n, float(T[0]))
        if method == "exact":
            res = exact_kmax_batch(tmpl, T, intervals=False)
            out[i] = [r.kmax for r in res]
        else:
            f = _resolve(method)
            out[i] = [f(tmpl.replace(period=float(t)), **options).critical_stiffness for t in T]
    return BoundaryResult(T, np.array(ns), out, method, loop.kind)
