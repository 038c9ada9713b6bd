"""``hapstab kmax | check | boundary hve|peb|4ch`` and ``hapstab demo``."""

from __future__ import annotations

import math
from typing import Any

import click
import numpy as np

from hapstab.cli.fourchannel import refuse_force_gains
from hapstab.cli.network import network_kmax, network_options, range_kmax
from hapstab.cli.options import (
    LOOP_KINDS,
    NONNEG,
    POS,
    STATE_SPACE_KINDS,
    bounds_of,
    console,
    damping_bound_options,
    emit,
    fmt,
    given,
    kind_methods,
    loop_options,
    provenance,
    refuse_method,
    rich_table,
)
from hapstab.cli.ranges import parse_delays, parse_periods, parse_range
from hapstab.errors import MAX_DELAY_SAMPLES, PERIOD_RANGE, HapstabError
from hapstab.results import dumps


@click.group()
def kmax() -> None:
    """Critical stiffness K_max: the largest K stable for every K in (0, K_max]."""


@click.group()
def check() -> None:
    """Stability verdict at a given stiffness."""


@click.group("boundary", short_help="K_max over sampling periods and delays (Fig. 5 / 6 curves).")
def boundary_cmd() -> None:
    """K_max over sampling periods and delays (Fig. 5 / Fig. 6 curves)."""


def _kmax_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @kmax.command(kind)
    @loop_options(kind)
    @damping_bound_options(kind)
    @click.option("--method", default="exact", show_default=True,
                  help="exact | " + " | ".join(m for m in kind_methods(kind) if m != "exact"))
    @click.option("--approximation", default=None,
                  help="For --method circle: forward | backward | tustin; for llewellyn "
                       "(peb, 4ch): forward | backward | tustin.")
    @network_options
    @click.option("--certify/--no-certify", default=None,
                  help="Prove the exact K_max in ball arithmetic (python-flint Arb): the safe "
                       "end of a proved enclosure, never above the truth (default for "
                       "--method exact). --no-certify: the float search alone, 1.2-2.5x "
                       "faster, not proved (docs/guide/certificate.md).")
    @click.option("--certificate", "cert_path", type=click.Path(dir_okay=False), default=None,
                  help="Write the exact method's proof as a JSON certificate to this file "
                       "(implies --certify; re-check it with `hapstab verify FILE`).")
    def _cmd(method: str, approximation: str | None, as_json: bool, certify: bool | None,
             cert_path: str | None, **kw: Any) -> None:
        from hapstab.analysis.methods import critical_stiffness

        net = {k: kw.pop(k) for k in ("loss", "burst", "delay_range")}
        if net["delay_range"] is not None:
            if net["loss"] is not None:
                raise HapstabError("--delay-range and --loss: give one of them, not both")
            return range_kmax(kind, net["delay_range"], make(kw, stiffness=1.0), method, as_json)
        if net["loss"] is not None:
            return network_kmax(kind, net, make(kw, stiffness=1.0), method, as_json)
        if net["burst"] is not None:
            raise HapstabError(f"--burst = {net['burst']!r}: applies with --loss only")

        refuse_method(kind, method)
        if method in ("circle", "passivity"):
            refuse_force_gains(kw, f"--method {method}")
        allowed = kind_methods(kind)
        if method not in allowed:
            raise HapstabError(f"--method = {method!r}: unknown for {kind}; allowed: {', '.join(allowed)}")
        bounds = bounds_of(kw, method)
        loop = make(kw, stiffness=1.0)
        if approximation and method not in ("circle", "llewellyn"):
            raise HapstabError(f"--approximation = {approximation!r}: applies to --method circle "
                               f"or llewellyn only (got --method {method})")
        opts = {"approximation": approximation, **bounds} if approximation else dict(bounds)
        opts.update(_certify_option(certify, method, cert_path is not None))
        res = critical_stiffness(loop, method=method, **opts)
        if cert_path is not None:
            write_certificate(res, cert_path)
        rows = [("critical stiffness", f"{fmt(res.critical_stiffness)} N/m"),
                ("method", res.method),
                ("stable intervals", ", ".join(f"({fmt(a)}, {fmt(b)}]" for a, b in res.stable_intervals)
                 or "none"),
                ("crossing frequency",
                 f"{res.crossing_frequency_hz:.6g} Hz" if math.isfinite(res.crossing_frequency_hz)
                 else "not given by this method" if res.method not in ("exact", "circle",
                                                                       "passivity")
                 else "none (no pole reaches |z| = 1)"),
                ("why", res.reason)]
        emit(res.to_dict(), as_json, lambda: rich_table(f"K_max, {kind}", rows, loop), loop)

    _cmd.__doc__ = f"K_max of the {kind.upper()} loop."


