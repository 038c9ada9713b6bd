"""CLI: ``hapstab identify LOG.csv`` (a device's m, b and Coulomb friction from a
recorded run, with confidence intervals, and the kmax command line for it)."""

from __future__ import annotations

from typing import Any

import click

from hapstab.cli.options import LENGTH, emit, rich_table
from hapstab.errors import HapstabError


def _columns(spec: str | None) -> tuple[str, str, str] | None:
    if spec is None:
        return None
    names = tuple(n.strip() for n in spec.split(","))
    if len(names) != 3 or not all(names):
        raise HapstabError(f"--columns = {spec!r}: must be three names TIME,FORCE,POSITION")
    return names[0], names[1], names[2]


@click.command("identify")
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
@click.option("--resolution", "resolution_m", type=LENGTH, default=None,
              help="The encoder's step: m, or with a unit (2um). Default: no quantisation.")
@click.option("--quantizer", type=click.Choice(["floor", "nearest"]), default="floor",
              show_default=True,
              help="How the encoder reads: floor (count of lines passed) or nearest step.")
@click.option("--friction", type=click.Choice(["auto", "yes", "no"]), default="auto",
              show_default=True,
              help="Coulomb friction: estimate it and keep it when its interval excludes 0 "
                   "(auto), always, or never.")
@click.option("--confidence", type=click.FloatRange(0.5, 0.9999), default=0.95,
              show_default=True, help="The intervals' confidence level.")
@click.option("--columns", "columns_spec", default=None, metavar="TIME,FORCE,POSITION",
              help="The CSV's column names (default: recognised names such as time_s, "
                   "force_N, position_m).")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
              help="Write the fit's figure (PNG or SVG by extension).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
              help="Write the log with the fitted position and the residuals.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def identify_cmd(log: str, resolution_m: float | None, quantizer: str, friction: str,
                 confidence: float, columns_spec: str | None, plot_path: str | None,
                 csv_path: str | None, as_json: bool) -> None:
    """A device's mass, damping and Coulomb friction from a recorded run.

    LOG is a CSV with a header: time (s), the commanded force (N, held until the next
    sample) and the encoder's position (m) at each sample of a fixed-rate run. The
    parameters are fitted on the exact ZOH model with the encoder's quantisation, with
    confidence intervals (white reading errors; see docs/guide/identify.md), and the
    kmax command line for the identified device is printed.
    """
    from hapstab.analysis.identification.identify import identify
    from hapstab.cli.files import check_files, write_files

    check_files(csv_path, plot_path, as_json)
    res = identify(log, resolution_m=resolution_m, quantizer=quantizer, friction=friction,
                   confidence=confidence, columns=_columns(columns_spec))
    write_files(res, csv_path, plot_path, dpi=120, bbox_inches="tight")
    emit(res.to_dict(), as_json, lambda: _table(res))


def _table(res: Any) -> None:
    from hapstab.analysis.identification.identify_result import interval_text

    pct = f"{100 * res.confidence:g} %"
    units = {"mass_kg": ("mass m", "kg"), "damping_N_s_per_m": ("damping b", "N*s/m"),
             "coulomb_friction_N": ("Coulomb friction f_c", "N"),
             "initial_position_m": ("initial position", "m"),
             "initial_velocity_m_per_s": ("initial velocity", "m/s")}
    rows = [(units[n][0], f"{interval_text(e, lo, hi)} {units[n][1]} ({pct} interval)")
            for n, e, lo, hi, _ in res.rows()]
    if not res.friction_fitted and res.friction_upper_N is not None:
        rows.append(("Coulomb friction f_c", f"not detected (<= {res.friction_upper_N:.3g} N)"))
    rows += [("samples, period", f"{res.time_s.size}, {res.period_s:.6g} s"),
             ("reading - fit (spread)", f"{res.residual_std_m:.3g} m"),
             ("noise model", "white reading errors (noise + quantisation); lag-1 "
                             f"autocorrelation of the residuals {res.whiteness:.2f}"),
             ("K_max of this device", res.commands()["estimate"]),
             ("  cautious (low b)", res.commands()["low_damping"])]
    rich_table(f"identified device ({res.source})", rows)
