"""The limit-cycle figure: what :func:`hapstab.limit_cycles`'s verdict solves, drawn.

With one nonlinearity the first-harmonic balance is two curves that meet at a cycle: the
loop the quantiser sees, C(e^{jwT}), against -1/N(A) (quantisation), or j P/(1 + C)
against -pi A/(4 f_c) (friction). With both, friction's equivalent damper
``4 f_c/(pi A w)`` depends on the amplitude, so C against -1/N(A) alone is not the balance
(its curves can cross where friction leaves no cycle, e.g. 0.05 N of friction on a 2 µm
encoder, whose K Δ is a thousandth of it); the figure is then the balance itself,
``F(A, f) = 1 + N(A) C + j (4 f_c/(pi A)) P = 0``, as the curves Re F = 0 and Im F = 0
over amplitude and frequency, which cross exactly at its roots.

References
----------
N. Diolaiti, G. Niemeyer, F. Barbagli and J. K. Salisbury, "Stability of haptic
rendering: discretization, quantization, time delay, and Coulomb effects," IEEE Trans.
Robotics 22(2), 2006. A. Gelb and W. E. Vander Velde, *Multiple-Input Describing
Functions and Nonlinear System Design*, McGraw-Hill, 1968.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["plot_limit_cycles", "balance_grid", "from_root", "NEAR_MISS_NOTE"]

#: How the notes of a cycle begin that harmonic balance found at a near miss of the first
#: harmonic (it has no root there: the figure's curves come close but do not meet);
#: :func:`hapstab.analysis.nonlinear.limit_cycles.limit_cycles` writes it.
NEAR_MISS_NOTE = "the describing function has no root here"



def from_root(cycle: Any) -> bool:
    """Whether a predicted cycle refines a root of the first-harmonic balance (where the
    figure's curves meet), not a near miss that only the harmonics close.

    Parameters
    ----------
    cycle : PredictedCycle

    Returns
    -------
    bool
    """
    return not cycle.notes.startswith(NEAR_MISS_NOTE)


def _mark(ax: Any, x: float, y: float, cycle: Any) -> None:
    """A cycle: a circle at a root (filled: stable), a square at a near miss."""
    ax.plot([x], [y], "o" if from_root(cycle) else "s", ms=8, color="k",
            mfc="k" if cycle.stable else "w")


def _legend_marks(res: Any) -> list[Any]:
    from matplotlib.lines import Line2D

    out = []
    if any(from_root(c) for c in res.cycles):
        out.append(Line2D([], [], ls="", marker="o", color="k",
                          label="cycles where they meet (filled: stable)"))
    if not all(from_root(c) for c in res.cycles):
        out.append(Line2D([], [], ls="", marker="s", color="k", mfc="w",
                          label="a cycle the harmonics close where they only come near"))
    return out


def balance_grid(res: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first-harmonic balance F on the result's grid (both nonlinearities).

    Parameters
    ----------
    res : LimitCycleResult
        With quantisation and Coulomb friction.

    Returns
    -------
    frequency_hz : array
        Of the angles per sample searched.
    amplitude_m : array
        The amplitudes searched.
    F : complex array
        ``F[i, j] = 1 + N(A_i) C(theta_j) + j (4 f_c/(pi A_i)) P(theta_j)``.
    """
    c = res.curves
    F = (1 + c["gain"][:, None] * c["loop"][None, :]
         + 1j * c["relay"][:, None] * c["plant"][None, :])
    return c["theta"] / (2 * math.pi * res.period_s), c["amplitude_m"], F


def plot_limit_cycles(res: Any, ax: Any = None) -> Any:
    """Draw a :class:`~hapstab.analysis.nonlinear.limit_cycle_results.LimitCycleResult`.

    Parameters
    ----------
    res : LimitCycleResult
    ax : matplotlib Axes, optional
        Where to draw; a new figure when omitted.

    Returns
    -------
    matplotlib Axes
    """
    from hapstab.plotting import axes_or_new

    ax = axes_or_new(ax)
    if res.resolution_m and res.coulomb_friction_N:
        return _balance(res, ax)
    g, inv = res.curves["loop"], res.curves["minus_inverse"]
    fin = np.isfinite(inv)
    quant = bool(res.resolution_m)
    ax.plot(g.real, g.imag, "-", color="tab:blue",
            label="C(e^jwT), the loop the quantiser sees" if quant else "j P/(1 + C)")
    ax.plot(inv[fin], np.zeros(int(fin.sum())), "-", lw=3, color="tab:red", alpha=0.6,
            label="-1/N(A)" if quant else "-pi A/(4 f_c)")
    marks = []
    for c in res.cycles:
        x = float(np.interp(c.describing_function_amplitude_m, res.curves["amplitude_m"],
                            inv.real))
        marks.append(abs(x))
        _mark(ax, x, 0.0, c)
    # the view: around the first phase crossover and the cycles (1e-300: never a 0 scale)
    R = 2 * max([1 / g for _, g in res.crossovers[:1] if quant] + marks + [1e-300])
    ax.set_xlim(-R, R / 2)
    ax.set_ylim(-R, R)
    ax.axhline(0, color="0.8", lw=0.5)
    ax.set_xlabel("real")
    ax.set_ylabel("imaginary")
    ax.set_title(f"describing function, K = {res.stiffness:g} N/m: {res.verdict}")
    handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=handles + _legend_marks(res), loc="best", fontsize=8)
    return ax


def _balance(res: Any, ax: Any) -> Any:
    """Quantisation and friction: Re F = 0 and Im F = 0 over (frequency, amplitude)."""
    from matplotlib.lines import Line2D

    f, A, F = balance_grid(res)
    keep = f > 0
    f, F = f[keep], F[:, keep]
    for part, color in ((F.real, "tab:blue"), (F.imag, "tab:red")):
        if np.nanmin(part) < 0 < np.nanmax(part):       # (contour warns on a level not met)
            ax.contour(f, A, part, levels=[0.0], colors=color, linewidths=1.5)
    for c in res.cycles:
        _mark(ax, c.describing_function_frequency_hz, c.describing_function_amplitude_m, c)
    ax.set_xscale("log")
    ax.set_yscale("log")
    seen = [fc for fc, _ in res.crossovers] + [c.describing_function_frequency_hz
                                               for c in res.cycles]
    if seen:                # from two decades below the crossovers and cycles to Nyquist
        ax.set_xlim(max(f[0], 1e-2 * min(seen)), f[-1])
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("amplitude A (m)")
    ax.set_title(f"first-harmonic balance with friction, K = {res.stiffness:g} N/m: "
                 f"{res.verdict}", fontsize=10)
    handles = [Line2D([], [], color="tab:blue", label="Re F = 0"),
               Line2D([], [], color="tab:red", label="Im F = 0"),
               Line2D([], [], ls="", label="F = 1 + N(A) C + j 4 f_c/(pi A) P: a cycle "
                      "where they cross")]
    ax.legend(handles=handles + _legend_marks(res), loc="best", fontsize=7)
    return ax
