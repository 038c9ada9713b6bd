"""The newcomer's path through the README (issue 29, acceptance): every ``$ hapstab ...``
command of its blocks runs as written, in an empty folder (as from a clean clone), prints
what the README shows under it and writes the files it names."""

from __future__ import annotations

import re
import shlex

import pytest
from click.testing import CliRunner

import paths
from hapstab.cli.main import cli

README = paths.ROOT / "README.md"


def _commands() -> list[tuple[list[str], list[str]]]:
    """(argv, the output lines the README shows under it), in the README's order: the
    lines of its plain code blocks (a block opens and closes with a line of three
    backticks), continuation backslashes joined."""
    out: list[tuple[list[str], list[str]]] = []
    fence, block = None, []
    for line in README.read_text().splitlines():
        if line.startswith("```"):
            if fence is None:
                fence, block = line[3:].strip(), []
                continue
            if fence == "":
                for row in "\n".join(block).replace("\\\n", " ").splitlines():
                    if row.startswith("$ hapstab "):
                        out.append((shlex.split(row[len("$ hapstab "):]), []))
                    elif out and row.strip() and not row.startswith(("$", "make ")):
                        out[-1][1].append(row)
            fence = None
        elif fence is not None:
            block.append(line)
    return out


COMMANDS = _commands()


def test_the_readme_has_the_newcomer_commands():
    assert [c[0][:2] for c in COMMANDS] == [["kmax", "hve"], ["boundary", "hve"],
                                             ["region", "hve"], ["simulate", "hve"]]
    assert COMMANDS[0][1][0].startswith("critical stiffness")


@pytest.mark.parametrize("argv, shown", COMMANDS, ids=lambda v: v[0] if v and
                         isinstance(v[0], str) else "")
def test_each_readme_command_runs_and_prints_what_it_shows(argv, shown, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)                 # an empty folder: nothing but the install
    r = CliRunner().invoke(cli, argv)
    assert r.exit_code == 0, r.stderr
    # the README shows the table's rows without its frame (rich's box characters)
    printed = [" ".join(re.sub("[\u2500-\u257f]", " ", line).split())
               for line in r.stdout.splitlines()]
    for line in shown:
        assert " ".join(line.split()) in printed, line
    for i, a in enumerate(argv):
        if a == "--plot":
            assert (tmp_path / argv[i + 1]).stat().st_size > 1000, argv[i + 1]
