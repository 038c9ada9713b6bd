"""CLI of the conditions room: ``hapstab passivity hve|peb|4ch`` (positive-real or
sampled-data passivity verdict at a stiffness) and ``hapstab audit hve|peb`` (closed
forms vs circle / passivity vs exact). ``hapstab kmax ... --method circle|passivity``
and ``check --margins`` live with ``kmax`` and ``check`` (:mod:`hapstab.cli.exact`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import click

from hapstab.cli.fourchannel import refuse_force_gains
from hapstab.cli.options import (
    LENGTH,
    LOOP_KINDS,
    NONNEG,
    PAPER_KINDS,
    POS,
    IntRange,
    console,
    emit,
    fmt,
    loop_options,
    rich_table,
)
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
