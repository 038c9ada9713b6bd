"""Plotting. matplotlib is imported here only, and only when a plot is asked for."""

from __future__ import annotations

from typing import Any

import numpy as np


def axes_or_new(ax: Any) -> Any:
    """``ax`` itself, or the axes of a new figure on pyplot's current backend (a library
    never switches the user's backend: in a notebook the figure shows inline, in a script
    on screen, and the CLI, which writes files, chooses Agg itself)."""
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6, 4))
    return ax


#: File formats a figure is written in: matplotlib's own writers, no external
#: program (pgf needs LaTeX, which a user may not have)
FORMATS = ("png", "svg", "svgz", "pdf", "eps", "ps", "jpg", "jpeg", "tif", "tiff", "webp")


def save_figure(fig: Any, path: Any, name: str = "plot", **kw: Any) -> None:
    """Write ``fig`` to ``path`` (atomically) in the format its extension names.

    Parameters
    ----------
    fig : matplotlib Figure
        The figure.
    path : str or os.PathLike
        The file; its extension is the format, one of :data:`FORMATS`.
    name : str
        The option or argument that gave it, named in errors (``"--plot"``).
    **kw
        Passed to ``savefig`` (e.g. ``dpi``).

    Raises
    ------
    OutputError
        Not a format hapstab writes, an empty path, a missing folder, or a failed write
        (the previous file, if any, is left as it was).
    """
    from hapstab.outputs import check_target, writing

    target = check_target(path, name, FORMATS)
    ext = target.rsplit(".", 1)[-1].lower()
    with writing(target, name, "wb") as fh:
        fig.savefig(fh, format=ext, **kw)


def _wrap(text: str, ax: Any, fontsize: float) -> str:
    """A model line broken into lines as wide as the axes' figure (a character is about
    0.6 of the font size wide)."""
    import textwrap

    width = int(ax.figure.get_figwidth() * 72 / (0.6 * fontsize))
    return "\n".join(textwrap.wrap(text, max(width, 40), break_long_words=False))


