"""What the commands share: number and delay types, the loop options of hve, peb and
4ch (4ch's own in :mod:`hapstab.cli.fourchannel`), and the output (one JSON object, or
a table)."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from contextvars import ContextVar
from typing import Any

import click

from hapstab.cli import output
from hapstab.errors import PERIOD_RANGE, HapstabError, ascii_float
from hapstab.models.controllers import (
    Controller,
    FilteredSpringDamper,
    SpringDamper,
    VelocityFilter,
)
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.models.parts import Device, parse_impedance
from hapstab.results import dumps

#: The human output, re-exported: the commands import it from here.
console, fmt, progress, rich_table = output.console, output.fmt, output.progress, output.rich_table


class Number(click.ParamType):
    """A finite real number, optionally > 0 or >= 0; the message says what is allowed."""

    name = "number"

    def __init__(self, positive: bool = False, nonnegative: bool = False,
                 span: tuple[float, float] | None = None) -> None:
        self.positive, self.nonnegative, self.span = positive, nonnegative, span

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        if isinstance(value, float):
            v = value
        else:
            try:
                v = ascii_float(value)
            except ValueError:
                self.fail(f"{value!r} is not a number (ASCII decimal digits)", param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r}: must be finite (not NaN or inf)", param, ctx)
        if self.positive and not v > 0:
            self.fail(f"{value!r}: must be > 0", param, ctx)
        if self.nonnegative and not v >= 0:
            self.fail(f"{value!r}: must be >= 0", param, ctx)
        if self.span is not None and not self.span[0] <= v <= self.span[1]:
            self.fail(f"{value!r}: must be between {self.span[0]:g} and {self.span[1]:g}", param,
                      ctx)
        return v


#: Units a quantity may carry (case-insensitive), to the SI unit.
#: Case matters where it changes the meaning (mHz is not MHz, Ms is not ms): only these
#: spellings are read.
UNITS = {"s": {"": 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6},
         "Hz": {"": 1.0, "Hz": 1.0, "hz": 1.0, "kHz": 1e3, "khz": 1e3, "KHz": 1e3, "MHz": 1e6},
         "m": {"": 1.0, "m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "nm": 1e-9}}
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([^\d\s]*)\s*$", re.ASCII)


def parse_quantity(text: Any, unit: str) -> float:
    """``"1ms"``, ``"1 ms"``, ``"0.001"`` (seconds) or ``"1kHz"`` as a number in ``unit``.

    Raises
    ------
    ValueError
        Not a number with one of the units of :data:`UNITS`; the message says which.
    """
    if isinstance(text, (int, float)):      # an int beyond doubles (10**400): inf, as 1e400
        return float(text) if isinstance(text, float) or abs(text) < 2 ** 1023 else \
            (math.inf if text > 0 else -math.inf)
    try:
        return ascii_float(text)        # a plain number (also nan and inf, refused later)
    except ValueError:
        pass
    m = _QUANTITY.match(str(text))
    if not m:
        raise ValueError(f"{text!r} is not a number (with a unit: "
                         f"{', '.join(u for u in UNITS[unit] if u)})")
    scale = UNITS[unit].get(m.group(2).replace("μ", "µ"))
    if scale is None:
        raise ValueError(f"{text!r}: unknown unit {m.group(2)!r}; allowed: "
                         f"{', '.join(u for u in UNITS[unit] if u)} (or none: {unit})")
    # decimal arithmetic: "100um" is the double nearest 1e-4, as "1e-4" is (100 * 1e-6 is not)
    from decimal import Decimal

    return float(Decimal(m.group(1)) * Decimal(repr(scale)))


class Quantity(Number):
    """A number with an optional unit (``1ms``, ``1 kHz``); plain numbers are in ``unit``."""

    def __init__(self, unit: str, positive: bool = False, nonnegative: bool = False) -> None:
        super().__init__(positive, nonnegative)
        self.unit = unit
        self.name = f"number[{unit}]"

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        try:
            v = parse_quantity(value, self.unit)
        except ValueError as e:
            self.fail(str(e), param, ctx)
        out = super().convert(v, param, ctx)
        if self.unit == "s":
            from hapstab.cli.notes import remember_plain_seconds
            remember_plain_seconds(value, param, ctx)
        return out


class Delay(click.ParamType):
    """A whole number of samples >= 0."""

    name = "samples"

    def convert(self, value: Any, param: Any, ctx: Any) -> int:
        if isinstance(value, int):
            v = value
        else:
            try:
                f = ascii_float(value)
            except ValueError:
                self.fail(f"{value!r} is not a number; a whole number of samples >= 0 is allowed",
                          param, ctx)
            if not math.isfinite(f) or not f.is_integer():
                self.fail(f"{value!r}: must be a whole number of samples >= 0", param, ctx)
            v = int(f)
        if v < 0:
            self.fail(f"{value!r}: must be a whole number of samples >= 0", param, ctx)
        return v


class IntRange(click.IntRange):
    """:class:`click.IntRange` of ASCII decimal digits only (Python's :func:`int` also
    takes mathematical bold or fullwidth digits and ``'1_000'``)."""

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        if isinstance(value, str) and not re.fullmatch(r"\s*[-+]?[0-9]+\s*", value, re.ASCII):
            self.fail(f"{value!r} is not a whole number (ASCII decimal digits)", param, ctx)
        return super().convert(value, param, ctx)


POS, NONNEG, REAL = Number(positive=True), Number(nonnegative=True), Number()
#: K_s/K_m and the scaling factors: scaled teleoperators use 1e-3...1e3; beyond 1e6 the
#: loop's numbers overflow
RATIO = Number(positive=True, span=(1e-6, 1e6))
#: A length such as an encoder's step: metres, or with a unit (2um, 0.01mm)
LENGTH = Quantity("m", positive=True)


def _stack(*decorators: Callable) -> Callable:
    def wrap(f: Callable) -> Callable:
        for d in reversed(decorators):
            f = d(f)
        return f
    return wrap


def _timing_options(kind: str, ranges: bool, jitter: bool = False) -> list[Callable]:
    """--period / --rate and the delay options; with ``ranges`` (``boundary``) ranges and
    lists of them; with ``jitter`` (``hapstab jitter``) one --delay LO:HI, the range each
    networked delay varies in."""
    if jitter:
        return [
            click.option("--period", "-T", type=Quantity("s", positive=True), default=1e-3,
                         show_default=True,
                         help="Sampling period T: seconds, or with a unit (1ms, 250us)."),
            click.option("--rate", type=Quantity("Hz", positive=True), default=None,
                         help="Sampling rate instead of --period: Hz, or with a unit (1kHz)."),
            click.option("--delay", "-n", "delay", required=True, metavar="LO:HI",
                         help="The range the delay varies in from sample to sample: whole "
                              "samples (5:15), or seconds with a unit (5ms:15ms), converted "
                              "to whole samples ceil(t / T) (a receiver acting at the "
                              "sampling instants)"
                              + ("; each direction independently." if kind == "peb" else ".")),
        ]
    if ranges:
        timing = [
            click.option("--period", "-T", "period", default="1ms:10ms:10", show_default=True,
                         help="Periods: start:stop[:count] (inclusive) or a comma list; "
                              "seconds, or with a unit (250us:2ms:8)."),
            click.option("--rate", default=None,
                         help="Sampling rates instead of --period: start:stop[:count] or a "
                              "comma list, Hz or with a unit (250Hz:4kHz:16)."),
            click.option("--delay", "-n", "delay", default="0,10" if kind == "hve" else "0,4",
                         show_default=True, help="Delays in whole samples (t_d = n T at "
                                                 "each T), a comma list."),
            click.option("--delay-s", "delay_s", default=None,
                         help="Delays held fixed in time as T varies, instead of --delay: "
                              "seconds or with a unit, a comma list (20ms,50ms)."),
        ]
    else:
        timing = [
            click.option("--period", "-T", type=Quantity("s", positive=True), default=1e-3,
                         show_default=True,
                         help="Sampling period T: seconds, or with a unit (1ms, 250us)."),
            click.option("--rate", type=Quantity("Hz", positive=True), default=None,
                         help="Sampling rate instead of --period: Hz, or with a unit (1kHz)."),
            click.option("--delay", "-n", "delay", type=Delay(), default=0, show_default=True,
                         help="Delay n in whole samples (t_d = n T)"
                              + (": one-way, in each direction (the round trip is 2n)."
                                 if kind in ("peb", "4ch") else ".")),
            click.option("--delay-s", "delay_s", type=Quantity("s", nonnegative=True), default=None,
                         help="Delay in seconds or with a unit (20ms), "
                              + ("one-way in each direction, " if kind in ("peb", "4ch") else "")
                              + ("a whole number of samples (4ch takes no fractional delay)"
                                 if kind == "4ch" else
                                 "any value (fractional samples modelled exactly)")
                              + "; instead of --delay."),
        ]
        if kind in ("peb", "4ch"):
            whole = "whole samples only" if kind == "4ch" else "fractional allowed"
            timing += [
                click.option("--delay-forward", "delay_forward", type=NONNEG, default=None,
                             help=f"Master->slave delay in samples ({whole}; not with --delay; "
                                  "default: the study's delay, else 0)."),
                click.option("--delay-backward", "delay_backward", type=NONNEG, default=None,
                             help=f"Slave->master delay in samples ({whole}; not with --delay; "
                                  "default: the study's delay, else 0)."),
            ]
    return timing


#: What a device's --friction does (its help).
FRICTION_HELP = ("simulate models it exactly (stick-slip between samples); the linear analyses "
                 "analyse the friction-free loop and say so.")


def loop_options(kind: str, ranges: bool = False, jitter: bool = False) -> Callable:
    """Options of one loop kind (defaults: the paper's simulation study). With
    ``ranges``, --period and --delay take a range / list (for ``boundary``); with
    ``jitter``, --delay is the range LO:HI of a time-varying delay (``hapstab jitter``)."""
    timing = _timing_options(kind, ranges, jitter)
    if kind == "hve":
        devices = [
            click.option("--mass", "-m", type=POS, default=0.15, show_default=True,
                         help="Device mass m in kg."),
            click.option("--damping", "-b", type=NONNEG, default=0.1, show_default=True,
                         help="Device damping b in N*s/m."),
            click.option("--friction", type=NONNEG, default=0.0, show_default=True,
                         help=f"Device Coulomb friction f_c in N. {FRICTION_HELP}"),
        ]
    else:
        devices = _teleoperator_options(kind)
    return _stack(
        *devices, *timing,
        click.option("--virtual-damping", "-B", type=REAL, default=0.0, show_default=True,
                     help="Virtual damping B in N*s/m (H(z) = K + B(z-1)/(Tz), eq. 23); any sign "
                          "(B < 0 cancels device damping or friction)"
                          + ("; C_m's." if kind == "4ch" else ".")),
        click.option("--operator", default="spring:1", show_default=True,
                     help="Operator impedance: none | spring:k | msd:m,b,k."),
        *([] if kind == "4ch" else [click.option(
            "--velocity-filter", default=None, metavar="lowpass:HZ|average:N",
            help="The damper acts on a filtered velocity: a first-order low-pass of the "
                 "backward difference (cutoff in Hz) or the mean of the last N differences.")]),
        click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout."),
    )


def _teleoperator_options(kind: str) -> list[Callable]:
    """The devices, environment and slave controller of peb and 4ch; peb's scaling, or
    4ch's transmitted controllers and force gains (:mod:`hapstab.cli.fourchannel`)."""
    if kind == "4ch":
        from hapstab.cli.fourchannel import four_channel_options

        ratio, own = four_channel_options()
    else:
        ratio = click.option(
            "--slave-stiffness-ratio", "slave_stiffness_ratio", type=RATIO, default=1.0,
            show_default=True, help="K_s / K_m, 1e-6...1e6: the slave's stiffness is this times "
                                    "the master's (K is the master's; the ratio is kept as K varies).")
        own = [click.option("--scaling-position", "position_scale", type=RATIO, default=1.0,
                            show_default=True,
                            help="Position scaling alpha, 1e-6...1e6: the slave follows alpha "
                                 "times the master's motion."),
               click.option("--scaling-force", "force_scale", type=RATIO, default=1.0,
                            show_default=True,
                            help="Force scaling beta, 1e-6...1e6: the operator feels beta times "
                                 "the environment's force.")]
    return [
        click.option("--master-mass", type=POS, default=0.015, show_default=True, help="kg"),
        click.option("--master-damping", type=NONNEG, default=0.02, show_default=True, help="N*s/m"),
        click.option("--slave-mass", type=POS, default=0.015, show_default=True, help="kg"),
        click.option("--slave-damping", type=NONNEG, default=0.02, show_default=True, help="N*s/m"),
        click.option("--master-friction", type=NONNEG, default=0.0, show_default=True,
                     help=f"Master's Coulomb friction f_c in N. {FRICTION_HELP}"),
        click.option("--slave-friction", type=NONNEG, default=0.0, show_default=True,
                     help=f"Slave's Coulomb friction f_c in N. {FRICTION_HELP}"),
        click.option("--environment", default="spring:1", show_default=True,
                     help="Environment impedance: none | spring:k | msd:m,b,k."),
        ratio,
        click.option("--slave-virtual-damping", "slave_virtual_damping", type=REAL, default=None,
                     help="Slave virtual damping B_s in N*s/m, any sign (default: "
                          "--virtual-damping, i.e. C_m = C_s)."),
        *own,
    ]


def damping_bound_options(kind: str) -> Callable:
    """Bounded impedance for Llewellyn's test (peb and 4ch): the least damping of every
    operator and environment (none for the HVE)."""
    if kind not in ("peb", "4ch"):
        return _stack()
    return _stack(
        click.option("--operator-damping-min", "operator_damping_min", type=NONNEG, default=None,
                     help="Llewellyn (bounded impedance): every operator has at least this "
                          "damping, N*s/m (default 0: any passive operator)."),
        click.option("--environment-damping-min", "environment_damping_min", type=NONNEG,
                     default=None,
                     help="Llewellyn (bounded impedance): every environment has at least this "
                          "damping, N*s/m (default 0: any passive environment)."))


def bounds_of(kw: dict[str, Any], method: str) -> dict[str, float]:
    """The damping bounds given (taken out of ``kw``), refused unless ``method`` is
    llewellyn."""
    popped = {k: kw.pop(k, None) for k in ("operator_damping_min", "environment_damping_min")}
    given_ = {k: v for k, v in popped.items() if v is not None}
    if given_ and method != "llewellyn":
        name = "--" + next(iter(given_)).replace("_", "-")
        raise HapstabError(f"{name}: applies to --method llewellyn only (got --method {method})")
    return given_


def given(name: str) -> bool:
    """Whether option ``name`` was typed on the command line (not its default)."""
    ctx = click.get_current_context(silent=True)
    if ctx is None:
        return False
    try:
        return ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE
    except Exception:
        return False


#: A sampling period this long is almost surely a unit mistake (1 meaning 1 ms): haptic
#: and teleoperation loops sample at 0.1...10 ms.
PLAUSIBLE_PERIOD_S = 0.1


def period_option(kw: dict[str, Any]) -> float:
    """T from --period or --rate (one of them), with a warning on stderr when it is
    implausibly long for a haptic loop."""
    rate = kw.get("rate")
    if rate is not None:
        if given("period"):
            raise HapstabError("--period and --rate: give one of them, not both")
        T = 1.0 / rate
        lo, hi = PERIOD_RANGE
        if not lo <= T <= hi:
            raise HapstabError(f"--rate = {rate:g} Hz: gives T = {T:g} s; the rate must be "
                               f"between {1 / hi:g} Hz and {1 / lo:g} Hz")
    else:
        T = kw["period"]
    if PLAUSIBLE_PERIOD_S <= T <= PERIOD_RANGE[1]:   # (out of range is an error of its own)
        click.echo(f"hapstab: warning: sampling period T = {T:g} s: haptic loops sample at "
                   "0.1-10 ms; if you meant milliseconds, write -T 1ms (or --rate 1kHz)",
                   err=True)
    return T


def _spring_damper(K: float, B: float, kw: dict[str, Any]) -> Controller:
    """Eq. (23)'s spring-damper, or with --velocity-filter its filtered form."""
    vf = kw.get("velocity_filter")
    if vf is None:
        return SpringDamper(K, B)
    return FilteredSpringDamper(K, B, VelocityFilter.parse(vf))


def hve_loop(kw: dict[str, Any], stiffness: float = 0.0) -> HapticLoop:
    """Build the HVE from parsed options."""
    loop = HapticLoop(Device(kw["mass"], kw["damping"], kw.get("friction", 0.0)),
                      _spring_damper(stiffness, kw["virtual_damping"], kw),
                      parse_impedance(kw["operator"], "--operator"), period_option(kw), kw["delay"])
    if kw.get("delay_s") is not None:
        if given("delay"):
            raise HapstabError("--delay and --delay-s: give one of them, not both")
        loop = loop.with_delay_s(kw["delay_s"])
        from hapstab.cli.notes import note_plain_seconds
        note_plain_seconds(kw["delay_s"])
    return loop


def peb_loop(kw: dict[str, Any], stiffness: float = 0.0) -> TeleoperationLoop:
    """Build the PEB teleoperator from parsed options: C_m = K + B(z-1)/(Tz) and
    C_s = R K + B_s(z-1)/(Tz), R = --slave-stiffness-ratio (default 1) and
    B_s = --slave-virtual-damping (default B), so C_m = C_s unless they are given."""
    ratio = kw.get("slave_stiffness_ratio", 1.0)
    B_s = kw.get("slave_virtual_damping")
    cm = _spring_damper(stiffness, kw["virtual_damping"], kw)
    cs = _spring_damper(ratio * stiffness, kw["virtual_damping"] if B_s is None else B_s, kw)
    loop = TeleoperationLoop(*teleoperator_devices(kw), cm, cs,
                             parse_impedance(kw["operator"], "--operator"),
                             parse_impedance(kw["environment"], "--environment"),
                             period_option(kw), kw["delay"],
                             position_scale=kw.get("position_scale", 1.0),
                             force_scale=kw.get("force_scale", 1.0))
    return with_delays(loop, kw)


def teleoperator_devices(kw: dict[str, Any]) -> tuple[Device, Device]:
    """The master and the slave from parsed options (mass, damping, Coulomb friction)."""
    return (Device(kw["master_mass"], kw["master_damping"], kw.get("master_friction", 0.0)),
            Device(kw["slave_mass"], kw["slave_damping"], kw.get("slave_friction", 0.0)))


def with_delays(loop: TeleoperationLoop, kw: dict[str, Any]) -> TeleoperationLoop:
    """A teleoperator's delays from --delay-s or --delay-forward / --delay-backward
    (its --delay is the default of a side not given); a 4ch loop refuses fractional ones."""
    fwd, bwd, ds = kw.get("delay_forward"), kw.get("delay_backward"), kw.get("delay_s")
    if ds is not None and (fwd is not None or bwd is not None or given("delay")):
        raise HapstabError("--delay-s with --delay or --delay-forward/--delay-backward: give the "
                           "delay one way (--delay is the default for a side not given)")
    if (fwd is not None or bwd is not None) and given("delay"):
        side = "--delay-forward" if fwd is not None else "--delay-backward"
        raise HapstabError(f"--delay = {kw.get('delay')!r} with {side} = "
                           f"{fwd if fwd is not None else bwd!r}: give the delay one way (both "
                           "sides with --delay-forward and --delay-backward, or one --delay)")
    T = loop.period
    if ds is not None:
        loop = loop.with_delays_s(ds)
        from hapstab.cli.notes import note_plain_seconds
        note_plain_seconds(float(ds))
    elif fwd is not None or bwd is not None:
        f = (fwd if fwd is not None else loop.delay_samples) * T
        b = (bwd if bwd is not None else loop.delay_samples) * T
        loop = loop.with_delays_s(f, b)
    return loop


def four_channel_loop(kw: dict[str, Any], stiffness: float = 0.0) -> TeleoperationLoop:
    """Build the 4-channel teleoperator (:func:`hapstab.cli.fourchannel.four_channel_loop`)."""
    from hapstab.cli.fourchannel import four_channel_loop as build

    return build(kw, stiffness)


#: Loop kinds whose state-space model (:func:`hapstab.engine.system.build`: ``check``,
#: ``simulate``, ``region``'s D-decomposition) the engine builds: every kind.
STATE_SPACE_KINDS = ("hve", "peb", "4ch")
#: Loop kinds the paper's closed forms are derived for (``audit``, region's "paper"
#: overlay); a 4ch loop has none.
PAPER_KINDS = ("hve", "peb")

def kind_methods(kind: str) -> list[str]:
    """The K_max methods the commands offer for ``kind``: the library's
    (:func:`~hapstab.analysis.methods.methods_for`) but simulation where the engine
    does not build the kind's state-space model (:data:`STATE_SPACE_KINDS`)."""
    from hapstab.analysis.methods import methods_for

    return [m for m in methods_for(kind) if m != "simulation" or kind in STATE_SPACE_KINDS]


def refuse_method(kind: str, method: str) -> None:
    """A method the library has for ``kind`` but the commands do not offer (a 4ch loop's
    simulation), refused naming why."""
    from hapstab.analysis.methods import methods_for

    if method in methods_for(kind) and method not in kind_methods(kind):
        raise HapstabError(f"--method = {method!r}: a {kind} loop is not simulated yet (the "
                           "engine's state-space model does not take its channels); allowed: "
                           f"{', '.join(kind_methods(kind))}")


#: loop kind -> its builder from the command's options
LOOP_KINDS: dict[str, Callable[..., HapticLoop | TeleoperationLoop]] = {
    "hve": hve_loop, "peb": peb_loop, "4ch": four_channel_loop}


#: The command line being run (set by the group): every JSON output echoes it.
ARGV: ContextVar[tuple[str, ...]] = ContextVar("hapstab_argv", default=())


def provenance(loop: Any = None) -> dict[str, Any]:
    """What an output was computed from: the hapstab version, the command line and the
    loop (every parameter, units in the keys)."""
    from hapstab import __version__

    inputs: dict[str, Any] = {"command_line": ["hapstab", *ARGV.get()]}
    if loop is not None:
        inputs["loop"] = loop.to_dict()
    return {"hapstab_version": __version__, "inputs": inputs}


def emit(data: dict[str, Any], as_json: bool, table: Callable[[], None], loop: Any = None) -> None:
    """One JSON object on stdout (the result, then its provenance), or a readable table.
    A linear analysis of a loop with Coulomb friction says that it analysed the
    friction-free loop (``friction_note``, unless its reason says so already)."""
    from hapstab.models.parts import friction_note

    note = friction_note(loop) if loop is not None and "nonlinear" not in data else ""
    if note and (note in str(data.get("reason", ""))
                 or (as_json and data.get("friction_note") == note)):
        note = ""                 # said once: in the reason, or the JSON's friction_note
    if as_json:
        click.echo(dumps({**data, **({"friction_note": note} if note else {}),
                          **provenance(loop)}))
    else:
        table()
        if note:
            click.echo(note)
