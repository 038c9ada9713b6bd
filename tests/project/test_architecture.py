"""The layout keeps its promises (issue #10's acceptance), checked on the source: the
layers import only downwards, the loop kinds are told apart only in models/ and the
engine's builder, no registry is built from strings, and modules and functions stay
short enough to hold in the head."""

import ast
import functools
import importlib
import pathlib
import re
import types

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


@functools.cache
def _tree(path: pathlib.Path) -> ast.Module:
    """The module's syntax tree, parsed once per process (the tests here only read it:
    parsed afresh by each, the ~170 modules cost ~1,300 parses, ~4 s of the lane)."""
    return ast.parse(path.read_text())


@functools.cache
def _imports_of(path: pathlib.Path) -> tuple[str, ...]:
    return tuple(_imports(_tree(path)))


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
    for mod in _imports_of(path):
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
            for mod in _imports_of(path):
                parts = mod.split(".")
                assert parts[0] != "hapstab" or parts[1] in LEAVES, f"{path.name} imports {mod}"


def test_the_library_never_imports_the_cli():
    for path in MODULES:
        if _layer(path) in ("cli", "__main__", "explorer"):  # `python -m hapstab` is the CLI;
            # the explorer answers with the CLI's commands
            continue
        assert not any(m.startswith("hapstab.cli") for m in _imports_of(path)), \
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
        for line, names in _class_checks(_tree(path)):
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
        for node in ast.walk(_tree(path)):
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
    for node in ast.walk(_tree(path)):
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
        for line, name in _cli_names_used(_tree(path)):
            assert not _private(name), f"explorer/{path.name}:{line} uses {name}"


def test_the_cli_imports_the_explorer_only_inside_a_command():
    """No import cycle at import time: the explorer imports the CLI (it runs its
    commands), and the CLI reaches the explorer only inside ``hapstab explore``'s body,
    so importing any CLI module never imports the explorer."""
    for path in sorted((SRC / "cli").rglob("*.py")):
        tree = _tree(path)
        inner = {id(n) for f in ast.walk(tree)
                 if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                 for n in ast.walk(f)}
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in inner:
                mods = [node.module or ""] if isinstance(node, ast.ImportFrom) else \
                    [a.name for a in node.names]
                assert not any(m.startswith("hapstab.explorer") for m in mods), \
                    f"cli/{path.name}:{node.lineno} imports the explorer at import time"


# ------------------------------------------------------------ seams (issue 28)
#: private-looking names that are another library's public API, each with its reason
FOREIGN_PUBLIC = {
    "os._exit",     # the standard library's documented exit without clean-up (cli/__init__)
}


def _private_seams(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, name) of each private name (one leading underscore, not a dunder) that a
    module takes from another: ``from m import _x``, ``import m._x``, and each read of
    ``obj._x`` through anything but ``self`` or ``cls`` (another object's insides)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            mod = "." * node.level + (node.module or "")
            names = [mod + ("" if mod.endswith(".") else ".") + a.name for a in node.names]
            found += [(node.lineno, name) for name in names if _private(name)]
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if _private(a.name)]
        elif isinstance(node, ast.Attribute) and _private(node.attr) and not (
                isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
            found.append((node.lineno, f"{ast.unparse(node.value)}.{node.attr}"))
    return sorted((line, name) for line, name in found if name not in FOREIGN_PUBLIC)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SRC)))
def test_no_private_name_crosses_a_module_seam(path):
    """Issue 28: what one module uses of another is that module's public seam; a private
    name (``_x``) may change without notice, so no module imports one from another, nor
    reads one of another object."""
    rel = path.relative_to(SRC)
    for line, name in _private_seams(_tree(path)):
        raise AssertionError(f"{rel}:{line} uses the private {name}: make it a public seam")


def test_the_seam_finder_sees_a_private_name():
    tree = ast.parse("from hapstab.analysis.exact.boxes import Cells, _dpoly\n"
                     "import hapstab.engine._hidden\n"
                     "x = out._va\n"
                     "y = self._va + cls._cache + obj.__class__.__name__\n"
                     "from . import _mine\n"
                     "os._exit(1)\n")
    assert _private_seams(tree) == [(1, "hapstab.analysis.exact.boxes._dpoly"),
                                    (2, "hapstab.engine._hidden"), (3, "out._va"),
                                    (5, "._mine")]


#: a dotted path into the package, in a Sphinx role (:mod:`~hapstab.engine.zoh`,
#: :func:`hapstab.analysis.exact.core.stability`) or bare
_DOTTED = re.compile(r"(?::(\w+):`~?)?(?<![\w.])(hapstab(?:\.[A-Za-z_]\w*)+)")


