"""The Z-width figure: passive and stable virtual walls in the (K, B) plane, and the
impedance one wall displays over frequency."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plot_zwidth"]


def plot_zwidth(res: Any, ax: Any = None) -> Any:
    """Draw a :class:`~hapstab.analysis.design.zwidth.ZWidthResult`.

    Parameters
    ----------
    res : ZWidthResult
        The Z-width.
    ax : pair of matplotlib Axes, optional
        Where to draw; a new figure with two panels when omitted.

    Returns
    -------
    array of two matplotlib Axes
    """
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(1, 2, figsize=(11, 4.4))
        fig.suptitle(res.headline, fontsize=8)
    left, right = np.ravel(np.asarray(ax, dtype=object))
    k0, k1 = res.K_window
    B = res.B_rows
    left.fill_betweenx(B, 0, np.minimum(res.K_stable, k1), color="tab:green", alpha=0.25,
                       label="stable with this operator (exact)")
    left.fill_betweenx(B, 0, np.minimum(res.K_passive, k1), color="tab:blue", alpha=0.35,
                       label="passive: stable with any passive operator")
    if res.K_quantised is not None:
        left.plot([res.K_quantised], [0.0], "v", color="tab:red", ms=8,
                  label=f"passive with friction and encoder (B = 0): {res.K_quantised:.4g} N/m")
    left.plot([res.K_at], [res.B_at], "o", color="k", label="the wall shown right")
    left.set_xlim(k0, k1)
    left.set_xlabel("virtual stiffness K (N/m)")
    left.set_ylabel("virtual damping B (N*s/m)")
    left.set_title("Z-width: the walls it renders passively and stably", fontsize=9)
    left.legend(fontsize=7, loc="upper left")
    left.grid(True, alpha=0.3)
    right.semilogx(res.frequencies_hz, res.displayed_stiffness, color="tab:blue",
                   label="displayed stiffness (N/m)")
    right.set_xlabel("frequency (Hz)")
    right.set_ylabel("stiffness (N/m)", color="tab:blue")
    twin = right.twinx()
    twin.semilogx(res.frequencies_hz, res.displayed_damping, color="tab:orange",
                  label="displayed damping (N*s/m)")
    twin.set_ylabel("damping (N*s/m)", color="tab:orange")
    right.set_title(f"impedance displayed by K = {res.K_at:.4g} N/m, B = {res.B_at:.4g} N*s/m",
                    fontsize=9)
    right.grid(True, alpha=0.3)
    return np.array([left, right], dtype=object)
