"""The closed-form stability conditions of the paper and of the works it cites.

Each function returns a :class:`~hapstab.results.CriticalStiffnessResult` whose
``critical_stiffness`` is the K at which the condition stops holding. They are
sufficient conditions (or approximations) with stated assumptions; the docstrings
say where each is known to fail. :func:`hapstab.audit` compares them with the
exact analysis.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

from hapstab.errors import AnalysisError
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.results import CriticalStiffnessResult

__all__ = ["colgate", "gil", "eq18", "eq29", "eq34", "gil2004", "CLOSED_FORMS", "TABLE",
           "ClosedForm", "PAPER", "EQUATION", "G_INVERSE", "closed_forms_for", "paper_condition"]


def _hve(loop, name: str) -> tuple[float, float, float, float]:
    """(b, B, T, t_d/T); t_d may be any delay, the formulas only use t_d."""
    if getattr(loop, "kind", None) != "hve":
        raise AnalysisError(f"method = {name!r}: applies to a HapticLoop (hve), not {type(loop).__name__}")
    loop = cast(HapticLoop, loop)
    gains = loop.controller.gains() if loop.controller.admits("eq23") else None
    if gains is None:
        raise AnalysisError(f"method = {name!r}: needs a SpringDamper virtual environment")
    return loop.device.damping, gains[1], loop.period, loop.delay_in_samples


def _peb(loop, name: str) -> tuple[float, float, float, float]:
    if getattr(loop, "kind", None) != "peb":
        raise AnalysisError(f"method = {name!r}: applies to a TeleoperationLoop (peb), "
                            f"not {type(loop).__name__}")
    loop = cast(TeleoperationLoop, loop)
    cm, cs = loop.master_controller, loop.slave_controller
    eq23 = cm.admits("eq23") and cs.admits("eq23")
    gm, gs = (cm.gains(), cs.gains()) if eq23 else (None, None)
    if gm is None or gs is None:
        raise AnalysisError(f"method = {name!r}: needs SpringDamper controllers")
    if gm != gs:
        raise AnalysisError(f"method = {name!r}: derived for C_m = C_s (equal K and B)")
    if not loop.symmetric_delay:
        raise AnalysisError(f"method = {name!r}: derived for equal delays in both directions")
    if loop.scaled:
        raise AnalysisError(f"method = {name!r}: derived without scaling (position_scale = "
                            f"{loop.position_scale:g}, force_scale = {loop.force_scale:g}; "
                            "both must be 1)")
    b = min(loop.master.damping, loop.slave.damping)
    return b, gm[1], loop.period, loop.delay_in_samples


def _result(K: float, method: str, reason: str, loop,
            need: tuple[float, str, float] | None = None) -> CriticalStiffnessResult:
    """``need = (b, label, value)``: when K <= 0, say that b does not exceed ``label``."""
    if not K > 0 and need is not None:
        b, label, value = need
        reason += (f"; no K > 0 satisfies it: b = {b:g} N*s/m does not exceed {label} = "
                   f"{value:g} N*s/m")
    K = max(0.0, K)
    return CriticalStiffnessResult(K, method, ((0.0, K),) if K > 0 else (), reason,
                                   loop.period, loop.delay_in_samples)


def colgate(loop: HapticLoop) -> CriticalStiffnessResult:
    """Colgate-Schenkel passivity condition, eq. (1) / (13): ``b > KT/2 + |B|``.

    Necessary and sufficient for passivity of the non-delayed sampled-data HVE
    (device damping b only; the operator is only assumed passive). The paper
    re-derives it as (13) with the forward-difference approximation. With delay
    (n >= 1) it is not a stability condition at all: it ignores the delay and
    over-promises; see :func:`eq18`.

    Negative virtual damping B < 0 enters through |B|, as eq. (1) has it: the
    passivity margin is ``b - KT/2 + B cos(wT)``, whose worst case is cos(wT) = -1
    for B > 0 and cos(wT) = +1 for B < 0, so ``K_max = 2 (b - |B|)/T`` either way
    (the paper's (13) writes ``+ B`` with B >= 0 in mind). ``|B| >= b`` gives
    K_max = 0 with the reason.

    Parameters
    ----------
    loop : HapticLoop
        With a :class:`~hapstab.models.SpringDamper` controller (its own stiffness is
        ignored: the result is a K_max); device damping b in N*s/m, period T in s.

    Returns
    -------
    CriticalStiffnessResult
        K_max in N/m, ``method = "colgate"``.

    References
    ----------
    Colgate & Schenkel 1997; the paper, eq. (1) and (13).
    """
    b, B, T, n = _hve(loop, "colgate")
    K = 2 * (b - abs(B)) / T
    note = "" if n == 0 else f"; derived without delay, here n = {n} (not valid)"
    return _result(K, "colgate", f"eq. (1)/(13) Colgate-Schenkel: b > KT/2 + |B|{note}", loop,
                   (b, "|B|", abs(B)))


def gil(loop: HapticLoop) -> CriticalStiffnessResult:
    """Gil et al.'s delayed condition, eq. (2): ``K < (B + b) / (T/2 + t_d)``.

    From a Routh-Hurwitz analysis of the delayed HVE; valid only for small
    virtual damping B (for large B the true boundary bends away from this line).
    Identical in form to the paper's eq. (18).

    B < 0 is used as written: ``K < (b - |B|)/(T/2 + t_d)`` (negative virtual
    damping subtracts from the device's). For B <= 0 the line is exactly the
    sampled-data passivity limit (see :func:`eq18`), so it is a sufficient
    stability bound with a passive operator; ``b + B <= 0`` gives K_max = 0.

    Parameters
    ----------
    loop : HapticLoop
        With a :class:`~hapstab.models.SpringDamper` controller (its own stiffness is
        ignored: the result is a K_max); device damping b in N*s/m, period T in s.

    Returns
    -------
    CriticalStiffnessResult
        K_max in N/m, ``method = "gil"``.

    References
    ----------
    Gil, Sanchez, Hulin, Preusche, Hirzinger 2013 (the paper's [6]); the paper, eq. (2).
    """
    b, B, T, n = _hve(loop, "gil")
    K = (B + b) / (T / 2 + n * T)
    return _result(K, "gil", "eq. (2) Gil et al.: K < (B + b)/(T/2 + t_d), valid for small B"
                   + _positive_b(B), loop, (b, "-B", -B))


def eq18(loop: HapticLoop) -> CriticalStiffnessResult:
    """The paper's delayed HVE condition, eq. (18): ``b + B > KT/2 + K t_d``.

    From the forward-difference circle criterion, eq. (15)-(17), assuming the
    worst case occurs at cos(wT) = 1 — true for B small; for larger B > 0 with
    delay it is not the worst case, and the line can promise unstable stiffnesses.

    For B <= 0 the assumption is exact: the real part (16) is
    ``b + B cos((n+1)wT) - (KT/2) D_n(wT)`` with the Dirichlet kernel
    ``D_n(x) = sin((n + 1/2)x)/sin(x/2) <= 2n + 1``, and both terms are smallest at
    w -> 0 when B <= 0. So for negative B, (18) reads ``K < (b - |B|)/(T/2 + t_d)``
    and *is* the exact sampled-data passivity limit (:mod:`hapstab.analysis.conditions.passivity`), a
    sufficient stability bound with a passive operator; ``b + B <= 0`` gives
    K_max = 0. At n = 0 it reduces to (1)/(13) for B <= 0 only; for B > 0 it
    gives 2(b + B)/T, above (1)'s 2(b - B)/T.

    Parameters
    ----------
    loop : HapticLoop
        With a :class:`~hapstab.models.SpringDamper` controller (its own stiffness is
        ignored: the result is a K_max); device damping b in N*s/m, period T in s.

    Returns
    -------
    CriticalStiffnessResult
        K_max in N/m, ``method = "eq18"``.
    """
    b, B, T, n = _hve(loop, "eq18")
    K = (b + B) / (T / 2 + n * T)
    return _result(K, "eq18", "eq. (18): b + B > KT/2 + K t_d (forward difference, B small)"
                   + _positive_b(B), loop, (b, "-B", -B))


def _positive_b(B: float) -> str:
    """What eq. (2) / (18)'s line is for virtual damping B > 0: not a bound."""
    if not B > 0:
        return ""
    # measured, a seeded check of 300 HVE loops with B up to 10 N*s/m: up to 7.8x the
    # exact K_max, and (0, K] claimed where no K > 0 is stable (tests/conditions)
    return (f"; here B = {B:g} N*s/m > 0: not a bound (its worst case is then not at "
            "cos(wT) = 1), the exact K_max may be several times lower")


def eq29(loop: TeleoperationLoop) -> CriticalStiffnessResult:
    """The paper's non-delayed PEB condition, eq. (29): ``b > KT + 2|B|``, b = min(b_m, b_s).

    Sufficient condition for C_m = C_s from the circle criterion on eq. (24),
    taking the worst case of cos(wT) in (26) and (28). Derived for n = 0.

    The paper writes ``2B`` with B >= 0 in mind; the worst case of
    ``KT/2 - B cos(wT)`` in (28) is ``KT/2 + |B|`` (cos(wT) = -1 for B > 0, +1 for
    B < 0), so negative virtual damping enters through |B|:
    ``K_max = (b - 2|B|)/T``, 0 when ``2|B| >= b``. With b_m = b_s this is the exact
    two-port sampled-data passivity limit for either sign of B.

    Parameters
    ----------
    loop : TeleoperationLoop
        With equal :class:`~hapstab.models.SpringDamper` controllers C_m = C_s (their own
        stiffness is ignored: the result is a K_max); dampings b_m, b_s in N*s/m.

    Returns
    -------
    CriticalStiffnessResult
        K_max in N/m, ``method = "eq29"``.
    """
    b, B, T, n = _peb(loop, "eq29")
    K = (b - 2 * abs(B)) / T
    note = "" if n == 0 else f"; derived without delay, here n = {n} (not valid)"
    return _result(K, "eq29", f"eq. (29): b > KT + 2|B|, b = min(b_m, b_s){note}", loop,
                   (b, "2|B|", 2 * abs(B)))


def eq34(loop: TeleoperationLoop) -> CriticalStiffnessResult:
    """The paper's delayed PEB condition, eq. (34): ``b + 2B > KT + K t_d``.

    From (32)-(33) assuming the worst case at cos(wT) = 1 — derived for B small.
    Note that at n = 0 with B > 0 it does *not* reduce to (29) (it allows more
    stiffness as B grows, where (29) allows less).

    For B <= 0 the assumption is exact: with equal controllers the passivity
    matrix needs ``b - KT/2 + B cos(wT) >= |B cos((n+1)wT) - (KT/2) D_n(wT)|``
    (D_n as in :func:`eq18`), whose worst case is w -> 0 when B <= 0. So for
    negative B, (34) reads ``K < (b - 2|B|)/(T + t_d)``, is the exact two-port
    passivity limit for b_m = b_s (sufficient, conservative otherwise), reduces
    to (29) at n = 0, and gives K_max = 0 when ``b + 2B <= 0``.

    Parameters
    ----------
    loop : TeleoperationLoop
        With equal :class:`~hapstab.models.SpringDamper` controllers C_m = C_s (their own
        stiffness is ignored: the result is a K_max); dampings b_m, b_s in N*s/m.

    Returns
    -------
    CriticalStiffnessResult
        K_max in N/m, ``method = "eq34"``.
    """
    b, B, T, n = _peb(loop, "eq34")
    K = (b + 2 * B) / (T + n * T)
    return _result(K, "eq34", "eq. (34): b + 2B > KT + K t_d, b = min(b_m, b_s) (B small)", loop,
                   (b, "-2B", -2 * B))


#: Below this bT/m the denominator of Gil et al. 2004's K_cr is summed as a series: its
#: closed form 1 - e^-a - a e^-a subtracts terms of size ~a to leave ~a^2/2, losing about
#: log10(4/a) digits (19 % at a = 2e-8). Above it the closed form loses at most ~4 ulp
#: (at a = 1 the two subtracted terms are 0.63 and 0.37 of a result 0.26), while the
#: series, alternating with terms <= 1/2 for a <= 1, has converged to 1 ulp after
#: _GIL_TERMS terms (the next term, 23 a^22 / 24!, is below 4e-23).
_GIL_SERIES_BELOW = 1.0
_GIL_TERMS = 22


def _gil_s(a: float) -> float:
    """``s(a) = (1 - e^-a - a e^-a) / a^2 = sum_j (-1)^j (j + 1) a^j / (j + 2)!``, to
    rounding for every a > 0 (series below :data:`_GIL_SERIES_BELOW`, closed form above)."""
    if a < _GIL_SERIES_BELOW:
        acc = 0.0
        for j in range(_GIL_TERMS - 1, -1, -1):      # Horner, smallest terms first
            acc = (j + 1) / math.factorial(j + 2) - a * acc
        return acc
    return (-math.expm1(-a) - a * math.exp(-a)) / (a * a)


def gil2004(loop: HapticLoop) -> CriticalStiffnessResult:
    """Gil et al. 2004's exact critical stiffness of the operator-free 1-DOF device
    with no delay and B = 0:

    ``K_cr = (b^2/m) (1 - d) / (1 - d - (bT/m) d)``, ``d = exp(-bT/m)``.

    Holds while bT/m is below about 3.72; past that a second Jury condition binds
    and this expression is no longer the boundary.

    Evaluated without cancellation, accurate to about 1e-15 relative for every
    a = bT/m > 0: with ``b^2/m = (m/T^2) a^2`` it is
    ``K_cr = (m/T^2) (1 - e^-a) / s(a)``, ``s(a) = (1 - e^-a - a e^-a)/a^2``, where
    ``1 - e^-a = -expm1(-a)`` and s(a) is summed as its power series
    ``1/2 - a/3 + a^2/8 - ...`` for a < 1 (the closed form's subtraction cancels
    there; see :data:`_GIL_SERIES_BELOW`). As a -> 0, K_cr -> 2b/T (eq. 1).

    Parameters
    ----------
    loop : HapticLoop
        SpringDamper with B = 0, no operator, no delay.

    Returns
    -------
    CriticalStiffnessResult
        ``method = "gil2004"``; the reason notes when bT/m is past 3.72.

    Raises
    ------
    AnalysisError
        If the loop has an operator, a delay or a virtual damping.

    References
    ----------
    Gil, Avello, Rubio, Florez, IEEE TCST 12(4):583-588, 2004 (the paper's [5]).
    """
    b, B, T, n = _hve(loop, "gil2004")
    m = loop.device.mass
    if not loop.operator.is_none or n != 0 or B != 0:
        raise AnalysisError("method = 'gil2004': needs no operator, delay_samples = 0 and "
                            "virtual damping B = 0")
    if b == 0:
        return _result(0.0, "gil2004", "b = 0: no stiffness is stable", loop)
    a = b * T / m
    if not 0 < _gil_s(a) < math.inf:    # b T / m beyond doubles (b = 1e308): no closed form
        raise AnalysisError(f"method = 'gil2004': b T / m = {a:.3g} is beyond its formula's "
                            "reach in double precision")
    K = (m / (T * T)) * -math.expm1(-a) / _gil_s(a)
    note = "" if a < 3.72 else f"; bT/m = {a:.3g} > 3.72: outside its range"
    return _result(K, "gil2004", f"Gil et al. 2004 exact K_cr (no operator, n = 0, B = 0){note}", loop)


@dataclass(frozen=True)
class ClosedForm:
    """One closed-form condition: what it applies to and what it claims.

    Attributes
    ----------
    key : str
        Method name (``critical_stiffness(loop, method=key)``).
    function : callable
        ``f(loop) -> CriticalStiffnessResult``.
    kind : {"hve", "peb"}
        The loop it was derived for.
    label : str
        Its source, for tables.
    claims : {"passivity", "stability"}
        What holding it promises.
    without_delay : bool
        Derived for n = 0 only (the paper's non-delayed condition).
    """

    key: str
    function: Callable[[Any], CriticalStiffnessResult]
    kind: str
    label: str
    claims: str
    without_delay: bool = False


#: Every closed form hapstab knows: the one table of which applies to which loop.
TABLE: tuple[ClosedForm, ...] = (
    ClosedForm("colgate", colgate, "hve", "eq. (1)/(13) Colgate-Schenkel", "passivity", True),
    ClosedForm("gil", gil, "hve", "eq. (2) Gil et al.", "stability"),
    ClosedForm("eq18", eq18, "hve", "eq. (18)", "passivity"),
    ClosedForm("gil2004", gil2004, "hve", "Gil et al. 2004 (no operator)", "stability"),
    ClosedForm("eq29", eq29, "peb", "eq. (29)", "passivity", True),
    ClosedForm("eq34", eq34, "peb", "eq. (34)", "passivity"),
)

CLOSED_FORMS = {c.key: c.function for c in TABLE}

#: The paper's own condition for each loop kind, without and with delay: the solid
#: lines of Fig. 5 (eq. 13, 18) and Fig. 6 (eq. 29, 34).
PAPER = {"hve": ("colgate", "eq18"), "peb": ("eq29", "eq34")}

#: Equation numbers of the paper's conditions, for labels.
EQUATION = {"colgate": "(13)", "eq18": "(18)", "eq29": "(29)", "eq34": "(34)"}

#: The paper's inverse transfer function G^-1(z) that the circle criterion tests, per
#: loop kind (other kinds use the same construction from their structure).
G_INVERSE = {"hve": "(15)", "peb": "(30)"}


def closed_forms_for(kind: str) -> tuple[ClosedForm, ...]:
    """The closed forms derived for loops of ``kind`` ("hve" or "peb")."""
    return tuple(c for c in TABLE if c.kind == kind)


def paper_condition(loop: Any) -> ClosedForm:
    """The paper's condition for ``loop``: eq. (13) / (29) without delay, (18) / (34) with.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop

    Returns
    -------
    ClosedForm

    Raises
    ------
    AnalysisError
        A loop of a kind the paper has no condition for (a 4-channel teleoperator).
    """
    if loop.kind not in PAPER:
        raise AnalysisError(f"loop kind {loop.kind!r}: no paper condition applies (the paper's "
                            f"closed forms are for {' and '.join(PAPER)} loops)")
    key = PAPER[loop.kind][0 if loop.delay_in_samples == 0 else 1]
    return next(c for c in TABLE if c.key == key)
