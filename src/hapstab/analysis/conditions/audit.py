"""Audit of the closed-form conditions: each applicable closed form beside the
numerical circle / passivity results and the exact stability limit, flagging any
condition that promises a stiffness the exact analysis calls unstable (or, for a
condition that claims passivity, one at which the positive-real test fails).

The paper's closed forms are approximations with limits: (18) and (34) assume B
small (the worst case is then at cos wT = 1); (34) at n = 0 with B > 0 does not
reduce to (29); (1)/(13) and (29) ignore delay. The audit shows where this
matters for a given design.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from hapstab import budget
from hapstab.analysis.conditions.circle import critical_stiffness_circle
from hapstab.analysis.conditions.closed_forms import closed_forms_for
from hapstab.analysis.conditions.passivity import critical_stiffness_passivity
from hapstab.analysis.exact.core import exact_critical_stiffness
from hapstab.analysis.nonlinear.nonlinear_passivity import abbott_okamura
from hapstab.engine.system import build
from hapstab.errors import AnalysisError
from hapstab.models.controllers import spring_damper
from hapstab.models.loops import HapticLoop, TeleoperationLoop, require_loop
from hapstab.results import Result, jsonable, write_csv

__all__ = ["AuditRow", "AuditResult", "audit"]

_REL = 1e-6  # K_max values agree to ~1e-9; a promise counts as broken beyond 1e-6 relative
_ABS = 1e-12  # N/m, added to that: a promise of K = 0 (to rounding) never breaks an exact 0

#: closed form -> (label, what it claims)


@dataclass(frozen=True)
class AuditRow(Result):
    """One condition of the audit.

    Attributes
    ----------
    key : str
        ``colgate``, ``eq18``, ..., ``circle-forward``, ``passivity``, ``exact``.
    label : str
    critical_stiffness : float
        The K_max the condition promises (N/m).
    claims : str
        ``"passivity"`` (derived from positive realness / passivity),
        ``"stability"`` or ``"exact"``.
    exact_verdict : str
        Exact stability verdict of the loop just below that stiffness (K (1 - 1e-6);
        ``"-"`` if K is 0 or inf).
    flag : str or None
        Why the promise is broken, or None.
    note : str
        The condition's own statement of its assumptions.
    """

    key: str
    label: str
    critical_stiffness: float
    claims: str
    exact_verdict: str
    flag: str | None
    note: str

    def to_dict(self) -> dict[str, Any]:
        return jsonable(dict(self.__dict__))


@dataclass(frozen=True)
class AuditResult(Result):
    """All rows for one set of parameters.

    Attributes
    ----------
    kind : {"hve", "peb"}
        The loop kind.
    period : float
        Sampling period T in s.
    delay_samples : int
        Delay n in samples.
    virtual_damping : float
        B in N*s/m (the master's for a teleoperator).
    rows : tuple of AuditRow
        One per condition, ending with the exact limit.
    exact_kmax : float
        The exact K_max in N/m.
    passivity_kmax : float
        Exact sampled-data passivity limit (= forward circle limit).
    flagged : tuple of str
        Keys of the flagged rows.
    """

    kind: str
    period: float
    delay_samples: int
    virtual_damping: float
    rows: tuple[AuditRow, ...]
    exact_kmax: float
    passivity_kmax: float

    @property
    def flagged(self) -> tuple[str, ...]:
        return tuple(r.key for r in self.rows if r.flag)

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"loop": self.kind, "period_s": self.period,
                         "delay_samples": float(self.delay_samples),
                         "virtual_damping": self.virtual_damping,
                         "exact_kmax": self.exact_kmax, "passivity_kmax": self.passivity_kmax,
                         "flagged": list(self.flagged), "rows": [r.to_dict() for r in self.rows]})

    def to_csv(self, path: Any) -> None:
        """Write one row per condition: key, label, critical_stiffness (N/m; ``inf``
        as written by Python), claims, exact_verdict, flag.

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        write_csv(path, ["key", "label", "critical_stiffness", "claims", "exact_verdict", "flag"],
                  ([r.key, r.label, repr(float(r.critical_stiffness)), r.claims,
                    r.exact_verdict, r.flag or ""] for r in self.rows))

    def plot(self, ax: Any = None) -> Any:
        """K_max of every condition as a bar, the exact limit as a line, broken
        promises in red (see :func:`hapstab.plotting.plot_audit`).

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw; a new figure when omitted.

        Returns
        -------
        matplotlib Axes
        """
        from hapstab.plotting import plot_audit
        return plot_audit(self, ax)




def _verdict(intervals: Any, K: float) -> str:
    """Exact verdict just below K, read from the certified stable intervals of K (the
    exact core's, the same for every row: no eigenvalue problem per row, which at 1000
    states and a stiff K took up to 17 s each); at K itself a boundary is marginal by
    definition, so the verdict is taken at K (1 - 1e-6)."""
    if not math.isfinite(K) or K <= 0:
        return "-"
    k = K * (1 - _REL)
    for a, b in intervals:
        if min(abs(k - a), abs(k - b)) <= 1e-9 * k:   # the intervals' ends are ~1e-12 exact
            return "marginal"
        if a < k < b:
            return "stable"
    return "unstable"


def audit(loop: HapticLoop | TeleoperationLoop, *, coulomb_friction_N: float | None = None,
          resolution_m: float | None = None, max_memory: float | None = None,
          max_seconds: float | None = None) -> AuditResult:
    """Closed forms vs circle / passivity vs exact, for the loop's parameters.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        SpringDamper controller(s); its own stiffness is ignored (every row is a
        K_max). PEB closed forms are listed only for C_m = C_s (as derived);
        (1)/(13) and (29) only for n = 0, Gil et al. 2004 only without operator,
        delay and B.
    coulomb_friction_N : float, optional
        f_c in N (default: the device's ``coulomb_friction``). With friction or
        ``resolution_m`` given (HVE only), a row ``abbott-okamura`` is added: the passivity
        limit with friction and quantisation
        (:func:`~hapstab.analysis.nonlinear.nonlinear_passivity.abbott_okamura`).
    resolution_m : float, optional
        Encoder resolution Δ in m, for that row.
    max_memory, max_seconds : float, optional
        Budget in bytes and seconds (default :mod:`hapstab.budget`'s), estimated first.

    Returns
    -------
    AuditResult

    Raises
    ------
    AnalysisError
        If the loop has no stiffness to vary; friction or quantisation for a teleoperator,
        or quantisation where Abbott and Okamura's condition does not apply (B != 0, delay).

    References
    ----------
    The paper, eq. (1), (2), (13), (18), (29), (34); Colgate and Schenkel 1997; Abbott and
    Okamura 2005.
    """
    require_loop(loop)
    kind = loop.kind
    N = build(loop).order
    # the exact stable set, passivity and three circle criteria: five certified K_max
    budget.check(budget.exact_points_cost(f"audit of a {N}-state loop", 5, N),
                 max_memory, max_seconds)
    passive = critical_stiffness_passivity(loop).critical_stiffness  # raises for non-SpringDamper
    exact_res = exact_critical_stiffness(loop)
    exact = exact_res.critical_stiffness
    rows: list[AuditRow] = []

    def add(key: str, label: str, K: float, claims: str, note: str) -> None:
        flags = []
        if claims != "exact" and K > exact * (1 + _REL) + _ABS:
            flags.append(f"over-promises: exact loop unstable beyond {exact:.6g} N/m")
        if claims == "passivity" and K > passive * (1 + _REL) + _ABS:
            flags.append(f"not passive: PR test fails beyond {passive:.6g} N/m")
        rows.append(AuditRow(key, label, float(K), claims, _verdict(exact_res.stable_intervals, K),
                             "; ".join(flags) or None, note))

    for c in closed_forms_for(kind):
        if c.without_delay and loop.delay_samples != 0:
            continue  # derived without delay: not a candidate condition here
        try:
            r = c.function(loop)
        except AnalysisError:
            continue  # not applicable to these parameters (e.g. C_m != C_s, operator attached)
        add(c.key, c.label, r.critical_stiffness, c.claims, r.reason)
    for a in ("forward", "backward", "tustin"):
        try:
            r = critical_stiffness_circle(loop, a)
        except AnalysisError as e:     # (say which rows: the exact one and passivity passed)
            raise AnalysisError(f"audit: the rows circle-forward, circle-backward and "
                                f"circle-tustin cannot be computed: {e}") from None
        note = r.reason
        add(f"circle-{a}", f"circle criterion, {a}", r.critical_stiffness, "passivity", note)
    add("passivity", "sampled-data passivity (Colgate-Schenkel)", passive, "passivity",
        "exact passivity of device + sampled controller; sufficient for stability with "
        "passive terminations")
    nonlinear = _abbott_okamura(loop, coulomb_friction_N, resolution_m)
    if nonlinear is not None:
        add("abbott-okamura", "Abbott-Okamura (friction, quantisation)",
            nonlinear.critical_stiffness, "passivity", nonlinear.reason)
    rows.append(AuditRow("exact", "exact sampled-data stability", float(exact), "exact",
                         _verdict(exact_res.stable_intervals, exact), None, exact_res.reason))
    name = loop.controller_names[0]
    B = spring_damper(loop.controllers[0], name).damping
    return AuditResult(kind, loop.period, loop.delay_samples, B, tuple(rows), float(exact),
                       float(passive))


def _abbott_okamura(loop: Any, coulomb_friction_N: float | None,
                    resolution_m: float | None) -> Any:
    """The Abbott-Okamura limit when friction or quantisation is asked for (or the device
    has friction); None otherwise, so a friction-free, quantisation-free audit is today's."""
    fc = getattr(getattr(loop, "device", None), "coulomb_friction", 0.0)
    if coulomb_friction_N is None and resolution_m is None and not fc:
        return None
    if len(loop.port_names) != 1:                # one device: the haptic loop
        raise AnalysisError(f"coulomb_friction_N / resolution_m: the Abbott-Okamura condition is "
                            f"derived for the haptic loop (hve), not a {loop.kind} loop")
    return abbott_okamura(loop, coulomb_friction_N=coulomb_friction_N, resolution_m=resolution_m)
