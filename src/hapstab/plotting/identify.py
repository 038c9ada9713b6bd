"""The identification figure: the encoder's readings, the fitted exact model, and the
residuals."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plot_identification"]


def plot_identification(res: Any, ax: Any = None) -> Any:
    """Draw an :class:`~hapstab.analysis.identification.identify_result.IdentificationResult`.

    Parameters
    ----------
    res : IdentificationResult
        The identified device.
    ax : matplotlib Axes or pair of Axes, optional
        One Axes: readings and fit; two: also the residuals; a new figure with the
        force, the fit and the residuals when omitted.

    Returns
    -------
    matplotlib Axes or array of them
    """
    import matplotlib.pyplot as plt

    if ax is None:
        fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True,
                                 gridspec_kw={"height_ratios": [1, 2, 1]})
        fig.suptitle(res.summary(), fontsize=8)
        force, fit, resid = axes
        force.step(res.time_s, res.force_N, where="post", color="tab:gray", lw=0.8)
        force.set_ylabel("commanded force (N)")
    else:
        axes = np.ravel(np.asarray(ax, dtype=object))
        fit, resid = axes[0], (axes[1] if axes.size > 1 else None)
    mm = 1e3
    fit.plot(res.time_s, res.position_m * mm, ".", ms=2, color="tab:blue",
             label="encoder reading")
    fit.plot(res.time_s, res.fitted_m * mm, "-", lw=1, color="tab:orange",
             label="fitted exact model")
    fit.set_ylabel("position (mm)")
    fit.legend(fontsize=8, loc="best")
    if resid is not None:
        r = res.residuals_m * 1e6
        resid.plot(res.time_s, r, ".", ms=2, color="tab:red")
        resid.axhline(0, color="k", lw=0.6)
        resid.set_ylabel("reading + Δ/2 - fit (µm)" if res.reading_offset_m
                         else "reading - fit (µm)")
        resid.set_xlabel("time (s)")
    else:
        fit.set_xlabel("time (s)")
    return axes
