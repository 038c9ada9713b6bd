"""CLI of the design room: ``hapstab region`` (the K-B stability region), ``hapstab
best-damping`` and ``hapstab zwidth`` (a device's passive and stable virtual walls and the
impedance one displays, Colgate and Brown's Z-width)."""

from __future__ import annotations

from typing import Any, cast

import click

from hapstab.cli.options import (
    LENGTH,
    LOOP_KINDS,
    NONNEG,
    PAPER_KINDS,
    POS,
    REAL,
    IntRange,
    emit,
    fmt,
    given,
    loop_options,
    rich_table,
)
from hapstab.cli.ranges import parse_range
from hapstab.cli.robust import box_from, operator_box_options
from hapstab.errors import HapstabError, ascii_float
from hapstab.models.loops import HapticLoop


def region_range(spec: str, name: str, signed: bool = False) -> tuple[float, float]:
    """``start:stop`` (the one range syntax, without a count: the grid's size is
    ``--resolution``); ``start >= 0`` unless ``signed`` (virtual damping)."""
    unit = "N*s/m" if signed else "N/m"
    lo, hi = parse_range(spec, name, unit, count=False, values="any" if signed else ">= 0")
    return lo, hi


def _equal_controllers(kw: dict[str, Any]) -> None:
    """A K-B region and the best damping are defined for C_m = C_s (and, for 4ch,
    C_1 = C_4 = C_m): refuse the options that make the controllers differ, naming the
    one given."""
    ratio, B_s = kw.get("slave_stiffness_ratio", 1.0), kw.get("slave_virtual_damping")
    _equal_channels(kw)
    if ratio is not None and ratio != 1.0:
        raise HapstabError(f"--slave-stiffness-ratio = {ratio:g}: a K-B region / best damping is "
                           "defined for C_m = C_s; allowed here: 1 (the default)")
    if B_s is not None:
        raise HapstabError(f"--slave-virtual-damping = {B_s:g}: a K-B region / best damping is "
                           "defined for C_m = C_s (B is the swept variable); allowed here: not given")
    if given("virtual_damping"):
        raise HapstabError(f"--virtual-damping / -B = {kw['virtual_damping']:g}: B is what a K-B "
                           "region and the best damping vary, so a given B would be ignored; "
                           "set the window with --B lo:hi (region) or --min-damping / "
                           "--max-damping (best-damping)")


def _equal_channels(kw: dict[str, Any]) -> None:
    """4ch: refuse a master without stiffness and C_1 / C_4 options that make them
    differ from C_m = C_s."""
    if kw.get("master_stiffness_ratio", 1.0) != 1.0:
        raise HapstabError(f"--master-stiffness-ratio = {kw['master_stiffness_ratio']:g}: a K-B "
                           "region / best damping varies K and B of every position controller "
                           "alike; allowed here: 1 (the default)")
    for c in ("c1", "c4"):
        r, b = kw.get(f"{c}_stiffness_ratio"), kw.get(f"{c}_virtual_damping")
        if r is not None and r != 1.0:
            raise HapstabError(f"--{c}-stiffness-ratio = {r:g}: a K-B region / best damping is "
                               "defined for C_1 = C_4 = C_m = C_s; allowed here: 1 (the default)")
        if b is not None:
            raise HapstabError(f"--{c}-virtual-damping = {b:g}: a K-B region / best damping is "
                               "defined for C_1 = C_4 = C_m = C_s (B is the swept variable); "
                               "allowed here: not given")


