"""The result of :func:`~hapstab.simulation.run.simulate`: time series at the sampling
instants (and optionally between them), port energies, the boundedness verdict,
CSV and plot.

References
----------
The paper, Section 5 (simulated outputs watched for boundedness).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.errors import AnalysisError
from hapstab.results import Result, jsonable
from hapstab.simulation.growth import BoundednessVerdict
from hapstab.simulation.tdpa import TdpaRecord

__all__ = ["SimulationResult"]


@dataclass(frozen=True)
class SimulationResult(Result):
    """A simulated run: time series at the sampling instants (and optionally between).

    Attributes
    ----------
    time : (M+1,) s
    position, velocity : (M+1, p) m, m/s, one column per port (``labels``)
    controller_force : (M+1, p) N
        u[k], computed at t_k and held over [t_k, t_k+1); it acts on the device as -u.
    exogenous_force : (M+1, p) N
        Operator (port 0) / environment (port 1) force held over each sample.
    port_energy : (M+1, p) J
        Energy that has flowed from each device port into the sampled-data
        controller, ``sum u[i] (x[i+1] - x[i])`` (exact: u is held). A passivity
        observer: negative means the controller has delivered net energy.
    exogenous_energy : (M+1, p) J
        Work done by the exogenous forces on each port.
    states : (M+1, N)
        Full closed-loop state (plant, delay registers, controller).
    verdict : BoundednessVerdict
        Bounded or not, from the run (see :mod:`hapstab.simulation.growth`).
    labels : tuple of str
        The ports' names (``device``; ``master``, ``slave``).
    period : float
        Sampling period T in s.
    delay_samples : float
        The delay in samples (t_d / T).
    stiffness : float
        The loop's K in N/m (the master's for a teleoperator).
    nonlinear : dict
        The nonlinear elements of the run (``wall``, ``saturation``, ``resolution``,
        ...); empty for a linear run.
    contact : (M+1,) bool or None
        Wall engaged at each sample (with ``wall``).
    dense_time, dense_position, dense_velocity : arrays or None
        Exact output between samples (``dense`` points per sample).
    rest : tuple of float
        Rest position of each port's operator / environment spring (m).
    model : str
        The loop in one line (devices, terminations, T, delay), for titles.
    tdpa : TdpaRecord or None
        With ``simulate(..., tdpa=...)``: each port's observed energy, the passivity
        controller's damping and the energy it dissipated, sample by sample
        (:mod:`hapstab.simulation.tdpa`).
    friction_energy : (M+1, p) J or None
        Energy each device's Coulomb friction has dissipated since t = 0 (exact: f_c
        times the distance slid); None when no device has friction.
    """

    time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    controller_force: np.ndarray
    exogenous_force: np.ndarray
    port_energy: np.ndarray
    exogenous_energy: np.ndarray
    states: np.ndarray = field(repr=False)
    verdict: BoundednessVerdict
    labels: tuple[str, ...]
    period: float
    delay_samples: float
    stiffness: float
    nonlinear: dict[str, Any] = field(default_factory=dict)
    contact: np.ndarray | None = field(default=None, repr=False)
    dense_time: np.ndarray | None = field(default=None, repr=False)
    dense_position: np.ndarray | None = field(default=None, repr=False)
    dense_velocity: np.ndarray | None = field(default=None, repr=False)
    rest: tuple[float, ...] = ()
    model: str = ""
    tdpa: TdpaRecord | None = field(default=None, repr=False)
    friction_energy: np.ndarray | None = field(default=None, repr=False)

    @property
    def bounded(self) -> bool:
        return self.verdict.bounded

    def summary(self) -> dict[str, Any]:
        """Scalars: verdict, peaks and final energies per port."""
        out: dict[str, Any] = {"samples": self.time.size - 1, "duration_s": float(self.time[-1]),
                               "period_s": self.period, "delay_samples": self.delay_samples,
                               "stiffness": self.stiffness, "nonlinear": self.nonlinear,
                               "rest_position_m": list(self.rest),
                               **self.verdict.to_dict()}
        tenth = max(self.time.size // 10, 2)     # the first and last tenth of the run
        for j, lab in enumerate(self.labels):
            x = self.position[:, j]
            # what a reader sees on the plot: half the peak-to-peak position at the start
            # and at the end of the run
            # (an overflowed run's inf - inf is nan: null in JSON, as its other values)
            with np.errstate(invalid="ignore"):
                out[f"swing_start_m_{lab}"] = float(np.ptp(x[:tenth]) / 2)
                out[f"swing_end_m_{lab}"] = float(np.ptp(x[-tenth:]) / 2)
            out[f"max_abs_position_{lab}"] = float(np.abs(self.position[:, j]).max())
            out[f"max_abs_force_{lab}"] = float(np.abs(self.controller_force[:, j]).max())
            out[f"final_port_energy_{lab}"] = float(self.port_energy[-1, j])
            if self.friction_energy is not None:
                out[f"friction_dissipated_J_{lab}"] = float(self.friction_energy[-1, j])
        if self.tdpa is not None:
            out.update(self.tdpa.summary(self.labels))
        return jsonable(out)

    def to_dict(self, series: bool = False) -> dict[str, Any]:
        d = self.summary()
        if series:
            d["series"] = {k: jsonable(v) for k, v in self._columns().items()}
        return d

    def _columns(self, dense: bool = False) -> dict[str, np.ndarray]:
        if dense:
            pos, vel = self.dense_position, self.dense_velocity
            if self.dense_time is None or pos is None or vel is None:
                raise AnalysisError("dense output was not requested: simulate(..., dense=m)")
            cols = {"time_s": self.dense_time}
            for j, lab in enumerate(self.labels):
                cols[f"x_{lab}_m"] = pos[:, j]
                cols[f"v_{lab}_m_per_s"] = vel[:, j]
            return cols
        cols = {"time_s": self.time}
        for j, lab in enumerate(self.labels):
            cols[f"x_{lab}_m"] = self.position[:, j]
            cols[f"v_{lab}_m_per_s"] = self.velocity[:, j]
            cols[f"u_{lab}_N"] = self.controller_force[:, j]
            cols[f"f_ext_{lab}_N"] = self.exogenous_force[:, j]
            cols[f"port_energy_{lab}_J"] = self.port_energy[:, j]
            if self.friction_energy is not None:
                cols[f"friction_energy_{lab}_J"] = self.friction_energy[:, j]
        if self.contact is not None:
            cols["contact"] = self.contact.astype(int)
        if self.tdpa is not None:
            cols.update(self.tdpa.columns(self.labels))
        return cols

    def to_csv(self, path: Any, dense: bool = False) -> None:
        """Write the sampled (or, with ``dense``, the between-sample) series as CSV.

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        dense : bool
            The between-sample series (needs ``simulate(..., dense=m)``).

        Raises
        ------
        OutputError
            The run left the range of double precision (a value is inf or NaN): a
            file of such numbers would be silently wrong, so nothing is written.
        """
        from hapstab.outputs import OutputError, writing

        cols = self._columns(dense)
        data = np.column_stack(list(cols.values()))
        bad = ~np.all(np.isfinite(data), axis=1)
        if bad.any():
            t = float(data[int(np.argmax(bad)), 0])
            raise OutputError(f"CSV not written: the run overflowed double precision at t = "
                              f"{t:.6g} s (the loop is unstable), so its series would be inf/NaN")
        with writing(path, "path") as fh:
            np.savetxt(fh, data, delimiter=",", header=",".join(cols), comments="", fmt="%.17g")

    def plot(self, ax: Any = None) -> Any:
        """Position, controller force and port energy against time (and, with TDPA, the
        observed energy, the PC's dissipation and its damping).

        Parameters
        ----------
        ax : sequence of 3 (with TDPA 4) matplotlib Axes, optional
            Where to draw the panels; a new figure when omitted.

        Returns
        -------
        array of 3 (with TDPA 4) matplotlib Axes
            (:func:`hapstab.plotting.save_plot` writes the figure to a file.)
        """
        from hapstab.plotting import plot_simulation
        return plot_simulation(self, ax)