def plot_boundary(res: Any, ax: Any = None) -> Any:
    """K_max against T (ms) or the sampling rate (Hz), one curve per delay (Fig. 5 / 6)."""
    ax = axes_or_new(ax)
    colors = ["tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown"]
    by_rate = getattr(res, "axis", "period") == "rate"
    x = 1.0 / res.periods if by_rate else res.periods * 1e3
    order = np.argsort(x)
    for i, d in enumerate(res.delays):
        label = (f"t_d = {d * 1e3:g} ms" if getattr(res, "delay_unit", "samples") == "s"
                 else f"n = {int(d)}")
        ax.plot(x[order], res.critical_stiffness[i][order], "o-" if x.size < 30 else "-",
                ms=3, color=colors[i % len(colors)], label=label)
    ax.set_xlabel("sampling rate 1/T (Hz)" if by_rate else "sampling period T (ms)")
    ax.set_ylabel("K_max (N/m)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(f"K_max of the {res.loop_kind.upper()} loop, method {res.method}")
    ax.legend(title="delay")
    return ax


def plot_poles(res: Any, ax: Any = None) -> Any:
    """Closed-loop poles and the unit circle."""
    ax = axes_or_new(ax)
    th = np.linspace(0, 2 * np.pi, 400)
    ax.plot(np.cos(th), np.sin(th), "k-", lw=0.8)
    p = np.array(res.poles)
    ax.plot(p.real, p.imag, "x", color="tab:red" if res.verdict == "unstable" else "tab:blue")
    ax.set_aspect("equal")
    ax.set_xlabel("Re z")
    ax.set_ylabel("Im z")
    ax.set_title(f"{res.verdict}: spectral radius {res.spectral_radius:.6g}")
    return ax


# ------------------------------------------------ simulation and reproduction (issue 4)
def _figure(nrows: int = 1, figsize: tuple[float, float] = (7, 4.5)) -> tuple[Any, Any]:
    """A new figure of ``nrows`` stacked axes on pyplot's current backend (see
    :func:`axes_or_new`)."""
    import matplotlib.pyplot as plt

    return plt.subplots(nrows, 1, figsize=figsize, sharex=nrows > 1, squeeze=False)


def panels_or_new(ax: Any, n: int, figsize: tuple[float, float]) -> np.ndarray:
    """``n`` stacked axes: the ones given (a sequence of n) or a new figure's."""
    if ax is None:
        return _figure(n, figsize)[1][:, 0]
    axs = np.ravel(np.asarray(ax, dtype=object))
    if axs.size != n:
        from hapstab.errors import ModelError

        raise ModelError(f"ax: {n} axes are needed here, one per panel; got {axs.size}")
    return axs


def plot_simulation(res: Any, ax: Any = None) -> Any:
    """Position, controller force and port energy (passivity observer) against time;
    with TDPA a fourth panel: each port's observed energy and the energy its passivity
    controller dissipated, and the controller's damping on a second axis.

    Parameters
    ----------
    res : SimulationResult
        The run.
    ax : sequence of 3 (with TDPA 4) matplotlib Axes, optional
        Where to draw the panels; a new figure when omitted.

    Returns
    -------
    array of 3 (with TDPA 4) matplotlib Axes
    """
    rec = getattr(res, "tdpa", None)
    axs = panels_or_new(ax, 3 if rec is None else 4, (7, 7) if rec is None else (7, 9))
    ax1, ax2, ax3 = axs[:3]
    # an overflowed run: its values past 1e100 are left out (a gap); matplotlib cannot
    # place ticks on an axis that spans ~1e300
    fin = lambda a: np.where(np.abs(a) < 1e100, a, np.nan)  # noqa: E731
    for j, lab in enumerate(res.labels):
        if res.dense_time is not None:
            ax1.plot(res.dense_time, fin(res.dense_position[:, j]), "-", lw=0.8, label=f"x {lab}")
        else:
            ax1.plot(res.time, fin(res.position[:, j]), "-", lw=0.8, label=f"x {lab}")
        ax2.step(res.time, fin(res.controller_force[:, j]), where="post", lw=0.8,
                 label=f"u {lab}")
        if np.any(res.exogenous_force[:, j] != 0):     # the force the user gave, held
            ax2.step(res.time, fin(res.exogenous_force[:, j]), where="post", lw=0.8, ls="--",
                     label=f"applied force on {lab}")
        ax3.plot(res.time, fin(res.port_energy[:, j]), "-", lw=0.8,
                 label=f"into controller from {lab}")
        fe = getattr(res, "friction_energy", None)     # the device's Coulomb friction
        if fe is not None and np.any(fe[:, j]):
            ax3.plot(res.time, fin(fe[:, j]), ":", lw=0.8, label=f"dissipated by friction, {lab}")
    ax1.set_ylabel("position (m)")
    ax2.set_ylabel("force (N)")
    ax3.set_ylabel("port energy (J)")
    axs[-1].set_xlabel("time (s)")
    if rec is not None:
        _tdpa_panel(res, rec, axs[3], fin)
    v = res.verdict
    nl = res.nonlinear or {}
    if nl.get("wall") is not None:
        ax1.axhline(nl["wall"], color="k", lw=1.0, ls="--", label=f"wall at {nl['wall']:g} m")
        x = fin(res.position[:, 0])
        ax1.fill_between(res.time, nl["wall"], x, where=x > nl["wall"], color="tab:red",
                         alpha=0.15, lw=0, label="penetration")
    if nl.get("saturation") is not None:
        for sign in (1, -1):
            ax2.axhline(sign * nl["saturation"], color="k", lw=1.0, ls=":",
                        label=f"saturation +-{nl['saturation']:g} N" if sign > 0 else None)
    ax1.set_title(f"K = {res.stiffness:g} N/m, T = {res.period * 1e3:g} ms, n = "
                  f"{res.delay_samples:g}: {v.words()}; growth rate {v.rate_words()}"
                  + (f"\n{_wrap(res.model, ax1, 8)}" if getattr(res, "model", "") else ""),
                  fontsize=8)
    for a in axs:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8, loc="best")
    if ax is None:
        ax1.figure.tight_layout()
    return axs


def _tdpa_panel(res: Any, rec: Any, ax: Any, fin: Any) -> None:
    """The TDPA panel: observed energy and dissipated energy per port (J), the PC's
    damping (N*s/m) on a second axis."""
    twin = ax.twinx()
    for j, lab in enumerate(res.labels):
        ax.plot(res.time, fin(rec.observed[:, j]), "-", lw=0.8, label=f"observed energy, {lab}")
        ax.plot(res.time, fin(rec.dissipated[:, j]), "--", lw=0.8,
                label=f"dissipated by the PC, {lab}")
        twin.plot(res.time, fin(rec.damping[:, j]), ":", lw=0.6, color="0.4",
                  label=f"PC damping, {lab}")
    ax.set_ylabel("TDPA energy (J)")
    twin.set_ylabel("PC damping (N s/m)", fontsize=8)
    twin.legend(fontsize=7, loc="lower right")


