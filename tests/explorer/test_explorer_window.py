"""The explorer's K-B window follows the answer (issue 29 item 8): for a 0.25 kg,
0.8 N·s/m device at 2 kHz with 10 ms of delay the best damping is B* = 22.3 N·s/m
(K* = 1320 N/m), but the region plot's window stayed at B <= 4b = 3.2 N·s/m, far from it.
The page now asks best-damping and sizes the window from its answer (static/window.js, a
pure function run here under node with the answer the explorer's API gives); the region
drawn in that window holds B* and K*."""

from __future__ import annotations

import json
import shutil
import subprocess

import pytest

pytest.importorskip("starlette")

import paths
from hapstab.explorer.api import check_request, run_command  # (after the skip)

STATIC = paths.ROOT / "src" / "hapstab" / "explorer" / "static"
NODE = shutil.which("node")
DEVICE = {"mass": 0.25, "damping": 0.8, "rate": "2kHz", "delay-s": "10ms"}


def api(command: str, options: dict) -> dict:
    """The explorer's answer to POST /api/v1/COMMAND (the same check and run)."""
    return json.loads(run_command(check_request(command, {"kind": "hve", "options": options})))


def window(kmax: float, K: float, B: float, b: float, best: dict | None) -> dict:
    if NODE is None:
        pytest.skip("node is not installed: window.js is run by the page's browser only")
    code = ("const W = require(process.argv[1]);"
            "const o = JSON.parse(require('fs').readFileSync(0, 'utf8'));"
            "console.log(JSON.stringify(W.kbWindow(o)));")
    out = subprocess.run([NODE, "-e", code, str(STATIC / "window.js")], check=True,
                         input=json.dumps({"kmax": kmax, "K": K, "B": B, "b": b, "best": best}),
                         capture_output=True, text=True)
    return {k: [float(x) for x in v.split(":")] for k, v in json.loads(out.stdout).items()}


@pytest.fixture(scope="module")
def answers():
    km = api("kmax", DEVICE)
    best = api("best-damping", DEVICE)
    return km, best


def test_the_window_holds_the_best_damping_and_every_stable_b(answers):
    km, best = answers
    Bs, Ks = best["virtual_damping"], best["critical_stiffness"]
    assert 20 < Bs < 25 and Ks > 10 * km["critical_stiffness"]      # the premise: far away
    old = window(km["critical_stiffness"], 100, 0, 0.8, None)
    assert old["B"][1] < Bs                                          # the old window missed it
    w = window(km["critical_stiffness"], 100, 0, 0.8, best)
    assert w["B"][0] <= 0 < Bs < w["B"][1] and w["K"] == [0, pytest.approx(1.2 * Ks, rel=1e-3)]
    c = best["curve"]
    stable = [b for b, k in zip(c["virtual_damping"], c["critical_stiffness"], strict=True)
              if k > 0]
    assert w["B"][0] < min(stable) and max(stable) < w["B"][1]
    # the user's own (K, B) stays inside, however far
    far = window(km["critical_stiffness"], 5000, 80, 0.8, best)
    assert far["B"][1] >= 160 and far["K"][1] >= 7500


def test_the_region_in_that_window_shows_the_peak(answers):
    km, best = answers
    w = window(km["critical_stiffness"], 100, 0, 0.8, best)
    region = api("region", {**DEVICE, "K": f"0:{w['K'][1]:g}",
                            "B": f"{w['B'][0]:g}:{w['B'][1]:g}", "resolution": 48,
                            "overlay": "none"})
    tops = [(r["virtual_damping"], max(hi for _, hi in r["stable_intervals"]))
            for r in region["rows"] if r["stable_intervals"]]
    B_top, K_top = max(tops, key=lambda t: t[1])
    # 48 rows over ~45 N·s/m: a row within 0.5 N·s/m of B*, where K_max(B) is flat to
    # ~1 % (1318.5, 1318.8, 1309.8 N/m at 21.7, 22.9, 24 N·s/m)
    assert abs(B_top - best["virtual_damping"]) < 1.0
    assert 0.98 * best["critical_stiffness"] <= K_top <= best["critical_stiffness"] * (1 + 1e-9)
    assert tops[0][0] > w["B"][0] and tops[-1][0] < w["B"][1]       # the region's ends inside


def test_the_page_asks_best_damping_and_sizes_the_window_with_it():
    js = (STATIC / "app.js").read_text()
    assert 'call("best-damping", "best-damping"' in js
    assert "HapstabWindow.kbWindow(" in js and "regionExtra(km, cur, best)" in js
    html = (STATIC / "index.html").read_text()
    assert html.index("static/window.js") < html.index("static/app.js")
