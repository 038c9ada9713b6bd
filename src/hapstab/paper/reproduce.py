"""Reproduce the paper's simulation study: Fig. 5 (HVE) and Fig. 6 (PEB).

For each sampling period T (1 to 10 ms in steps of 1 ms, as in Section 5) and each
delay (Fig. 5: n = 0 and 10; Fig. 6: n = 0 and 4) this computes

* ``theory``: the paper's condition, eq. (13) / (18) for the HVE and (29) / (34)
  for PEB (solid lines in the paper's figures);
* ``simulation``: the paper's procedure, the largest K whose simulated loop stays
  bounded (:func:`~hapstab.simulation.search.critical_stiffness_simulation`, the stars);
* ``exact``: the exact K_max of the sampled-data loop (:mod:`hapstab.analysis.exact`);
* ``circle``: the circle-criterion K_max, when that method is registered.

and writes ``figN.png``, ``figN.svg`` and ``figN.csv``.

References
----------
The paper, Section 5, Fig. 5 and Fig. 6; eq. (13), (18), (29), (34).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.analysis.conditions.closed_forms import EQUATION, PAPER, paper_condition
from hapstab.analysis.exact.core import exact_critical_stiffness
from hapstab.errors import AnalysisError, HapstabError
from hapstab.paper.loops import paper_hve, paper_peb
from hapstab.results import Result, jsonable, write_csv

__all__ = ["FIGURES", "PAPER_PERIODS", "FigureSpec", "Reproduction", "reproduce_figure",
           "write_figure", "COLUMNS"]

#: Section 5: "the sampling time is increased by steps of 1 ms"
PAPER_PERIODS = tuple(float(x) for x in np.round(np.arange(1, 11) * 1e-3, 12))

COLUMNS = ("period_s", "delay_samples", "theory", "exact", "simulation")


@dataclass(frozen=True)
class FigureSpec:
    """One of the paper's figures: loop, delays and the theoretical lines."""

    name: str
    title: str
    make: Callable[..., Any]
    delays: tuple[int, int]

    @property
    def equations(self) -> tuple[str, str]:
        """The paper's equation without and with delay (closed_forms.PAPER)."""
        keys = PAPER[self.make().kind]
        return EQUATION[keys[0]], EQUATION[keys[1]]


FIGURES: dict[str, FigureSpec] = {
    "fig5": FigureSpec("fig5", "Fig. 5: HVE, m = 0.15 kg, b = 0.1 Ns/m, operator 1/s, B = 0",
                       paper_hve, (0, 10)),
    "fig6": FigureSpec("fig6", "Fig. 6: PEB, m = 0.015 kg, b = 0.02 Ns/m, terminations 1/s, B = 0",
                       paper_peb, (0, 4)),
}


@dataclass(frozen=True)
class Reproduction(Result):
    """The points of one figure.

    Attributes
    ----------
    figure : FigureSpec
    rows : tuple of dict
        One per (delay, period): ``period_s, delay_samples, theory, exact,
        simulation`` (and ``circle``), plus ``equation``.
    columns : tuple of str
        The CSV columns.
    """

    figure: FigureSpec
    rows: tuple[dict[str, Any], ...]
    columns: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"figure": self.figure.name, "title": self.figure.title,
                         "rows": [dict(r) for r in self.rows]})

    def to_csv(self, path: Any) -> None:
        """Write the points as CSV, one row per (delay, period), columns :attr:`columns`.

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        write_csv(path, self.columns,
                  ([repr(float(r[c])) if c != "delay_samples" else int(r[c])
                    for c in self.columns] for r in self.rows))

    def plot(self, ax: Any = None) -> Any:
        """The figure like the paper's (see :func:`hapstab.plotting.plot_reproduction`).

        Parameters
        ----------
        ax : sequence of 2 matplotlib Axes, optional
            Where to draw the two panels; a new figure when omitted.

        Returns
        -------
        array of 2 matplotlib Axes
        """
        from hapstab.plotting import plot_reproduction
        return plot_reproduction(self, ax)

    def worst_simulation_error(self) -> float:
        """max |simulation / exact - 1| over the points with finite exact K_max."""
        errs = [abs(r["simulation"] / r["exact"] - 1) for r in self.rows
                if math.isfinite(r["exact"]) and r["exact"] > 0]
        return max(errs, default=math.nan)


def _circle(loop: Any) -> float:
    from hapstab.analysis.methods import critical_stiffness
    try:
        return float(critical_stiffness(loop, method="circle").critical_stiffness)
    except (HapstabError, ImportError):   # the method may not apply or not be installed yet
        return math.nan


def reproduce_figure(name: str, periods: Sequence[float] | None = None, *,
                     progress: Callable[[int], None] | None = None,
                     simulation_options: dict[str, Any] | None = None) -> Reproduction:
    """Compute the points of Fig. 5 or Fig. 6.

    Parameters
    ----------
    name : {"fig5", "fig6"}
    periods : sequence of float, optional
        Sampling periods in s (default: the paper's 1..10 ms).
    progress : callable, optional
        Called with 1 after each (period, delay) point.
    simulation_options : dict, optional
        Passed to :func:`~hapstab.simulation.search.critical_stiffness_simulation`.

    Returns
    -------
    Reproduction

    Raises
    ------
    AnalysisError
        Unknown figure name or invalid periods.
    """
    from hapstab import budget
    from hapstab.simulation.search import critical_stiffness_simulation, search_cost

    if name not in FIGURES:
        raise AnalysisError(f"figure = {name!r}: unknown; allowed: {', '.join(FIGURES)}")
    spec = FIGURES[name]
    T = PAPER_PERIODS if periods is None else tuple(float(t) for t in periods)
    if not T or not all(math.isfinite(t) and t > 0 for t in T):
        raise AnalysisError(f"periods = {list(T)}: need at least one finite period > 0")
    cols = (*COLUMNS, "circle")
    rows = []
    budget.check(search_cost(spec.make(min(T), max(spec.delays)),
                             len(T) * len(spec.delays)))
    for n in spec.delays:
        for t in T:
            loop = spec.make(t, n, 1.0)
            row: dict[str, Any] = {
                "period_s": t, "delay_samples": float(n),
                "theory": paper_condition(loop).function(loop).critical_stiffness,
                "exact": exact_critical_stiffness(loop).critical_stiffness,
                "simulation": critical_stiffness_simulation(
                    loop, **(simulation_options or {})).critical_stiffness}
            row["circle"] = _circle(loop)
            row["equation"] = EQUATION[paper_condition(loop).key]
            rows.append(row)
            if progress:
                progress(1)
    return Reproduction(spec, tuple(rows), cols)


def write_figure(rep: Reproduction, out_dir: str) -> list[str]:
    """Write ``<fig>.csv``, ``<fig>.png``, ``<fig>.svg`` and ``manifest.json`` into
    ``out_dir``, atomically (see :func:`hapstab.outputs.write_folder`).

    Parameters
    ----------
    rep : Reproduction
        The figure's points.
    out_dir : str
        The folder (created if missing).

    Returns
    -------
    list of str
        The paths written, the manifest last.

    Raises
    ------
    OutputError
        If ``out_dir`` cannot be created or written.
    """
    from hapstab import __version__
    from hapstab.outputs import write_folder

    manifest = {"command": "reproduce", "figure": rep.figure.name,
                "periods_s": sorted({r["period_s"] for r in rep.rows}),
                "hapstab_version": __version__}
    return write_folder(out_dir, [(rep.figure.name, rep)], manifest, "--out")
