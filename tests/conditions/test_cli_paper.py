"""CLI of the paper's method: kmax --method circle|passivity, passivity, audit;
--json prints exactly one JSON object; bad input is one line on stderr, exit 2."""

import json

import pytest
from click.testing import CliRunner

from hapstab.cli.main import cli


def run(*args):
    return CliRunner().invoke(cli, list(args))


def one_json(res):
    assert res.exit_code == 0, res.stderr
    return json.loads(res.stdout)  # fails unless stdout is exactly one JSON document


@pytest.mark.parametrize("args,K", [
    (("kmax", "hve", "--method", "circle", "-n", "10"), 9.5238),
    (("kmax", "hve", "--method", "passivity", "-b", "1", "-B", "0.5", "-n", "1"), 732.05),
    (("kmax", "peb", "--method", "circle"), 20.0),
    (("kmax", "peb", "--method", "circle", "-n", "4"), 4.0),
    (("kmax", "hve", "--method", "circle", "-n", "10", "--approximation", "tustin"), 10.0),
])
def test_kmax(args, K):
    d = one_json(run(*args, "--json"))
    # quoted to 4-5 significant digits in the issue
    assert d["critical_stiffness"] == pytest.approx(K, abs=0.005)
    for key in ("method", "stable_intervals", "reason", "period_s", "delay_samples",
                "crossing_frequency_hz"):
        assert key in d


def test_kmax_backward_without_delay_is_inf():
    d = one_json(run("kmax", "hve", "--method", "circle", "--approximation", "backward", "--json"))
    assert d["critical_stiffness"] is None and d["infinite"] == {"critical_stiffness": 1,
                                                                  "stable_intervals/0/1": 1}


@pytest.mark.parametrize("K,verdict", [("150", "positive real"), ("250", "not positive real")])
def test_passivity_circle(K, verdict):
    d = one_json(run("passivity", "hve", "--stiffness", K, "--method", "circle", "--json"))
    assert d["verdict"] == verdict
    for key in ("margin", "worst_frequency_rad_s", "worst_frequency_hz", "failed_condition"):
        assert key in d
    if verdict != "positive real":
        # Re G^-1 = b - KT/2 at n = 0: twice that is the smallest eigenvalue of G + G^H
        assert d["failed_condition"] == "hermitian part"
        assert d["margin"] == pytest.approx(2 * (0.1 - 250e-3 / 2), abs=1e-9)


def test_passivity_exact_peb():
    d = one_json(run("passivity", "peb", "-K", "10", "--method", "passivity", "--json"))
    assert d["verdict"] == "passive" and d["failed_condition"] is None
    # two-port, n = 0, B = 0: eigenvalues b and b - KT = 0.01 N*s/m
    assert d["margin"] == pytest.approx(0.01, abs=1e-12)


def test_tables_print():
    # the readable tables carry the same verdicts as the JSON
    verdict = one_json(run("passivity", "peb", "-K", "3", "-n", "4", "--json"))["verdict"]
    for args, needle in ((("passivity", "peb", "-K", "3", "-n", "4"), verdict),
                         (("audit", "hve", "-n", "10"), "eq. (18)"),
                         (("kmax", "peb", "--method", "passivity"), "20 N/m")):
        res = run(*args)
        assert res.exit_code == 0 and needle in res.stdout and not res.stderr
    # "passive" is also inside "not passive": the table says which one
    table = run("passivity", "peb", "-K", "3", "-n", "4").stdout
    assert ("not passive" in table) == (verdict == "not passive")
    assert verdict in ("passive", "not passive") and "N*s/m" in table


def test_passivity_speaks_of_passivity_by_default():
    # issue #12: `passivity -K 2000` said "not positive real" and "margin -10" (no unit)
    d = one_json(run("passivity", "hve", "-K", "2000", "--json"))
    assert d["verdict"] == "not passive" and d["method"] == "passivity"
    table = run("passivity", "hve", "-K", "2000").stdout
    assert "not passive" in table and "N*s/m (damping missing)" in table
    assert "positive real" not in table


def test_audit_json():
    d = one_json(run("audit", "peb", "-B", "0.005", "--json"))
    assert "eq34" in d["flagged"] and d["loop"] == "peb"


@pytest.mark.parametrize("args", [
    ("kmax", "hve", "--method", "circle", "--approximation", "euler"),
    ("kmax", "peb", "--method", "colgate"),
    ("passivity", "hve", "-K", "-1"),
    ("passivity", "hve", "-K", "10", "--method", "magic"),
    ("passivity", "hve", "-K", "10", "--method", "passivity", "--approximation", "tustin"),
    ("passivity", "hve"),
    ("passivity", "hve", "-K", "10", "--sector", "0"),
    ("audit", "hve", "-T", "0"),
    ("audit", "peb", "--operator", "spring:x"),
])
def test_bad_input_is_one_line_exit_2(args):
    res = run(*args, "--json")
    assert res.exit_code == 2
    # with --json the error is also one JSON object on stdout (issue #12), for tools
    err = json.loads(res.stdout)
    assert err["exit_code"] == 2 and "hapstab: error: " + err["error"] == res.stderr.strip()
    assert err["inputs"]["command_line"] == ["hapstab", *args, "--json"]
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hapstab: error:") and "Traceback" not in res.stderr


def test_the_margin_names_its_unit_with_and_without_a_sector():
    """G^-1 (and sampled passivity) is an impedance, its margin damping in N*s/m; with a
    finite sector the test is on G + 1/k, an admittance."""
    plain = run("passivity", "hve", "-K", "50", "--method", "circle")
    sector = run("passivity", "hve", "-K", "50", "--method", "circle", "--sector", "100")
    assert plain.exit_code == sector.exit_code == 0
    assert "N*s/m (damping" in plain.stdout and "m/(N*s)" not in plain.stdout
    assert "m/(N*s) (admittance of G + 1/k" in sector.stdout
