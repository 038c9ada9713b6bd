"""Exact stability and exact critical stiffness of the sampled-data loop.

``exact_critical_stiffness(loop)`` finds every K at which a pole reaches |z| = 1
(:mod:`~hapstab.analysis.exact.crossings`: certified branch and prune on the loop's
characteristic function with the delays as exact phases,
:mod:`~hapstab.engine.frequency`) and the stable
set in K. ``stability(loop)`` counts the poles outside the circle by the argument
principle, certified the same way (with a fraction of a sample of delay: by isolating the
characteristic polynomial's roots in balls, :mod:`hapstab.engine.arb_fraction`), and
reports the dominant pole (eigenvalues of
the closed-loop matrix, polished on the characteristic function). Rigid-body modes
(poles at z = 1 that no K moves) are divided out exactly and reported as marginal,
never as unstable.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hapstab import budget
from hapstab.analysis.exact.crossings import analyse, winding
from hapstab.analysis.exact.stable_set import StableSet
from hapstab.engine.frequency import LoopResponse, loop_response
from hapstab.engine.structure import channel_ratios, structure_of
from hapstab.engine.system import build
from hapstab.errors import AnalysisError, check_flag
from hapstab.models.loops import HapticLoop, TeleoperationLoop, describe
from hapstab.models.parts import friction_note
from hapstab.results import CriticalStiffnessResult, StabilityResult
from hapstab.tolerances import NEWTON_ANGLE_STEP, POLE_ON_CIRCLE

__all__ = ["stability", "exact_critical_stiffness", "exact_kmax_batch",
           "critical_stiffness_result"]

#: A polished dominant pole with ||z| - 1| below this is on the circle
#: (:data:`hapstab.tolerances.POLE_ON_CIRCLE`, with its reason).
MARGINAL_TOL = POLE_ON_CIRCLE


def exact_kmax_batch(loop: HapticLoop | TeleoperationLoop,
                     periods: Sequence[float] | np.ndarray | None = None,
                     intervals: bool = True, certify: bool = True) -> list[StableSet]:
    """Exact K_max (and the stable set in K) of ``loop`` at each sampling period.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controllers; K is the (master's) stiffness, K_s/K_m kept.
    periods : array of float, optional
        Sampling periods (s); default the loop's own.
    intervals : bool
        Every stable interval (True) or only K_max (False, faster).
    certify : bool
        Re-prove each answer in ball arithmetic (default True; False: the float search
        alone, see :func:`exact_critical_stiffness`).

    Returns
    -------
    list of StableSet
        One per period (see :func:`hapstab.analysis.exact.crossings.analyse`).
    """
    certify = check_flag("certify", certify)
    resp = loop_response(loop, periods)
    from hapstab.budget import check, exact_search_cost

    # a long delay's cost grows with the phase's power: refused up front, by name
    check(exact_search_cost(resp.phase_rate, len(resp.ports), len(resp.scale)))
    if not certify:     # the float search cannot resolve a heavy device either: 0 came out
        from hapstab.analysis.exact.proved import refuse_heavy
        for params in resp.params or ():
            if params is not None:
                refuse_heavy(params)
    try:
        return analyse(resp, full=intervals, proof=certify)
    except AnalysisError as e:       # the core gave up: say for which loop
        raise AnalysisError(f"{e}; the loop: {describe(loop)}") from None


# ---------------------------------------------------------------------- stability
def _spring_dampers(loop: HapticLoop | TeleoperationLoop) -> bool:
    """Whether the loop's K can be varied (the exact core's characteristic function
    then applies): spring-damper position controllers and a defined K rule."""
    return channel_ratios(structure_of(loop)) is not None


def _polish_pole(resp: LoopResponse, u: float, z0: complex) -> complex:
    """Newton's method on det M(z, K) = 0 (the exact characteristic function) from
    an eigenvalue z0 of the closed-loop matrix: eigenvalues of poles crowding z = 1
    lose accuracy, the characteristic function in y = z - 1 does not."""
    if z0 == 0:
        return z0
    from hapstab.analysis.exact.long_poles import det_and_slope
    th = np.array([-1j * np.log(z0)])
    for _ in range(30):
        f, df = det_and_slope(resp, u, th)     # the centres alone
        if not (np.isfinite(f[0]) and np.isfinite(df[0])) or df[0] == 0:
            return z0
        step = f[0] / df[0]
        th = th - step
        if abs(step) <= NEWTON_ANGLE_STEP * max(1.0, abs(th[0])):
            break
    z = complex(np.exp(1j * th[0]))
    # accept only a refinement of the same pole: z0 is off by rounding (~1e-8 at worst,
    # a double pole split by sqrt(eps)); a move beyond 1e-6 is a jump to another pole
    return z if abs(z - z0) <= 1e-6 * max(1.0, abs(z0)) else z0


def stability(loop: HapticLoop | TeleoperationLoop, *, max_memory: float | None = None,
              max_seconds: float | None = None, certify: bool = True) -> StabilityResult:
    """Exact stability of the sampled-data loop at its own parameters.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop

    max_memory, max_seconds : float, optional
        Budget in bytes and seconds (default :mod:`hapstab.budget`'s): the dense
        eigenvalue problem of the closed loop (N states, N^3 operations) is
        estimated first and refused above it -- except for a loop the certified count
        covers (whole-sample delays): above :data:`LONG_STATES` states, or over the
        budget, its dominant pole comes from Newton's method on the characteristic
        function near the circle (:mod:`~hapstab.analysis.exact.long_poles`), at a cost
        that hardly grows with the delay (10^5 samples in a few seconds).
    certify : bool
        Count the poles outside by the argument principle in ball arithmetic
        (python-flint Arb; :func:`~hapstab.analysis.exact.proof.count`), or with a
        fraction of a sample of delay by isolating the characteristic polynomial's roots
        in balls (:func:`~hapstab.engine.arb_fraction.fractional_count`), where the loop is
        covered (default True); the reason says which. False: the float enclosures alone, whose rounding
        allowances are not proved and are known to be short for stiff walls on light
        devices (k T^2 / m >> 1; issue 26).

    Returns
    -------
    StabilityResult
        ``stable`` if every closed-loop pole has |z| < 1, ``unstable`` if one has
        |z| > 1 (the count of poles outside comes from the argument principle,
        certified), ``marginal`` if a pole is on the circle to the model's accuracy
        (the count cannot be certified, or the dominant pole is within 1e-12 of the
        circle) or a rigid-body mode sits at z = 1. Of the friction-free loop: with a
        device's Coulomb friction its ``note`` says so
        (:func:`~hapstab.models.parts.friction_note`).

    References
    ----------
    Exact ZOH model of Fig. 2a / Fig. 3 with H(z) of eq. (23).
    """
    certify = check_flag("certify", certify)
    certified = _spring_dampers(loop)
    # the loops the certified count covers (whole-sample delays): past LONG_STATES, or
    # where the model or its eigenvalue problem is over the budget (a long delay), the
    # verdict is the count's and the dominant pole Newton's (_long_stability)
    resp0 = loop_response(loop) if certified and certify else None
    long = resp0 if resp0 is not None and resp0.params[0] is not None else None
    limits = (max_memory, max_seconds)
    tried = False               # Newton's search, run at most once
    try:
        sysm = build(loop)
        N = sysm.order
        if long is not None and N > LONG_STATES:
            tried, got = True, _long_stability(loop, long, limits)
            if got is not None:
                return got      # else: Newton missed a pole outside: the solver, if it may
        budget.check(budget.Cost(f"stability: the eigenvalues of a {N}-state closed loop",
                                 64.0 * N * N, budget.eig_seconds(N)), *limits)
    except budget.BudgetError:
        got = _long_stability(loop, long, limits) if long is not None and not tried else None
        if got is None:         # not covered, Newton tried already, or no pole found
            raise
        return got
    eigs = np.linalg.eigvals(sysm.closed_loop()[0])
    T = loop.period
    if certified:
        resp = resp0 if resp0 is not None else loop_response(loop)
        m = resp.rigid
        u = float(sysm.stiffness[0] / resp.scale[0])
        count, how = _certified_count(loop, resp, float(sysm.stiffness[0]), certify, eigs)
        if count is None:       # not covered by the ball-arithmetic core
            count = int(winding(resp, np.zeros(1, int), np.array([u]))[0])
            how = FLOAT_COUNT
    else:
        m = sysm.rigid_modes
        count, how = -2, ""
    rest = eigs
    if m:
        rest = eigs[np.argsort(np.abs(eigs - 1.0))[m:]]
    k = int(np.argmax(np.abs(rest))) if rest.size else 0
    dom = complex(rest[k]) if rest.size else complex(1.0)
    if certified:
        dom = _polish_pole(resp, u, dom)
    rho = abs(dom)
    freq = abs(math.atan2(dom.imag, dom.real)) / (2 * math.pi * T)
    verdict, reason = _verdict(count, rho, dom, T, m, how)
    if (verdict == "unstable" and count > 0 and rho <= 1) or (verdict == "stable" and rho >= 1):
        reason += (f" (the eigenvalue solver puts the largest pole at |z| = {rho:.12g}; with "
                   "poles crowding z = 1 it is less accurate than the certified count)")
    note = friction_note(loop)          # the linear loop: friction-free (said once)
    return StabilityResult(verdict, rho, dom, freq, reason, T, tuple(complex(e) for e in eigs), m,
                           note)


def _long_stability(loop: HapticLoop | TeleoperationLoop, resp: LoopResponse,
                    limits: tuple[float | None, float | None]) -> StabilityResult | None:
    """:func:`stability` of a loop of more than :data:`LONG_STATES` states, or whose
    closed-loop model or eigenvalue problem is over the budget: the verdict from the
    certified count (a cost that does not grow with the delay), the dominant pole from
    the poles near the circle found by Newton's method
    (:mod:`~hapstab.analysis.exact.long_poles`); None when Newton finds no pole, or fewer
    poles outside than the count: the eigenvalue problem then answers if the budget
    allows it, and is refused with its cost if not (never a radius the count
    contradicts). ``limits``: the caller's (max_memory, max_seconds), checked against
    the grid's cost."""
    from hapstab.analysis.exact.long_poles import CHUNK, grid_points, near_circle_poles
    pts = grid_points(resp)
    budget.check(budget.Cost(f"stability: the poles near the circle on {pts} angles",
                             700.0 * min(pts, CHUNK) + 16.0 * pts, 0.05 + NEWTON_SECONDS * pts),
                 *limits)
    st = structure_of(loop)
    K = float(st.channels[st.reference].controller.stiffness)   # type: ignore[union-attr]
    u = K / float(resp.scale[0])
    count = _proved_count(resp.params[0], K)
    found = near_circle_poles(resp, u)
    m = resp.rigid
    rest = found[np.abs(found - 1.0) > RIGID_NEAR] if m else found
    if not rest.size:
        return None
    dom = complex(rest[int(np.argmax(np.abs(rest)))])
    rho, T = abs(dom), loop.period
    freq = abs(math.atan2(dom.imag, dom.real)) / (2 * math.pi * T)
    out = np.abs(rest) > 1
    real = np.abs(rest.imag) <= REAL_POLE * np.abs(rest)   # listed once, no conjugate
    if count is not None and count > 2 * int(np.sum(out)) - int(np.sum(out & real)):
        return None     # a pole outside missed (or a multiple one found once): not answered
    verdict, reason = _verdict(-1 if count is None else count, rho, dom, T, m)
    reason += (f" (a closed loop of more than {LONG_STATES} states: the dominant pole is the "
               "largest of the poles Newton's method finds near the circle on the "
               "characteristic function, not an eigenvalue solver's")
    pairs = np.concatenate([found, np.conj(found[np.abs(found.imag) > REAL_POLE * np.abs(found)])])
    return StabilityResult(verdict, rho, dom, freq, reason + ")", T,
                           tuple(complex(p) for p in pairs), m, friction_note(loop))


#: Above this many states a loop the certified count covers is not handed to the dense
#: eigenvalue solver (~1.5 s at 1000 states, ~13 s at 2400, measured): the verdict is the
#: count's either way, and the dominant pole Newton's agrees with the solver's to ~1e-14
#: (tests/exact/test_long_poles.py)
LONG_STATES = 1000
#: Seconds per angle of the grid near_circle_poles evaluates, Newton included: PEB 10^5
#: samples each way, 3.2e6 angles on the unit circle, ~9 s; HVE 10^5, ~1.6e6, 1.2-3.3 s
#: (measured, session 12): 3e-6 is above both
NEWTON_SECONDS = 3e-6
#: A pole found with |Im z| below this share of |z| is real (Newton leaves ~1e-16 of an
#: imaginary part on a real pole; a pair's own is far above it): no conjugate is added
REAL_POLE = 1e-12
#: A pole found within this of z = 1 is a rigid-body mode's (divided out of the count;
#: the modes sit at z = 1 exactly, the other poles near it are ~(k T^2 / m)^(1/2) away)
RIGID_NEAR = 1e-6


#: How a count of poles outside is known (the verdict's reason says which).
ARGUMENT_PRINCIPLE = "certified by the argument principle"
ROOTS = "certified by isolating the characteristic polynomial's roots in ball arithmetic"
FLOAT_COUNT = ("by the argument principle on float enclosures, not proved in ball arithmetic "
               "for this loop's structure")


def _certified_count(loop: HapticLoop | TeleoperationLoop, resp: LoopResponse, K: float,
                     certify: bool, eigs: np.ndarray) -> tuple[int | None, str]:
    """(poles outside at K proved in ball arithmetic, -1 undecided, None not covered;
    how): whole delays by the argument principle on
    :class:`~hapstab.engine.arb_loop.ArbLoop`, delays with a fraction of a sample by
    isolating the roots of the characteristic polynomial
    (:mod:`hapstab.engine.arb_fraction`; the closed loop's eigenvalues ``eigs`` are its
    first guesses of them)."""
    if not certify:
        return None, ""
    if resp.params and resp.params[0] is not None:
        return _proved_count(resp.params[0], K), ARGUMENT_PRINCIPLE
    from hapstab.engine.arb_fraction import fractional_poles
    got = fractional_poles(loop, K, guess=eigs)
    return (None, "") if got is None else (got[0], ROOTS)


def _proved_count(params: dict | None, K: float) -> int | None:
    """Poles outside at K by the argument principle in ball arithmetic
    (:func:`~hapstab.analysis.exact.proof.count`) of the loop of ``params``
    (:func:`~hapstab.engine.arb_loop.arb_parameters`, as its response holds them): -1 if
    the balls cannot decide (a pole on or within their width of the circle); None if the
    loop is not covered (``params`` None)."""
    from hapstab.engine.arb_loop import ArbLoop
    if params is None:
        return None
    from hapstab.analysis.exact.proof import count
    got = count(ArbLoop(params), K).outside
    return -1 if got is None else int(got)


def _verdict(count: int, rho: float, dom: complex, T: float, m: int,
             how: str = ARGUMENT_PRINCIPLE) -> tuple[str, str]:
    """(verdict, reason) from the count of poles outside (-1: not certifiable, -2: not
    available), how it is known, and the dominant pole."""
    near = abs(rho - 1.0) <= MARGINAL_TOL
    if count == -1 or (count in (0, -2) and near and m == 0) or (count == -2 and near):
        return "marginal", (f"closed-loop pole on the unit circle to the model's accuracy "
                            f"({_describe(dom, T)}, |z| = {rho:.15g}): sustained oscillation or "
                            "drift; the count of poles outside cannot be certified")
    if count > 0 or (count == -2 and rho > 1 + MARGINAL_TOL):
        n = f"{count} closed-loop pole(s)" if count > 0 else "a closed-loop pole"
        reason = (f"{n} outside the unit circle ({how}); the "
                  f"largest at |z| = {rho:.10g} ({_describe(dom, T)}): the response grows")
        if count == -2:
            reason = (f"closed-loop pole at |z| = {rho:.10g} ({_describe(dom, T)}): the "
                      "response grows")
        if m:
            reason += f"; {m} rigid-body mode(s) at z = 1 excluded"
        return "unstable", reason
    if m:
        return "marginal", (f"{m} rigid-body mode(s) at z = 1: nothing ties the masses to ground, "
                            "so a constant offset persists; all other poles have |z| <= "
                            f"{rho:.6g} < 1")
    return "stable", (f"all closed-loop poles inside the unit circle (largest |z| = {rho:.10g}"
                      + (f"; none outside, {how})" if count == 0
                         else ")"))


def _describe(z: complex, T: float) -> str:
    th = abs(math.atan2(z.imag, z.real))
    if th < 1e-12:  # a real pole's angle is 0 to rounding (this only words the reason)
        return "real pole at z = +1 side (non-oscillatory)"
    if abs(th - math.pi) < 1e-9:  # pi to rounding (looser than at 0; only words it)
        return f"real pole at z = -1 side (oscillation at the Nyquist frequency {1 / (2 * T):.6g} Hz)"
    return f"complex pair, oscillation at {th / (2 * math.pi * T):.6g} Hz"


def exact_critical_stiffness(loop: HapticLoop | TeleoperationLoop, *,
                             certify: bool = True) -> CriticalStiffnessResult:
    """Exact K_max of the sampled-data loop (see the module docstring).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controller(s); B, T, n and impedances fixed. For
        teleoperation, K is the master's stiffness and K_s/K_m is kept.
    certify : bool
        Re-prove the stable set in ball arithmetic (python-flint Arb;
        :mod:`~hapstab.analysis.exact.proved`): K_max is then the safe end of a proved
        enclosure, never above the truth, and ``certificate`` holds the proof
        (:func:`~hapstab.analysis.verify.verify_certificate`). Default True. False: the
        float search alone (1.2-2.5x faster), whose rounding allowances are not proved
        (known to put K_max up to ~2e-5 relative too high for stiff walls on light
        devices, k T^2 / m >> 1; issue 26).

    Returns
    -------
    CriticalStiffnessResult
        ``method="exact"``; ``stable_intervals`` lists the stable intervals, each
        proved (that none is missing above K_max rests on the crossings proposed:
        :mod:`~hapstab.analysis.exact.candidates`).

    Raises
    ------
    AnalysisError
        If the controller is not a spring-damper.
    """
    res = exact_kmax_batch(loop, certify=certify)[0]
    return critical_stiffness_result(res, loop.period, loop.delay_in_samples)


def _zero_reason(res: StableSet) -> str:
    """Why K_max is 0: marginal, undecided above K -> 0+, or unstable there."""
    later = [iv for iv in res.intervals if iv[1] > iv[0] > 0]
    spans = ", ".join(f"[{a:.10g}, {b:.10g}]" for a, b in later)
    if res.outside_small_K < 0 and later:
        return ("marginal for K -> 0+: a pole is on the unit circle to the model's accuracy "
                f"(e.g. an undamped termination), so K_max = 0; stable for K in {spans} N/m")
    if res.outside_small_K < 0:
        return ("marginal for K -> 0+: a pole is on the unit circle to the model's accuracy "
                "(e.g. an undamped termination), so no K > 0 can be certified stable")
    if res.outside_small_K == 0 and res.uncertain:
        # no pole outside at K_0, but the range above it not decided: uncertain, not unstable
        return ("not proved stable for any K > 0: no closed-loop pole lies outside the unit "
                "circle as K -> 0+, but the range above could not be decided")
    if later:
        # K_max is 0 (not stable on (0, K] for any K), yet stable windows higher up
        return (f"unstable as K -> 0+ ({res.outside_small_K} closed-loop pole(s) outside the "
                f"unit circle), so K_max = 0; stable for K in {spans} N/m")
    return (f"unstable for every K > 0: already as K -> 0+, {res.outside_small_K} "
            "closed-loop pole(s) lie outside the unit circle (the virtual damping, delay "
            "and terminations alone destabilise the loop)")


def critical_stiffness_result(res: StableSet, T: float, n: int | float
                              ) -> CriticalStiffnessResult:
    """The exact analysis's answer for one loop, from its stable set.

    Parameters
    ----------
    res : StableSet
        The loop's stable set in K (with its ball proof, if any).
    T : float
        The sampling period (s): the crossing's frequency is theta / (2 pi T).
    n : int or float
        The delay in samples, reported as given.

    Returns
    -------
    CriticalStiffnessResult
        K_max, the stable intervals, the reason in words and the details (rigid-body
        modes, uncertain intervals, the proof and its certificate when there is one).
    """
    kmax, th = res.kmax, res.theta
    freq = th / (2 * math.pi * T) if np.isfinite(th) else math.nan
    if kmax == 0.0:
        reason = _zero_reason(res)
    elif math.isinf(kmax):
        reason = "stable for every K > 0 (no closed-loop pole reaches the unit circle)"
    elif not np.isfinite(th):
        reason = "no closed-loop pole reaches the unit circle up to K_max"
    elif th == 0.0:
        reason = "a real closed-loop pole crosses z = +1 at K_max (static divergence)"
    elif th == math.pi:
        reason = (f"a real closed-loop pole crosses z = -1 at K_max (oscillation at the "
                  f"Nyquist frequency, {1 / (2 * T):.6g} Hz)")
    else:
        reason = f"a complex pole pair crosses |z| = 1 at K_max, oscillating at {freq:.6g} Hz"
    if len(res.intervals) > 1:
        reason += f"; the stable set in K is not one interval ({len(res.intervals)} intervals)"
    if res.rigid:
        reason += f"; {res.rigid} rigid-body mode(s) at z = 1 (marginal, K-independent) divided out"
    near = [iv for iv in res.uncertain if math.isfinite(iv[1])]
    above = [a for a, b in res.uncertain if not math.isfinite(b)]
    if above:
        reason += (f"; not proved above K = {above[0]:.8g} N/m (the top of the range examined "
                   "in ball arithmetic; no pole on the unit circle up to there)"
                   + (": K_max is that top, the safe side" if kmax == above[0] else ""))
    if near:
        spans = ", ".join(f"[{a:.8g}, {b:.8g}]" for a, b in near)
        at = any(a == kmax for a, _ in near)
        reason += (f"; marginal within K in {spans}: a pole is within rounding of the unit "
                   "circle there, so the numerics cannot decide"
                   + (" (K_max is its lower end, the safe side)" if at else ""))
    details: dict = {"rigid_body_modes": res.rigid,
                     "uncertain_intervals": [list(iv) for iv in res.uncertain]}
    pr = res.proof
    if pr is not None:
        details["proof"] = "ball arithmetic (python-flint Arb)"
        details["kmax_enclosure"] = [kmax, pr.kmax_hi if kmax > 0 or pr.kmax_hi < math.inf
                                     else math.inf]
        details["base_point_N_per_m"] = pr.k0
        # what the balls proved: [K_0, K_max], K_0 standing for K -> 0+ (upper end
        # inf only when the tail above the examined range is proved, top.py)
        details["proved_range_N_per_m"] = [pr.k0, kmax]
        if kmax > 0:
            reason += (f"; proved stable for K in [K_0, K_max] = [{pr.k0:.6g}, {kmax:.10g}] N/m in "
                       "ball arithmetic, K_0 standing for K -> 0+ ((0, K_0) is not proved)")
        reason += _others_proved(len(res.intervals) - (1 if kmax > 0 else 0), kmax > 0)
    else:
        details["proof"] = "float enclosures (not re-proved in ball arithmetic)"
    cert = None
    # a certificate of something: a stable range, or poles outside at K_0 (not of a
    # K_max = 0 the balls could not decide, e.g. an undamped loop, marginal at K -> 0+)
    if pr is not None and (kmax > 0 or (pr.base_outside or 0) > 0):
        from hapstab.analysis.exact.certificate import certificate
        cert = certificate(pr)
    return CriticalStiffnessResult(kmax, "exact", res.intervals, reason, T, n, freq, details,
                                   certificate=cert)


def _others_proved(more: int, after_kmax: bool) -> str:
    """The reason's words for the stable intervals besides [K_0, K_max]: each is proved
    as that one is (:mod:`~hapstab.analysis.exact.proof`, step 4)."""
    if more <= 0:
        return ""
    what = (("the other stable interval" if more == 1 else f"the other {more} stable intervals")
            if after_kmax else ("the stable interval" if more == 1
                                else f"the {more} stable intervals"))
    return f"; {what}, above {'K_max' if after_kmax else 'K = 0'}, proved in ball arithmetic too"
