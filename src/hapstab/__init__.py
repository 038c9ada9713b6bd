"""hapstab: exact stability and critical stiffness of sampled-data, delayed haptic
(HVE) and position-error-based teleoperation loops.

Reference: N. Miandashti and M. Tavakoli, "Stability of Sampled-Data, Delayed
Haptic Interaction and Teleoperation", IEEE Haptics Symposium 2014.
"""

from .analysis import boundary, critical_stiffness, methods_for
from .closed_forms import colgate, eq18, eq29, eq34, gil, gil2004
from .engine import SampledSystem, build
from .errors import AnalysisError, HapstabError, ModelError
from .exact import stability
from .models import (NO_IMPEDANCE, Device, DiscreteController, HapticLoop, Impedance, SpringDamper,
                     TeleoperationLoop, mass_spring_damper, paper_hve, paper_peb, parse_impedance,
                     spring)
from .results import BoundaryResult, CriticalStiffnessResult, StabilityResult
from .positive_real import PositiveRealResult, RationalMatrix, circle_criterion, positive_real
from .circle import circle_test, loop_inverse
from .passivity import PassivityResult, sampled_passivity
from .audit import AuditResult, audit

__version__ = "0.1.0"

__all__ = [
    "Device", "Impedance", "NO_IMPEDANCE", "spring", "mass_spring_damper", "parse_impedance",
    "SpringDamper", "DiscreteController", "HapticLoop", "TeleoperationLoop", "paper_hve",
    "paper_peb", "build", "SampledSystem", "stability", "critical_stiffness", "boundary",
    "methods_for", "colgate", "gil", "eq18", "eq29", "eq34", "gil2004", "HapstabError",
    "ModelError", "AnalysisError", "StabilityResult", "CriticalStiffnessResult", "BoundaryResult",
    "RationalMatrix", "positive_real", "circle_criterion", "PositiveRealResult", "circle_test",
    "loop_inverse", "sampled_passivity", "PassivityResult", "audit", "AuditResult",
]
