"""PEB with unequal controllers from the command line (--slave-stiffness-ratio,
--slave-virtual-damping) through click's runner: every command that builds a PEB loop,
checked against the Python API and the independent brute force (tests/brute.py)."""

import json

import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli
from references import brute

UNEQUAL = ("--slave-stiffness-ratio", "2", "--slave-virtual-damping", "-0.003")


def run(*args):
    return CliRunner().invoke(cli, list(args))


def ok_json(r):
    assert r.exit_code == 0, r.stderr
    assert r.stderr == ""
    return json.loads(r.stdout)


def paper_unequal(K=1.0, n=0, T=1e-3, ratio=2.0, B=0.0, B_s=-0.003):
    dev = h.Device(0.015, 0.02)
    return h.TeleoperationLoop(dev, dev, h.SpringDamper(K, B), h.SpringDamper(ratio * K, B_s),
                               "spring:1", "spring:1", T, n)


def test_kmax_unequal_equals_api_and_brute_force():
    d = ok_json(run("kmax", "peb", *UNEQUAL, "--json"))
    api = h.critical_stiffness(paper_unequal()).critical_stiffness
    assert d["critical_stiffness"] == api
    ref = brute.kmax(brute.peb(0.015, 0.02, 0.015, 0.02, ((1,), (1, 0)), ((1,), (1, 0)), 0, 0.0, 1e-3,
                               ratio=2.0, B_s=-0.003))
    # brute-force bisection on float eigenvalues: ~1e-9, 1e-6 leaves margin
    assert d["critical_stiffness"] == pytest.approx(ref, rel=1e-6)
    # and the options matter: equal controllers give a different K_max
    assert abs(ok_json(run("kmax", "peb", "--json"))["critical_stiffness"] / ref - 1) > 0.1


def test_slave_damping_defaults_to_virtual_damping():
    a = ok_json(run("kmax", "peb", "-B", "-0.002", "--slave-stiffness-ratio", "1", "--json"))
    b = ok_json(run("kmax", "peb", "-B", "-0.002", "--slave-virtual-damping", "-0.002", "--json"))
    c = ok_json(run("kmax", "peb", "-B", "-0.002", "--json"))
    assert a["critical_stiffness"] == b["critical_stiffness"] == c["critical_stiffness"]
    assert c["critical_stiffness"] == pytest.approx(
        h.critical_stiffness(h.paper_peb(damping=-0.002)).critical_stiffness, rel=1e-15)


@pytest.mark.parametrize("K", [3.0, 15.0])
def test_check_unequal(K):
    d = ok_json(run("check", "peb", "-K", str(K), *UNEQUAL, "--json"))
    ref = h.stability(paper_unequal(K))
    assert d["verdict"] == ref.verdict and d["spectral_radius"] == ref.spectral_radius
    mk = brute.peb(0.015, 0.02, 0.015, 0.02, ((1,), (1, 0)), ((1,), (1, 0)), 0, 0.0, 1e-3,
                   ratio=2.0, B_s=-0.003)
    assert (brute.spectral_radius(mk, K) < 1) == (d["verdict"] == "stable")


def test_boundary_unequal():
    d = ok_json(run("boundary", "peb", "--period", "0.001:0.002:2", "--delay", "0,4", *UNEQUAL,
                    "--json"))
    api = h.boundary(paper_unequal(), [1e-3, 2e-3], [0, 4]).critical_stiffness
    assert d["critical_stiffness"] == [list(map(float, row)) for row in api]


@pytest.mark.parametrize("method", ["circle", "passivity"])
def test_passivity_and_kmax_methods_unequal(method):
    d = ok_json(run("passivity", "peb", "-K", "5", "--method", method, *UNEQUAL, "--json"))
    loop = paper_unequal(5.0)
    if method == "circle":
        from hapstab.analysis.conditions.circle import circle_test
        assert d["positive_real"] == circle_test(loop).positive_real
    else:
        from hapstab.analysis.conditions.passivity import sampled_passivity
        assert d["margin"] == sampled_passivity(loop).margin
    k = ok_json(run("kmax", "peb", "--method", method, *UNEQUAL, "--json"))
    assert k["critical_stiffness"] == h.critical_stiffness(paper_unequal(), method=method).critical_stiffness


def test_audit_unequal_lists_no_paper_lines():
    d = ok_json(run("audit", "peb", "--delay", "2", *UNEQUAL, "--json"))
    keys = {r["key"] for r in d["rows"]}
    assert not keys & {"eq29", "eq34"}          # derived for C_m = C_s: not applicable
    assert d["exact_kmax"] == h.critical_stiffness(paper_unequal(n=2)).critical_stiffness


def test_simulate_unequal():
    d = ok_json(run("simulate", "peb", "-K", "3", "--duration", "1", *UNEQUAL, "--json"))
    assert d["linear_loop_spectral_radius"] == h.stability(paper_unequal(3.0)).spectral_radius
    assert d["verdict"] == "bounded" and d["linear_loop_verdict"] == "stable"


@pytest.mark.parametrize("args,needle", [
    (("kmax", "peb", "--slave-stiffness-ratio", "0"), "'--slave-stiffness-ratio': '0': must be > 0"),
    (("check", "peb", "-K", "1", "--slave-stiffness-ratio", "-2"),
     "'--slave-stiffness-ratio': '-2': must be > 0"),
    (("simulate", "peb", "-K", "1", "--slave-stiffness-ratio", "nan"),
     "'--slave-stiffness-ratio': 'nan': must be finite"),
    (("audit", "peb", "--slave-stiffness-ratio", "two"), "'--slave-stiffness-ratio': 'two' is not a number"),
    (("kmax", "peb", "--slave-virtual-damping", "inf"), "'--slave-virtual-damping': 'inf': must be finite"),
    (("boundary", "peb", "--slave-virtual-damping", "x"), "'--slave-virtual-damping': 'x' is not a number"),
    (("kmax", "peb", "--slave-stiffness-ratio", "2", "--method", "eq34"), "derived for C_m = C_s"),
    (("region", "peb", "--K", "0:10", "--B", "0:1", "--slave-stiffness-ratio", "2"),
     "--slave-stiffness-ratio = 2: a K-B region / best damping is defined for C_m = C_s; allowed"),
    (("best-damping", "peb", "--slave-virtual-damping", "0.1"),
     "--slave-virtual-damping = 0.1: a K-B region / best damping is defined for C_m = C_s"),
    (("kmax", "hve", "--slave-stiffness-ratio", "2"), "No such option"),
])
def test_bad_slave_options_are_one_line_and_exit_2(args, needle):
    r = run(*args)
    assert r.exit_code == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hapstab: error: ") and needle in lines[0]
    assert r.stdout == "" and "Traceback" not in r.stderr


def test_help_lists_the_slave_options():
    for cmd in ("kmax", "check", "boundary", "passivity", "audit", "simulate", "region", "best-damping"):
        r = run(cmd, "peb", "--help")
        assert r.exit_code == 0 and "--slave-stiffness-ratio" in r.stdout
        assert "--slave-virtual-damping" in r.stdout, cmd
