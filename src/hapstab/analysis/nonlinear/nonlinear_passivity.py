"""Passivity of the sampled virtual wall with Coulomb friction and encoder quantisation
(Abbott and Okamura 2005), beside the linear Colgate-Schenkel condition.

The model (Abbott and Okamura's): a 1-DOF device of mass m with viscous damping b and
Coulomb friction f_c, held by a hand that may do anything (no assumption on it), one
encoder of resolution Δ (the controller reads a multiple of Δ: ``Δ floor(x/Δ)`` or the
nearest multiple), sampled every T with no delay, and a virtual spring
``u_k = -K x̃_k`` held by a zero-order hold. Its device side is passive if and only if

    b >= K T / 2    and    f_c >= K Δ / 2,    i.e.  K <= min(2 b / T, 2 f_c / Δ).

The two conditions are decoupled: the first is Colgate and Schenkel's (large, fast
motions, where the sampled spring's energy error ~ K δ²/2 per sample must be taken by
the damper's b δ²/T), the second is quantisation's (small motions across one encoder
line, where each crossing sensed late gives K Δ times the overshoot while friction takes
f_c per unit of path, 2 units per overshoot and return). Viscous damping does not help
the second (it dissipates δ², and δ may be as small as one likes), friction does not help
the first (f_c δ is outgrown by K δ²). Why it is the exact condition, in short: with the
staircase potential V(x) = ∫_0^x K x̃ ds as storage, the energy a sample can create is
at most K (δ²/2 + Δ |δ|/2) for a displacement δ, against at least b δ²/T + f_c |δ|
dissipated (sufficiency); a back-and-forth across one line and a fast two-sample
oscillation break each condition as soon as it fails (necessity; both constructions are
tests, ``tests/nonlinear/test_nonlinear_passivity.py``, which measure the energy on the
trajectories themselves). The condition is the same for a floor and a nearest encoder:
every reading jumps by Δ at a line either way.

Where it is applied: a :class:`~hapstab.models.HapticLoop` with a
:class:`~hapstab.models.SpringDamper`; with Δ > 0 only for B = 0 and no delay
(the paper's assumptions; anything else is refused, one line). With Δ = 0 the limit
is the exact linear passivity limit for *any* delay and B, whatever f_c: friction only
dissipates (so linear passivity suffices), and a motion scaled up by λ makes the
sampled controller's energy grow as λ² against friction's λ (so it is also necessary).
That is the friction-free, quantisation-free limit equal to today's
:func:`~hapstab.analysis.conditions.passivity.critical_stiffness_passivity`, exactly (the same call).

References
----------
J. J. Abbott and A. M. Okamura, "Effects of position quantization and sampling rate on
virtual-wall passivity", IEEE Trans. Robotics 21(5):952-964, 2005 (the condition; its
text was not retrievable here, so the statement above is re-derived and checked by the
tests' energy constructions, not copied from its figures). J. E. Colgate and G. G.
Schenkel, "Passivity of a class of sampled-data systems: application to haptic
interfaces", J. Robotic Systems 14(1), 1997 (b > KT/2 + |B|). N. Diolaiti, G. Niemeyer,
F. Barbagli and J. K. Salisbury, "Stability of haptic rendering: discretization,
quantization, time delay, and Coulomb effects", IEEE Trans. Robotics 22(2), 2006 (devices
that violate the quantisation condition are still stable: see
:mod:`hapstab.analysis.nonlinear.limit_cycles`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from hapstab.analysis.conditions.passivity import critical_stiffness_passivity, sampled_passivity
from hapstab.errors import AnalysisError, check_real
from hapstab.models.loops import HapticLoop, require_loop
from hapstab.results import CriticalStiffnessResult, Result, jsonable

__all__ = ["coulomb_friction_of", "resolution_of", "abbott_okamura", "nonlinear_passivity",
           "NonlinearPassivityResult"]


def coulomb_friction_of(loop: Any, coulomb_friction_N: Any = None) -> float:
    """The Coulomb friction level an analysis uses: ``coulomb_friction_N`` if given, else
    the device's ``coulomb_friction`` (0 for a device without one).

    Parameters
    ----------
    loop : HapticLoop
        The loop (its ``device``).
    coulomb_friction_N : float, optional
        f_c in N, >= 0.

    Returns
    -------
    float

    Raises
    ------
    ModelError
        A negative, non-finite or non-numeric value.
    """
    if coulomb_friction_N is None:
        return float(getattr(getattr(loop, "device", None), "coulomb_friction", 0.0))
    return check_real("coulomb_friction_N", coulomb_friction_N, nonnegative=True)


def resolution_of(resolution_m: Any) -> float:
    """The encoder resolution Δ in m (0 for ``None``: no quantisation).

    Parameters
    ----------
    resolution_m : float or None
        Δ in m, >= 0.

    Returns
    -------
    float

    Raises
    ------
    ModelError
        A negative, non-finite or non-numeric value.
    """
    return 0.0 if resolution_m is None else check_real("resolution_m", resolution_m,
                                                       nonnegative=True)


def _haptic(loop: Any, what: str) -> HapticLoop:
    require_loop(loop)
    if len(loop.port_names) != 1:                # one device: the haptic loop
        raise AnalysisError(f"{what}: derived for the haptic loop (hve: one device and a virtual "
                            f"environment), not a {loop.kind} loop")
    if not loop.controller.admits("eq23"):
        raise AnalysisError(f"{what}: derived for a spring-damper virtual environment "
                            "(SpringDamper), not a general H(z)")
    return loop


def _quantised_assumptions(loop: HapticLoop, delta: float) -> None:
    """Refuse what Abbott and Okamura's condition is not derived for, once Δ > 0."""
    B, n = loop.controller.damping, loop.delay_in_samples   # type: ignore[union-attr]
    if B != 0 or n != 0:
        raise AnalysisError(
            f"resolution_m = {delta:g}: the Abbott-Okamura condition is derived for a virtual "
            f"spring (B = 0) without delay; this loop has B = {B:g} N*s/m and a delay of "
            f"{n:g} samples; allowed with quantisation: B = 0 and no delay (or resolution_m = 0)")


