"""``hapstab jitter hve|peb --delay LO:HI``: K under a delay that varies from sample to
sample, as a bracket (:func:`hapstab.jitter`)."""

from __future__ import annotations

from typing import Any

import click

from hapstab.cli.network import parse_delay_range
from hapstab.cli.options import LOOP_KINDS, emit, fmt, loop_options, rich_table

__all__ = ["jitter_cmd"]


@click.group("jitter", short_help="K under a time-varying delay: a bracket, and the pattern "
                                  "that destabilises.")
def jitter_cmd() -> None:
    """K under a delay that changes from sample to sample anywhere in LO:HI (the controller
    uses the newest sample that has arrived): stable for every delay sequence up to
    stable_up_to (small-gain jitter margin), unstable from unstable_from (an explicit
    periodic delay pattern), the gap between them reported (docs/guide/networks.md)."""


def _jitter_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @jitter_cmd.command(kind)
    @loop_options(kind, jitter=True)
    @click.option("--max-length", "max_length", type=click.IntRange(1, 12), default=6,
                  show_default=True,
                  help="The longest periodic delay pattern enumerated, samples (at most "
                       "4000 patterns in all: longer lengths are dropped beyond that).")
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Also write both searches (K, growth rate / small-gain number) as CSV.")
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write both searches against K, the bracket shaded, as a figure.")
    def _cmd(max_length: int, csv_path: str | None, plot_path: str | None, as_json: bool,
             **kw: Any) -> None:
        from hapstab.analysis.network.jitter import jitter
        from hapstab.analysis.network.jitter_modes import at_lo
        from hapstab.cli.files import check_files, write_files

        check_files(csv_path, plot_path, as_json)
        lo, hi, seconds = parse_delay_range(kw.pop("delay"), "--delay")
        loop = make({**kw, "delay": 0}, stiffness=1.0)
        if seconds:
            res = jitter(loop, delay_s=(lo, hi), max_length=max_length)
        else:
            res = jitter(loop, (lo, hi), max_length=max_length)
        loop = at_lo(loop, res.delay_samples[0])      # the inputs name the nominal delay
        write_files(res, csv_path, plot_path)
        n_lo, n_hi = res.delay_samples
        rows = [("stable up to", f"{fmt(res.stable_up_to)} N/m (every delay sequence; "
                                 "small-gain jitter margin)"),
                ("unstable from", f"{fmt(res.unstable_from)} N/m"),
                ("pattern", res.pattern_text() + (" (constant)" if res.pattern_is_constant
                                                  else " (repeated)")),
                ("gap", f"{fmt(res.gap)} N/m ({100 * res.relative_gap:.3g} %)"),
                ("constant-delay worst", f"{fmt(res.constant_worst)} N/m"),
                ("delays", f"{n_lo}..{n_hi} samples" + (" (from seconds: ceil(t / T))"
                                                        if seconds else "")),
                ("why", res.reason)]
        emit(res.to_dict(), as_json, lambda: rich_table(f"K under jitter, {kind}", rows), loop)

    _cmd.__doc__ = (f"K of the {kind.upper()} loop under a delay varying in LO:HI from sample "
                    "to sample: a bracket [stable_up_to, unstable_from].")


for _kind in ("hve", "peb"):
    _jitter_command(_kind)

