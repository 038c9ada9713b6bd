"""hapstab: exact stability and critical stiffness of sampled-data, delayed haptic
(HVE) and position-error-based teleoperation loops.

Reference: N. Miandashti and M. Tavakoli, "Stability of Sampled-Data, Delayed
Haptic Interaction and Teleoperation", IEEE Haptics Symposium 2014.
"""

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:   # for type checkers and readers; at run time a name loads on first use
    from hapstab.analysis.conditions.audit import AuditResult, audit
    from hapstab.analysis.conditions.circle import circle_test, loop_inverse
    from hapstab.analysis.conditions.closed_forms import colgate, eq18, eq29, eq34, gil, gil2004
    from hapstab.analysis.conditions.passivity import PassivityResult, sampled_passivity
    from hapstab.analysis.conditions.positive_real import (
        PositiveRealResult,
        RationalMatrix,
        circle_criterion,
        positive_real,
    )
    from hapstab.analysis.design.damping import BestDampingResult, best_damping
    from hapstab.analysis.design.regions import RegionResult, stability_region
    from hapstab.analysis.exact.core import stability
    from hapstab.analysis.exact.many import critical_stiffness_many
    from hapstab.analysis.identification.identify import identify
    from hapstab.analysis.identification.identify_result import IdentificationResult
    from hapstab.analysis.interop import to_control
    from hapstab.analysis.margin_result import FrequencyView, MarginResult
    from hapstab.analysis.margins import frequency_view, margins
    from hapstab.analysis.methods import boundary, critical_stiffness, methods_for
    from hapstab.analysis.network.jitter import jitter
    from hapstab.analysis.network.jitter_result import JitterResult
    from hapstab.analysis.nonlinear.limit_cycle_results import LimitCycleResult, PredictedCycle
    from hapstab.analysis.nonlinear.limit_cycles import limit_cycles
    from hapstab.analysis.nonlinear.nonlinear_passivity import (
        NonlinearPassivityResult,
        abbott_okamura,
        nonlinear_passivity,
    )
    from hapstab.analysis.robust.robust import RobustStiffnessResult, robust_critical_stiffness
    from hapstab.analysis.robust.robust_damping import RobustDampingResult, robust_best_damping
    from hapstab.analysis.teleoperation.transparency import TransparencyResult, transparency
    from hapstab.analysis.teleoperation.twoport import TwoPortResult, llewellyn_test
    from hapstab.analysis.verify import CertificateCheck, verify_certificate
    from hapstab.budget import BudgetError
    from hapstab.engine.system import SampledSystem, build
    from hapstab.errors import AnalysisError, ArgumentTypeError, HapstabError, ModelError
    from hapstab.models.controllers import (
        AffineController,
        DiscreteController,
        FilteredSpringDamper,
        SpringDamper,
        VelocityFilter,
    )
    from hapstab.models.fourchannel import FourChannelLoop
    from hapstab.models.loops import HapticLoop, TeleoperationLoop
    from hapstab.models.operators import OperatorBox, operator_box
    from hapstab.models.parts import (
        NO_IMPEDANCE,
        Device,
        Impedance,
        mass_spring_damper,
        parse_impedance,
        spring,
    )
    from hapstab.outputs import OutputError
    from hapstab.paper.loops import paper_hve, paper_peb
    from hapstab.results import BoundaryResult, CriticalStiffnessResult, StabilityResult
    from hapstab.simulation import TDPA, SimulationResult, critical_stiffness_simulation, simulate
    from hapstab.sweep import SweepResult, sweep

__version__ = "0.1.0"

