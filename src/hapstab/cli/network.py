"""CLI of the network room (:mod:`hapstab.analysis.network`): ``hapstab kmax hve|peb
--loss P [--burst L]`` (mean-square K_max with packet loss), ``kmax ... --delay-range
A:B`` (the minimum of K_max over a range of constant delays) and ``hapstab jitter
hve|peb --delay LO:HI`` (K under a delay that varies from sample to sample, as a
bracket)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import click

from hapstab.cli.options import LOOP_KINDS, emit, fmt, loop_options, rich_table
from hapstab.cli.ranges import parse_range
from hapstab.errors import HapstabError

__all__ = ["network_options", "network_kmax", "range_kmax", "parse_delay_range",
           "refuse_loop_delay", "jitter_cmd"]



def parse_delay_range(spec: str, option: str) -> tuple[float, float, bool]:
    """``A:B`` as (lo, hi, seconds): seconds when either end has a unit (5ms:15ms), else
    whole samples (5:15).

    Parameters
    ----------
    spec : str
        The option's value.
    option : str
        Its name, for the messages.

    Returns
    -------
    (float, float, bool)
    """
    parts = spec.split(":")
    if len(parts) != 2:
        raise HapstabError(f"{option} = {spec!r}: allowed: A:B, e.g. 5ms:15ms or 5:15")
    if any(p.strip().lower().endswith("s") for p in parts):
        vals = parse_range(spec, option, "s", values=">= 0")
        return vals[0], vals[-1], True
    try:
        lo, hi = (int(p) for p in parts)
    except ValueError:
        raise HapstabError(f"{option} = {spec!r}: whole samples (5:15) or seconds with a unit "
                           "(5ms:15ms)") from None
    return lo, hi, False


def network_options(f: Callable) -> Callable:
    """The --loss, --burst and --delay-range options of ``kmax``."""
    f = click.option("--delay-range", "delay_range", default=None, metavar="A:B",
                     help="An unknown constant delay anywhere in A:B: seconds with a unit "
                          "(e.g. 5ms:15ms; hve: the delay acts between the samples, proved "
                          "over the continuum) or whole samples (e.g. 5:15, hve and peb): the "
                          "certified minimum K_max over the range and the worst delay.")(f)
    f = click.option("--burst", type=float, default=None, metavar="L",
                     help="With --loss: losses come in bursts, a Gilbert-Elliott chain per "
                          "networked term with mean burst length L samples (L >= 1).")(f)
    return click.option("--loss", default=None, metavar="P|P1:P2[:N]|P1,P2",
                        help="Packet loss: each networked position packet (hve: the device's; "
                             "peb: each direction) is lost with probability P and the receiver "
                             "holds its last value; K_max is then mean-square (exact criterion, "
                             "evaluated in floating point). A range gives K_max against P.")(f)


def network_kmax(kind: str, kw: dict[str, Any], loop: Any, method: str, as_json: bool) -> None:
    """Answer ``kmax --loss``: one loss rate as a table / JSON object, several as a curve.

    Parameters
    ----------
    kind : str
        The loop kind (``hve``, ``peb``).
    kw : dict
        The command's options (``loss``, ``burst``).
    loop : HapticLoop or TeleoperationLoop
        The loop built from them.
    method : str
        ``--method`` (only ``exact`` applies).
    as_json : bool
        Print JSON.
    """
    from hapstab.analysis.network import kmax_against_loss, loss_critical_stiffness

    if method != "exact":
        raise HapstabError(f"--loss with --method {method}: the mean-square analysis is its own "
                           "method; leave --method at exact")
    if kind == "4ch":
        raise HapstabError("--loss: modelled for hve and peb (the 4-channel loop's force "
                           "channels are not)")
    losses = parse_range(kw["loss"], "--loss", "N/m", values=">= 0")   # 1 and above: loss_chain refuses
    if len(losses) > 1:
        curve = kmax_against_loss(loop, losses, kw["burst"])
        rows = [(f"P = {r.loss:g}", f"{fmt(r.critical_stiffness)} N/m"
                 + ("" if r.certified else " (mean-square)")) for r in curve.rows]
        emit(curve.to_dict(), as_json, lambda: rich_table(f"K_max against loss, {kind}", rows,
                                                          loop), loop)
        return
    res = loss_critical_stiffness(loop, losses[0], kw["burst"])
    rows = [("critical stiffness", f"{fmt(res.critical_stiffness)} N/m"),
            ("method", res.method),
            ("unstable from", f"{fmt(res.upper_bound)} N/m" if math.isfinite(res.upper_bound)
             else "none found"),
            ("without loss", f"{fmt(res.loss_free_critical_stiffness)} N/m"),
            ("why", res.reason)]
    emit(res.to_dict(), as_json, lambda: rich_table(f"K_max with packet loss, {kind}", rows,
                                                    loop), loop)


def range_kmax(kind: str, spec: str, loop: Any, method: str, as_json: bool) -> None:
    """Answer ``kmax --delay-range A:B``.

    Parameters
    ----------
    kind : str
        The loop kind.
    spec : str
        ``A:B`` in seconds (with a unit) or whole samples.
    loop : HapticLoop or TeleoperationLoop
        The loop (its delay is replaced by the range's).
    method : str
        ``--method`` (only ``exact``).
    as_json : bool
        Print JSON.
    """
    from hapstab.analysis.network.delay_range import delay_range_critical_stiffness

    if method != "exact":
        raise HapstabError(f"--delay-range with --method {method}: the range's minimum uses the "
                           "exact core; leave --method at exact")
    refuse_loop_delay(spec)
    lo, hi, seconds = parse_delay_range(spec, "--delay-range")
    if seconds:
        from hapstab.analysis.network.frac_result import fractional_range_critical_stiffness
        _fraction_table(kind, fractional_range_critical_stiffness(loop, lo, hi), loop, as_json)
        return
    res = delay_range_critical_stiffness(loop, lo, hi, seconds=False)
    rows = [("critical stiffness", f"{fmt(res.critical_stiffness)} N/m"),
            ("worst delay", f"{res.worst_delay_samples} samples"
             + (" (round trip)" if res.round_trip else "")),
            ("delays analysed", f"{res.delays_samples[0]}..{res.delays_samples[-1]}"),
            ("why", res.reason)]
    # the table names no loop: its own delay is not the one analysed (the range is)
    emit(res.to_dict(), as_json, lambda: rich_table(f"K_max over a delay range, {kind}", rows),
         loop)


def _fraction_table(kind: str, res: Any, loop: Any, as_json: bool) -> None:
    """Print a :class:`~hapstab.analysis.network.frac_result.FractionalRangeResult`."""
    state = "certified" if res.certified else "uncertain above the lower end"
    rows = [("critical stiffness", f"{fmt(res.critical_stiffness)} N/m ({state})"),
            ("proved enclosure", f"[{fmt(res.critical_stiffness)}, {fmt(res.upper_bound)}] N/m"),
            ("worst delay", f"{fmt(res.worst_delay_s * 1e3)} ms "
                            f"({fmt(res.worst_delay_samples)} samples)"),
            ("exact core there", f"{fmt(res.kmax_at_worst)} N/m"),
            ("why", res.reason)]
    emit(res.to_dict(), as_json, lambda: rich_table(f"K_max over a delay range, {kind}", rows),
         loop)

def refuse_loop_delay(spec: str) -> None:
    """``--delay-range`` replaces the loop's delay: a delay option typed beside it is
    refused by name (it was silently ignored)."""
    from hapstab.cli.options import given

    typed = [o for o, name in (("--delay", "delay"), ("--delay-s", "delay_s"),
                               ("--delay-forward", "delay_forward"),
                               ("--delay-backward", "delay_backward")) if given(name)]
    if typed:
        raise HapstabError(f"--delay-range = {spec!r} with {', '.join(typed)}: the range replaces "
                           "the loop's delay; give the range alone")


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