def _region_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @region.command(kind)
    @loop_options(kind)
    @click.option("--K", "K_spec", required=True, help="Stiffness window lo:hi in N/m.")
    @click.option("--B", "B_spec", required=True,
                  help="Virtual damping window lo:hi in N*s/m, either sign (e.g. -2:20).")
    @click.option("--resolution", type=IntRange(2, 2000), default=200, show_default=True,
                  help="Rows (B values) and grid columns (K values).")
    @click.option("--overlay", "overlays", default=",".join(_overlays(kind)), show_default=True,
                  help=f"Comma list drawn on the plot: {', '.join(_overlays(kind))} (or none)"
                       + ("; the paper's conditions are for hve and peb." if kind not in
                          PAPER_KINDS else "."))
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write the K-B chart (PNG or SVG by extension).")
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Write every grid point: stiffness, virtual_damping, stable_exact, stable_grid.")
    def _cmd(K_spec: str, B_spec: str, resolution: int, overlays: str, plot_path: str | None,
             csv_path: str | None, as_json: bool, **kw: Any) -> None:
        from hapstab.analysis.design.regions import stability_region
        from hapstab.analysis.methods import METHODS
        from hapstab.cli.files import check_files, write_files

        check_files(csv_path, plot_path, as_json)
        _equal_controllers(kw)
        K, B = region_range(K_spec, "--K"), region_range(B_spec, "--B", signed=True)
        names = [o.strip() for o in overlays.split(",") if o.strip() and o.strip() != "none"]
        for o in names:
            if o not in _overlays(kind) or (o != "paper" and o not in METHODS):
                raise HapstabError(f"--overlay = {o!r}: unknown for {kind}; allowed: "
                                   f"{', '.join(_overlays(kind))}, none")
        ov = names if plot_path else []
        loop = make(kw, 1.0)
        res = stability_region(loop, K, B, resolution, overlays=ov)
        write_files(res, csv_path, plot_path, dpi=120, bbox_inches="tight")
        d = res.to_dict()
        kmax = res.kmax()
        rows = [("window", f"K in [{K[0]:g}, {K[1]:g}] N/m, B in [{B[0]:g}, {B[1]:g}] N*s/m"),
                ("K_max at B = lo", f"{fmt(kmax[0])} N/m"),
                ("largest K_max in window", f"{fmt(kmax.max())} N/m at B = "
                                            f"{res.B_rows[int(kmax.argmax())]:.6g} N*s/m"),
                ("grid cross-check", f"{res.agreement['disagree']} of {res.agreement['compared']} "
                                     "points differ away from the boundary")]
        if plot_path is not None:
            rows.append(("plot", plot_path))
        if csv_path is not None:
            rows.append(("csv", csv_path))
        emit(d, as_json, lambda: rich_table(f"K-B stability region, {kind}", rows, loop), loop)

    _cmd.__doc__ = f"Exact K-B stability region of the {kind.upper()} loop (D-decomposition)."


def _best_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @best.command(kind)
    @loop_options(kind)
    @click.option("--max-damping", "B_max", type=POS, default=None,
                  help="Largest B to search, > 0 (default: where K_max falls to 0).")
    @click.option("--min-damping", "B_min", type=REAL, default=None,
                  help="Smallest B to search, <= 0 (default: where K_max falls to 0 going "
                       "down; 0 searches B >= 0 only).")
    @operator_box_options
    def _cmd(B_max: float | None, B_min: float | None, as_json: bool, **kw: Any) -> None:
        from hapstab.analysis.design.damping import best_damping
        from hapstab.analysis.robust.robust_damping import robust_best_damping

        _equal_controllers(kw)
        if B_min is not None and B_min > 0:
            raise HapstabError(f"--min-damping = {B_min:g}: must be <= 0 (the search always "
                               "includes B = 0)")
        box = box_from(kw, nominal=True)
        loop = make(kw, 1.0)
        res: Any = (best_damping(loop, B_max=B_max, B_min=B_min) if box is None else
                    robust_best_damping(loop, box, B_max=B_max, B_min=B_min))
        nom = res if box is None else res.nominal
        rows = [("best virtual damping B*", f"{nom.damping:.10g} N*s/m"),
                ("critical stiffness K*", f"{fmt(nom.critical_stiffness)} N/m"),
                ("K_max at B = 0", f"{fmt(nom.critical_stiffness_at_zero_damping)} N/m")]
        if box is not None:
            rows.append(("robust K_max at B*", f"{fmt(res.robust.critical_stiffness)} N/m for "
                                               f"every operator of {box.describe()}"))
        rows.append(("design answer", res.reason))
        emit(res.to_dict(), as_json, lambda: rich_table(f"best virtual damping, {kind}", rows, loop),
             loop)

    _cmd.__doc__ = f"The virtual damping B that maximises K_max of the {kind.upper()} loop."


def _overlays(kind: str) -> tuple[str, ...]:
    """What region can draw over a loop of ``kind``: the paper's condition (hve, peb
    only), passivity and the circle criterion."""
    return (("paper",) if kind in PAPER_KINDS else ()) + ("passivity", "circle")


@click.group()
def region() -> None:
    """Exact K-B stability region (stable set shaded, boundary by D-decomposition)."""


@click.group("best-damping")
def best() -> None:
    """The virtual damping B* that maximises K_max, and K* = K_max(B*)."""


for _kind in LOOP_KINDS:
    _region_command(_kind)
    _best_command(_kind)


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