def abbott_okamura(loop: HapticLoop, *, coulomb_friction_N: float | None = None,
                   resolution_m: float | None = None) -> CriticalStiffnessResult:
    """Largest passive K with Coulomb friction and encoder quantisation (see the module).

    ``K_max = min(2 b/T, 2 f_c/Δ)`` for Δ > 0 (B = 0, no delay); for Δ = 0 the exact
    linear passivity limit (:func:`~hapstab.analysis.conditions.passivity.critical_stiffness_passivity`,
    any delay and B), whatever f_c.

    Parameters
    ----------
    loop : HapticLoop
        With a :class:`~hapstab.models.SpringDamper` (its own stiffness is ignored).
    coulomb_friction_N : float, optional
        f_c in N; default the device's ``coulomb_friction`` (0 if it has none).
    resolution_m : float, optional
        Encoder resolution Δ in m; default 0 (none).

    Returns
    -------
    CriticalStiffnessResult
        ``method = "abbott-okamura"``; ``details`` has ``coulomb_friction_N``,
        ``resolution_m``, ``sampling_limit`` (2b/T, N/m), ``quantization_limit``
        (2 f_c/Δ, N/m; inf without quantisation) and ``binding``.

    Raises
    ------
    AnalysisError
        Not a haptic loop with a SpringDamper; with Δ > 0, B != 0 or a delay.

    References
    ----------
    Abbott and Okamura 2005; Colgate and Schenkel 1997.
    """
    loop = _haptic(loop, "abbott-okamura")
    fc, delta = coulomb_friction_of(loop, coulomb_friction_N), resolution_of(resolution_m)
    if delta == 0:
        lin = critical_stiffness_passivity(loop)
        reason = ("no quantisation (resolution 0): the exact linear sampled-data passivity limit "
                  f"(Colgate-Schenkel), which Coulomb friction (f_c = {fc:g} N) does not change: "
                  "friction only dissipates, and a motion scaled up by l makes the sampled "
                  "controller's energy grow as l^2 against friction's l")
        details = {**lin.details, "coulomb_friction_N": fc, "resolution_m": 0.0,
                   "sampling_limit": lin.critical_stiffness, "quantization_limit": math.inf,
                   "binding": "sampling"}
        return CriticalStiffnessResult(lin.critical_stiffness, "abbott-okamura",
                                       lin.stable_intervals, reason, lin.period,
                                       lin.delay_samples, lin.crossing_frequency_hz, details)
    _quantised_assumptions(loop, delta)
    b, T = loop.device.damping, loop.period
    k_s, k_q = 2.0 * b / T, 2.0 * fc / delta
    K = min(k_s, k_q)
    binding = "sampling" if k_s <= k_q else "quantization"
    reason = (f"Abbott-Okamura: passive iff b >= KT/2 and f_c >= K*Delta/2, i.e. K <= "
              f"min(2b/T = {k_s:.6g}, 2 f_c/Delta = {k_q:.6g}) N/m; "
              + ("sampling binds (Colgate-Schenkel)" if binding == "sampling" else
                 "quantisation binds: friction does not cover the energy an encoder line "
                 "sensed late gives" + (" (no friction: no K > 0 is passive)" if fc == 0 else "")))
    details = {"coulomb_friction_N": fc, "resolution_m": delta, "sampling_limit": k_s,
               "quantization_limit": k_q, "binding": binding}
    return CriticalStiffnessResult(K, "abbott-okamura", ((0.0, K),) if K > 0 else (), reason, T,
                                   0, math.nan, details)


