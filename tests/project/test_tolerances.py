"""Every tolerance has a reason written next to it (issue #10), checked on the source:
a small float literal (|x| < 1e-3, e.g. ``1e-12`` or ``0.0001``) in a code expression
carries a ``#`` comment on its own line or on the line directly above, unless it is the
value of a module-level UPPER_CASE constant with a comment on the line(s) above it
(the ``#:`` comments of :mod:`hapstab.tolerances` and of each module's named floors).
Literals in docstrings and messages are strings, and are not looked at."""

from __future__ import annotations

import ast
import io
import re
import tokenize

import paths

SRC = paths.ROOT / "src" / "hapstab"
MODULES = sorted(SRC.rglob("*.py"))

#: a literal below this in absolute value is a tolerance or a floor, and needs a reason
SMALL = 1e-3
_CONSTANT_NAME = re.compile(r"_?[A-Z][A-Z0-9_]*\Z")


def _small(node: ast.AST) -> bool:
    return (isinstance(node, ast.Constant) and isinstance(node.value, (float, complex))
            and 0 < abs(node.value) < SMALL)


def _named_constant(stmt: ast.stmt) -> bool:
    """Whether a module-level statement assigns UPPER_CASE name(s) only."""
    if isinstance(stmt, ast.Assign):
        targets = stmt.targets
    elif isinstance(stmt, ast.AnnAssign) and stmt.value is not None:
        targets = [stmt.target]
    else:
        return False
    names = []
    for t in targets:
        names += t.elts if isinstance(t, (ast.Tuple, ast.List)) else [t]
    return all(isinstance(n, ast.Name) and _CONSTANT_NAME.match(n.id) for n in names)


def uncommented_literals(source: str) -> list[tuple[int, str]]:
    """(line, literal) of each small float literal in ``source`` without a reason nearby.

    A reason is a ``#`` comment on the literal's line, a comment-only line directly
    above it, or a comment ending the line above when that line belongs to the same
    statement (a condition continued over two lines). The value of a module-level
    UPPER_CASE constant is exempt when a comment-only line directly precedes the
    assignment, and so is anything inside an f-string (a message).
    """
    lines = source.splitlines()
    comment_lines = {tok.start[0] for tok in tokenize.generate_tokens(io.StringIO(source).readline)
                     if tok.type == tokenize.COMMENT}

    def comment_only(n: int) -> bool:
        return 1 <= n <= len(lines) and lines[n - 1].lstrip().startswith("#")

    tree = ast.parse(source)
    exempt: set[int] = set()
    for node in ast.walk(tree):     # an f-string's fields are part of a message
        if isinstance(node, ast.JoinedStr):
            exempt |= {id(n) for n in ast.walk(node)}
    for stmt in tree.body:
        if _named_constant(stmt) and comment_only(stmt.lineno - 1):
            exempt |= {id(n) for n in ast.walk(stmt)}
    # the innermost statement holding each line (for comments continued from the line above)
    start_of: dict[int, int] = {}
    for stmt in sorted((n for n in ast.walk(tree) if isinstance(n, ast.stmt)),
                       key=lambda s: s.lineno):
        for n in range(stmt.lineno, (stmt.end_lineno or stmt.lineno) + 1):
            start_of[n] = stmt.lineno

    out = []
    for node in ast.walk(tree):
        if not _small(node) or id(node) in exempt:
            continue
        n = node.lineno
        same_statement = start_of.get(n, n) < n
        if n in comment_lines or comment_only(n - 1) or (same_statement and n - 1 in comment_lines):
            continue
        out.append((n, ast.get_source_segment(source, node) or repr(node.value)))
    return sorted(out)


def test_every_small_literal_has_a_reason():
    missing = []
    for path in MODULES:
        rel = path.relative_to(SRC)
        missing += [f"{rel}:{n}: {lit}" for n, lit in uncommented_literals(path.read_text())]
    assert not missing, "tolerances without a reason beside them:\n" + "\n".join(missing)


def test_the_check_sees_a_bare_literal():
    bare = "def f(x):\n    return abs(x) < 1e-9\n"
    assert uncommented_literals(bare) == [(2, "1e-9")]
    assert uncommented_literals("y = -0.0001 * 3\n") == [(1, "0.0001")]
    assert uncommented_literals("Y = 1e-9\n") == [(1, "1e-9")]          # a name, no reason
    assert uncommented_literals("x = 1\ny = 2  # about x\nz = 1e-9\n") == [(3, "1e-9")]


def test_the_check_accepts_a_reason():
    assert uncommented_literals("def f(x):\n    return abs(x) < 1e-9  # rounding\n") == []
    assert uncommented_literals("# rounding of x\ny = 1e-9 * x\n") == []
    assert uncommented_literals("#: rounding of x\nTOL = 1e-9\n") == []
    assert uncommented_literals("#: the floors\nLO, HI = (1e-14,\n          1e10)\n") == []
    assert uncommented_literals("ok = (a < 1  # rounding\n      and b < 1e-9)\n") == []
    assert uncommented_literals('"""1e-9 in a docstring"""\nmsg = "below 1e-9"\n') == []
    assert uncommented_literals('msg = f"{x:.3g} > {1e-9 * x:.3g}"\n') == []
    assert uncommented_literals("x = 1e-3 + 0.5\n") == []              # not below 1e-3
