"""``hapstab limit-cycle hve``: limit cycles from encoder quantisation and Coulomb friction,
by describing function refined by harmonic balance
(:func:`hapstab.analysis.nonlinear.limit_cycles.limit_cycles`)."""

from __future__ import annotations

from typing import Any

import click

from hapstab.cli.options import (
    LENGTH,
    LOOP_KINDS,
    POS,
    REAL,
    IntRange,
    emit,
    loop_options,
    rich_table,
)


@click.group("limit-cycle",
             short_help="Limit cycles from quantisation and Coulomb friction (describing function).")
def limit_cycle_cmd() -> None:
    """Limit cycles of the haptic loop from encoder quantisation (--resolution, --quantizer)
    and the device's Coulomb friction (--friction): amplitude, frequency, stable or a
    threshold, and the conditions for their existence."""


@limit_cycle_cmd.command("hve")
@loop_options("hve")
@click.option("--stiffness", "-K", type=POS, required=True, help="K in N/m.")
@click.option("--resolution", type=LENGTH, default=None,
              help="Encoder resolution Delta: m, or with a unit (2um).")
@click.option("--quantizer", type=click.Choice(["floor", "nearest"]), default="floor",
              show_default=True, help="The encoder's reading: Delta floor(x/Delta), or the "
                                      "nearest multiple (as simulate's).")
@click.option("--rest", type=REAL, default=0.0, show_default=True,
              help="Where the operator's spring is relaxed, m (simulate's --rest; here 0 by "
                   "default, where the virtual spring pulls).")
@click.option("--harmonics", type=IntRange(1, 63), default=15, show_default=True,
              help="Harmonics of the refining harmonic balance (1: the describing function alone).")
@click.option("--max-amplitude", type=POS, default=None,
              help="Largest amplitude searched in m (default 64 Delta; 1e5 f_c/K with friction "
                   "alone).")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
              help="Write the describing-function plot (the loop against -1/N).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
              help="Write one row per predicted cycle.")
def limit_cycle_hve(stiffness: float, resolution: float | None, quantizer: str, rest: float,
                    harmonics: int,
                    max_amplitude: float | None, plot_path: str | None, csv_path: str | None,
                    as_json: bool, **kw: Any) -> None:
    """Limit cycles of the HVE at stiffness K from quantisation and Coulomb friction."""
    from hapstab.analysis.nonlinear.limit_cycles import limit_cycles
    from hapstab.cli.files import check_files, write_files

    check_files(csv_path, plot_path, as_json)
    loop = LOOP_KINDS["hve"](kw, stiffness)
    res = limit_cycles(loop, resolution_m=resolution, quantizer=quantizer,  # type: ignore[arg-type]
                       rest_position_m=rest, harmonics=harmonics, max_amplitude_m=max_amplitude)
    files = write_files(res, csv_path, plot_path)
    d = {**res.to_dict(), "files": files}
    rows = [("verdict", res.verdict), ("linear loop", res.linear_verdict)]
    for c in res.cycles:
        rows.append((f"{'stable' if c.stable else 'unstable'} cycle",
                     f"amplitude {c.amplitude_m:.4g} m, {c.frequency_hz:.5g} Hz, mean "
                     f"{c.offset_m:.3g} m (describing function alone: {c.describing_function_amplitude_m:.4g}"
                     f" m, {c.describing_function_frequency_hz:.5g} Hz)"
                     + ("" if c.trusted else f"; untrusted: {c.notes}")))
    rows += [("conditions", res.conditions), *[("wrote", f) for f in files]]
    emit(d, as_json, lambda: rich_table(f"limit cycles, hve, K = {stiffness:g} N/m", rows, loop),
         loop)
