"""Command-line interface: parse, call the library, print. Nothing else lives here.

Every user mistake is one line on stderr (``hapstab: error: ...``) and exit code 2.
Commands of later features live in their own ``cli_*`` modules listed in
``_PLUGINS`` and attach themselves to :data:`cli`.
"""

from __future__ import annotations

import importlib
import json
import math
import sys
import warnings
from typing import Any, Callable

import click
import numpy as np

from .errors import HapstabError
from .models import (Device, HapticLoop, SpringDamper, TeleoperationLoop, parse_impedance)

#: modules that add commands to ``cli`` (imported at the end of this module)
_PLUGINS: tuple[str, ...] = ("hapstab.cli_regions", "hapstab.cli_sim", "hapstab.cli_paper")


# ------------------------------------------------------------------ error handling
class HapstabGroup(click.Group):
    """A click group whose errors are one line on stderr and exit code 2."""

    def main(self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
             standalone_mode: bool = True, **extra: Any) -> Any:
        try:
            # extreme inputs overflow inside numpy: say so once, as an error, not as warnings
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                rv = super().main(args=args, prog_name=prog_name or "hapstab",
                                  complete_var=complete_var, standalone_mode=False, **extra)
        except click.exceptions.ClickException as e:
            _fail(e.format_message())
        except HapstabError as e:
            _fail(str(e))
        except OSError as e:
            _fail(f"cannot use {e.filename or 'the file'}: {e.strerror or e}")
        except MemoryError:
            _fail("out of memory: the model is too large for this machine")
        except ValueError as e:          # a plot format matplotlib does not know, NaN from overflow
            _fail(f"cannot do this: {e}")
        except (ArithmeticError, np.linalg.LinAlgError) as e:
            # parameters so extreme that the matrices overflow: the user's input, in one line
            _fail(f"cannot compute this: {type(e).__name__}: {e} (check the values: they may be "
                  "outside the range the model can represent)")
        except click.exceptions.Abort:
            click.echo("hapstab: aborted", err=True)
            sys.exit(1)
        sys.exit(rv if isinstance(rv, int) else 0)


def _fail(msg: str) -> None:
    click.echo("hapstab: error: " + " ".join(str(msg).split()), err=True)
    sys.exit(2)


class Number(click.ParamType):
    """A finite real number, optionally > 0 or >= 0; the message says what is allowed."""

    name = "number"

    def __init__(self, positive: bool = False, nonnegative: bool = False) -> None:
        self.positive, self.nonnegative = positive, nonnegative

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        if isinstance(value, float):
            v = value
        else:
            try:
                v = float(str(value).strip())
            except ValueError:
                self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r}: must be finite (not NaN or inf)", param, ctx)
        if self.positive and not v > 0:
            self.fail(f"{value!r}: must be > 0", param, ctx)
        if self.nonnegative and not v >= 0:
            self.fail(f"{value!r}: must be >= 0", param, ctx)
        return v


class Delay(click.ParamType):
    """A whole number of samples >= 0."""

    name = "samples"

    def convert(self, value: Any, param: Any, ctx: Any) -> int:
        if isinstance(value, int):
            v = value
        else:
            try:
                f = float(str(value).strip())
            except ValueError:
                self.fail(f"{value!r} is not a number; a whole number of samples >= 0 is allowed",
                          param, ctx)
            if not math.isfinite(f) or not f.is_integer():
                self.fail(f"{value!r}: must be a whole number of samples >= 0", param, ctx)
            v = int(f)
        if v < 0:
            self.fail(f"{value!r}: must be a whole number of samples >= 0", param, ctx)
        return v


POS, NONNEG, REAL = Number(positive=True), Number(nonnegative=True), Number()


def _stack(*decorators: Callable) -> Callable:
    def wrap(f: Callable) -> Callable:
        for d in reversed(decorators):
            f = d(f)
        return f
    return wrap