def _check_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @check.command(kind)
    @loop_options(kind)
    @click.option("--stiffness", "-K", type=NONNEG, required=True, help="K in N/m.")
    @click.option("--margins/--no-margins", default=None,
                  help="Also the delay margin (extra delay, added where the loop's delay is; "
                       "teleoperation: to each direction), the stiffness range and the "
                       "virtual-damping range with the loop stable (docs/guide/margins.md). "
                       f"Default: computed when estimated under {AUTO_MARGIN_SECONDS:g} s "
                       "(about 100 certified verdicts), the delay search cut at "
                       f"{AUTO_MARGIN_SECONDS:g} s, else said how to ask for them.")
    @click.option("--margin-seconds", type=POS, default=None,
                  help="Stop the delay margin's search after this many seconds (it then "
                       "holds up to the extra delay reached, and says so). Default: the "
                       f"whole search with --margins, {AUTO_MARGIN_SECONDS:g} s unasked.")
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write the Nyquist and Bode views of the exact sampled loop at K.")
    @click.option("--certify/--no-certify", default=True, show_default=True,
                  help="Count the poles outside in ball arithmetic (python-flint Arb); "
                       "--no-certify: the float enclosures alone, not proved "
                       "(docs/guide/certificate.md).")
    def _cmd(stiffness: float, margins: bool | None, margin_seconds: float | None,
             plot_path: str | None, certify: bool, as_json: bool, **kw: Any) -> None:
        from hapstab.analysis.exact.core import stability
        from hapstab.cli.files import check_files

        check_files(None, plot_path, as_json)
        loop = make(kw, stiffness)
        res = stability(loop, certify=certify)
        d = res.to_dict()
        d["stiffness"] = stiffness
        rows = [("verdict", res.verdict), ("spectral radius", f"{res.spectral_radius:.12g}"),
                ("dominant pole", f"{res.dominant_pole:.8g}"),
                ("frequency", f"{res.frequency_hz:.6g} Hz"), ("why", res.reason)]
        if margins is None:
            margins = _margins_cheap(loop, d)
            margin_seconds = margin_seconds or AUTO_MARGIN_SECONDS
            if not margins:
                rows.append(("margins", d["margins_reason"]))
        if margins or plot_path:
            try:
                rows += _margins(loop, d, margins, plot_path, margin_seconds)
            except HapstabError as e:      # the verdict stands; the margins say why not
                if plot_path:
                    raise
                d["margins_reason"] = f"no margins: {e}"
                rows.append(("margins", d["margins_reason"]))
        emit(d, as_json, lambda: rich_table(f"stability, {kind}, K = {stiffness:g} N/m", rows, loop),
             loop)

    _cmd.__doc__ = f"Stability of the {kind.upper()} loop at stiffness K."



#: ``check`` computes the margins unasked when they are estimated to take at most this
#: (about 100 certified verdicts, each one eigenvalue problem of the loop's N states).
AUTO_MARGIN_SECONDS = 10.0


def _margins_cheap(loop: Any, d: dict[str, Any]) -> bool:
    """Whether the margins are cheap enough to compute unasked; if not, ``d`` says so."""
    from hapstab import budget
    from hapstab.engine.system import build

    # one certified verdict: an eigenvalue problem plus the winding count (~20 ms measured
    # for a 22-state HVE); unasked, the margins also keep within a budget set lower
    est = 100 * (budget.eig_seconds(build(loop).order) + 0.02)
    try:
        budget.check(budget.Cost("the margins", 0.0, est), None, None)
        if est <= AUTO_MARGIN_SECONDS:
            return True
    except budget.BudgetError:
        pass
    d["margins_reason"] = (f"margins not computed: estimated {est:.3g} s for this "
                           f"{build(loop).order}-state loop; ask for them with --margins")
    return False


