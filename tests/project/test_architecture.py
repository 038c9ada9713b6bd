"""The layout keeps its promises (issue #10's acceptance), checked on the source: the
layers import only downwards, the loop kinds are told apart only in models/ and the
engine's builder, no registry is built from strings, and modules and functions stay
short enough to hold in the head."""

import ast
import pathlib

import pytest

import paths

SRC = paths.ROOT / "src" / "hapstab"
MODULES = sorted(SRC.rglob("*.py"))

#: modules every layer may use: they import only each other (plotting draws results
#: duck-typed and is imported lazily, by a result's .plot())
LEAVES = {"errors", "tolerances", "results", "plotting", "outputs", "budget", "reading"}
#: what each layer may import from hapstab, besides itself and the leaves
MAY_IMPORT = {
    "models": set(),
    "engine": {"models"},
    "analysis": {"models", "engine"},
    "simulation": {"models", "engine", "analysis"},
    "paper": {"models", "engine", "analysis", "simulation"},
    # design sweeps: many loops in chunks, on Dask (its loops are built by a function the
    # caller gives: the CLI's, from a study file's option names)
    "sweep": {"models", "engine", "analysis", "simulation", "paper"},
    "cli": {"models", "engine", "analysis", "simulation", "paper", "sweep"},
    # the explorer's web API runs the CLI's own commands (the same answers as --json)
    "explorer": {"models", "engine", "analysis", "simulation", "paper", "cli", "sweep"},
}
#: the exceptions, each with its reason
EXCEPTIONS = {
    # the one table of K_max methods includes the paper's simulation search
    ("analysis/methods.py", "hapstab.simulation.search"),
    # `hapstab explore` starts the explorer's server (imported when the command runs)
    ("cli/explore.py", "hapstab.explorer.app"),
}


def _layer(path: pathlib.Path) -> str:
    rel = path.relative_to(SRC).with_suffix("")
    return rel.parts[0]


def _imports(tree: ast.AST) -> list[str]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.append(node.module)
        elif isinstance(node, ast.Import):
            out += [a.name for a in node.names]
    return out


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SRC)))
def test_layers_import_only_downwards(path):
    layer = _layer(path)
    if layer not in MAY_IMPORT:
        return                      # the package's __init__ and the leaf modules
    allowed = MAY_IMPORT[layer] | LEAVES | {layer}
    for mod in _imports(ast.parse(path.read_text())):
        parts = mod.split(".")
        if (str(path.relative_to(SRC)), mod) in EXCEPTIONS:
            continue
        if parts[0] == "hapstab" and len(parts) > 1:
            assert parts[1] in allowed, f"{path.name} ({layer}) imports {mod}"


def test_leaf_modules_import_only_leaves():
    for name in LEAVES:
        # a leaf is a module or a package of modules (plotting/)
        files = [SRC / f"{name}.py"] if (SRC / f"{name}.py").exists() else \
            sorted((SRC / name).rglob("*.py"))
        assert files, name
        for path in files:
            for mod in _imports(ast.parse(path.read_text())):
                parts = mod.split(".")
                assert parts[0] != "hapstab" or parts[1] in LEAVES, f"{path.name} imports {mod}"


def test_the_library_never_imports_the_cli():
    for path in MODULES:
        if _layer(path) in ("cli", "__main__", "explorer"):  # `python -m hapstab` is the CLI;
            # the explorer answers with the CLI's commands
            continue
        assert not any(m.startswith("hapstab.cli") for m in _imports(ast.parse(path.read_text()))), \
            path


def test_no_registry_of_strings():
    for path in MODULES:
        if path == SRC / "__init__.py":   # the lazy public names (PEP 562): one table of
            continue                      # modules, checked by tests/cli/test_light_import.py
        assert "importlib" not in path.read_text(), path


#: The loop and controller classes: outside models/ and the engine's builder, code asks
#: them (models/protocol.py) instead of testing their class.
LOOP_CLASSES = {"HapticLoop", "TeleoperationLoop", "FourChannelLoop"}
CONTROLLER_CLASSES = {"SpringDamper", "FilteredSpringDamper", "AffineController",
                      "DiscreteController", "Controller", "StiffnessController"}


