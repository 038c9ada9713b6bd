"""The explorer's API without HTTP: a request checked and run as the CLI's own command.

A request ``{"kind": "hve", "options": {"mass": 0.3, "rate": "1kHz"}}`` to command
``kmax`` is checked as a study file's table is (:mod:`hapstab.cli.study`): every key
must be an option of ``hapstab kmax hve`` (its long name, with ``-`` or ``_``), every
value a JSON number, a string the option's own click type reads, or a boolean for a
flag; each value is converted by that type, so a refused value names its option. It is
then run as ``hapstab kmax hve --mass=0.3 --rate=1kHz --json``, in-process, through the
same click command (as ``hapstab run`` does), with the standard output captured: the
answer is exactly the JSON object the command line prints, ``inputs.command_line``
included. Errors are :class:`ApiError`: an HTTP status, the library's one-line message
and the option it is about.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import sys
import threading
import warnings
from collections.abc import Iterator
from contextvars import ContextVar
from typing import Any

import click

from hapstab.analysis.table import endpoints
from hapstab.errors import HapstabError

__all__ = ["ApiError", "COMMANDS", "KINDS", "MAX_BODY_BYTES", "BUDGET", "parse_body",
           "check_request", "run_command", "schema", "option_json", "command_kinds",
           "loop_command"]

#: Loop kinds the explorer builds.
KINDS = ("hve", "peb")
#: The commands the explorer runs (each under ``POST /api/v1/{command}``): the explorer
#: endpoints of the table of analyses (:mod:`hapstab.analysis.table`), in its order.
COMMANDS = endpoints()
#: Loop commands the explorer refuses, and why.
REFUSED = {"robust": "too slow for the explorer: use the CLI (hapstab robust ...)"}
#: The largest request body, bytes.
MAX_BODY_BYTES = 64 * 1024
#: The explorer's budget (hapstab.budget.limits): memory in bytes and seconds; a request
#: that would need more is refused before any work (422).
BUDGET = (512 * 1024 ** 2, 10.0)
#: The library's names of what an option gives (in its messages) -> the option.
#: Where several options give it, the first the request gave is the one (else the first).
ALIASES = {"delay_samples": ("delay",), "coulomb_friction": ("friction",),
           "coulomb_friction_N": ("friction",), "resolution_m": ("resolution",),
           "duration_s": ("duration",), "period_s": ("period", "rate"),
           "period": ("period", "rate"), "delay_forward_s": ("delay_s", "delay_forward"),
           "delay_backward_s": ("delay_s", "delay_backward"),
           "delay_forward_samples": ("delay_forward",),
           "delay_backward_samples": ("delay_backward",), "fractional_delay": ("delay_s",)}
#: Options a request cannot set (where the answer goes is the server's choice).
OUTPUT_OPTIONS = ("as_json", "csv_path", "plot_path")
_HIDDEN = ("json", "csv", "plot", "study", "variant", "yes", "debug", "help")
_LEADING = re.compile(r"^\s*(?:Invalid value for\s+)?['\"]?(--?[A-Za-z][\w-]*|"
                      r"[A-Za-z_][\w.-]*(?: [a-z]+)?)['\"]?\s*(?:=|:|and\b|/)")


class ApiError(Exception):
    """A request the explorer refuses: HTTP ``status``, one-line ``error``, the option
    (its long name, as the page's field) or None.

    Parameters
    ----------
    status : int
        400 malformed, 404 unknown command, 409 superseded, 413 too large, 422 refused.
    error : str
        One line.
    parameter : str or None
        The option (long name without dashes) or top-level field it is about.
    """

    def __init__(self, status: int, error: str, parameter: str | None = None) -> None:
        super().__init__(error)
        self.status, self.error, self.parameter = status, " ".join(str(error).split()), parameter

    def to_dict(self) -> dict[str, Any]:
        """``{"error", "parameter", "status"}``."""
        return {"error": self.error, "parameter": self.parameter, "status": self.status}


def _root() -> click.Group:
    from hapstab.cli.main import cli

    return cli


def loop_command(command: str, kind: Any) -> click.Command:
    """The click command ``hapstab COMMAND KIND``; :class:`ApiError` 404 for a command the
    explorer does not run, 422 for a kind it does not take.

    Parameters
    ----------
    command : str
        A name of :data:`COMMANDS`.
    kind : str
        A name of :data:`KINDS`.

    Returns
    -------
    click.Command

    Raises
    ------
    ApiError
    """
    takes = command_kinds(command)
    if kind not in takes:
        raise ApiError(422, f"kind = {kind!r:.40}: {command} in the explorer takes "
                            f"{' or '.join(takes)} loops", "kind")
    group = _root().commands[command]
    assert isinstance(group, click.Group)
    return group.commands[kind]


def command_kinds(command: str) -> tuple[str, ...]:
    """The loop kinds of :data:`KINDS` that ``hapstab COMMAND`` takes, read from the CLI's
    own command table (the kinds are the subcommands of its click group: ``twoport`` has
    ``peb`` only); :class:`ApiError` 404 for a command the explorer does not run, 422 for
    one it refuses (:data:`REFUSED`).

    Parameters
    ----------
    command : str
        The command's name (``kmax``).

    Returns
    -------
    tuple of str

    Raises
    ------
    ApiError
    """
    if command in REFUSED:
        raise ApiError(422, f"{command}: {REFUSED[command]}", None)
    if command not in COMMANDS:
        raise ApiError(404, f"unknown command {command[:60]!r}; allowed: {', '.join(COMMANDS)}")
    group = _root().commands[command]
    assert isinstance(group, click.Group)
    return tuple(k for k in KINDS if k in group.commands)


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON (numbers must be finite)")


def parse_body(raw: bytes) -> dict[str, Any]:
    """The request body as a JSON object (strict: no NaN / Infinity, UTF-8).

    Parameters
    ----------
    raw : bytes
        The body.

    Returns
    -------
    dict

    Raises
    ------
    ApiError
        400: empty, not UTF-8, not JSON, too deep, or not an object; 413 too large.
    """
    if len(raw) > MAX_BODY_BYTES:
        raise ApiError(413, f"request body of {len(raw)} bytes: at most {MAX_BODY_BYTES}")
    if not raw.strip():
        raise ApiError(400, "empty request body: send a JSON object")
    try:
        data = json.loads(raw.decode("utf-8"), parse_constant=_refuse_constant)
    except UnicodeDecodeError as e:
        raise ApiError(400, f"request body: not UTF-8 at byte {e.start}") from None
    except RecursionError:
        raise ApiError(400, "request body: JSON nested too deeply") from None
    except ValueError as e:       # JSONDecodeError, NaN/Infinity, an integer of 4300+ digits
        raise ApiError(400, f"request body: not valid JSON ({str(e)[:120]})") from None
    if not isinstance(data, dict):
        raise ApiError(400, f"request body: must be a JSON object, not {_json_type(data)}")
    return data


def _json_type(value: Any) -> str:
    for t, name in ((bool, "a boolean"), (dict, "an object"), (list, "an array"),
                    (str, "a string"), ((int, float), "a number")):
        if isinstance(value, t):
            return name
    return "null"


def option_names(cmd: click.Command) -> dict[str, click.Option]:
    """Every spelling a request may use (long names with ``-`` or ``_``, the parameter's
    name, short names no long name spells) -> the option."""
    from hapstab.cli.study import option_spellings

    params = {p.name: p for p in cmd.params if isinstance(p, click.Option) and p.name}
    return {k: params[v] for k, v in option_spellings(params).items()}


def long_name(param: click.Parameter) -> str:
    """The option's long name without dashes (``virtual-damping``; ``K`` for ``--K``)."""
    longs = [o for o in param.opts if o.startswith("--")]
    return (longs[0] if longs else param.opts[0]).lstrip("-")


def check_request(command: str, body: dict[str, Any]) -> list[str]:
    """Check a request's fields and options; the equivalent command line.

    Parameters
    ----------
    command : str
        The command (``kmax``).
    body : dict
        ``{"kind": ..., "options": {...}}``.

    Returns
    -------
    list of str
        ``[command, kind, --option=value, ..., --json]``; ``check`` without a
        ``margins`` option gets ``--no-margins`` (the verdict alone, at once; the page
        asks for the margins in a request of their own, ``"margins": true``).

    Raises
    ------
    ApiError
        400 for a field or value of the wrong JSON type, 404 an unknown command, 422 an
        unknown option or a value its type refuses.
    """
    extra = sorted(set(body) - {"kind", "options"})
    if extra:
        raise ApiError(400, f"unknown field {extra[0][:40]!r}; a request has kind and options",
                       extra[0][:40])
    if "kind" not in body:
        raise ApiError(400, "kind: missing; give \"hve\" or \"peb\"", "kind")
    kind, options = body["kind"], body.get("options", {})
    if not isinstance(kind, str):
        raise ApiError(400, f"kind: must be a string (\"hve\" or \"peb\"), not {_json_type(kind)}",
                       "kind")
    if not isinstance(options, dict):
        raise ApiError(400, f"options: must be an object of option: value, not "
                            f"{_json_type(options)}", "options")
    cmd = loop_command(command, kind)
    args = option_args(cmd, command, kind, options)
    if command == "check" and not any(k.replace("-", "_") == "margins" for k in options):
        # the verdict at once: the margins (seconds for a PEB) only when asked for,
        # in their own request (the page's "margins" channel), not computed unasked
        args.append("--no-margins")
    return [command, kind, *args, "--json"]


def option_args(cmd: click.Command, command: str, kind: str, options: dict[str, Any]) -> list[str]:
    """The options as command-line arguments (``--name=value``), each checked by its type.

    Parameters
    ----------
    cmd : click.Command
        ``hapstab COMMAND KIND``.
    command, kind : str
        Its names (for messages).
    options : dict
        Option name -> JSON value.

    Returns
    -------
    list of str

    Raises
    ------
    ApiError
        400 a value of the wrong JSON type; 422 an unknown option, one given twice or a
        value its type refuses.
    """
    names = option_names(cmd)
    seen: dict[str, str] = {}
    args: list[str] = []
    for key, value in options.items():
        p = names.get(key.replace("-", "_")) if key not in _HIDDEN else None
        if p is None or p.name in OUTPUT_OPTIONS:
            allowed = sorted({long_name(q) for q in names.values() if q.name not in OUTPUT_OPTIONS})
            raise ApiError(422, f"{key[:40]!r}: not an option of {command} {kind}; allowed: "
                                f"{', '.join(allowed)}", key[:40])
        name = long_name(p)
        if p.name in seen:
            raise ApiError(422, f"{seen[p.name]} and {key}: the same option twice; give it once",
                           name)
        seen[str(p.name)] = key
        args += _arg(p, name, value)
    return args


def _arg(p: click.Option, name: str, value: Any) -> list[str]:
    """One option's argument (its value is read by the option's own type when it runs)."""
    if p.is_flag:
        if not isinstance(value, bool):
            raise ApiError(400, f"{name}: a flag, true or false (not {_json_type(value)})", name)
        if not value and p.secondary_opts:       # --x/--no-x: false is --no-x
            return [p.secondary_opts[0]]
        return [f"--{name}"] if value else []
    if isinstance(value, (dict, list, bool)) or value is None:
        raise ApiError(400, f"{name}: must be a number or a string, as on the command line "
                            f"(not {_json_type(value)})", name)
    if isinstance(value, float):
        text = repr(value)
    else:
        try:
            text = str(value)
        except ValueError:          # an integer of 4300+ digits
            raise ApiError(422, f"--{name}: a number of thousands of digits", name) from None
    return [f"--{name}={text}"]


# ----------------------------------------------------------------------- running
_CAPTURE: ContextVar[io.StringIO | None] = ContextVar("hapstab_explorer_capture", default=None)
_LOCK = threading.Lock()
_USERS = [0]
_SAVED: list[Any] = [None]


class _Stdout(io.TextIOBase):
    """sys.stdout while the explorer computes: each computation's thread writes to its
    own buffer (contextlib.redirect_stdout would swap it for every thread)."""

    def __init__(self, fallback: Any) -> None:
        self.fallback = fallback

    @property
    def encoding(self) -> str:  # type: ignore[override]
        return "utf-8"

    def write(self, s: str) -> int:
        buf = _CAPTURE.get()
        return (buf if buf is not None else self.fallback).write(s)

    def flush(self) -> None:
        if _CAPTURE.get() is None and self.fallback is not None:
            self.fallback.flush()

    def isatty(self) -> bool:
        return False


@contextlib.contextmanager
def _captured() -> Iterator[io.StringIO]:
    """This thread's standard output, into a buffer."""
    with _LOCK:
        if _USERS[0] == 0:
            _SAVED[0] = sys.stdout
            sys.stdout = _Stdout(sys.stdout)
        _USERS[0] += 1
    buf = io.StringIO()
    token = _CAPTURE.set(buf)
    try:
        yield buf
    finally:
        _CAPTURE.reset(token)
        with _LOCK:
            _USERS[0] -= 1
            if _USERS[0] == 0:
                sys.stdout = _SAVED[0]


def run_command(argv: list[str]) -> str:
    """Run ``hapstab ARGV`` (a :func:`check_request` line) in-process within the explorer's
    :data:`BUDGET`; its JSON answer as printed.

    Parameters
    ----------
    argv : list of str
        ``[command, kind, options..., --json]``.

    Returns
    -------
    str
        The JSON text the command printed.

    Raises
    ------
    ApiError
        422 for anything the command refuses (a value, a missing option, the budget).
    """
    import numpy as np

    from hapstab import budget
    from hapstab.cli.files import STDOUT_TAKEN
    from hapstab.cli.main import click_message, one_line
    from hapstab.cli.options import ARGV

    root = _root()
    cmd = loop_command(argv[0], argv[1])
    token, taken = ARGV.set(tuple(argv)), STDOUT_TAKEN.set(False)
    try:
        with budget.limits(*BUDGET), np.errstate(all="ignore"), warnings.catch_warnings(), \
                _captured() as buf:
            warnings.simplefilter("ignore", RuntimeWarning)
            with root.make_context("hapstab", list(argv)) as ctx:
                root.invoke(ctx)
    except click.ClickException as e:
        p = getattr(e, "param", None)
        msg = one_line(click_message(list(argv), e))
        raise ApiError(422, msg, long_name(p) if isinstance(p, click.Option)
                       else _parameter(msg, cmd, argv)) from None
    except budget.BudgetError as e:    # (its "--yes" is the CLI's: the API takes none)
        msg = one_line(e).split("; run it anyway with --yes")[0]
        raise ApiError(422, f"{msg}: over the explorer's budget; narrow the request (fewer "
                            "points, a smaller range) or run it with the CLI and --yes",
                       _parameter(msg, cmd, argv)) from None
    except HapstabError as e:
        raise ApiError(422, one_line(e), _parameter(str(e), cmd, argv)) from None
    except MemoryError:
        raise ApiError(422, "out of memory: the model is too large for the explorer") from None
    finally:
        ARGV.reset(token)
        STDOUT_TAKEN.reset(taken)
    return buf.getvalue().strip()


def _parameter(message: str, cmd: click.Command, argv: list[str]) -> str | None:
    """The option a one-line message is about: its leading ``--name`` or ``name = value:``
    mapped to the option's long name (the library's names through :data:`ALIASES`, the
    one the request ``argv`` gave first); None when it names no option of ``cmd``."""
    m = _LEADING.match(message)
    if not m:
        return None
    word = m.group(1).lstrip("-").split(".")[-1].replace("-", "_").replace(" ", "_")
    names = option_names(cmd)
    found = [names[w] for w in ALIASES.get(word, (word,)) if w in names]
    if word in names and names[word] not in found:
        found.insert(0, names[word])
    given = [p for p in found if any(a.startswith(f"--{long_name(p)}=") or a == f"--{long_name(p)}"
                                     for a in argv)]
    return long_name((given or found)[0]) if found else None


# ------------------------------------------------------------------------ schema
def option_json(p: click.Option) -> dict[str, Any]:
    """One option as the page's form needs it (name, flags, type, choices, default,
    required, help).

    Parameters
    ----------
    p : click.Option

    Returns
    -------
    dict
    """
    from hapstab.cli.options import Delay, Number, Quantity

    t = p.type
    kind = ("flag" if p.is_flag else "choice" if isinstance(t, click.Choice)
            else "int" if isinstance(t, (Delay, click.types.IntParamType))
            else "float" if isinstance(t, (Number, click.types.FloatParamType)) else "text")
    default = p.default if isinstance(p.default, (int, float, str, bool)) else None
    if p.is_flag and not isinstance(default, bool):
        default = False
    return {"name": long_name(p), "flags": list(p.opts) + list(p.secondary_opts), "type": kind,
            "choices": [str(c) for c in t.choices] if isinstance(t, click.Choice) else None,
            "default": default, "required": bool(p.required), "help": p.help or "",
            "unit": t.unit if isinstance(t, Quantity) else None}


def schema() -> dict[str, Any]:
    """Every command's options for each kind: ``{"hve": {"commands": {"kmax": [...]}}}``.

    Returns
    -------
    dict
    """
    out: dict[str, Any] = {}
    root = _root()
    for kind in KINDS:
        cmds = {}
        for command in COMMANDS:
            group = root.commands[command]
            assert isinstance(group, click.Group)
            if kind in group.commands:
                cmds[command] = [option_json(p) for p in group.commands[kind].params
                                 if isinstance(p, click.Option) and p.name not in OUTPUT_OPTIONS]
        out[kind] = {"commands": cmds}
    return out
