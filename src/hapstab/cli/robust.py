"""CLI: ``hapstab robust`` (K_max over a box of operators, certified from below) and
the operator-box options that ``best-damping`` shares."""

from __future__ import annotations

from typing import Any

import click

from hapstab.cli.options import (
    LOOP_KINDS,
    PAPER_KINDS,
    IntRange,
    Number,
    emit,
    fmt,
    given,
    loop_options,
    rich_table,
)
from hapstab.cli.ranges import parse_range
from hapstab.errors import HapstabError

__all__ = ["robust", "operator_box_options", "box_from"]

_UNITS = {"mass": "kg", "damping": "N*s/m", "stiffness": "N/m"}


def operator_box_options(f: Any) -> Any:
    """``--operator-box PRESET`` and ``--operator-mass/-damping/-stiffness lo:hi``."""
    for name in reversed(("mass", "damping", "stiffness")):
        f = click.option(f"--operator-{name}", f"operator_{name}", default=None,
                         metavar="LO:HI",
                         help=f"Operator {name} range lo:hi (or one value) in "
                              f"{_UNITS[name]}.")(f)
    return click.option("--operator-box", "operator_box", default=None, metavar="PRESET",
                        help="A preset box of operators (arm-grasp); --operator-mass, "
                             "-damping, -stiffness override its ranges.")(f)


def _side(spec: str | None, name: str) -> tuple[float, float] | None:
    """``lo:hi`` or one value (lo = hi), each >= 0 in the parameter's unit."""
    if spec is None:
        return None
    opt, unit = f"--operator-{name}", _UNITS[name]
    parts = spec.split(":")
    if len(parts) > 2 or not all(p.strip() for p in parts):
        raise HapstabError(f"{opt} = {spec!r}: expected lo:hi or one value in {unit}, "
                           "e.g. 0.1:2")
    vals = []
    for p in parts:
        try:
            v = parse_range(p, opt, unit, values=">= 0")
        except HapstabError:
            raise HapstabError(f"{opt} = {spec!r}: expected lo:hi or one value, each a number "
                               f">= 0 in {unit}, e.g. 0.1:2") from None
        vals.append(v[0])
    lo, hi = vals[0], vals[-1]
    if hi < lo:
        raise HapstabError(f"{opt} = {spec!r}: the lower end must not exceed the upper end")
    return (lo, hi)


def box_from(kw: dict[str, Any], nominal: bool = False) -> Any:
    """The operator box the options describe (None when none is given); removes them
    from ``kw``. ``nominal``: --operator is the nominal operator (best-damping), not
    refused."""
    from hapstab.models.operators import operator_box

    preset = kw.pop("operator_box", None)
    specs = {n: kw.pop(f"operator_{n}", None) for n in _UNITS}
    sides = {n: _side(specs[n], n) for n in _UNITS}
    if preset is None and all(v is None for v in sides.values()):
        return None
    missing = [f"--operator-{n}" for n, v in sides.items() if v is None]
    if preset is None and missing:
        have = ", ".join(f"--operator-{n} = {specs[n]!r}" for n in _UNITS if specs[n] is not None)
        raise HapstabError(f"{have}: {' and '.join(missing)} not given; give all three ranges "
                           "(or --operator-box PRESET, which they then override)")
    if given("operator") and not nominal:
        raise HapstabError(f"--operator = {kw.get('operator')!r}: the operator is varied over "
                           "the box (--operator-box, --operator-mass, -damping, -stiffness); "
                           "allowed here: not given")
    return operator_box(preset, **sides)


def _robust_command(kind: str) -> None:
    make = LOOP_KINDS[kind]

    @robust.command(kind)
    @loop_options(kind)
    @operator_box_options
    # rtol from 1e-12 (the exact core's accuracy) to 0.5; 1e-6 as the library's default
    @click.option("--rtol", type=Number(span=(1e-12, 0.5)), default=1e-6, show_default=True,
                  help="Stop when upper - lower <= rtol * upper.")
    @click.option("--max-boxes", type=IntRange(1, 100000), default=6000,
                  show_default=True, help="Budget of operator sub-boxes.")
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write a heat map of K_max over the box (PNG or SVG by extension).")
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Write the named operator and the vertex minimum.")
    def _cmd(rtol: float, max_boxes: int, plot_path: str | None, csv_path: str | None,
             as_json: bool, **kw: Any) -> None:
        from hapstab.analysis.robust.robust import robust_critical_stiffness
        from hapstab.cli.files import check_files, write_files

        check_files(csv_path, plot_path, as_json)
        box = box_from(kw)
        if box is None:
            raise HapstabError("operator box: not given; give --operator-box arm-grasp or "
                               "--operator-mass, --operator-damping, --operator-stiffness")
        loop = make(kw, 0.0)
        res = robust_critical_stiffness(loop, box, rtol=rtol, max_boxes=max_boxes)
        write_files(res, csv_path, plot_path, dpi=120, bbox_inches="tight")
        m, b, k = res.operator
        rows = [("robust K_max (certified)", f"{fmt(res.critical_stiffness)} N/m"),
                ("worst operator", f"m = {m:.6g} kg, b = {b:.6g} N*s/m, k = {k:.6g} N/m"),
                ("its exact K_max", f"{fmt(res.operator_critical_stiffness)} N/m"),
                ("gap", f"{res.gap:.3g} N/m ({'converged' if res.converged else 'NOT converged'}"
                        f", {res.boxes} sub-boxes, {res.seconds:.2f} s)"),
                ("vertices alone", f"{fmt(res.vertex_minimum)} N/m"),
                ("operator box", res.box.describe()),
                ("answer", res.reason)]
        # the loop row and the JSON inputs show the loop with the worst operator
        for label, path in (("plot", plot_path), ("csv", csv_path)):
            if path is not None:
                rows.append((label, path))
        shown = loop.replace(operator=box.operator(*res.operator)) \
            if res.operator[0] == res.operator[0] else loop        # (nan: no operator named)
        emit(res.to_dict(), as_json, lambda: rich_table(f"robust K_max, {kind}", rows, shown),
             shown)

    _cmd.__doc__ = (f"Robust K_max of the {kind.upper()} loop over a box of operators "
                    "(certified lower bound, the operator that attains it).")


@click.group()
def robust() -> None:
    """K_max over a box of operator masses, dampings and stiffnesses: a certified lower
    bound and the operator that attains it."""


for _kind in PAPER_KINDS:
    _robust_command(_kind)
