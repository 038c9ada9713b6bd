"""``import hapstab`` and ``hapstab --version`` stay light (issue 26): no numpy, scipy,
matplotlib or python-flint until a name is used (the package's ``__getattr__``).

Checked in a fresh interpreter each (``sys.modules`` after the import), not by timing: a
time limit would fail on a busy machine and pass on a fast one; the modules imported
decide the cost (benchmarks/bench_core.py measures the seconds).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

import hapstab

#: what makes an import heavy (scipy alone was ~0.5 s of the 0.9 s, via the friction
#: simulator); numpy is listed too: nothing at import time needs it
HEAVY = ("numpy", "scipy", "matplotlib", "flint", "mpmath", "click", "rich")

_PROBE = """
import json, sys
{code}
print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}})))
"""


def _top_modules(code: str) -> set[str]:
    r = subprocess.run([sys.executable, "-c", _PROBE.format(code=code)], capture_output=True,
                       text=True, check=True)
    return set(json.loads(r.stdout.splitlines()[-1]))


def test_import_hapstab_imports_nothing_heavy():
    assert not _top_modules("import hapstab") & set(HEAVY)


def test_version_imports_nothing_heavy():
    code = ("sys.argv = ['hapstab', '--version']\nfrom hapstab.cli import main\n"
            "try:\n    main()\nexcept SystemExit as e:\n    assert e.code == 0\n")
    assert not _top_modules(code) & set(HEAVY)


def test_version_says_what_click_says():
    # the fast path prints what click's version_option prints (the installed metadata):
    # with --debug the line does not take the fast path
    fast, slow = (subprocess.run([sys.executable, "-m", "hapstab", *a], capture_output=True,
                                 text=True, check=True) for a in (["--version"],
                                                                  ["--debug", "--version"]))
    assert fast.stdout == slow.stdout
    assert CliRunner().invoke(hapstab.cli.cli, ["--version"]).exit_code == 0
    assert fast.stdout == f"hapstab, version {hapstab.__version__}\n"


def test_a_name_loads_its_module_on_use():
    mods = _top_modules("import hapstab\nhapstab.critical_stiffness")
    assert {"numpy", "hapstab"} <= mods


def test_every_public_name_resolves():
    for name in hapstab.__all__:
        assert getattr(hapstab, name) is not None, name
    assert set(hapstab.__all__) <= set(dir(hapstab))
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        _ = hapstab.no_such_name


def test_lazy_table_equals_the_type_checking_imports():
    # the names for type checkers (the `if TYPE_CHECKING:` imports) and the table that
    # loads them at run time are written twice: they must agree, and cover __all__
    tree = ast.parse(Path(hapstab.__file__).read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If)
                 and getattr(n.test, "id", "") == "TYPE_CHECKING")
    imported = {a.name: n.module for n in block.body if isinstance(n, ast.ImportFrom)
                for a in n.names}
    assert imported == hapstab._MODULE_OF
    assert set(hapstab.__all__) <= set(imported)


def test_subpackages_still_reachable_as_attributes():
    import importlib

    mod = importlib.import_module("hapstab")
    assert mod.analysis.exact.__name__ == "hapstab.analysis.exact"
    assert hapstab.cli.cli.name == "cli"
