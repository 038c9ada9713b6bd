"""The one table of analyses: for each, its room, its function, its result, its picture,
its command, its explorer endpoint and its sweep quantity.

The command line registers the analyses' commands in this table's order
(``hapstab.cli.main``), the design sweep takes its quantities and their columns from it
(``hapstab.sweep.evaluate.QUANTITIES``), and ``tests/project/test_analysis_table.py`` checks that
every name in a row exists and that the row agrees with it (the function returns the
result, the result draws with the plot named, the command takes the loop kinds named, the
sweep's quantity has its columns). Adding an analysis is its module, its row, and its
tests (docs/architecture.md, "adding an analysis").

The table names things by their import path (``"module:name"``) and is plain data: it
imports nothing, so that the command line and a sweep read it without loading every
analysis.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Analysis", "TABLE", "row", "quantities", "commands", "endpoints"]

KINDS_ALL = ("hve", "peb", "4ch")
TELEOPERATORS = ("peb", "4ch")
PAPER_KINDS = ("hve", "peb")
A = "hapstab.analysis."
RES = "hapstab.results:"
PLOT = "hapstab.plotting:"


@dataclass(frozen=True)
class Analysis:
    """One analysis: what a user asks, and where each layer answers it.

    Parameters
    ----------
    name : str
        Its name (the table's key).
    room : str
        Its room: the package of ``hapstab.analysis`` it lives in (``exact``,
        ``conditions``, ``teleoperation``, ``design``, ``robust``, ``nonlinear``,
        ``identification``, ``network``), or ``simulation``.
    function : str
        The public function, ``"module:name"``.
    result : str
        The class it returns, ``"module:name"``.
    plot : str or None
        What draws the result (``result.plot(ax)`` calls it), ``"module:name"``; None when
        it has no picture.
    command : str or None
        The ``hapstab`` command that answers it (None: the Python API only).
    option : str or None
        The command's option that asks for it, when the command's default answers
        another row (``kmax --loss``).
    kinds : tuple of str
        The loop kinds the command takes as subcommands (``()``: not a loop command).
    endpoint : str or None
        The explorer's command, ``POST /api/v1/{endpoint}`` (None: not in the explorer).
    quantity : str or None
        The design sweep's quantity (a study's ``[sweep] quantities``).
    columns : tuple of (str, str)
        The quantity's columns in a sweep's table: (name, Arrow type).
    """

    name: str
    room: str
    function: str
    result: str
    plot: str | None = None
    command: str | None = None
    option: str | None = None
    kinds: tuple[str, ...] = ()
    endpoint: str | None = None
    quantity: str | None = None
    columns: tuple[tuple[str, str], ...] = ()


#: Every analysis; the sweep's quantities in the order of their columns.
TABLE: tuple[Analysis, ...] = (
    Analysis("kmax", "exact", A + "methods:critical_stiffness", RES + "CriticalStiffnessResult",
             None, "kmax", None, KINDS_ALL, "kmax", "kmax",
             (("critical_stiffness_N_per_m", "float64"), ("reason", "string"),
              ("crossing_frequency_hz", "float64"))),
    Analysis("passivity", "conditions", A + "conditions.passivity:sampled_passivity",
             A + "conditions.passivity:PassivityResult", None, "passivity", None, KINDS_ALL,
             "passivity", "passivity", (("passivity_kmax_N_per_m", "float64"),)),
    Analysis("closed-form", "conditions", A + "conditions.closed_forms:paper_condition",
             A + "conditions.closed_forms:ClosedForm", None, "kmax", "--method", KINDS_ALL,
             None, "closed-form",
             (("closed_form_equation", "string"), ("closed_form_N_per_m", "float64"),
              ("closed_form_over_promises", "bool"))),
    Analysis("check", "exact", A + "exact.core:stability", RES + "StabilityResult",
             PLOT + "plot_poles", "check", None, KINDS_ALL, "check", "check",
             (("verdict_at_K", "string"),)),
    Analysis("best-damping", "design", A + "design.damping:best_damping",
             A + "design.damping:BestDampingResult", PLOT + "plot_best_damping",
             "best-damping", None, KINDS_ALL, "best-damping", "best-damping",
             (("best_damping_B_N_s_per_m", "float64"), ("best_damping_K_N_per_m", "float64"))),
    Analysis("loss", "network", A + "network.loss:loss_critical_stiffness",
             A + "network.result:LossStiffnessResult",
             A + "network.result:LossStiffnessResult.plot", "kmax", "--loss", KINDS_ALL,
             None, "loss-kmax", (("loss_kmax_N_per_m", "float64"),)),
    Analysis("delay-range", "network", A + "network.delay_range:delay_range_critical_stiffness",
             A + "network.delay_range:DelayRangeResult",
             A + "network.delay_range:DelayRangeResult.plot", "kmax", "--delay-range",
             KINDS_ALL, None, "delay-range-kmax",
             (("delay_range_kmax_N_per_m", "float64"), ("worst_delay_samples", "float64"))),
    # kmax --delay-range in seconds for the hve answers it (the row above: whole samples)
    Analysis("delay-range-between", "network",
             A + "network.frac_result:fractional_range_critical_stiffness",
             A + "network.frac_result:FractionalRangeResult",
             A + "network.frac_result:FractionalRangeResult.plot"),
    Analysis("jitter", "network", A + "network.jitter:jitter",
             A + "network.jitter_result:JitterResult",
             A + "network.jitter_result:JitterResult.plot", "jitter", None, PAPER_KINDS,
             "jitter", "jitter",
             (("jitter_stable_up_to_N_per_m", "float64"),
              ("jitter_unstable_from_N_per_m", "float64"))),
    Analysis("boundary", "exact", A + "methods:boundary", RES + "BoundaryResult",
             PLOT + "plot_boundary", "boundary", None, KINDS_ALL, "boundary"),
    Analysis("margins", "conditions", A + "margins:margins", A + "margin_result:MarginResult",
             "hapstab.plotting.margins:plot_margins", "check", "--margins", KINDS_ALL),
    Analysis("audit", "conditions", A + "conditions.audit:audit",
             A + "conditions.audit:AuditResult", PLOT + "plot_audit", "audit", None,
             PAPER_KINDS, "audit"),
    Analysis("positive-real", "conditions", A + "conditions.positive_real:positive_real",
             A + "conditions.positive_real:PositiveRealResult", PLOT + "plot_positive_real"),
    Analysis("twoport", "teleoperation", A + "teleoperation.twoport:llewellyn_test",
             A + "teleoperation.twoport:TwoPortResult", PLOT + "plot_twoport", "twoport",
             None, TELEOPERATORS, "twoport"),
    Analysis("transparency", "teleoperation", A + "teleoperation.transparency:transparency",
             A + "teleoperation.transparency:TransparencyResult", PLOT + "plot_transparency",
             "transparency", None, TELEOPERATORS, "transparency"),
    Analysis("region", "design", A + "design.regions:stability_region",
             A + "design.regions:RegionResult", PLOT + "plot_region", "region", None,
             KINDS_ALL, "region"),
    Analysis("zwidth", "design", A + "design.zwidth:zwidth", A + "design.zwidth:ZWidthResult",
             "hapstab.plotting.zwidth:plot_zwidth", "zwidth", None, ("hve",), "zwidth"),
    Analysis("robust", "robust", A + "robust.robust:robust_critical_stiffness",
             A + "robust.robust_result:RobustStiffnessResult",
             A + "robust.robust_result:RobustStiffnessResult.plot", "robust", None,
             PAPER_KINDS),
    Analysis("limit-cycle", "nonlinear", A + "nonlinear.limit_cycles:limit_cycles",
             A + "nonlinear.limit_cycle_results:LimitCycleResult",
             "hapstab.plotting.limit_cycles:plot_limit_cycles", "limit-cycle", None,
             ("hve",), "limit-cycle"),
    Analysis("nonlinear-passivity", "nonlinear",
             A + "nonlinear.nonlinear_passivity:nonlinear_passivity",
             A + "nonlinear.nonlinear_passivity:NonlinearPassivityResult", None, "passivity",
             "--resolution", KINDS_ALL),
    Analysis("identify", "identification", A + "identification.identify:identify",
             A + "identification.identify_result:IdentificationResult",
             "hapstab.plotting.identify:plot_identification", "identify"),
    Analysis("simulate", "simulation", "hapstab.simulation.run:simulate",
             "hapstab.simulation.result:SimulationResult", PLOT + "plot_simulation",
             "simulate", None, KINDS_ALL, "simulate"),
)


def row(name: str) -> Analysis:
    """The row named ``name``.

    Parameters
    ----------
    name : str
        An analysis's name.

    Returns
    -------
    Analysis

    Raises
    ------
    KeyError
        No such row.
    """
    for r in TABLE:
        if r.name == name:
            return r
    raise KeyError(name)


def quantities() -> dict[str, tuple[tuple[str, str], ...]]:
    """The design sweep's quantities -> their columns, in the table's order.

    Returns
    -------
    dict
    """
    return {r.quantity: r.columns for r in TABLE if r.quantity is not None}


def commands() -> tuple[str, ...]:
    """The commands that answer an analysis, each once, in the table's order.

    Returns
    -------
    tuple of str
    """
    return tuple(dict.fromkeys(r.command for r in TABLE if r.command is not None))


def endpoints() -> tuple[str, ...]:
    """The explorer's analysis commands, in the table's order.

    Returns
    -------
    tuple of str
    """
    return tuple(r.endpoint for r in TABLE if r.endpoint is not None)