def _class_checks(tree: ast.AST):
    """(line, names) of each isinstance / issubclass call and each comparison of a
    ``type(x).__name__`` with a string, with the class names it tests."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and len(node.args) == 2 and \
                getattr(node.func, "id", "") in ("isinstance", "issubclass"):
            yield node.lineno, {getattr(n, "id", getattr(n, "attr", None))
                                for n in ast.walk(node.args[1])}
        if isinstance(node, ast.Compare) and any(
                isinstance(n, ast.Attribute) and n.attr == "__name__"
                for n in ast.walk(node.left)):
            yield node.lineno, {c.value for c in node.comparators
                                if isinstance(c, ast.Constant)}


def test_loop_kinds_are_told_apart_only_in_models_and_the_builder():
    for path in MODULES:
        rel = str(path.relative_to(SRC))
        if rel.startswith("models/") or rel == "engine/structure.py":
            continue
        for line, names in _class_checks(ast.parse(path.read_text())):
            assert not names & LOOP_CLASSES, f"{rel}:{line} isinstance on a loop kind"
            assert not names & CONTROLLER_CLASSES, (
                f"{rel}:{line} a class check on a controller: ask it instead "
                "(models/protocol.py: gains, affine_parts, response, realisation, admits)")


def test_the_library_asks_a_loop_rather_than_comparing_its_kind():
    """Below the command line (whose commands are named by kind), a loop's kind is a key
    into a table (``PAPER[loop.kind]``), never compared with a literal: the loop answers
    (``port_names``, ``controller_names``, its controllers' ``admits``)."""
    for path in MODULES:
        rel = str(path.relative_to(SRC))
        if rel.startswith(("models/", "cli/", "explorer/")):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Compare) and isinstance(node.left, ast.Attribute) \
                    and node.left.attr == "kind" and getattr(node.left.value, "id", "") == "loop":
                literal = [c for c in node.comparators if isinstance(c, (ast.Constant, ast.Tuple))]
                assert not literal, f"{rel}:{node.lineno} compares loop.kind with a literal"


def test_the_class_check_finder_sees_a_check(tmp_path):
    tree = ast.parse("if isinstance(c, (SpringDamper, m.FilteredSpringDamper)): pass\n"
                     "if type(loop).__name__ == 'HapticLoop': pass\n"
                     "if isinstance(x, float): pass\n")
    found = dict(_class_checks(tree))
    assert found[1] & CONTROLLER_CLASSES == {"SpringDamper", "FilteredSpringDamper"}
    assert found[2] & LOOP_CLASSES == {"HapticLoop"}
    assert not found[3] & (LOOP_CLASSES | CONTROLLER_CLASSES)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SRC)))
def test_modules_and_functions_are_short(path):
    text = path.read_text()
    assert len(text.splitlines()) <= 510, f"{path.name}: {len(text.splitlines())} lines"  # ~500
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            doc = (isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                   and isinstance(body[0].value.value, str))
            start = body[0].end_lineno + 1 if doc and len(body) > 1 else body[0].lineno
            code = node.end_lineno - start + 1
            assert code <= 62, f"{path.name}: {node.name} has {code} lines of code"  # ~60


def _cli_names_used(tree: ast.AST) -> list[tuple[int, str]]:
    """Every name a module takes from hapstab.cli: ``from hapstab.cli.x import name``,
    ``import hapstab.cli.x as m`` / ``from hapstab.cli import x`` then ``m.name``."""
    used, aliases = [], set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("hapstab.cli"):
            used += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
            aliases |= {a.asname or a.name for a in node.names}
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("hapstab.cli"):
                    used.append((node.lineno, a.name))
                    aliases.add(a.asname or a.name)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and ast.unparse(node.value) in aliases:
            used.append((node.lineno, f"{ast.unparse(node.value)}.{node.attr}"))
    return used


def _private(dotted: str) -> bool:
    return any(p.startswith("_") and not (p.startswith("__") and p.endswith("__"))
               for p in dotted.split("."))


def test_the_explorer_asks_the_cli_through_public_names_only():
    """Issue 28: the explorer runs the CLI's commands through the CLI's public seams
    (``cli.study.option_spellings``, the click group's table of commands), never a private
    name of cli (one starting with ``_``): a private name may change without notice."""
    for path in sorted((SRC / "explorer").rglob("*.py")):
        for line, name in _cli_names_used(ast.parse(path.read_text())):
            assert not _private(name), f"explorer/{path.name}:{line} uses {name}"


def test_the_cli_imports_the_explorer_only_inside_a_command():
    """No import cycle at import time: the explorer imports the CLI (it runs its
    commands), and the CLI reaches the explorer only inside ``hapstab explore``'s body,
    so importing any CLI module never imports the explorer."""
    for path in sorted((SRC / "cli").rglob("*.py")):
        tree = ast.parse(path.read_text())
        inner = {id(n) for f in ast.walk(tree)
                 if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                 for n in ast.walk(f)}
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in inner:
                mods = [node.module or ""] if isinstance(node, ast.ImportFrom) else \
                    [a.name for a in node.names]
                assert not any(m.startswith("hapstab.explorer") for m in mods), \
                    f"cli/{path.name}:{node.lineno} imports the explorer at import time"