#: where each public name lives: ``import hapstab`` imports none of these modules (no
#: numpy, scipy or matplotlib: ``hapstab --version`` stays light); the first use of a
#: name imports its module (:func:`__getattr__`). Keep it equal to the imports above
#: (tests/cli/test_light_import.py checks).
_LAZY = {
    "hapstab.analysis.conditions.audit": ("AuditResult", "audit"),
    "hapstab.analysis.conditions.circle": ("circle_test", "loop_inverse"),
    "hapstab.analysis.conditions.closed_forms": ("colgate", "eq18", "eq29", "eq34", "gil", "gil2004"),
    "hapstab.analysis.design.damping": ("BestDampingResult", "best_damping"),
    "hapstab.analysis.exact.core": ("stability",),
    "hapstab.analysis.exact.many": ("critical_stiffness_many",),
    "hapstab.analysis.nonlinear.limit_cycle_results": ("LimitCycleResult", "PredictedCycle"),
    "hapstab.analysis.nonlinear.limit_cycles": ("limit_cycles",),
    "hapstab.analysis.methods": ("boundary", "critical_stiffness", "methods_for"),
    "hapstab.analysis.nonlinear.nonlinear_passivity": (
        "NonlinearPassivityResult", "abbott_okamura", "nonlinear_passivity",
    ),
    "hapstab.analysis.conditions.passivity": ("PassivityResult", "sampled_passivity"),
    "hapstab.analysis.conditions.positive_real": (
        "PositiveRealResult", "RationalMatrix", "circle_criterion", "positive_real",
    ),
    "hapstab.analysis.design.regions": ("RegionResult", "stability_region"),
    "hapstab.analysis.robust.robust": ("RobustStiffnessResult", "robust_critical_stiffness"),
    "hapstab.analysis.robust.robust_damping": ("RobustDampingResult", "robust_best_damping"),
    "hapstab.analysis.teleoperation.transparency": ("TransparencyResult", "transparency"),
    "hapstab.analysis.teleoperation.twoport": ("TwoPortResult", "llewellyn_test"),
    "hapstab.analysis.verify": ("CertificateCheck", "verify_certificate"),
    "hapstab.budget": ("BudgetError",),
    "hapstab.engine.system": ("SampledSystem", "build"),
    "hapstab.errors": ("AnalysisError", "ArgumentTypeError", "HapstabError", "ModelError"),
    "hapstab.models.controllers": (
        "AffineController", "DiscreteController", "FilteredSpringDamper", "SpringDamper",
        "VelocityFilter",
    ),
    "hapstab.models.fourchannel": ("FourChannelLoop",),
    "hapstab.models.loops": ("HapticLoop", "TeleoperationLoop"),
    "hapstab.models.operators": ("OperatorBox", "operator_box"),
    "hapstab.models.parts": (
        "NO_IMPEDANCE", "Device", "Impedance", "mass_spring_damper", "parse_impedance",
        "spring",
    ),
    "hapstab.outputs": ("OutputError",),
    "hapstab.paper.loops": ("paper_hve", "paper_peb"),
    "hapstab.results": ("BoundaryResult", "CriticalStiffnessResult", "StabilityResult"),
    "hapstab.simulation": ("TDPA", "SimulationResult", "critical_stiffness_simulation", "simulate"),
    "hapstab.sweep": ("SweepResult", "sweep"),
    "hapstab.analysis.interop": ("to_control",),
    "hapstab.analysis.margin_result": ("FrequencyView", "MarginResult",),
    "hapstab.analysis.margins": ("frequency_view", "margins",),
    "hapstab.analysis.identification.identify": ("identify",),
    "hapstab.analysis.identification.identify_result": ("IdentificationResult",),
    "hapstab.analysis.network.jitter": ("jitter",),
    "hapstab.analysis.network.jitter_result": ("JitterResult",),
}
_MODULE_OF = {name: module for module, names in _LAZY.items() for name in names}

__all__ = [
    "Device", "Impedance", "NO_IMPEDANCE", "spring", "mass_spring_damper", "parse_impedance",
    "SpringDamper", "FilteredSpringDamper", "VelocityFilter", "AffineController",
    "DiscreteController", "HapticLoop", "TeleoperationLoop", "FourChannelLoop",
    "paper_hve",
    "paper_peb", "build", "SampledSystem", "stability", "critical_stiffness", "boundary",
    "methods_for", "colgate", "gil", "eq18", "eq29", "eq34", "gil2004", "HapstabError",
    "ModelError", "AnalysisError", "StabilityResult", "CriticalStiffnessResult", "BoundaryResult",
    "RationalMatrix", "positive_real", "circle_criterion", "PositiveRealResult", "circle_test",
    "loop_inverse", "sampled_passivity", "PassivityResult", "audit", "AuditResult",
    "stability_region", "RegionResult", "best_damping", "BestDampingResult", "simulate",
    "SimulationResult", "critical_stiffness_simulation", "ArgumentTypeError", "BudgetError",
    "OutputError", "transparency", "TransparencyResult", "llewellyn_test", "TwoPortResult",
    "TDPA", "abbott_okamura", "nonlinear_passivity", "NonlinearPassivityResult", "limit_cycles",
    "LimitCycleResult", "PredictedCycle",
    "OperatorBox", "operator_box", "robust_critical_stiffness", "RobustStiffnessResult",
    "robust_best_damping", "RobustDampingResult", "sweep", "SweepResult",
    "critical_stiffness_many",
    "to_control", "margins", "frequency_view", "MarginResult", "FrequencyView",
    "identify", "IdentificationResult",
    "verify_certificate", "CertificateCheck",
    "jitter", "JitterResult",
]


def __getattr__(name: str) -> Any:
    """Import a public name's module on first use (PEP 562), or a subpackage."""
    import importlib

    module = _MODULE_OF.get(name)
    if module is not None:
        value = getattr(importlib.import_module(module), name)
        globals()[name] = value        # once: later lookups do not come here
        return value
    if not name.startswith("_"):
        try:
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as e:
            if e.name != f"{__name__}.{name}":
                raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
