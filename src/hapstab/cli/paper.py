"""CLI commands of the paper's method: ``hapstab passivity hve|peb|4ch`` (positive-real
or sampled-data passivity verdict at a stiffness) and ``hapstab audit hve|peb``
(closed forms vs circle / passivity vs exact), ``hapstab twoport peb|4ch`` (Llewellyn)
and ``hapstab transparency peb|4ch`` (felt impedance, hybrid matrix, tracking). ``hapstab kmax ...
--method circle|passivity`` comes from the registration in :mod:`hapstab.analysis`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import click
import numpy as np

from hapstab.cli.fourchannel import refuse_force_gains
from hapstab.cli.options import (
    LENGTH,
    LOOP_KINDS,
    NONNEG,
    PAPER_KINDS,
    POS,
    IntRange,
    bounds_of,
    console,
    damping_bound_options,
    emit,
    fmt,
    loop_options,
    rich_table,
)
from hapstab.cli.ranges import parse_range
from hapstab.errors import HapstabError

if TYPE_CHECKING:
    from rich.console import JustifyMethod

_APPROX = ("forward", "backward", "tustin")


def _margin_words(margin: float, sector: float | None) -> str:
    """The margin with its unit: damping (N*s/m) for G^-1 and sampled passivity; with a
    finite sector the test is on the loop transfer G + 1/k, an admittance (m/(N*s))."""
    if sector is not None:
        return (f"{margin:.6g} m/(N*s) (admittance of G + 1/k, "
                + ("to spare" if margin >= 0 else "missing") + ")")
    return f"{margin:.6g} N*s/m (" + ("damping to spare" if margin >= 0 else "damping missing") + ")"


@click.group("passivity")
def passivity_cmd() -> None:
    """Is the device side passive at a stiffness K (exact sampled-data passivity), or, with
    --method circle, is G^-1(z) positive real (the paper's circle criterion)?"""


@click.group("audit")
def audit_cmd() -> None:
    """The paper's closed forms beside the circle, passivity and exact results."""


def _passivity_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @passivity_cmd.command(kind)
    @loop_options(kind)
    @click.option("--stiffness", "-K", type=NONNEG, required=True, help="K in N/m.")
    @click.option("--method", default="passivity", show_default=True,
                  help="passivity (exact sampled-data passivity, Colgate-Schenkel) | circle "
                       "(G^-1 positive real, Definition 1, the paper's test).")
    @click.option("--approximation", default=None,
                  help="For --method circle: forward (default) | backward | tustin.")
    @click.option("--sector", type=POS, default=None,
                  help="For --method circle: finite sector bound k of the termination(s) "
                       "(Theorem 2.1); default: passive limit.")
    @_resolution_option(kind, "passivity")
    @CURVE
    def _cmd(stiffness: float, method: str, approximation: str | None, sector: float | None,
             curve_points: int, as_json: bool, **kw: Any) -> None:
        refuse_force_gains(kw, "the circle criterion" if method == "circle"
                           else "sampled-data passivity")
        resolution = kw.pop("resolution", None)
        loop = make(kw, stiffness)
        res: Any
        if curve_points and method != "passivity":
            raise HapstabError(f"--curve = {curve_points}: the margin over frequency of "
                               "--method passivity only")
        if method == "passivity" and (resolution is not None or kw.get("friction")):
            _nonlinear_passivity(loop, stiffness, resolution, approximation, sector, as_json, kind,
                                 curve_points)
            return
        if method == "circle":
            from hapstab.analysis.conditions.circle import circle_test

            approx = approximation or "forward"
            if approx not in _APPROX:
                raise HapstabError(f"--approximation = {approximation!r}: allowed: {', '.join(_APPROX)}")
            res = circle_test(loop, approx, sector)
        elif method == "passivity":
            from hapstab.analysis.conditions.passivity import sampled_passivity

            if approximation is not None or sector is not None:
                raise HapstabError("--approximation/--sector: apply to --method circle only; "
                                   "'passivity' is exact")
            res, approx = sampled_passivity(loop, curve_points=curve_points), None
        else:
            raise HapstabError(f"--method = {method!r}: allowed: circle, passivity")
        d = res.to_dict()
        d.update(stiffness=stiffness, method=method, approximation=approx, sector=sector)
        rows = [("verdict", res.verdict), ("margin", _margin_words(res.margin, sector)),
                ("worst frequency", f"{res.worst_frequency_hz:.6g} Hz "
                                    f"({res.worst_frequency_rad_s:.6g} rad/s)"),
                ("failing condition", res.failed_condition or "none"),
                ("why", res.reason)]
        title = f"{method}{', ' + approx if approx else ''}, {kind}, K = {stiffness:g} N/m"
        emit(d, as_json, lambda: rich_table(title, rows, loop), loop)

    _cmd.__doc__ = (f"Is the {kind.upper()} loop's sampled-data side passive at stiffness K (or, "
                    "with --method circle, its G^-1(z) positive real)? Verdict, margin in "
                    "N*s/m, worst frequency.")


#: ``passivity --curve POINTS``: the margin over frequency in the JSON.
CURVE = click.option(
    "--curve", "curve_points", type=IntRange(0, 100_000), default=0, show_default=True,
    help="With --json: add the passivity margin over frequency at POINTS evenly spaced "
         "frequencies from 0 to the Nyquist frequency (\"margin_curve\"; its minimum is the "
         "margin); 0: none.")


def _resolution_option(kind: str, command: str) -> Any:
    """``--resolution`` (the encoder's step, m) for the HVE's passivity and audit: the
    Abbott-Okamura condition with the device's ``--friction``; no option for the others."""
    if kind != "hve":
        return lambda f: f
    return click.option("--resolution", type=LENGTH, default=None,
                        help="Encoder resolution Delta, m or with a unit (2um): adds the "
                             "Abbott-Okamura condition (b >= KT/2 and f_c >= K Delta/2, with "
                             "--friction f_c; B = 0 and no delay)"
                             + (" as a row." if command == "audit" else "."))


def _nonlinear_passivity(loop: Any, stiffness: float, resolution: float | None,
                         approximation: str | None, sector: float | None, as_json: bool,
                         kind: str, curve_points: int = 0) -> None:
    """``passivity hve`` with friction and / or quantisation: both conditions (and the
    friction-free loop's margin over frequency, whose minimum is the margin shown)."""
    from hapstab.analysis.conditions.passivity import sampled_passivity
    from hapstab.analysis.nonlinear.nonlinear_passivity import nonlinear_passivity

    if approximation is not None or sector is not None:
        raise HapstabError("--approximation/--sector: apply to --method circle only; "
                           "'passivity' is exact")
    res = nonlinear_passivity(loop, resolution_m=resolution)
    d = res.to_dict()
    d.update(stiffness=stiffness, method="passivity", approximation=None, sector=None)
    if curve_points:
        d["margin_curve"] = sampled_passivity(loop, curve_points=curve_points).to_dict()[
            "margin_curve"]
    nl = d["nonlinear"]
    rows = [("verdict", res.verdict), ("margin", _margin_words(res.margin, None)),
            ("quantisation margin", f"{res.quantization_margin_N:.6g} N (f_c - K Delta/2)"
             if res.resolution_m else "no quantisation"),
            ("K_max with friction and quantisation", f"{fmt(nl['critical_stiffness'])} N/m"
             if nl["critical_stiffness"] is not None else "inf"),
            ("failing condition", res.failed_condition or "none"), ("why", res.reason)]
    title = f"passivity, {kind}, K = {stiffness:g} N/m, f_c = {res.coulomb_friction_N:g} N, " \
            f"Delta = {res.resolution_m:g} m"
    emit(d, as_json, lambda: rich_table(title, rows, loop), loop)


def _audit_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @audit_cmd.command(kind)
    @loop_options(kind)
    @_resolution_option(kind, "audit")
    def _cmd(as_json: bool, **kw: Any) -> None:
        from hapstab.analysis.conditions.audit import audit

        resolution = kw.pop("resolution", None)
        loop = make(kw, 1.0)
        res = audit(loop, resolution_m=resolution)
        emit(res.to_dict(), as_json, lambda: _audit_table(res), loop)

    _cmd.__doc__ = (f"Closed-form K_max conditions for the {kind.upper()} loop beside the circle, "
                    "passivity and exact results; flags promises the exact analysis breaks.")


def _audit_table(res: Any) -> None:
    from rich.table import Table

    t = Table(title=f"audit, {res.kind}: T = {res.period * 1e3:.4g} ms, n = {res.delay_samples}, "
                    f"B = {res.virtual_damping:g} N*s/m")
    columns: tuple[tuple[str, JustifyMethod], ...] = (
        ("condition", "left"), ("K_max (N/m)", "right"), ("claims", "left"),
        ("exact just below", "left"), ("flag", "left"))
    for c, j in columns:
        t.add_column(c, justify=j)
    for r in res.rows:
        t.add_row(r.label, fmt(r.critical_stiffness), r.claims, r.exact_verdict,
                  f"[red]{r.flag}[/red]" if r.flag else "ok")
    console().print(t)


for _kind in LOOP_KINDS:
    _passivity_command(_kind)
    if _kind in PAPER_KINDS:
        _audit_command(_kind)


@click.group("twoport", short_help="Absolute stability (Llewellyn) of a teleoperator's two-port at K.")
def twoport_cmd() -> None:
    """Is the teleoperator absolutely stable (Llewellyn: stable with every pair of passive
    terminations) at a stiffness K? Margin and eta against frequency."""


def _twoport_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @twoport_cmd.command(kind)
    @loop_options(kind)
    @damping_bound_options(kind)
    @click.option("--stiffness", "-K", type=NONNEG, required=True,
                  help="K in N/m (the master's" + (", or the slave's when the master has none)."
                                                   if kind == "4ch" else ")."))
    @click.option("--approximation", default="forward", show_default=True,
                  help="X(z): forward (a bound for the exact loop in every campaign) | backward | "
                       "tustin (neither of these is).")
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write the margin and eta against frequency (PNG, SVG, PDF).")
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Write frequency_rad_s, margin_N_s_per_m, eta per angle.")
    def _cmd(stiffness: float, approximation: str, plot_path: str | None,
             csv_path: str | None, as_json: bool, **kw: Any) -> None:
        from hapstab.analysis.teleoperation.twoport import llewellyn_test
        from hapstab.cli.files import check_files, write_files

        check_files(csv_path, plot_path, as_json)
        bounds = bounds_of(kw, "llewellyn")
        loop = make(kw, stiffness)
        res = llewellyn_test(loop, approximation, **bounds)  # type: ignore[arg-type]  # a teleoperator
        files = write_files(res, csv_path, plot_path)
        d = {**res.to_dict(), "files": files}
        rows = [("verdict", res.verdict),
                ("margin", f"{res.margin:.6g} N*s/m ("
                           + ("damping to spare" if res.margin >= 0 else "damping missing") + ")"),
                ("worst frequency", f"{res.worst_frequency_hz:.6g} Hz "
                                    f"({res.worst_frequency_rad_s:.6g} rad/s)"),
                ("smallest eta", f"{res.eta_min:.6g} (>= 1 needed; away from w = 0)"),
                ("why", res.reason), *[("wrote", f) for f in files]]
        emit(d, as_json, lambda: rich_table(f"two-port, {kind}, K = {stiffness:g} N/m", rows, loop),
             loop)

    _cmd.__doc__ = (f"Llewellyn's absolute stability of the {NAMES[kind]} two-port G^-1(z) at "
                    "stiffness K: verdict, margin in N*s/m, worst frequency, eta.")


#: What the twoport and transparency commands call each teleoperator.
NAMES = {"peb": "PEB", "4ch": "4-channel (position channels only)"}


@click.group("transparency", short_help="What the operator feels through the teleoperator.")
def transparency_cmd() -> None:
    """Transparency over frequency: the impedance the operator feels in free motion, with the
    environment and against a rigid one (the Z-width), and the slave's position tracking."""


#: Points of a --frequencies range given as start:stop (log-spaced, a Bode plot's grid).
FREQUENCY_COUNT = 400


def _frequencies(spec: str | None, period_s: float) -> list[float] | None:
    """--frequencies in Hz: start:stop[:count] log-spaced (count default
    :data:`FREQUENCY_COUNT`), or a comma list as given; none above 1/(2T)."""
    from hapstab.analysis.teleoperation.transparency import NYQUIST_SLACK

    if spec is None:
        return None
    ranged = ":" in spec
    text = spec + f":{FREQUENCY_COUNT}" if spec.count(":") == 1 else spec
    f = parse_range(text, "--frequencies", "Hz")
    if ranged and len(f) > 1:
        f = [float(v) for v in np.geomspace(f[0], f[-1], len(f))]
    nyquist = 1.0 / (2.0 * period_s)
    if max(f) > nyquist * (1 + NYQUIST_SLACK):
        raise HapstabError(f"--frequencies = {spec!r}: {max(f):g} Hz is above the Nyquist "
                           f"frequency 1/(2T) = {nyquist:g} Hz; allowed: (0, {nyquist:g}] Hz")
    return f


def _transparency_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @transparency_cmd.command(kind)
    @loop_options(kind)
    @click.option("--stiffness", "-K", type=NONNEG, required=True,
                  help="K in N/m (the master's" + (", or the slave's when the master has none)."
                                                   if kind == "4ch" else ")."))
    @click.option("--approximation", default="forward", show_default=True,
                  help="X(z), the hold's approximation: forward | backward | tustin.")
    @click.option("--frequencies", default=None,
                  help="Frequencies in Hz: start:stop[:count] (log-spaced, count default 400) or "
                       "a comma list; at most 1/(2T). Default: 4 decades up to 1/(2T).")
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write |Z_felt|, its phase and the tracking against frequency (PNG, SVG, PDF).")
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Write the felt impedances, X_s/X_m and h11..h22 (re, im) per frequency.")
    def _cmd(stiffness: float, approximation: str, frequencies: str | None,
             plot_path: str | None, csv_path: str | None, as_json: bool, **kw: Any) -> None:
        from hapstab.analysis.teleoperation.transparency import transparency
        from hapstab.cli.files import check_files, write_files

        check_files(csv_path, plot_path, as_json)
        loop = make(kw, stiffness)
        res = transparency(loop, approximation,  # type: ignore[arg-type]  # a teleoperator
                           _frequencies(frequencies, loop.period))
        files = write_files(res, csv_path, plot_path)
        d = {**res.to_dict(), "stiffness": stiffness, "files": files}
        rows = [("felt stiffness (w -> 0)",
                 f"{fmt(res.felt_stiffness_free)} free, {fmt(res.felt_stiffness_environment)} "
                 f"environment, {fmt(res.felt_stiffness_rigid)} rigid (N/m)"),
                ("tracking X_s/X_m (w -> 0)", f"{res.static_tracking:.6g}"),
                *_at_decades(res), *[("wrote", f) for f in files]]
        emit(d, as_json, lambda: rich_table(f"transparency, {kind}, K = {stiffness:g} N/m, "
                                            f"{res.approximation}", rows, loop), loop)

    _cmd.__doc__ = (f"Transparency of the {NAMES[kind]} teleoperator at stiffness K: the felt "
                    "impedance (free motion, the environment, rigid), the hybrid matrix and "
                    "X_s/X_m over frequency.")


def _at_decades(res: Any) -> list[tuple[str, str]]:
    """Table rows at the grid's points nearest each decade of Hz (at most 6)."""
    f = res.frequencies_hz
    marks = 10.0 ** np.arange(np.ceil(np.log10(f[0])), np.floor(np.log10(f[-1])) + 1)
    idx = sorted({int(np.argmin(np.abs(np.log(f / m)))) for m in marks[-6:]} or {0, f.size - 1})
    return [(f"|Z_felt|, |X_s/X_m| at {f[i]:.4g} Hz",
             f"{abs(res.felt_free[i]):.4g} free, {abs(res.felt_environment[i]):.4g} environment, "
             f"{abs(res.felt_rigid[i]):.4g} rigid (N*s/m); tracking {abs(res.tracking[i]):.4g}")
            for i in idx]


for _kind in NAMES:
    _twoport_command(_kind)
    _transparency_command(_kind)
