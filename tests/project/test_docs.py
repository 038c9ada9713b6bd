"""Every public function and class documents itself and each of its parameters (numpydoc).

The public API is what ``__all__`` lists in ``hapstab`` and in each subpackage. A
parameter counts as documented when its name appears in the docstring's "Parameters"
section (numpydoc's ``a, b : type`` lines name several); a class's parameters may also
be documented as "Attributes" (its fields). ``*args`` / ``**kwargs`` may appear under
any starred name (``**options``).
"""

from __future__ import annotations

import importlib
import inspect
import warnings

import pytest
from numpydoc.docscrape import NumpyDocString

PACKAGES = ["hapstab", "hapstab.models", "hapstab.engine", "hapstab.analysis",
            "hapstab.analysis.exact", "hapstab.analysis.network", "hapstab.simulation",
            "hapstab.paper"]


def _public() -> dict[str, object]:
    out: dict[str, object] = {}
    for pkg in PACKAGES:
        mod = importlib.import_module(pkg)
        for name in mod.__all__:
            obj = getattr(mod, name)
            if inspect.isfunction(obj) or inspect.isclass(obj):
                out.setdefault(f"{obj.__module__}.{obj.__qualname__}", obj)
    return out


PUBLIC = _public()


def _documented(doc: NumpyDocString, sections: tuple[str, ...]) -> set[str]:
    names: set[str] = set()
    for sec in sections:
        for p in doc[sec]:
            names.update(n.strip() for n in p.name.split(","))
    return names


def _parameters(obj: object) -> list[inspect.Parameter]:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):   # no introspectable signature
        return []
    return [p for p in sig.parameters.values() if p.name not in ("self", "cls")]


def test_public_api_is_found():
    assert len(PUBLIC) > 50
    assert "hapstab.simulation.run.simulate" in PUBLIC


@pytest.mark.parametrize("qualname", sorted(PUBLIC))
def test_documents_every_parameter(qualname):
    obj = PUBLIC[qualname]
    text = inspect.getdoc(obj)
    assert text and text.strip(), f"{qualname}: no docstring"
    with warnings.catch_warnings():
        # numpydoc warns on sections it does not know; the check below is what matters
        warnings.simplefilter("ignore")
        doc = NumpyDocString(text)
    sections = ("Parameters", "Other Parameters") + (("Attributes",) if inspect.isclass(obj) else ())
    have = _documented(doc, sections)
    starred = {n.lstrip("*") for n in have if n.startswith("**")}
    starred_args = {n.lstrip("*") for n in have if n.startswith("*") and not n.startswith("**")}
    missing = []
    for p in _parameters(obj):
        if p.kind is inspect.Parameter.VAR_KEYWORD:
            ok = bool(starred) or p.name in have
        elif p.kind is inspect.Parameter.VAR_POSITIONAL:
            ok = bool(starred_args) or p.name in have
        else:
            ok = p.name in have
        if not ok:
            missing.append(p.name)
    assert not missing, f"{qualname}: parameters not documented: {', '.join(missing)}"
