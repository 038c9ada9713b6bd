"""Plotting. matplotlib is imported here only, and only when a plot is asked for."""

from __future__ import annotations

from typing import Any

import numpy as np


def _axes(ax: Any) -> Any:
    if ax is None:
        import matplotlib

        if matplotlib.get_backend().lower() not in ("agg", "svg", "pdf") and not _has_display():
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6, 4))
    return ax


def _has_display() -> bool:
    import os

    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def plot_boundary(res: Any, ax: Any = None) -> Any:
    """K_max against T, one curve per delay (Fig. 5 / Fig. 6 style)."""
    ax = _axes(ax)
    colors = ["tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange"]
    for i, n in enumerate(res.delays):
        ax.plot(res.periods * 1e3, res.critical_stiffness[i], "-", color=colors[i % len(colors)],
                label=f"{res.method}, n = {n}")
    ax.set_xlabel("sampling period T (ms)")
    ax.set_ylabel("K_max (N/m)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return ax


def plot_poles(res: Any, ax: Any = None) -> Any:
    """Closed-loop poles and the unit circle."""
    ax = _axes(ax)
    th = np.linspace(0, 2 * np.pi, 400)
    ax.plot(np.cos(th), np.sin(th), "k-", lw=0.8)
    p = np.array(res.poles)
    ax.plot(p.real, p.imag, "x", color="tab:red" if res.verdict == "unstable" else "tab:blue")
    ax.set_aspect("equal")
    ax.set_xlabel("Re z")
    ax.set_ylabel("Im z")
    ax.set_title(f"{res.verdict}: spectral radius {res.spectral_radius:.6g}")
    return ax
