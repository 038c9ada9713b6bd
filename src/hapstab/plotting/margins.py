"""Nyquist and Bode views of the exact sampled loop (:mod:`hapstab.analysis.margins`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from hapstab.plotting import axes_or_new, panels_or_new


def _nyquist(view: Any, ax: Any) -> None:
    """L(e^{j theta}) for theta in (0, pi] and its mirror, the critical point -1 and, where
    it applies, the circle criterion's line Re L = -1."""
    L = view.loop
    ax.plot(L.real, L.imag, "-", color="tab:blue", lw=1.2, label="L(e^{j 2 pi f T}), 0 < f <= 1/(2T)")
    ax.plot(L.real, -L.imag, "--", color="tab:blue", lw=0.8, label="mirror (negative f)")
    ax.plot([-1.0], [0.0], "x", color="tab:red", ms=9, mew=2, label="critical point -1")
    if view.circle_bound:
        ax.axvline(-1.0, color="tab:orange", ls="-.", lw=1.2,
                   label="circle criterion, sector [0, K]: Re L > -1")
    # the view is centred on -1: a free mass's pole at z = 1 sends L far out at low f
    r = max(2.5, min(10.0, 1.5 * float(np.percentile(np.abs(L + 1.0), 30))))
    ax.set_xlim(-1.0 - r, -1.0 + r)
    ax.set_ylim(-r, r)
    ax.set_aspect("equal", adjustable="box")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set_xlabel("Re L")
    ax.set_ylabel("Im L")
    ax.set_title(f"Nyquist, K = {view.stiffness:.6g} N/m (open-loop poles outside: "
                 f"{view.open_loop_outside})", fontsize=9)
    ax.legend(fontsize=7, loc="best")


def _bode(view: Any, mag: Any, phase: Any) -> None:
    """|L| in dB and its phase against frequency, with 0 dB and -180 deg marked."""
    f, L = view.frequency_hz, view.loop
    # a floor against division by zero / rounding, far below the answer's own accuracy
    mag.semilogx(f, 20 * np.log10(np.maximum(np.abs(L), 1e-300)), "-", color="tab:blue", lw=1.0)
    mag.axhline(0.0, color="tab:red", lw=0.8, ls="--", label="|L| = 1 (0 dB)")
    mag.set_ylabel("|L| (dB)")
    # the phase wrapped into (-360, 0] (a delay turns it by 360 deg per 1/t_d Hz): dots
    ph = -np.mod(-np.degrees(np.angle(L)), 360.0)
    phase.semilogx(f, ph, ".", color="tab:blue", ms=2)
    phase.axhline(-180.0, color="tab:red", lw=0.8, ls="--", label="-180 deg")
    phase.set_ylim(-360.0, 0.0)
    phase.set_yticks([-360, -270, -180, -90, 0])
    phase.set_ylabel("phase of L (deg)")
    phase.set_xlabel("frequency (Hz)")
    mag.set_title(f"Bode, T = {view.period * 1e3:g} ms (Nyquist frequency "
                  f"{0.5 / view.period:.4g} Hz)", fontsize=9)
    for a in (mag, phase):
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7, loc="best")


def _three(ax: Any) -> np.ndarray:
    """Three axes: the ones given, or a new figure's Nyquist (square, on top) above the
    Bode pair (which share their frequency axis)."""
    if ax is not None:
        axs = np.ravel(np.asarray(ax, dtype=object))
        if axs.size != 3:
            from hapstab.errors import ModelError

            raise ModelError(f"ax: 3 axes are needed here (Nyquist, |L|, phase); got {axs.size}")
        return axs
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(7, 11))
    grid = fig.add_gridspec(3, 1, height_ratios=[1.6, 1, 1])
    nyq = fig.add_subplot(grid[0])
    mag = fig.add_subplot(grid[1])
    return np.array([nyq, mag, fig.add_subplot(grid[2], sharex=mag)], dtype=object)


def plot_frequency_view(view: Any, ax: Any = None, kind: str = "both") -> Any:
    """Nyquist (one axes), Bode (two) or both (three) of a :class:`FrequencyView`.

    Parameters
    ----------
    view : FrequencyView
        The stiffness loop.
    ax : matplotlib Axes or sequence of them, optional
        1 for ``"nyquist"``, 2 for ``"bode"``, 3 for ``"both"``; a new figure when omitted.
    kind : {"both", "nyquist", "bode"}
        Which views.

    Returns
    -------
    matplotlib Axes or array of them
    """
    from hapstab.errors import ModelError

    if kind not in ("both", "nyquist", "bode"):
        raise ModelError(f"kind = {kind!r}: allowed: both, nyquist, bode")
    if kind == "nyquist":
        a = axes_or_new(ax)
        _nyquist(view, a)
        return a
    axs = panels_or_new(ax, 2, (7, 5.5)) if kind == "bode" else _three(ax)
    if kind == "both":
        _nyquist(view, axs[0])
    _bode(view, *axs[-2:])
    if ax is None:
        axs[0].figure.tight_layout()
    return axs


def plot_margins(res: Any, ax: Any = None) -> Any:
    """A :class:`MarginResult`'s Nyquist and Bode views (three panels) under a title with
    its margins; without a view, one axes that says why.

    Parameters
    ----------
    res : MarginResult
        The margins.
    ax : sequence of 3 matplotlib Axes (one without a view), optional
        Where to draw; a new figure when omitted.

    Returns
    -------
    array of 3 matplotlib Axes, or one Axes
    """
    if res.view is None:
        a = axes_or_new(ax)
        a.text(0.5, 0.5, "no Nyquist / Bode view:\n" + res.reason, ha="center", va="center",
               wrap=True, fontsize=8, transform=a.transAxes)
        a.set_axis_off()
        return a
    axs = plot_frequency_view(res.view, ax=ax, kind="both")
    rows = dict(res.rows())
    axs[0].set_title(f"delay margin {rows['delay margin']}\nstiffness {rows['stiffness range']}"
                     f"\n{axs[0].get_title()}", fontsize=8)
    return axs