@dataclass(frozen=True)
class NonlinearPassivityResult(Result):
    """Passivity of the device side at one K with friction and quantisation.

    Parameters
    ----------
    passive : bool
        Both conditions hold.
    stiffness : float
        K in N/m.
    critical_stiffness : float
        The Abbott-Okamura limit (N/m), :func:`abbott_okamura`.
    margin : float
        The linear (Colgate-Schenkel) damping margin at K in N*s/m (negative: missing).
    quantization_margin_N : float
        ``f_c - K Δ/2`` in N (negative: friction missing); inf without quantisation.
    worst_frequency_hz : float
        Where the linear margin is least.
    failed_condition : str or None
        ``"colgate-schenkel"``, ``"abbott-okamura"`` (quantisation), both joined by
        ``"+"``, or None.
    coulomb_friction_N, resolution_m : float
        f_c (N) and Δ (m) used.
    reason : str
        The verdict in words.
    period : float
        T in s.
    """

    passive: bool
    stiffness: float
    critical_stiffness: float
    margin: float
    quantization_margin_N: float
    worst_frequency_hz: float
    failed_condition: str | None
    coulomb_friction_N: float
    resolution_m: float
    reason: str
    period: float

    @property
    def verdict(self) -> str:
        return "passive" if self.passive else "not passive"

    @property
    def worst_frequency_rad_s(self) -> float:
        return 2 * math.pi * self.worst_frequency_hz

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"verdict": self.verdict, "passive": self.passive,
                         "margin": self.margin, "worst_frequency_hz": self.worst_frequency_hz,
                         "worst_frequency_rad_s": self.worst_frequency_rad_s,
                         "failed_condition": self.failed_condition, "reason": self.reason,
                         "period_s": self.period, "nonlinear": {
                             "condition": "abbott-okamura",
                             "coulomb_friction_N": self.coulomb_friction_N,
                             "resolution_m": self.resolution_m,
                             "critical_stiffness": self.critical_stiffness,
                             "quantization_margin_N": self.quantization_margin_N}})


def nonlinear_passivity(loop: HapticLoop, *, coulomb_friction_N: float | None = None,
                        resolution_m: float | None = None) -> NonlinearPassivityResult:
    """Is the device side passive at the loop's K, with friction f_c and quantisation Δ?

    Both conditions: the exact Colgate-Schenkel test
    (:func:`~hapstab.analysis.conditions.passivity.sampled_passivity`) and, with Δ > 0,
    ``f_c >= K Δ/2`` (Abbott and Okamura; B = 0 and no delay then).

    Parameters
    ----------
    loop : HapticLoop
        With a :class:`~hapstab.models.SpringDamper` at the stiffness to test.
    coulomb_friction_N : float, optional
        f_c in N; default the device's ``coulomb_friction``.
    resolution_m : float, optional
        Δ in m; default 0.

    Returns
    -------
    NonlinearPassivityResult

    Raises
    ------
    AnalysisError
        As :func:`abbott_okamura`.

    References
    ----------
    Abbott and Okamura 2005; Colgate and Schenkel 1997.
    """
    limit = abbott_okamura(loop, coulomb_friction_N=coulomb_friction_N,
                           resolution_m=resolution_m)
    lin = sampled_passivity(loop)
    K = loop.controller.stiffness                     # type: ignore[union-attr]
    fc, delta = limit.details["coulomb_friction_N"], limit.details["resolution_m"]
    q_margin = fc - K * delta / 2 if delta > 0 else math.inf
    failed = [c for c, ok in (("colgate-schenkel", lin.passive),
                              ("abbott-okamura", q_margin >= 0)) if not ok]
    words = lin.reason
    if delta > 0:
        words += (f"; quantisation (Abbott-Okamura): f_c - K*Delta/2 = {q_margin:.6g} N"
                  + (" >= 0" if q_margin >= 0 else " < 0: an encoder line sensed late gives "
                     "more energy than friction takes"))
    return NonlinearPassivityResult(not failed, float(K), limit.critical_stiffness, lin.margin,
                                    q_margin, lin.worst_frequency_hz, "+".join(failed) or None,
                                    fc, delta, words, loop.period)
