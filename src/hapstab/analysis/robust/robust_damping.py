"""The best virtual damping for an uncertain operator: the nominal B* (for the
loop's own operator, :func:`hapstab.analysis.design.damping.best_damping`) checked over a
box of operators with the certified robust K_max
(:func:`hapstab.analysis.robust.robust.robust_critical_stiffness`), saying whether B*
keeps the loop stable at K* for every operator of the box, and which operator
breaks it if not.

References
----------
J. E. Colgate and G. G. Schenkel, "Passivity of a class of sampled-data systems:
application to haptic interfaces", J. Robot. Syst. 14 (1997) 37-47 (the passivity
limit of the device side, whatever the operator).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hapstab.analysis.design.damping import BestDampingResult, best_damping
from hapstab.analysis.design.kb_plane import with_gains
from hapstab.analysis.robust.robust import DEFAULT_RTOL, MAX_BOXES, robust_critical_stiffness
from hapstab.analysis.robust.robust_result import RobustStiffnessResult
from hapstab.models.operators import OperatorBox
from hapstab.results import Result, jsonable

__all__ = ["RobustDampingResult", "robust_best_damping"]


@dataclass(frozen=True)
class RobustDampingResult(Result):
    """The nominal best damping B* and what it gives for every operator of a box.

    Parameters
    ----------
    nominal : BestDampingResult
        B* and K* for the loop's own operator.
    robust : RobustStiffnessResult
        The robust K_max at B* over the box (certified lower bound, worst operator).
    """

    nominal: BestDampingResult
    robust: RobustStiffnessResult

    @property
    def stable_for_all(self) -> bool:
        """Whether K* is stable for every operator of the box (certified)."""
        return self.robust.critical_stiffness >= self.nominal.critical_stiffness

    @property
    def fails_for_some(self) -> bool:
        """Whether some operator of the box is unstable at K* (the named one is)."""
        return self.robust.upper_bound < self.nominal.critical_stiffness

    @property
    def reason(self) -> str:
        """B* and K*, and whether they hold for every operator of the box, in words."""
        n, r = self.nominal, self.robust
        op = ", ".join(f"{v:.6g} {u}" for v, u in zip(r.operator, ("kg", "N*s/m", "N/m"),
                                                        strict=True))
        words = (f"{n.reason}. Over the operator box ({r.box.describe()}) at B* = "
                 f"{n.damping:.6g} N*s/m every operator is stable up to K = "
                 f"{r.critical_stiffness:.8g} N/m (certified)")
        if self.stable_for_all:
            return words + f", so K* = {n.critical_stiffness:.8g} N/m holds for all of them"
        if self.fails_for_some:
            return words + (f"; B* loses stability for other operators: with the operator "
                            f"({op}) K_max = {r.operator_critical_stiffness:.8g} N/m < K* = "
                            f"{n.critical_stiffness:.8g} N/m")
        return words + (f"; whether K* = {n.critical_stiffness:.8g} N/m holds for every operator "
                        f"is not decided within the budget (the smallest K_max lies in "
                        f"[{r.critical_stiffness:.8g}, {r.upper_bound:.8g}] N/m)")

    def to_dict(self) -> dict[str, Any]:
        d = self.nominal.to_dict()
        rob = self.robust.to_dict()
        d.update({"reason": self.reason, "stable_for_every_operator": self.stable_for_all,
                  "unstable_for_some_operator": self.fails_for_some,
                  "robust_critical_stiffness": rob["critical_stiffness"],
                  "worst_operator": rob["operator"],
                  "worst_operator_critical_stiffness": rob["operator_critical_stiffness"],
                  "operator_box": rob["operator_box"], "robust_converged": rob["converged"]})
        return jsonable(d)

    def plot(self, ax: Any = None) -> Any:
        """The nominal K_max against B (see :meth:`BestDampingResult.plot`), with the
        robust K_max at B* marked.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw; a new figure when omitted.

        Returns
        -------
        matplotlib Axes
        """
        ax = self.nominal.plot(ax)
        ax.plot([self.nominal.damping], [self.robust.critical_stiffness], "rv", ms=9,
                label="robust K_max at B* (every operator)")
        ax.legend(loc="best", fontsize="small")
        return ax

    def to_csv(self, path: Any) -> None:
        """The nominal scanned curve (see :meth:`BestDampingResult.to_csv`).

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write.
        """
        self.nominal.to_csv(path)


def robust_best_damping(loop: Any, box: OperatorBox, B_max: float | None = None,
                        resolution: int = 64, B_min: float | None = None, *,
                        rtol: float = DEFAULT_RTOL, max_boxes: int = MAX_BOXES,
                        max_memory: float | None = None,
                        max_seconds: float | None = None) -> RobustDampingResult:
    """The nominal best damping B* (for the loop's own operator) and the robust K_max
    at B* over every operator of ``box``.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        C_m = C_s for teleoperation; its operator is the nominal one.
    box : OperatorBox
        The operators B* must also serve.
    B_max, resolution, B_min : optional
        As :func:`hapstab.analysis.design.damping.best_damping`.
    rtol, max_boxes : optional
        As :func:`hapstab.analysis.robust.robust.robust_critical_stiffness`.
    max_memory, max_seconds : float, optional
        Budget in bytes and seconds, for each of the two searches.

    Returns
    -------
    RobustDampingResult
        The reason says when B* leaves some operator of the box unstable at K*
        (naming the worst one and its K_max); the nominal part says when K* is
        above the device side's passivity limit at B* (whatever the operator).

    Raises
    ------
    AnalysisError
        As the two functions above.
    """
    nominal = best_damping(loop, B_max, resolution, B_min, max_memory=max_memory,
                           max_seconds=max_seconds)
    at_B = with_gains(loop, 0.0, nominal.damping)
    rob = robust_critical_stiffness(at_B, box, rtol=rtol, max_boxes=max_boxes,
                                    max_memory=max_memory, max_seconds=max_seconds)
    return RobustDampingResult(nominal, rob)
