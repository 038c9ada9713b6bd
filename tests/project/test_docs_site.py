"""The documentation site: the API reference names every public name, the CLI reference
every command, the README stays short and its Python example runs, docstring examples run.

The full Sphinx build (``make docs``, -W) takes about a minute on the project's 2-core
machine, so it is not run here; these checks read the sources it is built from.
"""

from __future__ import annotations

import doctest
import importlib
import re

import hapstab
import paths

ROOT = paths.ROOT
DOCS = ROOT / "docs"


def test_api_reference_lists_every_public_name() -> None:
    text = (DOCS / "reference" / "api.md").read_text()
    listed = re.findall(r"^   (\w+)$", text, flags=re.M)
    assert sorted(listed) == sorted(hapstab.__all__)


def test_cli_reference_covers_every_command() -> None:
    text = (DOCS / "reference" / "cli.md").read_text()
    # sphinx-click's :nested: full documents every subcommand of the group it is given
    assert ".. click:: hapstab.cli.main:cli" in text and ":nested: full" in text
    from hapstab.cli.main import cli

    assert len(cli.commands) > 10  # the group is registered, so sphinx-click sees them all


def test_readme_is_short_and_its_python_runs() -> None:
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 250
    blocks = re.findall(r"```python\n(.*?)```", readme, flags=re.S)
    assert blocks
    for code in blocks:
        scope: dict[str, object] = {}
        exec(compile(code, "README.md", "exec"), scope)
    res = scope["res"]
    # the README states 9.536097554689 N/m (12 significant digits, as printed there)
    assert abs(res.critical_stiffness - 9.536097554689) < 1e-9  # type: ignore[attr-defined]


def test_docstring_examples_run() -> None:
    modules = sorted(p for p in (ROOT / "src" / "hapstab").rglob("*.py") if ">>>" in p.read_text())
    assert modules
    for path in modules:
        name = ".".join(path.relative_to(ROOT / "src").with_suffix("").parts)
        mod = importlib.import_module(name.removesuffix(".__init__"))
        result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
        assert result.failed == 0, name


def test_the_guide_names_each_room_in_every_layer() -> None:
    """The guide's index has one row per room of the table of analyses, naming the room's
    package, its command-line module and its tests' folder, all of which exist."""
    from hapstab.analysis.table import TABLE

    index = (ROOT / "docs" / "guide" / "index.md").read_text()
    for room in sorted({r.room for r in TABLE}):
        row = next((line for line in index.splitlines() if line.startswith(f"| {room} |")), None)
        assert row, f"docs/guide/index.md has no row for the room {room}"
        code = "simulation/" if room == "simulation" else f"analysis/{room}/"
        for part in (code, f"cli/{room}.py", f"tests/{room}/"):
            assert f"`{part}" in row, (room, part)
            where = part if part.startswith("tests") else "src/hapstab/" + part
            assert (ROOT / where).exists(), where
