"""The exact critical stiffness of many loops at once: ``critical_stiffness_many``.

Loops that share a *structure* (loop kind, ports and the order of their
terminations, which port each channel measures with which sign and whole and
fractional delay, velocity filters, free ports and rigid-body modes; for several
channels per port also which channels have no damper or no stiffness) have
characteristic functions ``det M = F0 + u F1 + u^2 F2`` of the same form, differing
only in numbers (masses, dampings, terminations, period, virtual damping B, K
ratios, filter poles): :func:`hapstab.engine.frequency.build_responses` builds them
as one batch (one row per loop), and the certified crossing search of
:mod:`~hapstab.analysis.exact.crossings` runs over every loop of the batch in the
same vectorised rounds (then, by default, each loop's stable set is re-proved in ball
arithmetic, :mod:`~hapstab.analysis.exact.proved`). The answer for each loop is bitwise
the one the single-loop core gives
(:func:`~hapstab.analysis.methods.critical_stiffness`); what is shared is the Python
work per round and per call, most of a single call's float search.

Batches are sized by :func:`batch_size` so that a chunk of any size is analysed in
bounded memory; a loop the core refuses (its parameters, or a search beyond the
core's limits) is isolated by splitting its batch until it is alone, and then gets
exactly the error the single-loop call raises.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any, Literal, overload

from hapstab.analysis.exact.core import critical_stiffness_result
from hapstab.analysis.exact.crossings import analyse
from hapstab.engine.frequency import (
    ResponsePlan,
    build_responses,
    check_plan,
    loop_response,
    plan_response,
)
from hapstab.errors import AnalysisError, ArgumentTypeError, HapstabError
from hapstab.models.loops import HapticLoop, TeleoperationLoop, describe, require_loop
from hapstab.models.parts import friction_note
from hapstab.results import CriticalStiffnessResult

__all__ = ["critical_stiffness_many", "batch_size", "BATCH", "BATCH_BYTES"]

#: Most loops analysed in one batch (more gains nothing in speed).
BATCH = 256
#: Memory one batch's search may take (bytes); its size is chosen by it. The search
#: keeps every theta-cell of every loop of its batch (~300 bytes a cell) and
#: evaluates each round's boxes at once; measured peak (tracemalloc) per loop and unit
#: of the phase rate (delays in samples, both ways, plus the plant order) per port:
#: 23-61 KB (HVE 10 samples 34 KB, PEB 15 and 30 samples each way 61 and 48 KB),
#: taken as :data:`PER_RATE` = 70 KB. A chunk of any size then peaks near this
#: budget (batches run one after another): PEB with 30 samples each way goes 32
#: loops a batch, the paper's HVE with 10 samples 256.
BATCH_BYTES = 300e6
PER_RATE = 70e3

Outcome = CriticalStiffnessResult | HapstabError


@overload
def critical_stiffness_many(loops: Sequence[HapticLoop | TeleoperationLoop], *,
                            errors: Literal["raise"] = ..., certify: bool = ...
                            ) -> list[CriticalStiffnessResult]: ...


@overload
def critical_stiffness_many(loops: Sequence[HapticLoop | TeleoperationLoop], *,
                            errors: Literal["return"], certify: bool = ...
                            ) -> list[Outcome]: ...


def critical_stiffness_many(loops: Sequence[HapticLoop | TeleoperationLoop], *,
                            errors: str = "raise", certify: bool = True) -> list[Any]:
    """Exact K_max of every loop: ``[critical_stiffness(loop) for loop in loops]``,
    batched over loops of one structure.

    Parameters
    ----------
    loops : sequence of HapticLoop, TeleoperationLoop or FourChannelLoop
        Any mix of kinds, structures and parameters; duplicates are analysed again.
    errors : {"raise", "return"}
        What a loop the exact core refuses gives: ``"raise"`` raises the error of the
        first such loop in input order (after every loop is analysed: the error the
        list comprehension would raise); ``"return"`` puts the
        :class:`~hapstab.errors.HapstabError` instance in that loop's slot and goes on.
    certify : bool
        Re-prove each loop's stable set in ball arithmetic (default True, as
        ``critical_stiffness(loop)``: K_max the safe end of a proved enclosure, with its
        certificate; the proof runs loop by loop after the batched search). False: the
        float search alone (the fast path, 4-6x faster in a batch: 100 loops of the
        paper's HVE 0.31 s against 1.9 s, PEB 0.89 s against 3.8 s; its rounding
        allowances are not proved, and its K_max can be above the truth for stiff walls
        on light devices), equal to ``critical_stiffness(loop, certify=False)``.

    Returns
    -------
    list of CriticalStiffnessResult (or HapstabError with ``errors="return"``)
        In the order of ``loops``; each equal to
        ``critical_stiffness(loop, certify=certify)``: the
        same K_max (to the last bits: see the notes), stable intervals, reason,
        crossing frequency, uncertain intervals and rigid-body modes.

    Raises
    ------
    HapstabError
        With ``errors="raise"``: the first refused loop's error (e.g. an
        :class:`~hapstab.errors.AnalysisError` for a controller that is not a
        spring-damper, or port masses more than 1e12 apart).
    ArgumentTypeError
        ``errors`` is not "raise" or "return", or ``loops`` is not a sequence.

    Notes
    -----
    The results are bitwise those of the single-loop call, not merely close: every
    operation of the search on one loop's rows is elementwise (the characteristic
    function, the boxes' tests and splits, the windings, summed in the same order);
    the three places where the rows of a batch met are per loop now: the Newton
    polishing of a round's crossings stops for each loop when its own boxes have
    converged (it ran until all had, so a loop could take one step more in a batch
    and move K_max by an ulp), the search's safety valve on rounds counts each
    loop's own rounds, and a winding that runs out of splits marks only the loops
    still splitting. Checked bitwise on seeded mixed campaigns (tests/exact/test_exact_many.py).

    References
    ----------
    R. Krawczyk, "Newton-Algorithmen zur Bestimmung von Nullstellen mit
    Fehlerschranken", Computing 4 (1969) 187-201; R. E. Moore, R. B. Kearfott and
    M. J. Cloud, *Introduction to Interval Analysis*, SIAM 2009, ch. 8 (the certified
    search, batched here); N. Miandashti and M. Tavakoli, "Stability of Sampled-Data,
    Delayed Haptic Interaction and Teleoperation", IEEE Haptics Symposium 2014,
    eq. (20) and (23) (the loops).
    """
    if not isinstance(errors, str) or errors not in ("raise", "return"):
        raise ArgumentTypeError(f"errors = {errors!r:.40}: allowed: 'raise', 'return'")
    if not isinstance(certify, bool):
        raise ArgumentTypeError(f"certify = {certify!r:.40}: must be True or False")
    if isinstance(loops, (str, bytes)) or not isinstance(loops, Sequence):
        raise ArgumentTypeError(f"loops = {loops!r:.60}: must be a sequence (list or tuple) "
                                "of loops")
    out: list[Any] = [None] * len(loops)
    groups: dict[tuple, list[tuple[int, ResponsePlan]]] = {}
    for i, loop in enumerate(loops):
        try:
            require_loop(loop)
            plan = plan_response(loop)
            check_plan(plan)
        except HapstabError as e:
            out[i] = _refusal(loop, e)
            continue
        groups.setdefault(plan.key(), []).append((i, plan))
    for members in groups.values():
        size = batch_size(members[0][1])
        for k in range(0, len(members), size):
            _analyse_batch(loops, members[k:k + size], out, certify)
    if errors == "raise":
        for o in out:
            if isinstance(o, HapstabError):
                raise o
    return out


def batch_size(plan: ResponsePlan) -> int:
    """How many loops of ``plan``'s structure one batch takes: :data:`BATCH` at most,
    fewer when its phase rate (the delays) would take the search beyond
    :data:`BATCH_BYTES`; at least 8.

    Parameters
    ----------
    plan : ResponsePlan
        Any loop of the structure.

    Returns
    -------
    int
    """
    ports = len(plan.matrices)
    most = [0] * ports
    for ch, terms in zip(plan.st.channels, plan.terms, strict=True):
        most[ch.port] = max(most[ch.port], *(n + math.ceil(f) for _, _, n, f in terms))
    # the velocity filters' orders raise det M's degree (LoopResponse.phase_rate) as delays do
    rate = sum(most) + sum(m[0].shape[0] for m in plan.matrices) + 2 + \
        plan.filter_rate
    return int(max(8, min(BATCH, BATCH_BYTES // (PER_RATE * rate * ports))))


def _refusal(loop: Any, e: HapstabError) -> HapstabError:
    """The error the single-loop core gives a loop refused before its polynomials are
    built: when it fails a check made after them, it may fail one made before too."""
    try:
        loop_response(loop)
    except HapstabError as first:
        return first
    return e


def _analyse_batch(loops: Sequence[Any], members: list[tuple[int, ResponsePlan]],
                   out: list[Any], certify: bool) -> None:
    """Analyse one batch into ``out``; a refusal splits it until the refused loop is
    alone, which then gets the single-loop core's error."""
    def split() -> None:
        half = len(members) // 2
        _analyse_batch(loops, members[:half], out, certify)
        _analyse_batch(loops, members[half:], out, certify)

    try:
        resp = build_responses([pl for _, pl in members])
    except HapstabError as e:
        if len(members) > 1:
            return split()
        out[members[0][0]] = e
        return None
    try:
        sets = analyse(resp, full=True, proof=certify)
    except HapstabError as e:
        if len(members) > 1:
            return split()
        i = members[0][0]       # as exact_kmax_batch words it
        out[i] = AnalysisError(f"{e}; the loop: {describe(loops[i])}") \
            if isinstance(e, AnalysisError) else e
        return None
    for (i, _), res in zip(members, sets, strict=True):
        loop = loops[i]
        r = critical_stiffness_result(res, loop.period, loop.delay_in_samples)
        note = friction_note(loop)          # as critical_stiffness words it
        out[i] = dataclasses.replace(r, note=note) if note else r
    return None
