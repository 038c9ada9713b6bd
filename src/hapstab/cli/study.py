"""Study files: a TOML file that keeps a study reproducible.

A study names the loop kind, the loop (its options, by the command line's own names),
variants of it, and the analyses ``hapstab run`` produces::

    kind = "hve"
    title = "My 1 kHz device behind 20 ms of network"

    [loop]                      # the loop options, named as on the command line
    mass = 0.3
    damping = 0.5
    operator = "msd:0.5,5,500"
    rate = "1kHz"
    delay-s = "20ms"

    [[variant]]                 # a name and the options it changes
    name = "damped"
    virtual-damping = 2

    [run.kmax]                  # an analysis of `hapstab run` and its options
    [run.boundary]
    rate = "250Hz:4kHz:16"
    delay-s = "0,20ms"

Every loop command takes ``--study FILE`` (and ``--variant NAME``): the file gives the
defaults, the command line overrides them. The file is parsed with :mod:`tomllib` (never
evaluated) and checked before any work: an unknown key, a value of the wrong kind or an
unknown variant is one line naming the file, the line and the key.
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass, field
from typing import Any

import click

from hapstab.cli.options import LOOP_KINDS
from hapstab.errors import HapstabError

if sys.version_info >= (3, 11):
    import tomllib
else:                                    # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[import-not-found,unused-ignore]

__all__ = ["Study", "load_study", "study_defaults", "option_spellings", "BASE", "OUTPUT_KEYS"]

#: The variant that is the [loop] table itself.
BASE = "base"
#: Options a study cannot set: where the answer goes is the command line's (or run's).
OUTPUT_KEYS = ("json", "csv", "plot", "study", "variant", "yes", "debug", "help",
               "certificate", "cert_path")
#: Options that give one quantity two ways: a later layer's choice drops the earlier other.
ALTERNATIVES = (("period", "rate"), ("delay", "delay_s"))
#: Loop options a command varies itself: a study's value is not used there (not an error:
#: a variant with its own B still has a K-B region).
VARIED = {"region": ("virtual_damping",), "best-damping": ("virtual_damping",)}
#: Loop options a command replaces by a range of its own: ``jitter``'s ``--delay LO:HI`` is
#: the delay, so the [loop]'s or a variant's one constant delay (``delay``, ``n``,
#: ``delay-s``) is not used there; [run.jitter] gives the range.
REPLACED = {"jitter": ("delay", "n", "delay_s")}
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")      # fullmatch: no trailing newline
#: The largest study file read: 4 MiB, room for tens of thousands of variants (one is
#: about 60 bytes); a larger one is refused before it is read.
MAX_STUDY_BYTES = 4 * 1024 ** 2
#: The deepest nesting of tables and arrays a study may have (the documented ones nest
#: three deep: [run.boundary], [sweep.axes] and their lists).
MAX_STUDY_DEPTH = 16


class StudyError(HapstabError):
    """A study file that cannot be used (the message names the file, line and key)."""


@dataclass(frozen=True)
class Study:
    """A parsed study file.

    Attributes
    ----------
    path : str
        The file.
    kind : {"hve", "peb", "4ch"}
        The loop kind.
    title : str
        What the study is about (may be empty).
    loop : dict
        The [loop] table: option name -> value.
    variants : dict
        Variant name -> the options it changes (the base variant changes none).
    run : dict
        Analysis (command name) -> its options, in the file's order.
    text : str
        The file's text (for line numbers and the run's manifest).
    """

    path: str
    kind: str
    title: str
    loop: dict[str, Any]
    variants: dict[str, dict[str, Any]]
    run: dict[str, dict[str, Any]]
    text: str = field(repr=False)

    def line_of(self, key: str, table: str | None = None) -> int | None:
        """The line (1-based) where ``key`` is set, within ``table`` if given."""
        return _line_of(self.text, key, table)

    def where(self, key: str, table: str | None = None) -> str:
        """``"FILE line N: "`` for a message."""
        n = self.line_of(key, table)
        return f"{self.path}{f' line {n}' if n else ''}: "


def load_study(path: Any, name: str = "--study") -> Study:
    """Read and check the structure of a study file.

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file.
    name : str
        The option or argument that gave it, named in errors about the file as a whole.

    Returns
    -------
    Study

    Raises
    ------
    StudyError
        The file is missing, not TOML, or its tables are not as documented.
    """
    p = os.fspath(path)
    raw = _read_bounded(p, name)
    try:
        text = raw.decode("utf-8")       # TOML is UTF-8; the file is kept as it is
        data = tomllib.loads(text)
    except UnicodeDecodeError as e:
        raise StudyError(f"{name} = {p!r}: not UTF-8 at byte {e.start} (a TOML file is UTF-8)"
                         ) from None
    except (tomllib.TOMLDecodeError, ValueError) as e:   # ValueError: an integer of 4300+ digits
        raise StudyError(f"{name} = {p!r}: not a valid TOML file ({str(e)[:200]})") from None
    except RecursionError:
        raise StudyError(f"{name} = {p!r}: arrays or tables nested too deep to read (allowed: "
                         f"at most {MAX_STUDY_DEPTH} levels)") from None
    if _depth(data) > MAX_STUDY_DEPTH:
        raise StudyError(f"{name} = {p!r}: arrays or tables nested {_depth(data)} deep; allowed: "
                         f"at most {MAX_STUDY_DEPTH} levels")
    known = {"kind", "title", "loop", "variant", "run", "sweep"}     # [sweep]: hapstab sweep
    for key in data:
        if key not in known:
            raise StudyError(f"{p}{_at(text, key)}: unknown key {key!r}; allowed: "
                             f"{', '.join(sorted(known))}")
    kind = data.get("kind")
    if not isinstance(kind, str) or kind not in LOOP_KINDS:     # (a TOML list is unhashable)
        raise StudyError(f"{p}{_at(text, 'kind')}: kind = {kind!r}: allowed: "
                         + ", ".join(f'"{k}"' for k in LOOP_KINDS))
    title = data.get("title", "")
    if not isinstance(title, str) or any((c < " " and c != "\t") or c == "\x7f" for c in title):
        raise StudyError(f"{p}{_at(text, 'title')}: title = {title!r:.40}: must be a string "
                         "without control characters (it is printed on the terminal)")
    loop = _table(p, text, data, "loop")
    run = _table(p, text, data, "run")
    for name, opts in run.items():
        if not isinstance(opts, dict):
            raise StudyError(f"{p}{_at(text, name, 'run')}: run.{name} must be a table "
                             f"([run.{name}]) of that command's options")
    return Study(p, kind, str(title), _flat(loop, (p, text)), _variants(p, text, data), run, text)


def _read_bounded(p: str, name: str) -> bytes:
    """The bytes of the regular file ``p``, at most :data:`MAX_STUDY_BYTES` of them
    (:func:`hapstab.reading.read_bounded`: a device, FIFO, socket, folder or larger
    file is refused)."""
    from hapstab.reading import read_bounded
    return read_bounded(p, name, MAX_STUDY_BYTES, "a study is a TOML file of at most "
                        f"{MAX_STUDY_BYTES} bytes", StudyError)


def _depth(data: Any) -> int:
    """How deep tables and arrays nest in ``data`` (iterative: no recursion limit)."""
    deepest, todo = 0, [(data, 0)]
    while todo:
        x, d = todo.pop()
        if isinstance(x, dict):
            todo += [(v, d + 1) for v in x.values()]
        elif isinstance(x, list):
            todo += [(v, d + 1) for v in x]
        else:
            continue
        deepest = max(deepest, d)
        if deepest > MAX_STUDY_DEPTH:
            break
    return deepest


def _table(p: str, text: str, data: dict[str, Any], name: str) -> dict[str, Any]:
    value = data.get(name, {})
    if not isinstance(value, dict):
        raise StudyError(f"{p}{_at(text, name)}: {name} must be a table ([{name}])")
    return value


def _flat(opts: dict[str, Any], where: Any = None, table: str = "loop") -> dict[str, Any]:
    """Option names as the command's parameters spell them (``delay-s`` -> ``delay_s``);
    one key given in both spellings is refused (the last would silently win). ``where``:
    the study (or ``(path, text)``) to name the line."""
    out: dict[str, Any] = {}
    first: dict[str, str] = {}
    for k, v in opts.items():
        flat = k.replace("-", "_")
        if flat in out:
            at = where.where(k, table) if isinstance(where, Study) else \
                f"{where[0]}{_at(where[1], k, table)}: " if where else ""
            raise StudyError(f"{at}{first[flat]} and {k} in [{table}]: the same option spelt "
                             "twice; give it once")
        out[flat], first[flat] = v, k
    return out


def _variants(p: str, text: str, data: dict[str, Any]) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {BASE: {}}
    items = data.get("variant", [])
    if not isinstance(items, list) or not all(isinstance(v, dict) for v in items):
        raise StudyError(f"{p}{_at(text, 'variant')}: variants are [[variant]] tables, each "
                         "with a name and the loop options it changes")
    for v in items:
        name = v.get("name")
        if not isinstance(name, str) or not _NAME.fullmatch(name) or name in out \
                or name in ("manifest.json", "study.toml"):
            raise StudyError(f"{p}{_at(text, 'name', None, str(name))}: variant name = {name!r}: "
                             "each [[variant]] needs a unique name of letters, digits, '.', "
                             f"'_' or '-' (not {BASE!r}, the [loop] table itself, nor the "
                             "run's manifest.json or study.toml)")
        out[name] = _flat({k: x for k, x in v.items() if k != "name"}, (p, text), "variant")
    return out


def _at(text: str, key: str, table: str | None = None, value: str | None = None) -> str:
    n = _line_of(text, key, table, value)
    return f" line {n}" if n else ""


def _line_of(text: str, key: str, table: str | None = None, value: str | None = None) -> int | None:
    """The first line setting ``key`` (spelled with - or _), inside ``[table]`` or
    ``[table.*]`` if given; or the first table header ``[key]`` / ``[[key]]``."""
    spellings = {key, key.replace("_", "-"), key.replace("-", "_")}
    current = ""
    for i, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        header = re.match(r"^\[\[?\s*([^\]]+?)\s*\]\]?", s)
        if header:
            current = header.group(1)
            if table is None and current.split(".")[-1] in spellings:
                return i
            continue
        m = re.match(r"^[\"']?([A-Za-z0-9_-]+)[\"']?\s*=\s*(.*)$", s)
        if not m or m.group(1) not in spellings:
            continue
        if value is not None and value not in m.group(2):
            continue
        if table is None or current == table or current.startswith(table + "."):
            return i
    return None


def study_defaults(study: Study, cmd: click.Command, command: str, variant: str,
                   argv: list[str], run: bool = True) -> dict[str, Any]:
    """The defaults a study gives one command: [loop], then the variant, then
    [run.<command>], each checked against the command's options and converted by their
    own types; an option given on the command line drops the study's alternative to it.

    Parameters
    ----------
    study : Study
    cmd : click.Command
        The loop-kind subcommand (e.g. ``kmax hve``).
    command : str
        Its group's name (``kmax``): the [run.<command>] table applies (with ``run``;
        False: [loop] and the variant only, as ``hapstab sweep`` reads the loop).
    variant : str
        A name of ``study.variants``.
    argv : list of str
        The command line after the loop kind (what overrides the study).

    Returns
    -------
    dict
        Parameter name -> value, for click's ``default_map``.

    Raises
    ------
    StudyError
        An unknown variant, key or value, naming the file, line and key.
    """
    if variant not in study.variants:
        raise StudyError(f"--variant = {variant!r}: {study.path} has "
                         f"{', '.join(map(repr, study.variants))}")
    params = {p.name: p for p in cmd.params if isinstance(p, click.Option) and p.name}
    names = option_spellings(params)
    out: dict[str, Any] = {}
    by_variant: set[str] = set()
    layers = [("loop", study.loop), ("variant", study.variants[variant]),
              (f"run.{command}", _flat(study.run.get(command, {}) if run else {},
                                       study, f"run.{command}"))]
    for table, opts in layers:
        seen: dict[str, str] = {}
        for key, value in opts.items():
            if not table.startswith("run.") and key in REPLACED.get(command, ()):
                continue
            name = names.get(key)
            if name is None or key in OUTPUT_KEYS:
                raise _unknown(study, table, key, command, names)
            _once(study, table, key, name, seen)
            if name in VARIED.get(command, ()):
                if table.startswith("run."):
                    raise StudyError(f"{study.where(key, table)}{key.replace('_', '-')}: "
                                     f"{command} varies it itself; give its window instead")
                continue
            if table.startswith("run."):
                _not_over_variant(study, table, key, name, variant, by_variant)
            elif table == "variant":
                by_variant.add(name)
            _drop_alternative(out, name)
            out[name] = _convert(study, table, key, value, params[name])
    for name in _given(params, argv).values():
        _drop_alternative(out, name)
    return out


def _not_over_variant(study: Study, table: str, key: str, name: str, variant: str,
                      by_variant: set[str]) -> None:
    """Refuse a [run.<command>] option that would replace what the variant sets (itself or
    its alternative: ``delay-s`` for ``delay``): every variant would silently get the same."""
    alts = {name, *(b for a, b in ALTERNATIVES if a == name), *(a for a, b in ALTERNATIVES
                                                                 if b == name)}
    hit = sorted(alts & by_variant)
    if hit:
        raise StudyError(f"{study.where(key, table)}{key.replace('_', '-')}: would replace "
                         f"the {hit[0].replace('_', '-')} of variant {variant!r} (every variant "
                         "would get the same); set it in each variant or in [loop] instead")


def _once(study: Study, table: str, key: str, name: str, seen: dict[str, str]) -> None:
    """Refuse one option set twice in one table (``m`` and ``mass``; ``period`` and
    ``rate``), as the command line does."""
    for a, b in ((name, name), *ALTERNATIVES, *[(y, x) for x, y in ALTERNATIVES]):
        if name == a and b in seen:
            raise StudyError(f"{study.where(key, table)}{key.replace('_', '-')} and "
                             f"{seen[b].replace('_', '-')} in [{table}]: give one of them, not "
                             "both")
    seen[name] = key


def option_spellings(params: dict[str, click.Option]) -> dict[str, str]:
    """Every spelling a study (or an explorer request) may use for an option -> the
    parameter's name.

    The parameter's name, its long options without dashes (``delay_s``, ``K``) and its
    short ones where no long option spells the same (``K`` for simulate's ``-K``; region's
    ``--B`` is the window, not ``-B``). Where the answer goes (``--json``, ``--csv``,
    ``--plot``) has no spelling.

    Parameters
    ----------
    params : dict of str to click.Option
        A command's options by parameter name.

    Returns
    -------
    dict of str to str
        Spelling (with ``_`` for ``-``) -> parameter name.
    """
    out: dict[str, str] = {}
    short: dict[str, str] = {}
    for name, p in params.items():
        if name in ("as_json", "csv_path", "plot_path"):
            continue
        out[name] = name
        for o in p.opts:
            if o.startswith("--"):
                out[o[2:].replace("-", "_")] = name
            else:
                short[o[1:]] = name
    return {**short, **out}


def _unknown(study: Study, table: str, key: str, command: str, names: dict[str, str]) -> StudyError:
    import difflib

    allowed = sorted(k.replace('_', '-') for k in names)
    close = difflib.get_close_matches(key.replace('_', '-'), allowed, n=1)
    why = ("where the answer goes is chosen on the command line (or by hapstab run)"
           if key in OUTPUT_KEYS else
           f"not an option of {command} {study.kind}"
           + (f" (did you mean {close[0]}?)" if close else "")
           + f"; allowed: {', '.join(allowed)}")
    return StudyError(f"{study.where(key, table)}{key.replace('_', '-')}: {why}")


def _convert(study: Study, table: str, key: str, value: Any, param: click.Option) -> Any:
    if isinstance(value, (dict, list)) or (isinstance(value, bool) and not param.is_flag):
        raise StudyError(f"{study.where(key, table)}{key.replace('_', '-')} = {value!r}: must be "
                         "a number or a string, as on the command line")
    if isinstance(param.type, click.types.IntParamType) and not _whole_text(value):
        raise StudyError(f"{study.where(key, table)}{key.replace('_', '-')} = {value!r:.40}: "
                         "must be a whole number (ASCII digits), as on the command line")
    if param.is_flag and not isinstance(value, bool):
        raise StudyError(f"{study.where(key, table)}{key.replace('_', '-')} = {value!r}: must be "
                         "true or false (a switch)")
    try:
        return param.type.convert(value, param, None)
    except click.BadParameter as e:
        raise StudyError(f"{study.where(key, table)}{key.replace('_', '-')} = {value!r}: "
                         f"{e.message}") from None


def _whole_text(value: Any) -> bool:
    """A whole number as TOML gives it (an integer, a whole float) or ASCII digits: what
    click's int type would read without truncating (2.9 -> 2) or reading other scripts'
    digits."""
    if isinstance(value, str):
        return re.fullmatch(r"\s*[-+]?[0-9]+\s*", value, re.ASCII) is not None
    if isinstance(value, float):
        return value.is_integer()
    return isinstance(value, int)


def _drop_alternative(out: dict[str, Any], name: str) -> None:
    for a, b in ALTERNATIVES:
        if name in (a, b):
            out.pop(b if name == a else a, None)


def _given(params: dict[str, click.Option], argv: list[str]) -> dict[str, str]:
    """Options typed on the command line (``--period 1ms``, ``--period=1ms``, ``-T1ms``)."""
    out = {}
    for name, p in params.items():
        for o in p.opts:
            if any(a == o or a.startswith(o + "=") or (len(o) == 2 and a.startswith(o) and
                                                        not a.startswith("--")) for a in argv):
                out[o] = name
    return out
