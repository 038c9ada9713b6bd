"""Sphinx configuration of hapstab's documentation (``make docs``: offline, warnings are errors)."""

from __future__ import annotations

import os
import re
import shutil

from sphinx_gallery.scrapers import figure_rst

import hapstab

project = "hapstab"
author = "the hapstab authors"
release = version = hapstab.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx_click",
    "sphinx_gallery.gen_gallery",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "reference/generated/*.md", "gallery/*.ipynb",
                    "gallery/*.py", "gallery/*.zip", "gallery/*.md5"]
html_theme = "furo"
html_title = "hapstab"
# plain text unless a block names its language (```python, ```toml): console sessions,
# tables and equations in ``` blocks are not Python
highlight_language = "none"

# headings get anchors so that pages can link to a section (guide/networks.md#delay-ranges)
myst_heading_anchors = 3

# the API reference: one page per public name (hapstab.__all__), generated at build time
autosummary_generate = True
autosummary_imported_members = True
# signatures without annotations: the numpydoc "Parameters" sections carry the types, and
# annotations name private module paths (hapstab.models.loops.HapticLoop) that are
# documented under their public name, which nitpicky mode would report as unresolved
autodoc_typehints = "none"
autodoc_default_options = {"members": False}
# members are listed by the class template (reference/_templates), not by numpydoc
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
# numpydoc's validation is tests/project/test_docs.py's job; here only the rendering
numpydoc_validation_checks: set[str] = set()
templates_path = ["reference/_templates"]

# every reference must resolve (unresolved ones are warnings, and -W makes them errors)
nitpicky = True
# targets outside hapstab: there is no offline inventory of Python's, NumPy's or click's
# documentation (intersphinx would need the network), so these names stay plain text
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|scipy|matplotlib|click|control|pyarrow|dask|mpmath|flint)(\..*)?"),
    (r"py:.*", r"(float|int|str|bool|bytes|dict|list|tuple|object|callable|None|Exception)"),
]


# the gallery: the scripts of examples/ run at build time (sphinx-gallery), each writing its
# figures with save_plot into FIGURES (its first argument); the scraper below shows the
# figures a block wrote right after that block's code and printed output
DOCS = os.path.dirname(os.path.abspath(__file__))
FIGURES = os.path.join(DOCS, "_build", "gallery-figures")


class _SavedFigures:
    """sphinx-gallery's image scraper for figures written to files (save_plot closes its
    figure, so the matplotlib scraper would find none): the PNGs that appeared or changed
    in :data:`FIGURES` while a block ran, in the order they were written."""

    def __init__(self) -> None:
        self.seen: dict[str, float] = {}

    def __repr__(self) -> str:        # sphinx-gallery caches its configuration by repr
        return "SavedFigures"

    def __call__(self, block, block_vars, gallery_conf) -> str:
        if not os.path.isdir(FIGURES):
            return ""
        new = []
        for name in os.listdir(FIGURES):
            path = os.path.join(FIGURES, name)
            mtime = os.path.getmtime(path)
            if name.endswith(".png") and self.seen.get(path) != mtime:
                self.seen[path] = mtime
                new.append((mtime, path))
        shown = []
        for _, path in sorted(new):
            target = next(block_vars["image_path_iterator"])
            shutil.copyfile(path, target)
            shown.append(target)
        return figure_rst(shown, gallery_conf["src_dir"])


def _figures_folder(gallery_conf, script_vars) -> list[str]:
    """The example's command line: the folder its figures go to."""
    os.makedirs(FIGURES, exist_ok=True)
    return [FIGURES]


# the gallery's configuration holds callables, which Sphinx cannot pickle to decide whether
# a later build may reuse this one's environment: it rebuilds instead (what `make docs`
# does anyway), so the warning that says so is not a problem of the docs
suppress_warnings = ["config.cache"]

sphinx_gallery_conf = {
    "examples_dirs": os.path.join(DOCS, "..", "examples"),
    "gallery_dirs": os.path.join(DOCS, "gallery"),
    "filename_pattern": r"\.py$",              # run every example, not only plot_*.py
    "image_scrapers": (_SavedFigures(),),
    "reset_argv": _figures_folder,
    "abort_on_example_error": True,           # a failing example fails the build
    "download_all_examples": False,
    "show_memory": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "write_computation_times": False,
}


def _resolve(name: str, module: str | None) -> bool:
    """Whether ``name`` (absolute, or relative to ``module``) is a real hapstab object."""
    import importlib

    for full in ([name] if name.startswith("hapstab") else []) + (
            [f"{module}.{name}"] if module else []):
        parts = full.split(".")
        for cut in range(len(parts), 0, -1):
            try:
                obj: object = importlib.import_module(".".join(parts[:cut]))
            except ImportError:
                continue
            try:
                for attr in parts[cut:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                break
            return True
    return False


def _internal_reference(app, env, node, contnode):
    """Let a docstring name hapstab's internals (modules, private helpers) as plain text.

    The API reference documents ``hapstab.__all__`` only; a docstring may still point a
    reader of the code at ``hapstab.budget`` or ``engine.structure.rigid_modes``. Such a
    reference is accepted when the object really exists (imported here), so a reference to
    a module or function that no longer exists stays an error under ``-W``.
    """
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~.")
    # a relative name is looked up beside the object whose docstring holds it
    # (docutils records "docstring of hapstab.analysis.conditions.frequency_grid.theta_grid" as the source)
    owner = re.search(r"docstring of ([\w.]+)", node.source or "")
    scopes = [node.get("py:module")]
    if owner:
        parts = owner.group(1).split(".")
        scopes += [".".join(parts[:cut]) for cut in range(len(parts), 0, -1)]
    if any(_resolve(target, scope) for scope in scopes):
        return contnode
    return None


_LITERAL = re.compile(r"(``.*?``)")
_BARS = re.compile(r"(?<![\\`|])\|(?=\S)([^|\n]*?\S)\|(?![|`])")


def _escape_bars(text: str) -> str:
    """``|z|`` (a modulus, as docstrings write it) as text, not a reST substitution."""
    pieces = _LITERAL.split(text)
    return "".join(p if p.startswith("``") else _BARS.sub(r"\\|\1\\|", p) for p in pieces)


def _docstring(app, what, name, obj, options, lines) -> None:
    lines[:] = [_escape_bars(line) for line in lines]


def _click_text(app, ctx, lines) -> None:
    # help texts are plain text: N*s/m is a unit, not the start of an emphasis
    lines[:] = [_escape_bars(line).replace("*", "\\*") for line in lines]


def setup(app) -> None:
    app.connect("missing-reference", _internal_reference)
    app.connect("autodoc-process-docstring", _docstring)
    app.connect("sphinx-click-process-description", _click_text)
    app.connect("sphinx-click-process-options", _click_text)
