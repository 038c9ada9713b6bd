"""The result of the robust K_max over an operator box: the certified bound, the
operator that attains the best upper bound, and a heat map of K_max over the box."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.models.operators import OperatorBox
from hapstab.results import Result, jsonable, write_csv

__all__ = ["RobustStiffnessResult"]

_NAMES = ("mass", "damping", "stiffness")
_UNITS = ("kg", "N*s/m", "N/m")


@dataclass(frozen=True)
class RobustStiffnessResult(Result):
    """Robust K_max: every operator of the box is stable for K in (0, critical_stiffness].

    Parameters
    ----------
    critical_stiffness : float
        Certified lower bound of the smallest exact K_max over the box, N/m (never
        above it).
    operator : (float, float, float)
        The operator (m kg, b N*s/m, k N/m) with the smallest K_max found.
    operator_critical_stiffness : float
        Its exact K_max (N/m), from the exact core.
    upper_bound : float
        A certified upper bound of the smallest K_max (N/m): the upper end of the
        named operator's enclosed K_max.
    converged : bool
        upper - lower <= rtol * upper (else the budget of sub-boxes was spent).
    boxes : int
        Sub-boxes evaluated.
    rtol : float
        The relative gap asked for.
    vertex_minimum : float
        The smallest K_max over the box's vertices alone (N/m, upper end of its
        enclosure): above the true minimum when that is not at a vertex.
    vertex : (float, float, float)
        The vertex that gives it.
    box : OperatorBox
        The box analysed.
    seconds : float
        Wall time of the search.
    loop : HapticLoop or TeleoperationLoop
        The loop (its own operator is not used); kept for the plot.
    stopped : {"", "boxes", "time"}
        Why an unconverged search stopped: its ``max_boxes`` or its time budget
        (:func:`hapstab.budget.seconds_allowed`) spent; the bounds hold either way.
    """

    critical_stiffness: float
    operator: tuple[float, float, float]
    operator_critical_stiffness: float
    upper_bound: float
    converged: bool
    boxes: int
    rtol: float
    vertex_minimum: float
    vertex: tuple[float, float, float]
    box: OperatorBox
    seconds: float
    loop: Any = field(repr=False, default=None)
    stopped: str = ""

    @property
    def gap(self) -> float:
        """upper_bound - critical_stiffness, N/m."""
        if math.isinf(self.upper_bound) and math.isinf(self.critical_stiffness):
            return 0.0
        return self.upper_bound - self.critical_stiffness

    @property
    def reason(self) -> str:
        """The answer in words."""
        op = ", ".join(f"{n} {v:.6g} {u}" for n, v, u in zip(_NAMES, self.operator, _UNITS,
                                                             strict=True))
        if math.isinf(self.critical_stiffness):
            return "stable for every K > 0 with every operator of the box"
        if self.upper_bound == 0.0:
            return (f"K_max = 0: with the operator ({op}) the loop is unstable for every K > 0 "
                    "(already as K -> 0+)")
        words = (f"every operator of the box ({self.box.describe()}) is stable for K up to "
                 f"{self.critical_stiffness:.10g} N/m (certified); the operator ({op}) has "
                 f"K_max = {self.operator_critical_stiffness:.10g} N/m")
        if self.converged:
            words += f" (gap {self.gap:.3g} N/m, at most {self.rtol:g} relative)"
        else:
            spent = (f"the time budget is spent after {self.seconds:.3g} s and {self.boxes} "
                     "sub-boxes" if self.stopped == "time" else
                     f"the budget of {self.boxes} sub-boxes is spent")
            words += (f"; {spent}: the smallest K_max "
                      f"lies in [{self.critical_stiffness:.8g}, {self.upper_bound:.8g}] N/m")
        # above the gap asked for (and the enclosures' 1e-9): the vertices miss the minimum
        if self.vertex_minimum > self.upper_bound * (1 + max(self.rtol, 1e-9)):
            words += (f"; the box's vertices alone give {self.vertex_minimum:.8g} N/m: the "
                      "smallest K_max is not at a vertex")
        return words

    def to_dict(self) -> dict[str, Any]:
        op = dict(zip(("mass_kg", "damping_N_s_per_m", "stiffness_N_per_m"), self.operator,
                      strict=True))
        vx = dict(zip(("mass_kg", "damping_N_s_per_m", "stiffness_N_per_m"), self.vertex,
                      strict=True))
        return jsonable({"critical_stiffness": self.critical_stiffness,
                         "operator": op,
                         "operator_critical_stiffness": self.operator_critical_stiffness,
                         "upper_bound": self.upper_bound, "gap": self.gap,
                         "converged": self.converged, "rtol": self.rtol,
                         "sub_boxes": self.boxes, "vertex_minimum": self.vertex_minimum,
                         "vertex": vx, "operator_box": self.box.to_dict(),
                         "seconds": self.seconds, "stopped": self.stopped,
                         "reason": self.reason})

    def to_csv(self, path: Any) -> None:
        """Write the named operator and the box's vertices: mass_kg, damping_N_s_per_m,
        stiffness_N_per_m, critical_stiffness (N/m), role.

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        rows = [[*map(repr, self.operator), repr(self.operator_critical_stiffness), "minimum"]]
        rows.append([*map(repr, self.vertex), repr(self.vertex_minimum), "vertex minimum"])
        write_csv(path, ["mass_kg", "damping_N_s_per_m", "stiffness_N_per_m",
                         "critical_stiffness", "role"], rows)

    def grid(self, resolution: int = 24) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray]:
        """Exact K_max over the two widest (relative) ranges of the box, the third
        parameter at the named operator's value.

        Parameters
        ----------
        resolution : int
            Points per axis.

        Returns
        -------
        i, j : int
            The parameters on the axes (0 mass, 1 damping, 2 stiffness).
        x, y : arrays
            Their values.
        K : (len(y), len(x)) array
            Exact K_max (N/m).
        """
        from hapstab.analysis.exact.crossings import analyse
        from hapstab.engine.frequency import loop_response, stack_responses

        lo, hi = self.box.lo, self.box.hi
        rel = np.where(hi > lo, (hi - lo) / np.maximum(hi, 1e-300), -1.0)   # 0 / 0 guarded
        order = np.argsort(-rel)
        i, j = int(order[0]), int(order[1])
        x = np.linspace(lo[i], hi[i], resolution)
        y = np.linspace(lo[j], hi[j], resolution if hi[j] > lo[j] else 1)
        P = np.repeat(np.array(self.operator, float)[None], x.size * y.size, axis=0)
        P[:, i] = np.tile(x, y.size)
        P[:, j] = np.repeat(y, x.size)
        # the exact core's K_max of every grid operator, in one batch
        resp = stack_responses([loop_response(self.loop.replace(operator=self.box.operator(*q)))
                                for q in P])
        K = np.array([r.kmax for r in analyse(resp, full=False)]).reshape(y.size, x.size)
        return i, j, x, y, K

    def plot(self, ax: Any = None, resolution: int = 24) -> Any:
        """A heat map of the exact K_max over the two widest ranges of the box (a curve
        when only one varies), the named operator marked.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw; a new figure when omitted.
        resolution : int
            Points per axis.

        Returns
        -------
        matplotlib Axes
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 4.5))
        i, j, x, y, K = self.grid(resolution)
        label = lambda k: f"operator {_NAMES[k]} ({_UNITS[k]})"  # noqa: E731
        if y.size == 1:
            ax.plot(x, K[0], color="C0", label="exact K_max")
            ax.plot(self.operator[i], self.operator_critical_stiffness, "r*", ms=12,
                    label="smallest K_max")
            ax.set_ylabel("K_max (N/m)")
        else:
            mesh = ax.pcolormesh(x, y, K, shading="auto", cmap="viridis")
            ax.figure.colorbar(mesh, ax=ax, label="exact K_max (N/m)")
            ax.plot(self.operator[i], self.operator[j], "r*", ms=14,
                    label=f"smallest K_max {self.operator_critical_stiffness:.4g} N/m")
            ax.set_ylabel(label(j))
        ax.set_xlabel(label(i))
        ax.set_title(f"robust K_max >= {self.critical_stiffness:.6g} N/m")
        ax.legend(loc="best", fontsize="small")
        return ax