def _docstrings(tree: ast.AST):
    """(line, text) of the module's, each class's and each function's docstring."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            text = ast.get_docstring(node, clean=False)
            if text:
                yield getattr(node, "lineno", 1), text


def _target(dotted: str) -> object | None:
    """What ``dotted`` names: the longest importable module, then attributes (a
    dataclass's field or an annotated attribute counts); None if it names nothing."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        name = ".".join(parts[:i])
        try:
            obj: object = importlib.import_module(name)
        except ModuleNotFoundError as e:
            if e.name is None or not (name == e.name or name.startswith(f"{e.name}.")):
                raise       # an optional dependency missing, not a wrong path
            continue
        for p in parts[i:]:
            fields = {**getattr(obj, "__dataclass_fields__", {}),
                      **getattr(obj, "__annotations__", {})}
            if not hasattr(obj, p) and p not in fields:
                return None
            obj = getattr(obj, p, fields.get(p))
        return obj
    return None


def _missing_names(source: str, tree: ast.Module | None = None) -> list[tuple[int, str]]:
    """(line of the docstring's owner, path) of each ``hapstab.x.y`` a docstring names
    that does not exist, or that a :mod: role names and is not a module (``tree``: the
    source's, parsed already)."""
    out = []
    for line, text in _docstrings(tree or ast.parse(source)):
        for role, dotted in _DOTTED.findall(text):
            obj = _target(dotted)
            if obj is None or (role == "mod" and not isinstance(obj, types.ModuleType)):
                out.append((line, f":{role}:`{dotted}`" if role else dotted))
    return out


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SRC)))
def test_docstrings_name_only_what_exists(path):
    """Issue 28: a docstring that points at ``hapstab.x.y`` (a module, a function, a
    class or one of its attributes) points at something that exists under that name:
    renames and moves take the prose along."""
    rel = path.relative_to(SRC)
    missing = _missing_names(path.read_text(), _tree(path))
    assert not missing, f"{rel}: " + "; ".join(f"line {ln}: {n}" for ln, n in missing)


def test_the_docstring_check_sees_a_missing_name():
    source = ('"""See :mod:`~hapstab.engine.zoh` and :func:`hapstab.analysis.exact.core.nothing`;\n'
              'not :mod:`hapstab.loopfreq` nor hapstab.engine.nowhere.expm."""\n'
              'def f():\n'
              '    """:mod:`hapstab.paper_hve` is a function; '
              ':attr:`hapstab.results.CriticalStiffnessResult.critical_stiffness` a field."""\n')
    assert _missing_names(source) == [
        (1, ":func:`hapstab.analysis.exact.core.nothing`"), (1, ":mod:`hapstab.loopfreq`"),
        (1, "hapstab.engine.nowhere.expm"), (3, ":mod:`hapstab.paper_hve`")]


def _module_name(path: pathlib.Path, root: pathlib.Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_time_imports(tree: ast.Module):
    """The imports a module runs when it is imported: at module level, including under
    ``if``/``try``/``with``, but not inside a function or class body, nor under
    ``if TYPE_CHECKING:`` (for type checkers only: it never runs)."""
    todo = list(tree.body)
    while todo:
        node = todo.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, ast.If):
            if "TYPE_CHECKING" not in ast.unparse(node.test):
                todo += node.body
            todo += node.orelse
        elif isinstance(node, ast.Try):
            todo += node.body + node.orelse + node.finalbody + \
                [s for h in node.handlers for s in h.body]
        elif isinstance(node, (ast.With, ast.AsyncWith)):
            todo += node.body


def _import_graph(root: pathlib.Path) -> dict[str, set[str]]:
    """Module -> the package's modules it imports at import time (``from p import m``
    counts ``p`` and, when it is a module, ``p.m``; relative imports resolved). A parent
    package a dotted import runs on the way is not counted: it is never part of a cycle
    that the modules themselves do not make."""
    files = {_module_name(p, root): p for p in sorted(root.rglob("*.py"))}
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        out: set[str] = set()
        for node in _import_time_imports(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                out |= {a.name for a in node.names}
                continue
            base = here[:len(here) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            out |= {mod} | {f"{mod}.{a.name}" for a in node.names}
        graph[name] = {m for m in out if m in files and m != name}
    return graph


def _cycles(graph: dict[str, set[str]]) -> set[frozenset[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: set[frozenset[str]] = set()

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = {stack.pop()}
            while v not in comp:
                comp.add(stack.pop())
            if len(comp) > 1:
                found.add(frozenset(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


#: Import cycles the package has today (none): a new one fails the test below
KNOWN_CYCLES: set[frozenset[str]] = set()


def test_no_import_cycles():
    """Issue 28: the package's modules import each other at import time without a cycle
    (a cycle makes the import order matter and half-initialised modules possible);
    an import inside a function, run later, is the way to reach upwards when needed."""
    graph = _import_graph(SRC)
    assert len(graph) == len(MODULES) and sum(map(len, graph.values())) > 300
    found = _cycles(graph)
    assert found == KNOWN_CYCLES, "import cycles: " + "; ".join(
        " <-> ".join(sorted(c)) for c in found ^ KNOWN_CYCLES)


def test_the_cycle_finder_sees_a_cycle(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    files = {"__init__.py": "", "a.py": "from pkg.b import x\n",
             "b.py": "from . import c\nx = 1\n",
             "c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.b\n"
                     "def f():\n    import pkg.a\n",
             "sub/__init__.py": "", "sub/d.py": "from ..sub import e\n",
             "sub/e.py": "try:\n    import pkg.sub.d\nexcept ImportError:\n    pass\n"}
    for name, text in files.items():
        (pkg / name).write_text(text)
    graph = _import_graph(pkg)
    assert graph["pkg.a"] == {"pkg.b"} and graph["pkg.b"] == {"pkg", "pkg.c"}
    assert graph["pkg.c"] == set()        # under TYPE_CHECKING, inside a function: not run
    assert _cycles(graph) == {frozenset({"pkg.sub.d", "pkg.sub.e"})}
    (pkg / "c.py").write_text("import pkg.a\n")
    assert _cycles(_import_graph(pkg)) == {frozenset({"pkg.sub.d", "pkg.sub.e"}),
                                           frozenset({"pkg.a", "pkg.b", "pkg.c"})}
