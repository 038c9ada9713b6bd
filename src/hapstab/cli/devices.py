"""CLI: ``hapstab zwidth`` (a device's passive and stable virtual walls and the impedance
one displays, Colgate and Brown's Z-width)."""

from __future__ import annotations

from typing import Any, cast

import click

from hapstab.cli.options import (
    LENGTH,
    LOOP_KINDS,
    NONNEG,
    IntRange,
    emit,
    fmt,
    loop_options,
    rich_table,
)
from hapstab.cli.regions import region_range
from hapstab.errors import HapstabError, ascii_float
from hapstab.models.loops import HapticLoop


@click.group("zwidth")
def zwidth_cmd() -> None:
    """A device's Z-width: the virtual walls it renders passively and stably, and the
    impedance a wall displays over frequency."""


def _at(spec: str | None) -> tuple[float, float] | None:
    """``K,B`` of the wall whose displayed impedance is shown."""
    if spec is None:
        return None
    try:
        K, B = (ascii_float(v) for v in spec.split(","))
    except ValueError:
        raise HapstabError(f"--at = {spec!r}: must be K,B (N/m, N*s/m)") from None
    return K, B


@zwidth_cmd.command("hve")
@loop_options("hve")
@click.option("--K", "K_spec", required=True, help="Stiffness window lo:hi in N/m (the plot).")
@click.option("--B", "B_spec", required=True, help="Virtual dampings lo:hi in N*s/m, either sign.")
@click.option("--rows", type=IntRange(2, 2000), default=60, show_default=True,
              help="Virtual dampings scanned.")
@click.option("--at", "at_spec", default=None, metavar="K,B",
              help="The wall whose displayed impedance is shown (default: -K and -B).")
@click.option("--stiffness", "-K", type=NONNEG, default=0.0, show_default=True,
              help="K of the wall shown, N/m (with --at unset).")
@click.option("--resolution", "resolution_m", type=LENGTH, default=None,
              help="Encoder resolution, m or with a unit (2um): adds Abbott and Okamura's "
                   "passive limit at B = 0 (with the device's --friction).")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
              help="Write the Z-width figure (PNG or SVG by extension).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
              help="Write the rows: virtual damping, passive and stable K.")
def zwidth_hve(K_spec: str, B_spec: str, rows: int, at_spec: str | None, stiffness: float,
               resolution_m: float | None, plot_path: str | None,
               csv_path: str | None, as_json: bool, **kw: Any) -> None:
    """Z-width of the HVE's device: passive and stable walls, displayed impedance."""
    from hapstab.analysis.design.zwidth import zwidth
    from hapstab.cli.files import check_files, write_files

    check_files(csv_path, plot_path, as_json)
    B_at = kw["virtual_damping"]
    K, B = region_range(K_spec, "--K"), region_range(B_spec, "--B", signed=True)
    # without --at, -K or -B the wall shown is the passive limit at B = 0 (K = B = 0 would
    # display a flat zero)
    at = _at(at_spec) or ((stiffness, B_at) if stiffness or B_at else None)
    loop = cast(HapticLoop, LOOP_KINDS["hve"](kw, 0.0 if at is None else 1.0))
    res = zwidth(loop, K, B, rows, at=at, resolution_m=resolution_m)
    at = (res.K_at, res.B_at)
    write_files(res, csv_path, plot_path, dpi=120, bbox_inches="tight")
    table = [("passive up to (B = 0)", f"{fmt(res.K_passive_B0)} N/m"),
             ("stable up to (B = 0)", f"{fmt(res.K_stable_B0)} N/m"),
             ("largest passive K", f"{fmt(res.K_passive.max())} N/m at B = "
                                   f"{res.B_rows[int(res.K_passive.argmax())]:.6g} N*s/m"),
             ("with friction and encoder", "-" if res.K_quantised is None
              else f"{fmt(res.K_quantised)} N/m (B = 0)"),
             (f"displayed at {res.frequencies_hz[0]:.3g} Hz",
              f"{fmt(res.displayed_stiffness[0])} N/m, {fmt(res.displayed_damping[0])} N*s/m "
              f"(wall K = {at[0]:g} N/m, B = {at[1]:g} N*s/m)")]
    emit(res.to_dict(), as_json, lambda: rich_table("Z-width, hve", table, loop), loop)