def plot_reproduction(res: Any, ax: Any = None) -> Any:
    """K_max against T like the paper's Fig. 5 / Fig. 6, and below it each method's
    K_max relative to the paper's line (%), where the differences the upper log-scale
    panel hides (0.01 to a few %) show.

    Upper panel: the paper's theoretical lines (solid), simulation stars, exact boundary
    (dashed) and circle criterion (dotted) if present; one colour per delay. Lower panel:
    100 (K / K_paper - 1) for exact, circle and simulation. The legends name each style
    and each colour once.

    Parameters
    ----------
    res : Reproduction
        The figure's points (rows with ``period_s, delay_samples, theory, exact,
        simulation`` and maybe ``circle``) and its title and equations.
    ax : sequence of 2 matplotlib Axes, optional
        Where to draw the two panels; a new figure when omitted.

    Returns
    -------
    array of 2 matplotlib Axes
    """
    from matplotlib.lines import Line2D

    axs = panels_or_new(ax, 2, (7, 7))
    top, bottom = axs
    rows, equations = list(res.rows), res.figure.equations
    delays = sorted({r["delay_samples"] for r in rows})
    colors = ["tab:blue", "tab:red", "tab:green", "tab:purple"]
    styles = {"theory": ("-", None, 1.5), "exact": ("--", None, 1.0), "circle": (":", None, 1.4),
              "simulation": ("", "*", 0.0)}
    shown = [k for k in styles if k in rows[0]]
    for i, n in enumerate(delays):
        c = colors[i % len(colors)]
        sel = sorted((r for r in rows if r["delay_samples"] == n), key=lambda r: r["period_s"])
        T = np.array([r["period_s"] for r in sel]) * 1e3
        paper = np.array([r["theory"] for r in sel], float)
        for k in shown:
            ls, mk, lw = styles[k]
            y = np.array([r[k] for r in sel], float)
            top.plot(T, y, ls, marker=mk, color=c, lw=lw, ms=8)
            if k != "theory":
                with np.errstate(all="ignore"):
                    bottom.plot(T, 100 * (y / paper - 1), ls or "", marker=mk or ".", color=c,
                                lw=max(lw, 1.0), ms=7)
    by_style = [Line2D([], [], color="k", ls=styles[k][0] or "none", marker=styles[k][1],
                       lw=styles[k][2] or 1.0,
                       label={"theory": "paper (eq. " + " / ".join(equations) + ")",
                              "exact": "exact", "circle": "circle criterion",
                              "simulation": "simulation"}[k]) for k in shown]
    by_delay = [Line2D([], [], color=colors[i % len(colors)], lw=3, label=f"n = {n:g}")
                for i, n in enumerate(delays)]
    top.add_artist(top.legend(handles=by_style, fontsize=8, loc="upper right"))
    top.legend(handles=by_delay, fontsize=8, loc="lower left")
    top.set_ylabel("K_max (N/m)")
    top.set_yscale("log")
    top.set_title(res.figure.title, fontsize=10)
    bottom.axhline(0.0, color="k", lw=0.8)
    bottom.set_ylabel("K_max / paper - 1 (%)")
    bottom.set_xlabel("sampling period T (ms)")
    for a in axs:
        a.grid(True, which="both", alpha=0.3)
    if ax is None:
        top.figure.tight_layout()
    return axs


