"""Every stable set the exact core reports, re-proved in ball arithmetic
(:mod:`~hapstab.analysis.exact.proof`) where the loop is covered
(:func:`~hapstab.engine.arb_loop.arb_parameters`): the float search proposes, the
balls decide. What they cannot decide is reported uncertain with its extent.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from hapstab.analysis.exact.boxes import U_HI
from hapstab.analysis.exact.stable_set import StableSet
from hapstab.engine.arb_loop import base_point
from hapstab.engine.frequency import LoopResponse
from hapstab.engine.port_poly import PortPoly

__all__ = ["prove_sets", "item_response", "refuse_heavy"]


def item_response(resp: LoopResponse, i: int) -> LoopResponse:
    """Item ``i`` of a batch alone (the same arrays, one row)."""
    sl = slice(i, i + 1)
    ports = [PortPoly(pp.d[sl], pp.dhat[sl], pp.N[sl], {f: a[sl] for f, a in pp.Nt.items()},
                      {f: a[sl] for f, a in pp.D.items()}, {k: a[sl] for k, a in pp.err.items()},
                      None if pp.R is None else pp.R[sl],
                      None if pp.mz_M is None else pp.mz_M[sl]) for pp in resp.ports]
    gain = None if resp.gain is None else resp.gain[sl]
    return dataclasses.replace(resp, ports=ports, k=resp.k[sl], beta=resp.beta[sl],
                               scale=resp.scale[sl], periods=resp.periods[sl], gain=gain,
                               params=resp.params[sl] if resp.params else ())


def prove_sets(resp: LoopResponse, sets: list[StableSet], full: bool, search: Any) -> list[StableSet]:
    """Each item's stable set, proved in balls where its loop is covered.

    Parameters
    ----------
    resp : LoopResponse
        The batch (``resp.params`` per item).
    sets : list of StableSet
        The float search's answers (with their ``events``).
    full : bool
        Every stable interval, or K_max alone.
    search : callable
        ``search(resp_one_item) -> StableSet``: the float search with every crossing
        (used when the proof's count at K -> 0+ disagrees with the float one's, so
        K_max alone needs the candidates it skipped).

    Returns
    -------
    list of StableSet
        Proved sets (``proof`` set) or, for loops not covered, the float ones.
    """
    out = []
    for i, ss in enumerate(sets):
        params = resp.params[i] if resp.params else None
        out.append(ss if params is None else _prove_one(resp, i, ss, params, full, search))
    return out


def _prove_one(resp: LoopResponse, i: int, ss: StableSet, params: dict, full: bool,
               search: Any) -> StableSet:
    """One item (see :func:`prove_sets`)."""
    from hapstab.analysis.exact.proof import prove_base
    refuse_heavy(params)
    s = float(resp.scale[i])
    # K_0 from the loop's numbers alone (a certificate's is re-derived the same way)
    k0, k_top = base_point(params), U_HI * s
    events = ss.events
    if not full and ss.outside_small_K != 0 and not events:
        al, base = prove_base(params, k0)
        if base.outside != 0:
            return _from_proof(ss, _unstable(al, params, k0, k_top, base))
        events = search(item_response(resp, i)).events
    from hapstab.analysis.exact.proof import prove
    # the float search's stable set and unresolved zones (widened by 1e-6: their ends are
    # its own) tell which gaps to examine; when it could not count at K -> 0+ it has
    # none: examine them all
    def widen(ivs: tuple) -> tuple:
        # 1e-6: far above the float search's ~1e-13 placement of its own ends
        return tuple((a * (1 - 1e-6), b * (1 + 1e-6)) for a, b in ivs)
    if ss.outside_small_K >= 0:
        hint, unsure = widen(ss.intervals), widen(ss.uncertain)
    else:
        hint, unsure = ((0.0, math.inf),), ()
    pr = prove(params, events, k0, k_top, full, hint, unsure)
    if _reaches_top(pr):
        # stable up to the float search's top: look above it (analysis/exact/top.py)
        from hapstab.analysis.exact.top import raise_top
        from hapstab.engine.arb_loop import ArbLoop
        top, extra = raise_top(ArbLoop(params), events, k_top)
        pr = prove(params, tuple(sorted(events + extra)), k0, top, full, hint, unsure)
    return _from_proof(ss, pr)


def _reaches_top(pr: Any) -> bool:
    """Whether a proved stable interval ends at the top of the examined range."""
    return any(b >= pr.k_top for _a, b in pr.intervals)


#: Smallest largest dimensionless group (b T / m, |B| T / m, k T^2 / m over the ports)
#: the proof resolves: below it every pole of interest lies within 1e-12 of z = 1 at
#: the stiffnesses that matter (K T^2 / m ~ b T / m), closer than the double-precision
#: angles of the proof's pieces can separate (they stop at 4e-16 rad).
HEAVY = 1e-12


def refuse_heavy(params: dict) -> None:
    """Refuse a loop whose poles all crowd z = 1 beyond the proof's reach (a heavy
    device: 1e12 kg at T = 1 ms with b = 0.1 N*s/m has b T / m = 1e-16); a loop whose
    groups are all zero (undamped, no termination spring) is not refused."""
    from hapstab.errors import AnalysisError
    T = params["period_s"]
    groups = []
    for p in params["ports"]:
        M = p["mass_kg"] + p["termination_mass_kg"]
        groups += [(p["damping_N_s_per_m"] + p["termination_damping_N_s_per_m"]) * T / M,
                   p["termination_stiffness_N_per_m"] * T * T / M]
        groups += [abs(c["damping_N_s_per_m"]) * T / M for c in params["channels"]]
    # all zero (no damping, no termination spring): no group sets a small K scale, the
    # loop is m/T^2's alone like any undamped one (K_0 from k_scale), not a heavy device
    if 0.0 < max(groups) < HEAVY:
        masses = ", ".join(f"{p['mass_kg']:g}" for p in params["ports"])
        raise AnalysisError(f"mass = {masses} kg at T = {T:g} s: the loop's dimensionless "
                            f"groups b T/m, |B| T/m, k T^2/m are all below {HEAVY:g} "
                            f"(largest {max(groups):.3g}), so every pole crowds z = 1 closer "
                            "than the certified core resolves; a lighter device, more damping "
                            "or a longer period is within range")


def _unstable(al: Any, params: dict, k0: float, k_top: float, base: Any) -> Any:
    from hapstab.analysis.exact.proof import Exclusion, Gap, Proof
    return Proof(params, k0, [], [Gap(k0, k0, True, base.outside, Exclusion(), base)], [],
                 0.0, math.inf, [], math.nan, al.prec, k_top, base.outside)


def _from_proof(ss: StableSet, pr: Any) -> StableSet:
    """The StableSet of a proof: intervals (the first from K -> 0+ reported from 0),
    K_max the safe end, the base count, the uncertain ranges."""
    base = pr.base_outside
    intervals = [(0.0 if a == pr.k0 else a, math.inf if b >= pr.k_top and pr.tail_proved else b)
                 for a, b in pr.intervals]
    unc = list(pr.uncertain)
    if base is None:
        unc.insert(0, (0.0, pr.k0))
    kmax = pr.kmax
    return dataclasses.replace(ss, kmax=float(kmax), intervals=tuple(intervals),
                               theta=float(pr.theta) if np.isfinite(pr.theta) else math.nan,
                               outside_small_K=-1 if base is None else int(base),
                               uncertain=tuple(sorted(set(unc))), proof=pr)
