"""``hapstab kmax hve|peb --loss P [--burst L]``: mean-square K_max with packet loss
(:mod:`hapstab.analysis.network`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import click

from hapstab.cli.options import emit, fmt, rich_table
from hapstab.cli.ranges import parse_range
from hapstab.errors import HapstabError

__all__ = ["network_options", "network_kmax"]


def network_options(f: Callable) -> Callable:
    """The --loss and --burst options of ``kmax``."""
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
