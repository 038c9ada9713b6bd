""""Copy as CLI" and "copy as Python": the command line and a script for a request.

The command line is the request's own (:func:`hapstab.explorer.api.check_request`),
each word shell-quoted: run, it prints the API's answer. The script builds the same loop
with the public models (:class:`hapstab.Device`, :class:`hapstab.SpringDamper` /
:class:`hapstab.FilteredSpringDamper`, :class:`hapstab.HapticLoop` /
:class:`hapstab.TeleoperationLoop`), with every value as the command's own types read it
(``"1kHz"`` is ``period=1 / 1000.0``, ``"20ms"`` is ``0.02``), calls the analysis and
prints its headline: kmax, check, passivity, simulate and audit; for the other commands
the script runs the command itself in Python (``hapstab.cli.main.main([...])``).
"""

from __future__ import annotations

import shlex
from typing import Any

import click

from hapstab.cli.main import one_line
from hapstab.explorer.api import ApiError, check_request, long_name, loop_command, option_names

__all__ = ["code_for", "cli_line", "python_script", "MAPPED"]

#: Commands whose script builds the loop with the public models and calls the library;
#: the others' script runs the command itself (``hapstab.cli.main.main``).
MAPPED = ("kmax", "check", "passivity", "simulate", "audit")


def cli_line(argv: list[str]) -> str:
    """``hapstab ARGV``, each word shell-quoted.

    Parameters
    ----------
    argv : list of str
        A :func:`~hapstab.explorer.api.check_request` line.

    Returns
    -------
    str
    """
    return shlex.join(["hapstab", *argv])


def code_for(body: dict[str, Any]) -> dict[str, str]:
    """The command line and the Python script of ``{"kind", "command", "options"}``.

    Parameters
    ----------
    body : dict
        The request.

    Returns
    -------
    dict
        ``{"cli": ..., "python": ...}``.

    Raises
    ------
    ApiError
        As for the command's own request; 400 without a command.
    """
    command = body.get("command")
    if not isinstance(command, str):
        raise ApiError(400, "command: missing or not a string; e.g. \"kmax\"", "command")
    argv = check_request(command, {k: v for k, v in body.items() if k != "command"})
    kind = str(body["kind"])
    return {"cli": cli_line(argv), "python": python_script(command, kind, body.get("options", {}))}


def _values(command: str, kind: str, options: dict[str, Any]) -> dict[str, Any]:
    """Every parameter of ``hapstab COMMAND KIND``: the request's value read by the option's
    own type, or the option's default."""
    cmd = loop_command(command, kind)
    names = option_names(cmd)
    out: dict[str, Any] = {}
    for p in cmd.params:
        if isinstance(p, click.Option) and p.name:
            d = p.default
            out[p.name] = d if isinstance(d, (int, float, str)) else (False if p.is_flag else None)
    given = {names[k.replace("-", "_")].name for k in options}
    for p in cmd.params:
        if p.required and p.name not in given:
            flags = " / ".join(f"'{o}'" for o in p.opts)
            raise ApiError(422, f"Missing option {flags}.", p.opts[0].lstrip("-"))
    for key, value in options.items():
        p = names[key.replace("-", "_")]
        text = repr(value) if isinstance(value, float) else str(value)   # as on the line
        try:
            out[str(p.name)] = value if p.is_flag else p.type.convert(text, p, None)
        except click.BadParameter as e:
            raise ApiError(422, one_line(e.format_message()), long_name(p)) from None
    return out


def _controller(K: str, B: str, vf: str | None) -> str:
    if vf is None:
        return f"h.SpringDamper({K}, {B})"
    return f"h.FilteredSpringDamper({K}, {B}, h.VelocityFilter.parse({vf!r}))"


def _loop_lines(kind: str, v: dict[str, Any], K: str) -> list[str]:
    """Lines building ``loop`` (``K`` is the stiffness's expression)."""
    period = f"1 / {v['rate']!r}" if v.get("rate") is not None else repr(v["period"])
    B, vf = repr(v["virtual_damping"]), v.get("velocity_filter")
    if kind == "hve":
        lines = [f"device = h.Device({v['mass']!r}, {v['damping']!r}, {v['friction']!r})",
                 f"loop = h.HapticLoop(device, {_controller(K, B, vf)},",
                 f"                    h.parse_impedance({v['operator']!r}),",
                 f"                    period={period}, delay_samples={v['delay']!r})"]
        if v.get("delay_s") is not None:
            lines.append(f"loop = loop.with_delay_s({v['delay_s']!r})")
        return lines
    Bs = B if v.get("slave_virtual_damping") is None else repr(v["slave_virtual_damping"])
    ratio = repr(v["slave_stiffness_ratio"])
    lines = [f"master = h.Device({v['master_mass']!r}, {v['master_damping']!r}, "
             f"{v['master_friction']!r})",
             f"slave = h.Device({v['slave_mass']!r}, {v['slave_damping']!r}, "
             f"{v['slave_friction']!r})",
             f"loop = h.TeleoperationLoop(master, slave, {_controller(K, B, vf)},",
             f"                           {_controller(f'{ratio} * {K}', Bs, vf)},",
             f"                           h.parse_impedance({v['operator']!r}),",
             f"                           h.parse_impedance({v['environment']!r}),",
             f"                           period={period}, delay_samples={v['delay']!r},",
             f"                           position_scale={v['position_scale']!r}, "
             f"force_scale={v['force_scale']!r})"]
    fwd, bwd = v.get("delay_forward"), v.get("delay_backward")
    if v.get("delay_s") is not None:
        lines.append(f"loop = loop.with_delays_s({v['delay_s']!r})")
    elif fwd is not None or bwd is not None:
        f = repr(fwd) if fwd is not None else "loop.delay_samples"
        b = repr(bwd) if bwd is not None else "loop.delay_samples"
        lines.append(f"loop = loop.with_delays_s({f} * loop.period, {b} * loop.period)")
    return lines


