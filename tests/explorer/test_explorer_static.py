"""The explorer's page files: shipped in the package, offline, the vendored uPlot unchanged.

The page must work with no network (no CDN, no web font) and must be installed with the
package: every file under ``hapstab/explorer/static`` is read here through
:mod:`importlib.resources` and matched by a ``[tool.setuptools.package-data]`` pattern of
pyproject.toml (a file no pattern matches would be missing from ``pip install .``).
"""

from __future__ import annotations

import fnmatch
import hashlib
import importlib.resources
import re
import sys

import paths

if sys.version_info >= (3, 11):
    import tomllib
else:                                    # pragma: no cover - Python 3.10
    import tomli as tomllib

ROOT = paths.ROOT
STATIC = importlib.resources.files("hapstab.explorer") / "static"
PAGE = ("index.html", "app.js", "plots.js", "window.js", "network.js", "app.css")
VENDOR = ("uPlot.iife.min.js", "uPlot.min.css", "uPlot.LICENSE", "README.md")


def _files(d, prefix: str = "") -> list[str]:
    out = []
    for p in d.iterdir():
        if p.is_dir():
            out += _files(p, f"{prefix}{p.name}/")
        else:
            out.append(prefix + p.name)
    return sorted(out)


def test_the_page_and_the_vendored_library_are_package_resources():
    files = _files(STATIC)
    assert set(PAGE) <= set(files)
    assert {f"vendor/{v}" for v in VENDOR} <= set(files)
    for name in files:
        assert (STATIC / name).read_bytes(), name


def test_package_data_ships_every_static_file():
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())
    patterns = conf["tool"]["setuptools"]["package-data"]["hapstab"]
    for name in _files(STATIC):
        path = f"explorer/static/{name}"
        # setuptools' globs: '*' stays within one folder
        assert any(fnmatch.fnmatch(path, p) and path.count("/") == p.count("/")
                   for p in patterns), f"{path} is matched by no package-data pattern"


def test_the_vendored_files_are_the_ones_the_readme_names():
    readme = (STATIC / "vendor" / "README.md").read_text()
    version = re.search(r"uPlot (\d+\.\d+\.\d+)", readme).group(1)
    js = (STATIC / "vendor" / "uPlot.iife.min.js").read_text()
    assert js.startswith(f"/*! https://github.com/leeoniya/uPlot (v{version}) */")
    for name in ("uPlot.iife.min.js", "uPlot.min.css"):
        digest = hashlib.sha256((STATIC / "vendor" / name).read_bytes()).hexdigest()
        assert f"→ `{name}`\n    (sha256 {digest})" in readme, name
    assert "MIT License" in (STATIC / "vendor" / "uPlot.LICENSE").read_text()


def test_the_page_works_offline_and_its_references_exist():
    html = (STATIC / "index.html").read_text()
    refs = re.findall(r'(?:src|href)="([^"]+)"', html)
    assert refs
    for ref in refs:
        if ref.startswith("data:"):
            continue
        assert not re.match(r"^[a-z]+:|^//", ref), f"external reference {ref}"
        assert ref.startswith("static/") and (STATIC / ref.removeprefix("static/")).is_file(), ref
    for name in PAGE:
        text = (STATIC / name).read_text()
        # no CDN, no web font, no absolute address (relative to the page: works behind a prefix)
        assert not re.search(r"https?://|@import|@font-face|url\(", text), name
        assert '"/api' not in text and "'/api" not in text, name
    js = (STATIC / "vendor" / "uPlot.iife.min.js").read_text()
    # the library's only address is its own banner; it loads nothing
    assert re.findall(r"https?://[^\s\"')]+", js) == ["https://github.com/leeoniya/uPlot"]


def test_the_page_asks_the_api_the_contract_names():
    js = (STATIC / "app.js").read_text()
    assert 'const API = "api/v1/"' in js
    for header in ("X-Hapstab-Channel", "X-Hapstab-Seq", "AbortController", "history.replaceState"):
        assert header in js, header
    for command in ("kmax", "check", "audit", "passivity", "simulate", "boundary", "region", "code"):
        assert f'"{command}"' in js, command
