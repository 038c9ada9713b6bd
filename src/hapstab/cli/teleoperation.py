"""CLI of the teleoperation room: ``hapstab twoport peb|4ch`` (Llewellyn's absolute
stability of the two-port) and ``hapstab transparency peb|4ch`` (felt impedance, hybrid
matrix, tracking)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import click
import numpy as np

from hapstab.cli.options import (
    LOOP_KINDS,
    NONNEG,
    bounds_of,
    damping_bound_options,
    emit,
    fmt,
    loop_options,
    rich_table,
)
from hapstab.cli.ranges import parse_range
from hapstab.errors import HapstabError

if TYPE_CHECKING:
    pass

@click.group("twoport", short_help="Absolute stability (Llewellyn) of a teleoperator's two-port at K.")
def twoport_cmd() -> None:
    """Is the teleoperator absolutely stable (Llewellyn: stable with every pair of passive
    terminations) at a stiffness K? Margin and eta against frequency."""


def _twoport_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @twoport_cmd.command(kind)
    @loop_options(kind)
    @damping_bound_options(kind)
    @click.option("--stiffness", "-K", type=NONNEG, required=True,
                  help="K in N/m (the master's" + (", or the slave's when the master has none)."
                                                   if kind == "4ch" else ")."))
    @click.option("--approximation", default="forward", show_default=True,
                  help="X(z): forward (a bound for the exact loop in every campaign) | backward | "
                       "tustin (neither of these is).")
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write the margin and eta against frequency (PNG, SVG, PDF).")
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Write frequency_rad_s, margin_N_s_per_m, eta per angle.")
    def _cmd(stiffness: float, approximation: str, plot_path: str | None,
             csv_path: str | None, as_json: bool, **kw: Any) -> None:
        from hapstab.analysis.teleoperation.twoport import llewellyn_test
        from hapstab.cli.files import check_files, write_files

        check_files(csv_path, plot_path, as_json)
        bounds = bounds_of(kw, "llewellyn")
        loop = make(kw, stiffness)
        res = llewellyn_test(loop, approximation, **bounds)  # type: ignore[arg-type]  # a teleoperator
        files = write_files(res, csv_path, plot_path)
        d = {**res.to_dict(), "files": files}
        rows = [("verdict", res.verdict),
                ("margin", f"{res.margin:.6g} N*s/m ("
                           + ("damping to spare" if res.margin >= 0 else "damping missing") + ")"),
                ("worst frequency", f"{res.worst_frequency_hz:.6g} Hz "
                                    f"({res.worst_frequency_rad_s:.6g} rad/s)"),
                ("smallest eta", f"{res.eta_min:.6g} (>= 1 needed; away from w = 0)"),
                ("why", res.reason), *[("wrote", f) for f in files]]
        emit(d, as_json, lambda: rich_table(f"two-port, {kind}, K = {stiffness:g} N/m", rows, loop),
             loop)

    _cmd.__doc__ = (f"Llewellyn's absolute stability of the {NAMES[kind]} two-port G^-1(z) at "
                    "stiffness K: verdict, margin in N*s/m, worst frequency, eta.")


#: What the twoport and transparency commands call each teleoperator.
NAMES = {"peb": "PEB", "4ch": "4-channel (position channels only)"}


@click.group("transparency", short_help="What the operator feels through the teleoperator.")
def transparency_cmd() -> None:
    """Transparency over frequency: the impedance the operator feels in free motion, with the
    environment and against a rigid one (the Z-width), and the slave's position tracking."""


#: Points of a --frequencies range given as start:stop (log-spaced, a Bode plot's grid).
FREQUENCY_COUNT = 400