def loop_options(kind: str, ranges: bool = False) -> Callable:
    """Options of one loop kind (defaults: the paper's simulation study). With
    ``ranges``, --period and --delay take a range / list (for ``boundary``)."""
    if ranges:
        timing = [
            click.option("--period", "-T", "period", default="0.001:0.010:10", show_default=True,
                         help="Periods in s: start:stop:count (inclusive) or a comma list."),
            click.option("--delay", "-n", "delay", default="0,10" if kind == "hve" else "0,4",
                         show_default=True, help="Delays in whole samples, a comma list."),
        ]
    else:
        timing = [
            click.option("--period", "-T", type=POS, default=1e-3, show_default=True,
                         help="Sampling period T in seconds."),
            click.option("--delay", "-n", "delay", type=Delay(), default=0, show_default=True,
                         help="Delay n in whole samples (t_d = n T)."),
            click.option("--delay-s", "delay_s", type=NONNEG, default=None,
                         help="Delay in seconds, any value (fractional samples modelled exactly); "
                              "instead of --delay."),
        ]
        if kind == "peb":
            timing += [
                click.option("--delay-forward", "delay_forward", type=NONNEG, default=None,
                             help="Master->slave delay in samples (fractional allowed; "
                                  "default --delay)."),
                click.option("--delay-backward", "delay_backward", type=NONNEG, default=None,
                             help="Slave->master delay in samples (fractional allowed; "
                                  "default --delay)."),
            ]
    if kind == "hve":
        devices = [
            click.option("--mass", "-m", type=POS, default=0.15, show_default=True,
                         help="Device mass m in kg."),
            click.option("--damping", "-b", type=NONNEG, default=0.1, show_default=True,
                         help="Device damping b in N*s/m."),
        ]
    else:
        devices = [
            click.option("--master-mass", type=POS, default=0.015, show_default=True, help="kg"),
            click.option("--master-damping", type=NONNEG, default=0.02, show_default=True, help="N*s/m"),
            click.option("--slave-mass", type=POS, default=0.015, show_default=True, help="kg"),
            click.option("--slave-damping", type=NONNEG, default=0.02, show_default=True, help="N*s/m"),
            click.option("--environment", default="spring:1", show_default=True,
                         help="Environment impedance: none | spring:k | msd:m,b,k."),
            click.option("--slave-stiffness-ratio", "slave_stiffness_ratio", type=POS, default=1.0,
                         show_default=True,
                         help="K_s / K_m, > 0: the slave's stiffness is this times the master's "
                              "(K is the master's; the ratio is kept as K varies)."),
            click.option("--slave-virtual-damping", "slave_virtual_damping", type=REAL, default=None,
                         help="Slave virtual damping B_s in N*s/m, any sign (default: "
                              "--virtual-damping, i.e. C_m = C_s)."),
        ]
    return _stack(
        *devices, *timing,
        click.option("--virtual-damping", "-B", type=REAL, default=0.0, show_default=True,
                     help="Virtual damping B in N*s/m (H(z) = K + B(z-1)/(Tz), eq. 23); any sign "
                          "(B < 0 cancels device damping or friction)."),
        click.option("--operator", default="spring:1", show_default=True,
                     help="Operator impedance: none | spring:k | msd:m,b,k."),
        click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout."),
    )


def _given(name: str) -> bool:
    ctx = click.get_current_context(silent=True)
    if ctx is None:
        return False
    try:
        return ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE
    except Exception:
        return False


def hve_loop(kw: dict[str, Any], stiffness: float = 0.0) -> HapticLoop:
    """Build the HVE from parsed options."""
    loop = HapticLoop(Device(kw["mass"], kw["damping"]),
                      SpringDamper(stiffness, kw["virtual_damping"]),
                      parse_impedance(kw["operator"], "--operator"), kw["period"], kw["delay"])
    if kw.get("delay_s") is not None:
        if _given("delay"):
            raise HapstabError("--delay and --delay-s: give one of them, not both")
        loop = loop.with_delay_s(kw["delay_s"])
    return loop


def peb_loop(kw: dict[str, Any], stiffness: float = 0.0) -> TeleoperationLoop:
    """Build the PEB teleoperator from parsed options: C_m = K + B(z-1)/(Tz) and
    C_s = R K + B_s(z-1)/(Tz), R = --slave-stiffness-ratio (default 1) and
    B_s = --slave-virtual-damping (default B), so C_m = C_s unless they are given."""
    ratio = kw.get("slave_stiffness_ratio", 1.0)
    B_s = kw.get("slave_virtual_damping")
    cm = SpringDamper(stiffness, kw["virtual_damping"])
    cs = SpringDamper(ratio * stiffness, kw["virtual_damping"] if B_s is None else B_s)
    loop = TeleoperationLoop(Device(kw["master_mass"], kw["master_damping"]),
                             Device(kw["slave_mass"], kw["slave_damping"]), cm, cs,
                             parse_impedance(kw["operator"], "--operator"),
                             parse_impedance(kw["environment"], "--environment"),
                             kw["period"], kw["delay"])
    fwd, bwd, ds = kw.get("delay_forward"), kw.get("delay_backward"), kw.get("delay_s")
    if ds is not None and (fwd is not None or bwd is not None or _given("delay")):
        raise HapstabError("--delay-s with --delay or --delay-forward/--delay-backward: give the "
                           "delay one way (--delay is the default for a side not given)")
    T = loop.period
    if ds is not None:
        loop = loop.with_delays_s(ds)
    elif fwd is not None or bwd is not None:
        f = (fwd if fwd is not None else loop.delay_samples) * T
        b = (bwd if bwd is not None else loop.delay_samples) * T
        loop = loop.with_delays_s(f, b)
    return loop