def _margins(loop: Any, d: dict[str, Any], keys: bool, plot_path: str | None,
             max_seconds: float | None = None) -> list[tuple[str, str]]:
    """The margins' rows of ``check``'s table; their keys added to ``d`` (``--margins``)
    and the Nyquist / Bode figure written (``--plot``)."""
    from hapstab.analysis.margins import margins
    from hapstab.cli.files import write_files

    m = margins(loop, view=plot_path is not None, max_seconds=max_seconds)
    if plot_path:
        write_files(m, None, plot_path)
    if not keys:
        return []
    md = {k: v for k, v in m.to_dict().items()
          if k not in d and k not in ("verdict", "reason", "friction_note")}
    d.update(md, margins_reason=m.reason)
    return [r for r in m.rows() if r[0] != "verdict at K"] + [("margins", m.reason)]


def _boundary_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @boundary_cmd.command(kind)
    @loop_options(kind, ranges=True)
    @click.option("--method", default="exact", show_default=True)
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Also write the table as CSV.")
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write K_max against T (or against the rate, with --rate) as a figure.")
    def _cmd(method: str, csv_path: str | None, plot_path: str | None, as_json: bool,
             **kw: Any) -> None:
        from hapstab.analysis.methods import boundary
        from hapstab.cli.files import check_files, write_files

        check_files(csv_path, plot_path, as_json)
        refuse_method(kind, method)
        if method in ("circle", "passivity"):
            refuse_force_gains(kw, f"--method {method}")
        periods, axis = _grid_periods(kw)
        rows_s = None if kw["delay_s"] is None else parse_range(kw["delay_s"], "--delay-s", "s",
                                                                values=">= 0")
        if rows_s is not None and given("delay"):
            raise HapstabError("--delay and --delay-s: give one of them, not both")
        if rows_s is not None and max(rows_s) / min(periods) > MAX_DELAY_SAMPLES:
            raise HapstabError(f"--delay-s = {kw['delay_s']!r}: {max(rows_s):g} s is "
                               f"{max(rows_s) / min(periods):.4g} samples at T = "
                               f"{min(periods):g} s; at most {MAX_DELAY_SAMPLES}")
        delays = parse_delays(kw["delay"])
        kw.update(period=periods[0], delay=delays[0], rate=None, delay_s=None)
        template = make(kw, 1.0)
        res = boundary(template, periods, delays, method=method, delays_s=rows_s, axis=axis)
        write_files(res, csv_path, plot_path)
        emit(res.to_dict(), as_json, lambda: _boundary_table(res), template)

    _cmd.__doc__ = (f"K_max of the {kind.upper()} loop over sampling periods or rates and "
                    "delays (in samples, or fixed in seconds).")


def _grid_periods(kw: dict[str, Any]) -> tuple[list[float], str]:
    """The periods from --period or --rate (one of them), and the plot's axis."""
    if kw.get("rate") is None:
        return parse_periods(kw["period"]), "period"
    if given("period"):
        raise HapstabError("--period and --rate: give one of them, not both")
    rates = parse_range(kw["rate"], "--rate", "Hz")
    lo, hi = PERIOD_RANGE
    for r in rates:
        if not lo <= 1.0 / r <= hi:
            raise HapstabError(f"--rate = {kw['rate']!r}: {r:g} Hz gives T = {1 / r:g} s; "
                               f"rates must be between {1 / hi:g} Hz and {1 / lo:g} Hz")
    return sorted(1.0 / r for r in rates), "rate"


def _boundary_table(res: Any) -> None:
    from rich.table import Table

    t = Table(title=f"K_max (N/m), {res.loop_kind}, method {res.method}")
    t.add_column("T (ms)", justify="right")
    by_rate = res.axis == "rate"
    if by_rate:
        t.add_column("rate (Hz)", justify="right")
    for d in res.delays:
        t.add_column(f"t_d = {d * 1e3:g} ms" if res.delay_unit == "s" else f"n = {d}",
                     justify="right")
    for j, T in enumerate(res.periods):
        t.add_row(f"{T * 1e3:.4g}", *([f"{1 / T:.5g}"] if by_rate else []),
                  *[fmt(res.critical_stiffness[i, j]) for i in range(len(res.delays))])
    console().print(t)


for _kind in LOOP_KINDS:
    _kmax_command(_kind)
    if _kind in STATE_SPACE_KINDS:        # (its verdict comes from the state-space model)
        _check_command(_kind)
    _boundary_command(_kind)