def _frequencies(spec: str | None, period_s: float) -> list[float] | None:
    """--frequencies in Hz: start:stop[:count] log-spaced (count default
    :data:`FREQUENCY_COUNT`), or a comma list as given; none above 1/(2T)."""
    from hapstab.analysis.teleoperation.transparency import NYQUIST_SLACK

    if spec is None:
        return None
    ranged = ":" in spec
    text = spec + f":{FREQUENCY_COUNT}" if spec.count(":") == 1 else spec
    f = parse_range(text, "--frequencies", "Hz")
    if ranged and len(f) > 1:
        f = [float(v) for v in np.geomspace(f[0], f[-1], len(f))]
    nyquist = 1.0 / (2.0 * period_s)
    if max(f) > nyquist * (1 + NYQUIST_SLACK):
        raise HapstabError(f"--frequencies = {spec!r}: {max(f):g} Hz is above the Nyquist "
                           f"frequency 1/(2T) = {nyquist:g} Hz; allowed: (0, {nyquist:g}] Hz")
    return f


def _transparency_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @transparency_cmd.command(kind)
    @loop_options(kind)
    @click.option("--stiffness", "-K", type=NONNEG, required=True,
                  help="K in N/m (the master's" + (", or the slave's when the master has none)."
                                                   if kind == "4ch" else ")."))
    @click.option("--approximation", default="forward", show_default=True,
                  help="X(z), the hold's approximation: forward | backward | tustin.")
    @click.option("--frequencies", default=None,
                  help="Frequencies in Hz: start:stop[:count] (log-spaced, count default 400) or "
                       "a comma list; at most 1/(2T). Default: 4 decades up to 1/(2T).")
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write |Z_felt|, its phase and the tracking against frequency (PNG, SVG, PDF).")
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Write the felt impedances, X_s/X_m and h11..h22 (re, im) per frequency.")
    def _cmd(stiffness: float, approximation: str, frequencies: str | None,
             plot_path: str | None, csv_path: str | None, as_json: bool, **kw: Any) -> None:
        from hapstab.analysis.teleoperation.transparency import transparency
        from hapstab.cli.files import check_files, write_files

        check_files(csv_path, plot_path, as_json)
        loop = make(kw, stiffness)
        res = transparency(loop, approximation,  # type: ignore[arg-type]  # a teleoperator
                           _frequencies(frequencies, loop.period))
        files = write_files(res, csv_path, plot_path)
        d = {**res.to_dict(), "stiffness": stiffness, "files": files}
        rows = [("felt stiffness (w -> 0)",
                 f"{fmt(res.felt_stiffness_free)} free, {fmt(res.felt_stiffness_environment)} "
                 f"environment, {fmt(res.felt_stiffness_rigid)} rigid (N/m)"),
                ("tracking X_s/X_m (w -> 0)", f"{res.static_tracking:.6g}"),
                *_at_decades(res), *[("wrote", f) for f in files]]
        emit(d, as_json, lambda: rich_table(f"transparency, {kind}, K = {stiffness:g} N/m, "
                                            f"{res.approximation}", rows, loop), loop)

    _cmd.__doc__ = (f"Transparency of the {NAMES[kind]} teleoperator at stiffness K: the felt "
                    "impedance (free motion, the environment, rigid), the hybrid matrix and "
                    "X_s/X_m over frequency.")


def _at_decades(res: Any) -> list[tuple[str, str]]:
    """Table rows at the grid's points nearest each decade of Hz (at most 6)."""
    f = res.frequencies_hz
    marks = 10.0 ** np.arange(np.ceil(np.log10(f[0])), np.floor(np.log10(f[-1])) + 1)
    idx = sorted({int(np.argmin(np.abs(np.log(f / m)))) for m in marks[-6:]} or {0, f.size - 1})
    return [(f"|Z_felt|, |X_s/X_m| at {f[i]:.4g} Hz",
             f"{abs(res.felt_free[i]):.4g} free, {abs(res.felt_environment[i]):.4g} environment, "
             f"{abs(res.felt_rigid[i]):.4g} rigid (N*s/m); tracking {abs(res.tracking[i]):.4g}")
            for i in idx]


for _kind in NAMES:
    _twoport_command(_kind)
    _transparency_command(_kind)