LOOP_KINDS = {"hve": hve_loop, "peb": peb_loop}


def emit(data: dict[str, Any], as_json: bool, table: Callable[[], None]) -> None:
    """One JSON object on stdout, or a readable table."""
    if as_json:
        click.echo(json.dumps(data))
    else:
        table()


def rich_table(title: str, rows: list[tuple[str, str]]) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title=title, show_header=False)
    t.add_column(style="bold")
    t.add_column()
    for k, v in rows:
        t.add_row(k, v)
    Console().print(t)


def fmt(x: float) -> str:
    return "inf" if math.isinf(x) else f"{x:.10g}"


# ------------------------------------------------------------------------- commands
@click.group(cls=HapstabGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="hapstab")
def cli() -> None:
    """Exact stability and critical stiffness of sampled-data, delayed haptic (hve) and
    PEB teleoperation (peb) loops. Defaults are the paper's simulation study."""


@cli.group()
def kmax() -> None:
    """Critical stiffness K_max: the largest K stable for every K in (0, K_max]."""


@cli.group()
def check() -> None:
    """Stability verdict at a given stiffness."""


@cli.group("boundary")
def boundary_cmd() -> None:
    """K_max over sampling periods and delays (Fig. 5 / Fig. 6 curves)."""


def _kmax_command(kind: str) -> None:
    make = LOOP_KINDS[kind]
    from .analysis import methods_for

    @kmax.command(kind)
    @loop_options(kind)
    @click.option("--method", default="exact", show_default=True,
                  help="exact | " + " | ".join(m for m in methods_for(kind) if m != "exact"))
    @click.option("--approximation", default=None,
                  help="For --method circle: forward | backward | tustin.")
    def _cmd(method: str, approximation: str | None, as_json: bool, **kw: Any) -> None:
        from .analysis import critical_stiffness, methods_for

        allowed = methods_for(kind)
        if method not in allowed:
            raise HapstabError(f"--method = {method!r}: unknown for {kind}; allowed: {', '.join(allowed)}")
        loop = make(kw, stiffness=1.0)
        if approximation and method != "circle":
            raise HapstabError(f"--approximation = {approximation!r}: applies to --method circle only "
                               f"(got --method {method})")
        opts = {"approximation": approximation} if approximation else {}
        res = critical_stiffness(loop, method=method, **opts)
        rows = [("critical stiffness", f"{fmt(res.critical_stiffness)} N/m"),
                ("method", res.method),
                ("stable intervals", ", ".join(f"({fmt(a)}, {fmt(b)}]" for a, b in res.stable_intervals)
                 or "none"),
                ("crossing frequency", f"{res.crossing_frequency_hz:.6g} Hz"),
                ("why", res.reason)]
        emit(res.to_dict(), as_json, lambda: rich_table(f"K_max, {kind}", rows))

    _cmd.__doc__ = f"K_max of the {kind.upper()} loop."


def _check_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @check.command(kind)
    @loop_options(kind)
    @click.option("--stiffness", "-K", type=NONNEG, required=True, help="K in N/m.")
    def _cmd(stiffness: float, as_json: bool, **kw: Any) -> None:
        from .exact import stability

        res = stability(make(kw, stiffness))
        d = res.to_dict()
        d["stiffness"] = stiffness
        rows = [("verdict", res.verdict), ("spectral radius", f"{res.spectral_radius:.12g}"),
                ("dominant pole", f"{res.dominant_pole:.8g}"),
                ("frequency", f"{res.frequency_hz:.6g} Hz"), ("why", res.reason)]
        emit(d, as_json, lambda: rich_table(f"stability, {kind}, K = {stiffness:g} N/m", rows))

    _cmd.__doc__ = f"Stability of the {kind.upper()} loop at stiffness K."


def parse_periods(spec: str) -> list[float]:
    """``start:stop:count`` (inclusive, evenly spaced) or a comma list, seconds."""
    allowed = "allowed: start:stop:count (e.g. 0.001:0.010:10) or a comma list of periods > 0"
    parts = spec.split(":") if ":" in spec else None
    if parts is not None and len(parts) != 3:
        raise HapstabError(f"--period = {spec!r}: expected start:stop:count; {allowed}")
    try:
        nums = [float(x) for x in (parts if parts is not None else spec.split(",")) if x.strip()]
    except ValueError:
        raise HapstabError(f"--period = {spec!r}: malformed number; {allowed}") from None
    if parts is not None:
        lo, hi, cnt = nums
        if not (math.isfinite(cnt) and cnt.is_integer() and 1 <= cnt <= 100_000):
            raise HapstabError(f"--period = {spec!r}: count must be a whole number from 1 to "
                               f"100000; {allowed}")
        if not hi >= lo:
            raise HapstabError(f"--period = {spec!r}: the range is empty (stop < start); {allowed}")
        nums = [lo + (hi - lo) * i / max(int(cnt) - 1, 1) for i in range(int(cnt))]
    if not nums:
        raise HapstabError(f"--period = {spec!r}: the range is empty; {allowed}")
    for v in nums:
        if not (math.isfinite(v) and v > 0):
            raise HapstabError(f"--period = {spec!r}: every period must be finite and > 0; {allowed}")
    return nums


