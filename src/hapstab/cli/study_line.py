"""``--study FILE`` and ``--variant NAME`` on a loop command's line: taken out of the
line wherever they are given and turned into click's default map (the study file itself is
read and checked by :mod:`hapstab.cli.study`)."""

from __future__ import annotations

from typing import Any

import click

from hapstab.cli.study import BASE, Study, StudyError, load_study, study_defaults

__all__ = ["take_study", "kind_command", "loop_commands"]


def take_study(argv: list[str], group: click.Group) -> tuple[list[str], dict[str, Any] | None]:
    """Take ``--study FILE`` and ``--variant NAME`` out of the command line (they may be
    given anywhere) and turn the study into click's ``default_map`` for the command run.
    Without a loop kind on the line (``hapstab kmax --study f.toml``) the study's is used.

    Parameters
    ----------
    argv : list of str
        The command line after ``hapstab``.
    group : click.Group
        The ``hapstab`` group.

    Returns
    -------
    (list of str, dict or None)
        The command line left, and the default map (None without ``--study``).
    """
    rest, path = _take(argv, "--study")
    rest, variant = _take(rest, "--variant")
    if path is None:
        if variant is not None:
            raise StudyError("--variant: names a variant of a study; give the file with --study")
        return argv, None
    study = load_study(path)
    command = rest[0] if rest else ""
    sub = group.commands.get(command)
    if not isinstance(sub, click.Group):
        raise StudyError(f"--study: applies to the loop commands ({', '.join(loop_commands(group))})"
                         f"; use hapstab run {path} to run the study's analyses")
    if len(rest) < 2 or rest[1] not in sub.commands:
        rest = [rest[0], study.kind, *rest[1:]]
    elif rest[1] != study.kind:
        raise StudyError(f"--study = {path!r}: its kind is {study.kind!r}, not {rest[1]!r}; "
                         f"hapstab {command} {study.kind} ... (or leave the kind out)")
    cmd = kind_command(study, sub, command)
    defaults = study_defaults(study, cmd, command, variant or BASE, rest[2:])
    return rest, {command: {study.kind: defaults}}


def kind_command(study: Study, group: click.Group, command: str, where: str = "") -> click.Command:
    """The study's loop kind under the loop command ``group`` (``kmax 4ch``), or a
    StudyError (prefixed by ``where``, else the file) when that command has no such kind
    (``check`` takes no 4ch loop)."""
    cmd = group.commands.get(study.kind)
    if cmd is None:
        names = list(group.commands)
        raise StudyError(f"{where or study.path + ': '}{command} takes "
                         f"{', '.join(names[:-1])}{' or ' if len(names) > 1 else ''}{names[-1]} "
                         f"loops, not the study's {study.kind}")
    return cmd


def loop_commands(group: click.Group) -> list[str]:
    """The commands that build a loop (a loop kind under them)."""
    return [n for n, c in group.commands.items() if isinstance(c, click.Group)]


def _take(argv: list[str], opt: str) -> tuple[list[str], str | None]:
    """Remove ``opt VALUE`` / ``opt=VALUE`` from ``argv``: (the rest, VALUE or None)."""
    out, values, i = [], [], 0
    while i < len(argv):
        a = argv[i]
        if a == opt:
            if i + 1 >= len(argv):
                raise StudyError(f"{opt}: needs a value")
            values.append(argv[i + 1])
            i += 2
            continue
        if a.startswith(opt + "="):
            values.append(a[len(opt) + 1:])
        else:
            out.append(a)
        i += 1
    if len(values) > 1:
        raise StudyError(f"{opt}: given {len(values)} times; give it once")
    return out, (values[0] if values else None)
