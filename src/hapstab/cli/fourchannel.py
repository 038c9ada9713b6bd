"""The ``4ch`` loop kind of the CLI: Lawrence's 4-channel teleoperator
(:class:`~hapstab.models.fourchannel.FourChannelLoop`), its options and its builder.

It takes PEB's options but the scaling (express scaling in the gains), plus: whether the
master has a local stiffness (``--master-stiffness-ratio`` 1 or 0), the transmitted
position controllers C_1 and C_4 (ratios of their stiffness to K and their virtual
damping) and the four force gains C_2, C_3, C_5, C_6. K is the master's stiffness, or
the slave's when the master has none; every other stiffness keeps its ratio to K.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import click

from hapstab.cli.options import (
    RATIO,
    REAL,
    Number,
    period_option,
    teleoperator_devices,
    with_delays,
)
from hapstab.errors import HapstabError, ModelError
from hapstab.models.controllers import SpringDamper
from hapstab.models.fourchannel import FourChannelLoop
from hapstab.models.parts import parse_impedance

__all__ = ["four_channel_options", "four_channel_loop"]

#: The span of a stiffness ratio other than 0 (the slave's, --slave-stiffness-ratio).
RATIO_SPAN = RATIO.span or (1e-6, 1e6)


class TransmittedRatio(Number):
    """A transmitted controller's stiffness over K: 0 (none), or 1e-6...1e6 as the
    slave's ratio (beyond, the loop's numbers overflow)."""

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        v = super().convert(value, param, ctx)
        if v != 0 and not RATIO_SPAN[0] <= v <= RATIO_SPAN[1]:
            self.fail(f"{value!r}: must be 0 or between {RATIO_SPAN[0]:g} and {RATIO_SPAN[1]:g}",
                      param, ctx)
        return v


TRANSMITTED_RATIO = TransmittedRatio(nonnegative=True)


class MasterRatio(Number):
    """C_m's stiffness over K: 1 (K is the master's) or 0 (C_m a damper, K the slave's)."""

    name = "1|0"

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        v = super().convert(value, param, ctx)
        if v not in (0.0, 1.0):
            self.fail(f"{value!r}: allowed: 1 (C_m a spring-damper; K is its stiffness) or 0 "
                      "(C_m a damper only; K is the slave's stiffness)", param, ctx)
        return v


#: A force gain (N/N): any sign; beyond 1e6 the loop's numbers overflow (as for ratios).
GAIN = Number(span=(-1e6, 1e6))

#: The force gains: option, parameter, Lawrence's name and what it does.
FORCE_OPTIONS = (
    ("--c2", "force_to_master", "C_2: environment force to master (force reflection; "
                                "the slave's measured force, delayed, pushes the master)"),
    ("--c3", "force_to_slave", "C_3: operator force to slave (the master's measured force, "
                               "delayed, pushes the slave)"),
    ("--c5", "slave_force_feedback", "C_5: slave local force feedback (on the slave's own "
                                     "measured environment force)"),
    ("--c6", "master_force_feedback", "C_6: master local force feedback (on the master's own "
                                      "measured operator force)"),
)


def four_channel_options() -> tuple[Callable, list[Callable]]:
    """(--slave-stiffness-ratio, the other options of 4ch but PEB's), for
    :func:`hapstab.cli.options.loop_options`."""
    ratio = click.option(
        "--slave-stiffness-ratio", "slave_stiffness_ratio", type=RATIO, default=None,
        help="K_s / K_m, 1e-6...1e6 (default 1): the slave's stiffness is this times the "
             "master's, kept as K varies; not with --master-stiffness-ratio 0 (K is then the "
             "slave's stiffness).")
    own = [
        click.option("--master-stiffness-ratio", "master_stiffness_ratio", type=MasterRatio(),
                     default=1.0, show_default=True,
                     help="1: C_m = K + B(z-1)/(Tz), K is the master's stiffness; 0: C_m is the "
                          "damper B(z-1)/(Tz) only and K is the slave's stiffness (force "
                          "reflection: with --c4-stiffness-ratio 0 and --c2)."),
        click.option("--c1-stiffness-ratio", "c1_stiffness_ratio", type=TRANSMITTED_RATIO,
                     default=None,
                     help="C_1 (the slave's controller on the delayed master position): its "
                          "stiffness over K, 0 or 1e-6...1e6 (default: the slave's ratio, C_1 = C_s)."),
        click.option("--c1-virtual-damping", "c1_virtual_damping", type=REAL, default=None,
                     help="C_1's virtual damping in N*s/m (default: C_s's B)."),
        click.option("--c4-stiffness-ratio", "c4_stiffness_ratio", type=TRANSMITTED_RATIO,
                     default=None,
                     help="C_4 here is the master's controller on the delayed slave position, "
                          "with PEB's sign (Lawrence's -C_4; PEB is C_4 = C_m, C_1 = C_s): its "
                          "stiffness over K, 0 or 1e-6...1e6 (default: the master's ratio)."),
        click.option("--c4-virtual-damping", "c4_virtual_damping", type=REAL, default=None,
                     help="C_4's virtual damping in N*s/m (default: C_m's B, --virtual-damping)."),
    ]
    own += [click.option(flag, name, type=GAIN, default=0.0, show_default=True,
                         help=f"{what}; N/N, any sign, -1e6...1e6.")
            for flag, name, what in FORCE_OPTIONS]
    return ratio, own


def four_channel_loop(kw: dict[str, Any], stiffness: float = 0.0) -> FourChannelLoop:
    """Build the 4-channel teleoperator from parsed options: C_m = r_m K + B(z-1)/(Tz)
    (r_m = --master-stiffness-ratio, 1 or 0), C_s = r_s K + B_s(z-1)/(Tz) (r_s = 1 when
    r_m = 0: K is then the slave's), C_1 = r_1 K + B_1(z-1)/(Tz) (default C_s),
    C_4' = r_4 K + B_4(z-1)/(Tz) (default C_m) and the force gains; PEB's delays."""
    rm = kw.get("master_stiffness_ratio", 1.0)
    rs = kw.get("slave_stiffness_ratio")
    if rm == 0 and rs is not None:
        raise HapstabError(f"--slave-stiffness-ratio = {rs:g}: with --master-stiffness-ratio 0, "
                           "K is the slave's stiffness (its ratio is 1); allowed here: not given "
                           "(set C_1's and C_4's stiffness with --c1-/--c4-stiffness-ratio)")
    rs = 1.0 if rs is None else rs
    B = kw["virtual_damping"]
    Bs = B if kw.get("slave_virtual_damping") is None else kw["slave_virtual_damping"]
    r1, B1 = _or(kw.get("c1_stiffness_ratio"), rs), _or(kw.get("c1_virtual_damping"), Bs)
    r4, B4 = _or(kw.get("c4_stiffness_ratio"), rm), _or(kw.get("c4_virtual_damping"), B)
    gains = {name: kw.get(name, 0.0) for _, name, _ in FORCE_OPTIONS}
    loop = FourChannelLoop(*teleoperator_devices(kw),
                           SpringDamper(rm * stiffness, B), SpringDamper(rs * stiffness, Bs),
                           parse_impedance(kw["operator"], "--operator"),
                           parse_impedance(kw["environment"], "--environment"),
                           period_option(kw), kw["delay"],
                           slave_from_master=SpringDamper(r1 * stiffness, B1),
                           master_from_slave=SpringDamper(r4 * stiffness, B4), **gains)
    try:
        return with_delays(loop, kw)  # type: ignore[return-value]  # replace keeps the class
    except ModelError as e:        # (a fractional delay): name the option that gave it
        given = [f"--{k.replace('_', '-')} = {kw[k]:g}"
                 for k in ("delay_forward", "delay_backward", "delay_s") if kw.get(k) is not None]
        if not given:
            raise
        raise ModelError(f"{', '.join(given)}: {e}") from None


def _or(value: float | None, default: float) -> float:
    return default if value is None else value


def refuse_force_gains(kw: dict[str, Any], what: str) -> None:
    """Refuse a force gain given to an analysis derived for position-measuring
    controllers (passivity, circle, Llewellyn, transparency), naming its option; a
    loop of another kind has none."""
    for flag, name, _ in FORCE_OPTIONS:
        if kw.get(name, 0.0) != 0.0:
            raise HapstabError(f"{flag} = {kw[name]:g}: {what} is derived for controllers that "
                               "measure positions; a 4ch loop with force gains (--c2, --c3, --c5, "
                               "--c6: C_2, C_3, C_5, C_6) has the exact analysis (kmax, boundary, "
                               "check, simulate, region, best-damping) and Llewellyn's test and "
                               "transparency as approximations; allowed here: 0")