def parse_delays(spec: str) -> list[int]:
    allowed = "allowed: a comma list of whole numbers of samples >= 0 (e.g. 0,10)"
    out = []
    for x in spec.split(","):
        x = x.strip()
        if not x:
            continue
        try:
            f = float(x)
        except ValueError:
            raise HapstabError(f"--delay = {spec!r}: malformed number {x!r}; {allowed}") from None
        if not (math.isfinite(f) and f.is_integer() and f >= 0):
            raise HapstabError(f"--delay = {spec!r}: {x!r} is not a whole number >= 0; {allowed}")
        out.append(int(f))
    if not out:
        raise HapstabError(f"--delay = {spec!r}: the list is empty; {allowed}")
    return out


def _boundary_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @boundary_cmd.command(kind)
    @loop_options(kind, ranges=True)
    @click.option("--method", default="exact", show_default=True)
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Also write the table as CSV.")
    def _cmd(method: str, csv_path: str | None, as_json: bool, **kw: Any) -> None:
        from .analysis import boundary

        periods, delays = parse_periods(kw["period"]), parse_delays(kw["delay"])
        kw.update(period=periods[0], delay=delays[0])
        res = boundary(make(kw, 1.0), periods, delays, method=method)
        if csv_path:
            res.to_csv(csv_path)
        emit(res.to_dict(), as_json, lambda: _boundary_table(res))

    _cmd.__doc__ = f"K_max of the {kind.upper()} loop over a range of periods and delays."


def _boundary_table(res: Any) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"K_max (N/m), {res.loop_kind}, method {res.method}")
    t.add_column("T (ms)", justify="right")
    for n in res.delays:
        t.add_column(f"n = {n}", justify="right")
    for j, T in enumerate(res.periods):
        t.add_row(f"{T * 1e3:.4g}", *[fmt(res.critical_stiffness[i, j]) for i in range(len(res.delays))])
    Console().print(t)


for _kind in LOOP_KINDS:
    _kmax_command(_kind)
    _check_command(_kind)
    _boundary_command(_kind)


@cli.command()
@click.option("--json", "as_json", is_flag=True)
def demo(as_json: bool) -> None:
    """The paper's Fig. 5 and Fig. 6 boundaries: exact K_max beside the paper's lines."""
    from .analysis import boundary
    from .closed_forms import eq18, eq29, eq34
    from .models import paper_hve, paper_peb

    import numpy as np

    T = np.linspace(1e-3, 1e-2, 10)
    figs = [("Fig. 5 (HVE)", paper_hve(), (0, 10), eq18), ("Fig. 6 (PEB)", paper_peb(), (0, 4), None)]
    data: dict[str, Any] = {}
    for title, loop, delays, _ in figs:
        res = boundary(loop, T, delays)
        rows = []
        for i, n in enumerate(delays):
            for j, t in enumerate(T):
                lp = loop.replace(period=float(t), delay_samples=n)
                if isinstance(lp, HapticLoop):
                    theory, eq = eq18(lp).critical_stiffness, "(13)" if n == 0 else "(18)"
                else:
                    theory = (eq29(lp) if n == 0 else eq34(lp)).critical_stiffness
                    eq = "(29)" if n == 0 else "(34)"
                rows.append({"period_s": float(t), "delay_samples": n, "theory": theory,
                             "equation": eq, "exact": float(res.critical_stiffness[i, j])})
        data[title] = rows
    if as_json:
        click.echo(json.dumps(data))
        return
    from rich.console import Console
    from rich.table import Table

    con = Console()
    for title, rows in data.items():
        t = Table(title=f"{title}: K_max (N/m), paper's condition vs exact sampled-data loop")
        for c in ("T (ms)", "n", "paper", "eq.", "exact", "exact/paper"):
            t.add_column(c, justify="right")
        for r in rows:
            t.add_row(f"{r['period_s'] * 1e3:.0f}", str(r["delay_samples"]), f"{r['theory']:.6g}",
                      r["equation"], f"{r['exact']:.6g}", f"{r['exact'] / r['theory']:.5f}")
        con.print(t)


for _mod in _PLUGINS:
    importlib.import_module(_mod)


def main(argv: list[str] | None = None) -> None:
    """Console entry point."""
    cli.main(args=argv)