@click.command(short_help="The paper's Fig. 5 and Fig. 6 boundaries: exact beside the paper.")
@click.option("--json", "as_json", is_flag=True)
def demo(as_json: bool) -> None:
    """The paper's Fig. 5 and Fig. 6 boundaries: exact K_max beside the paper's lines."""

    from hapstab.analysis.conditions.closed_forms import EQUATION, paper_condition
    from hapstab.analysis.methods import boundary
    from hapstab.models.loops import Loop
    from hapstab.paper.loops import paper_hve, paper_peb

    T = np.linspace(1e-3, 1e-2, 10)
    figs: list[tuple[str, Loop, tuple[int, int]]] = [
        ("Fig. 5 (HVE)", paper_hve(), (0, 10)), ("Fig. 6 (PEB)", paper_peb(), (0, 4))]
    data: dict[str, Any] = {}
    for title, loop, delays in figs:
        res = boundary(loop, T, delays)
        rows = []
        for i, n in enumerate(delays):
            for j, t in enumerate(T):
                lp = loop.replace(period=float(t), delay_samples=n)
                cond = paper_condition(lp)
                theory, eq = cond.function(lp).critical_stiffness, EQUATION[cond.key]
                rows.append({"period_s": float(t), "delay_samples": float(n), "theory": theory,
                             "equation": eq, "exact": float(res.critical_stiffness[i, j])})
        data[title] = rows
    if as_json:
        click.echo(dumps({**data, **provenance()}))
        return
    from rich.table import Table

    con = console()
    for title, rows in data.items():
        t = Table(title=f"{title}: K_max (N/m), paper's condition vs exact sampled-data loop")
        for c in ("T (ms)", "n", "paper", "eq.", "exact", "exact/paper"):
            t.add_column(c, justify="right")
        for r in rows:
            t.add_row(f"{r['period_s'] * 1e3:.0f}", str(r["delay_samples"]), f"{r['theory']:.6g}",
                      r["equation"], f"{r['exact']:.6g}", f"{r['exact'] / r['theory']:.5f}")
        con.print(t)


def _certify_option(certify: bool | None, method: str, cert_file: bool = False) -> dict[str, bool]:
    """The exact method's ``certify`` option from --certify/--no-certify / --certificate
    (None: the default, proved for --method exact)."""
    if cert_file and certify is False:
        raise HapstabError("--certificate and --no-certify: a certificate needs the proof; "
                           "give one of them")
    if cert_file:
        certify = True
    if certify is not None and method != "exact":
        raise HapstabError(f"--certify / --no-certify / --certificate: apply to --method "
                           f"exact only (got --method {method})")
    return {} if certify is None else {"certify": certify}


def write_certificate(res: Any, path: str) -> None:
    """Write a K_max result's certificate as JSON (refused if it has none)."""
    import json
    if res.certificate is None and str(res.details.get("proof", "")).startswith("ball"):
        raise HapstabError(f"--certificate = {path!r}: the proof has nothing to certify "
                           f"(K_max = {res.critical_stiffness:g} N/m: {res.reason})")
    if res.certificate is None:
        raise HapstabError(f"--certificate = {path!r}: this K_max has no ball-arithmetic "
                           f"certificate (method {res.method!r}; only --method exact on loops "
                           "the certified core covers: one or two ports, spring-damper "
                           "controllers, whole delays, mass-spring-damper terminations)")
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(res.certificate, fh)


@click.command("verify", short_help="Re-check a K_max certificate in ball arithmetic.")
@click.argument("path", type=click.Path(exists=True, dir_okay=False))
@click.option("--json", "as_json", is_flag=True)
def verify_cmd(path: str, as_json: bool) -> None:
    """Re-check the certificate in PATH (from `hapstab kmax ... --certificate PATH`) from
    the loop's numbers alone, in ball arithmetic, independently of the search that wrote
    it. Exits 0 if valid, 1 if invalid (the reason says which check failed)."""
    import json

    from hapstab.analysis.verify import verify_certificate
    try:
        with open(path, encoding="utf-8") as fh:
            cert = json.load(fh)
    except (OSError, ValueError) as e:
        raise HapstabError(f"certificate = {path!r}: cannot read it as JSON ({e})") from None
    chk = verify_certificate(cert)
    if as_json:
        click.echo(json.dumps(chk.to_dict()))
    else:
        click.echo(("VALID: " if chk.valid else "INVALID: ") + chk.reason)
    if not chk.valid:
        raise SystemExit(1)