def _analysis_lines(command: str, kind: str, v: dict[str, Any]) -> list[str]:
    """Lines computing ``res`` and printing its headline."""
    if command == "kmax":
        opts = "".join(f", {k}={v[k]!r}" for k in ("approximation", "operator_damping_min",
                                                   "environment_damping_min")
                       if v.get(k) is not None)
        return [f"res = h.critical_stiffness(loop, method={v['method']!r}{opts})",
                "print(res.critical_stiffness)   # K_max in N/m", "print(res.reason)"]
    if command == "check":
        return ["res = h.stability(loop)", "print(res.verdict)", "print(res.reason)"]
    if command == "passivity":
        if v["method"] == "circle":
            call = (f"h.circle_test(loop, {v.get('approximation') or 'forward'!r}, "
                    f"{v.get('sector')!r})")
        elif v.get("resolution") is not None or v.get("friction"):
            call = f"h.nonlinear_passivity(loop, resolution_m={v.get('resolution')!r})"
        else:
            call = f"h.sampled_passivity(loop, curve_points={v.get('curve_points', 0)!r})"
        return [f"res = {call}", "print(res.verdict)", "print(res.margin)   # N*s/m",
                "print(res.reason)"]
    if command == "simulate":
        return _simulate_lines(kind, v)
    if command == "audit":
        return [f"res = h.audit(loop, resolution_m={v.get('resolution')!r})",
                "for row in res.rows:", "    print(row.label, row.critical_stiffness)"]
    raise AssertionError(command)          # (python_script maps only MAPPED)


def _simulate_lines(kind: str, v: dict[str, Any]) -> list[str]:
    tdpa = {k: v[f"tdpa_{k}"] for k in ("observer", "velocity", "max_damping")
            if v.get(f"tdpa_{k}") is not None}
    force = None if v["force"] == "none" else v["force"]
    args = [f"force={force!r}"]
    if kind == "hve":
        args += [f"initial_position={v['x0']!r}", f"rest_position={v.get('rest')!r}",
                 f"wall={v.get('wall')!r}", f"wall_pulls={bool(v.get('wall_pulls'))!r}"]
    else:
        ef = v.get("environment_force")
        rest = None if v.get("rest") is None else [v["rest"], 0.0]
        args += [f"environment_force={None if ef in (None, 'none') else ef!r}",
                 f"initial_position={[v['x0'], 0.0]!r}", f"rest_position={rest!r}"]
    args += [f"saturation={v.get('saturation')!r}", f"resolution={v.get('resolution')!r}",
             f"quantizer={v['quantizer']!r}", f"dense={v['dense']!r}",
             f"tdpa={tdpa if tdpa or v.get('tdpa') else None!r}"]
    return [f"res = h.simulate(loop, {v['duration']!r},", *[f"                 {a}," for a in args],
            "                 )", "print(res.verdict.verdict)", "print(res.verdict.reason)"]


def python_script(command: str, kind: str, options: dict[str, Any]) -> str:
    """A script that builds the request's loop with the public models, runs the analysis
    and prints its headline (the first line printed is the API answer's headline value:
    ``critical_stiffness``, ``verdict``, ...).

    Parameters
    ----------
    command, kind : str
        The command and the loop kind (checked by :func:`check_request` first).
    options : dict
        The request's options.

    Returns
    -------
    str
    """
    if command not in MAPPED:
        argv = check_request(command, {"kind": kind, "options": options})
        return ("# hapstab " + command + ": not mapped to the library's calls here; this runs\n"
                "# the command itself in Python (the same JSON as the command line)\n"
                "from hapstab.cli.main import main\n\n"
                f"main({argv!r})\n")
    v = _values(command, kind, options)
    # A command without a stiffness (kmax, audit) builds its loop at K = 1, as the CLI does:
    # the slave's stiffness is --slave-stiffness-ratio times K, lost at K = 0.
    takes_k = any(p.name == "stiffness" for p in loop_command(command, kind).params)
    K = repr(v["stiffness"]) if takes_k else "1.0"
    lines = ["import hapstab as h", "", f"K = {K}   # N/m", *_loop_lines(kind, v, "K"),
             *_analysis_lines(command, kind, v)]
    return "\n".join(lines) + "\n"