def plot_audit(res: Any, ax: Any = None) -> Any:
    """K_max of every condition of an audit (bars, log scale), the exact limit as a
    vertical line; a condition that promises more than the exact limit is red.

    Parameters
    ----------
    res : AuditResult
        The audit.
    ax : matplotlib Axes, optional
        Where to draw; a new figure when omitted.

    Returns
    -------
    matplotlib Axes
    """
    ax = axes_or_new(ax)
    rows = [r for r in res.rows if np.isfinite(r.critical_stiffness) and r.critical_stiffness > 0]
    y = np.arange(len(rows))
    ax.barh(y, [r.critical_stiffness for r in rows],
            color=["tab:red" if r.flag else "tab:blue" for r in rows])
    ax.set_yticks(y, [r.label for r in rows], fontsize=8)
    if np.isfinite(res.exact_kmax) and res.exact_kmax > 0:
        ax.axvline(res.exact_kmax, color="k", lw=1.0, ls="--",
                   label=f"exact K_max = {res.exact_kmax:.6g} N/m")
        ax.legend(fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("K_max (N/m)")
    ax.set_title(f"audit, {res.kind}: T = {res.period * 1e3:g} ms, n = {res.delay_samples:g} "
                 "(red: promises more than the exact limit)", fontsize=9)
    ax.grid(True, axis="x", which="both", alpha=0.3)
    return ax


def plot_best_damping(res: Any, ax: Any = None) -> Any:
    """K_max against the virtual damping B, with the best B* marked.

    Parameters
    ----------
    res : BestDampingResult
        The scan.
    ax : matplotlib Axes, optional
        Where to draw; a new figure when omitted.

    Returns
    -------
    matplotlib Axes
    """
    ax = axes_or_new(ax)
    ax.plot(res.B_curve, res.K_curve, "-", color="tab:blue", lw=1.2)
    ax.plot([res.damping], [res.critical_stiffness], "o", color="k",
            label=f"B* = {res.damping:.6g} N*s/m, K* = {res.critical_stiffness:.6g} N/m")
    ax.set_xlabel("virtual damping B (N*s/m)")
    ax.set_ylabel("K_max (N/m)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return ax


def save_plot(res: Any, path: Any, name: str = "plot", **kw: Any) -> str:
    """Draw ``res.plot()`` on a new figure, write it to ``path`` and close it.

    Parameters
    ----------
    res : result object
        Anything with a ``plot(ax=None)`` returning its axes.
    path : str or os.PathLike
        The file; its extension names the format (:data:`FORMATS`).
    name : str
        The option or argument that gave it, named in errors (``"--plot"``).
    **kw
        Passed to ``savefig`` (e.g. ``dpi``).

    Returns
    -------
    str
        ``path``.

    Raises
    ------
    OutputError
        See :func:`save_figure`; checked before anything is drawn.
    """
    from hapstab.outputs import Outputs, check_target, figure_to

    check_target(path, name, FORMATS)
    with Outputs() as out:
        figure_to(out, res, str(path), name, **kw)
    return str(path)


def plot_positive_real(res: Any, ax: Any = None) -> Any:
    """Smallest eigenvalue of G(e^{jw}) + G^H(e^{jw}) against frequency (Definition 1,
    condition iii), with the worst frequency marked."""
    ax = axes_or_new(ax)
    f = np.asarray(res.frequencies_rad_s) / (2 * np.pi)
    lam = np.asarray(res.min_eigenvalues, dtype=float)
    ok = np.isfinite(lam)
    ax.plot(f[ok], lam[ok], "-", color="tab:blue" if res.positive_real else "tab:red", lw=1.2)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.plot([res.worst_frequency_hz], [res.margin], "o", color="k",
            label=f"margin {res.margin:.4g} at {res.worst_frequency_hz:.4g} Hz")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("min eig of G + G^H")
    ax.set_title(res.verdict + (f" (fails: {res.failed_condition})" if res.failed_condition else ""))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return ax


def plot_region(res: Any, ax: Any = None) -> Any:
    """K-B chart: the exact stable region shaded, its D-decomposition boundary, the
    cross-check grid's disagreements (if any) and the overlays (passivity, circle
    criterion, the paper's line)."""
    ax = axes_or_new(ax)
    K0, K1 = res.K_range
    B0, B1 = res.B_range
    ax.pcolormesh(res.K_grid, res.B_rows, res.stable_exact.astype(float), cmap="Greens",
                  vmin=0, vmax=2.5, shading="nearest", rasterized=True)
    first = True
    for c in res.boundary["curves"]:
        inwin = (c[:, 0] >= K0) & (c[:, 0] <= K1) & (c[:, 1] >= B0) & (c[:, 1] <= B1)
        if inwin.any():
            # the first point outside is kept, so the line reaches the window's edge (the
            # axes clip it); points farther out are left out
            near = inwin | np.r_[inwin[1:], False] | np.r_[False, inwin[:-1]]
            seg = np.where(near, 1.0, np.nan)
            ax.plot(c[:, 0] * seg, c[:, 1] * seg, "k-", lw=1.0,
                    label="exact boundary (|z| = 1)" if first else None)
            first = False
    for K in res.boundary["z1"]:
        if K0 <= K <= K1:
            ax.axvline(K, color="k", lw=1.0, ls="-")
    T = res.period
    Bl = np.array([B0, B1])
    for c in res.boundary["zm1"]:
        ax.plot(c - res.boundary.get("zm1_B_per_s", 2 / T) * Bl, Bl, "k-", lw=1.0)
    styles = {"passivity": ("tab:blue", "--", "passivity (Colgate)"),
              "circle": ("tab:orange", "-.", "circle criterion (forward)"),
              "paper": ("tab:red", ":", "paper's condition")}
    for name, K in res.overlays.items():
        col, ls, lab = styles.get(name, ("tab:gray", "--", name))
        ax.plot(K, res.B_rows, color=col, ls=ls, lw=1.5, label=lab)
    bad = res.disagreement
    if bad is not None and bad.any():
        KK, BB = np.meshgrid(res.K_grid, res.B_rows)
        ax.plot(KK[bad], BB[bad], "r.", ms=2, label="grid check differs")
    ax.set_xlim(K0, K1)
    ax.set_ylim(B0, B1)
    ax.set_xlabel("stiffness K (N/m)")
    ax.set_ylabel("virtual damping B (N·s/m)")
    n = res.delay_samples
    ax.set_title(f"{res.kind.upper()} stable region (shaded), T = {T * 1e3:g} ms, "
                 f"t_d = {n:g} T" + (f"\n{_wrap(res.model, ax, 9)}" if getattr(res, "model", "")
                                      else ""), fontsize=9)
    if ax.get_legend_handles_labels()[0]:     # (no overlay and no boundary: no legend)
        ax.legend(loc="best", fontsize=8)
    return ax


def plot_twoport(res: Any, ax: Any = None) -> Any:
    """Llewellyn's margin (N*s/m) and eta against frequency: absolutely stable where the
    margin is >= 0 (eta >= 1) at every frequency."""
    axs = panels_or_new(ax, 2, (7, 5.5))
    top, bottom = axs
    f = res.frequency_rad_s / (2 * np.pi)
    top.semilogx(f, res.margins, "-", lw=1.0, color="tab:blue", label="margin")
    top.axhline(0.0, color="k", lw=0.8)
    top.plot([res.worst_frequency_hz], [res.margin], "o", color="tab:red",
             label=f"worst: {res.margin:.3g} N*s/m at {res.worst_frequency_hz:.3g} Hz")
    top.set_ylabel("Llewellyn margin (N*s/m)")
    top.set_title(f"{res.verdict}: K = {res.stiffness:g} N/m, T = {res.period * 1e3:g} ms, "
                  f"{res.approximation} approximation", fontsize=9)
    bottom.semilogx(f, res.eta, "-", lw=1.0, color="tab:green", label="eta")
    bottom.axhline(1.0, color="k", lw=0.8, ls="--", label="eta = 1")
    bottom.set_ylabel("eta")
    bottom.set_xlabel("frequency (Hz)")
    finite = res.eta[np.isfinite(res.eta)]
    if finite.size:
        # eta grows without bound where the coupling fades: show the part near 1
        bottom.set_ylim(min(0.0, float(np.percentile(finite, 1))),
                        min(max(2.0, float(np.percentile(finite, 50))), 10.0))
    for a in axs:
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8, loc="best")
    return axs


def plot_transparency(res: Any, ax: Any = None) -> Any:
    """Bode-style transparency: |Z_felt| and its phase in free motion, with the
    environment and against a rigid one (the band between free and rigid is the Z-width),
    and the tracking |X_s/X_m| and its error |1 - X_s/X_m|.

    Parameters
    ----------
    res : TransparencyResult
        The curves.
    ax : sequence of 3 matplotlib Axes, optional
        Where to draw the three panels; a new figure when omitted.

    Returns
    -------
    array of 3 matplotlib Axes
    """
    mag, phase, track = panels_or_new(ax, 3, (7, 7.5))
    f = res.frequencies_hz
    curves = (("free motion", res.felt_free, "tab:green"),
              ("environment", res.felt_environment, "tab:blue"),
              ("rigid", res.felt_rigid, "tab:red"))
    for label, z, color in curves:
        mag.loglog(f, np.abs(z), "-", lw=1.0, color=color, label=label)
        phase.semilogx(f, np.degrees(np.angle(z)), "-", lw=1.0, color=color, label=label)
    mag.fill_between(f, np.abs(res.felt_free), np.abs(res.felt_rigid), color="0.85",
                     label="free to rigid (Z-width)")
    mag.set_ylabel("|Z_felt| (N*s/m)")
    mag.set_title(f"felt impedance and tracking: T = {res.period_s * 1e3:g} ms, delays "
                  f"{res.delay_samples[0]}/{res.delay_samples[1]} samples, "
                  f"{res.approximation} approximation", fontsize=9)
    phase.set_ylabel("phase of Z_felt (deg)")
    track.loglog(f, np.abs(res.tracking), "-", lw=1.0, color="tab:blue", label="|X_s/X_m|")
    track.loglog(f, np.abs(res.tracking_error), "--", lw=1.0, color="tab:orange",
                 label="|1 - X_s/X_m|")
    track.set_ylabel("tracking")
    track.set_xlabel("frequency (Hz)")
    for a in (mag, phase, track):
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8, loc="best")
    return np.array([mag, phase, track], dtype=object)
