"""CLI of regions, best damping and the delay options, through the runner."""

import json

import pytest
from click.testing import CliRunner

from hapstab.cli.main import cli
from reference_data import ref


def run(*args):
    return CliRunner().invoke(cli, list(args))


def test_region_json_plot_csv(tmp_path):
    png, csv = tmp_path / "r.png", tmp_path / "r.csv"
    r = run("region", "hve", "--delay", "10", "--K", "0:900", "--B", "0:20", "--resolution", "20",
            "--plot", str(png), "--csv", str(csv), "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["rows"][0]["stable_intervals"][0][1] == pytest.approx(9.5361, rel=1e-4)
    assert d["agreement"]["disagree"] == 0
    assert png.stat().st_size > 5000 and csv.stat().st_size > 0


def test_region_b_window_through_zero(tmp_path):
    png = tmp_path / "neg.png"
    r = run("region", "hve", "--delay", "10", "--K", "0:900", "--B", "-2:20", "--resolution", "20",
            "--plot", str(png), "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["B_range"] == [-2.0, 20.0] and d["rows"][0]["virtual_damping"] == -2.0
    assert d["rows"][0]["stable_intervals"] == []          # |B| > b: unstable for every K
    assert d["agreement"]["disagree"] == 0 and png.stat().st_size > 5000


def test_best_damping_min_damping():
    d = json.loads(run("best-damping", "hve", "--delay", "10", "--min-damping", "0", "--json").stdout)
    assert d["curve"]["virtual_damping"][0] == 0.0
    assert d["virtual_damping"] == pytest.approx(12.61, rel=1e-3)
    d = json.loads(run("best-damping", "hve", "--delay", "10", "--json").stdout)
    assert d["curve"]["virtual_damping"][0] < 0             # both signs searched by default


def test_best_damping_json():
    r = run("best-damping", "hve", "--delay", "10", "--json")
    d = json.loads(r.stdout)
    assert r.exit_code == 0 and d["virtual_damping"] == pytest.approx(12.61, rel=1e-3)


def test_delay_options():
    a = json.loads(run("kmax", "hve", "--delay-s", "0.010", "--json").stdout)["critical_stiffness"]
    b = json.loads(run("kmax", "hve", "--delay", "10", "--json").stdout)["critical_stiffness"]
    assert a == b
    c = json.loads(run("kmax", "hve", "--delay-s", "0.0105", "--json").stdout)["critical_stiffness"]
    assert c < b
    d = json.loads(run("kmax", "peb", "--delay-forward", "2", "--delay-backward", "6",
                       "--json").stdout)["critical_stiffness"]
    k, rel = ref("peb_forward2_backward6_kmax")
    assert d == pytest.approx(k, rel=rel)


@pytest.mark.parametrize("args,needle", [
    (("kmax", "hve", "--delay", "3", "--delay-s", "0.01"), "give one of them"),
    (("kmax", "peb", "--delay-s", "0.01", "--delay-forward", "2"), "one way"),
    (("kmax", "hve", "--delay-s", "-1"), "must be >= 0"),
    (("region", "hve", "--K", "5:1", "--B", "0:1"), "--K = '5:1'"),
    (("region", "hve", "--K", "0:x", "--B", "0:1"), "--K = '0:x': 'x' is not a number"),
    (("region", "hve", "--K", "0:10", "--B", "0:1", "--overlay", "magic"), "--overlay = 'magic'"),
    (("region", "hve", "--K", "-1:10", "--B", "0:1"), "--K = '-1:10': every value must be "
                                                      "finite and >= 0; allowed: start:stop"),
    (("region", "hve", "--K", "0:10", "--B", "1:-1"), "--B = '1:-1': the range is empty "
                                                      "(stop <= start)"),
    (("best-damping", "hve", "--min-damping", "0.5"), "--min-damping = 0.5: must be <= 0"),
    (("best-damping", "hve", "--max-damping", "0"), "'--max-damping': '0': must be > 0"),
])
def test_errors_one_line_exit_2(args, needle):
    r = run(*args)
    assert r.exit_code == 2 and len(r.stderr.strip().splitlines()) == 1 and needle in r.stderr


def test_region_of_rigid_body_peb_and_asymmetric_plot(tmp_path):
    d = json.loads(run("region", "peb", "--operator", "none", "--environment", "none", "--K", "0:50",
                       "--B", "0:0.1", "--resolution", "30", "--json").stdout)
    assert d["agreement"]["disagree"] == 0          # the rigid-body pole is divided out
    png = tmp_path / "a.png"
    r = run("region", "peb", "--delay-forward", "2", "--delay-backward", "6", "--K", "0:50",
            "--B", "0:0.1", "--resolution", "20", "--plot", str(png))
    assert r.exit_code == 0 and png.stat().st_size > 5000


def test_an_undamped_mode_on_the_boundarys_angle_grid_is_a_gap_not_a_crash():
    """A 1e6 kg device on the 1 N/m operator, no damping: its open-loop mode sits at
    theta = sqrt(k/m) T = 1e-6, the D-decomposition's first angle, where zI - A0 is
    singular to working precision (numpy raised LinAlgError: an internal error, found by
    a session-13 hostile run). G has a pole there: the boundary skips that angle."""
    r = CliRunner().invoke(cli, ["region", "hve", "--K", "0:100", "--B", "0:1", "--resolution",
                                 "12", "--damping", "0", "--mass", "1e6", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert d["rows"][0]["stable_intervals"] == []          # B = 0, b = 0: nothing stable
    assert d["rows"][1]["stable_intervals"] == [[0.0, 100.0]]
