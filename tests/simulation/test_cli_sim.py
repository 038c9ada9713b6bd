"""CLI of the simulation feature through click's runner: exit codes, JSON on
stdout, one-line errors on stderr, files written."""

import json
import math

import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.analysis.exact.core import stability
from hapstab.cli.main import cli


def run(args):
    return CliRunner().invoke(cli, args)


def test_simulate_hve_json_agrees_with_exact(tmp_path):
    csv_path, png = tmp_path / "r.csv", tmp_path / "r.png"
    r = run(["simulate", "hve", "-K", "9", "-n", "10", "--duration", "3", "--force", "sine:1,2",
             "--csv", str(csv_path), "--plot", str(png), "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    ex = stability(h.paper_hve(1e-3, 10, 9.0))
    assert d["verdict"] == "bounded" and d["linear_loop_verdict"] == ex.verdict == "stable"
    # rate fitted from the trajectory vs the exact dominant pole (noise-free data)
    assert d["growth_rate_per_s"] == pytest.approx(math.log(ex.spectral_radius) / 1e-3, rel=1e-6)
    assert d["samples"] == 3000
    assert csv_path.stat().st_size > 0 and png.stat().st_size > 0


def test_simulate_peb_unstable_and_table():
    r = run(["simulate", "peb", "-K", "30", "-n", "0", "--duration", "2"])
    assert r.exit_code == 0, r.output
    assert "unbounded" in r.stdout and "unstable" in r.stdout


def test_simulate_nonlinear_options():
    r = run(["simulate", "hve", "-K", "100", "-b", "2", "--wall", "0.001", "--saturation", "5",
             "--resolution", "1e-5", "--duration", "1", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert d["nonlinear"] == {"wall": 0.001, "saturation": 5.0, "resolution": 1e-5,
                              "quantizer": "floor"}
    assert d["max_abs_force_device"] <= 5.0


@pytest.mark.parametrize("args,word", [
    (["simulate", "hve", "-K", "1", "--force", "ramp:1"], "force"),
    (["simulate", "hve", "--duration", "1"], "stiffness"),
    (["simulate", "hve", "-K", "1", "--duration", "0.001"], "duration"),
    (["simulate", "peb", "-K", "1", "--environment-force", "sine:x"], "environment_force"),
    (["reproduce", "fig9"], "fig9"),
    (["reproduce", "fig5", "--periods", "0.002:0.001:3"], "--period"),
])
def test_errors_are_one_line_exit_2(args, word):
    r = run(args)
    assert r.exit_code == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hapstab: error:") and word in lines[0]


def test_reproduce_json_reduced_grid(tmp_path):
    r = run(["reproduce", "all", "--out", str(tmp_path), "--periods", "0.003,0.008", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)          # --json: nothing but the JSON object on stdout
    assert [f["figure"] for f in d["figures"]] == ["fig5", "fig6"]
    assert len(d["files"]) == 7 and d["worst_simulation_error"] < 0.01
    assert d["files"][-1].endswith("manifest.json")       # written last, naming the run
    man = json.loads((tmp_path / "manifest.json").read_text())
    assert man["figure"] == "all" and man["periods_s"] == [0.003, 0.008]
    assert man["files"] == [f"fig{k}.{e}" for k in (5, 6) for e in ("csv", "png", "svg")]
    for name in ("fig5", "fig6"):
        for ext in ("csv", "png", "svg"):
            assert (tmp_path / f"{name}.{ext}").stat().st_size > 0


def test_reproduce_table_lists_files(tmp_path):
    r = run(["reproduce", "fig5", "--out", str(tmp_path), "--periods", "0.004"])
    assert r.exit_code == 0, r.output
    assert "(13)" in r.stdout and "(18)" in r.stdout and "fig5.svg" in r.stdout
