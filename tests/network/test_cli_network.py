"""``hapstab kmax ... --loss P [--burst L]`` (issue 30): the CLI gives the library's answer."""

import json

import pytest
from click.testing import CliRunner

from hapstab import paper_hve, paper_peb
from hapstab.analysis.network import loss_critical_stiffness
from hapstab.cli.main import cli


def _run(*args):
    return CliRunner().invoke(cli, list(args))


def test_kmax_loss_is_the_librarys():
    r = _run("kmax", "hve", "--delay", "2", "--loss", "0.05", "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    want = loss_critical_stiffness(paper_hve(delay_samples=2), 0.05)
    assert d["critical_stiffness"] == want.critical_stiffness and d["method"] == "mean-square"


def test_kmax_burst_peb_and_curve():
    r = _run("kmax", "peb", "--delay", "1", "--loss", "0.1", "--burst", "3", "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["critical_stiffness"] == loss_critical_stiffness(
        paper_peb(delay_samples=1), 0.1, 3.0).critical_stiffness
    r = _run("kmax", "hve", "--loss", "0:0.2:3", "--json")
    assert r.exit_code == 0, r.stderr
    c = json.loads(r.stdout)
    assert c["losses"] == [0.0, 0.1, 0.2] and c["certified"] == [True, False, False]
    assert c["critical_stiffness"][0] > c["critical_stiffness"][1] > c["critical_stiffness"][2]


@pytest.mark.parametrize("args, words", [
    (("--loss", "1.5"), "loss = 1.5"),
    (("--burst", "2"), "--burst"),
    (("--loss", "0.1", "--method", "eq18"), "--method eq18"),
    (("--loss", "0.1", "--delay-s", "1.5ms"), "whole samples"),
    (("--loss", "0.6", "--burst", "1.2"), "burst"),
])
def test_refusals_are_one_line_and_exit_2(args, words):
    r = _run("kmax", "hve", *args)
    assert r.exit_code == 2 and words in r.stderr and r.stderr.count("\n") == 1, r.stderr


def test_kmax_delay_range_is_the_librarys():
    from hapstab.analysis.network import fractional_range_critical_stiffness

    # 5-8 ms (was 5-15 ms, computed twice: by the command and here, 1.2 s each): the
    # command's answer is still the library's bit for bit at a window's worst end
    r = _run("kmax", "hve", "--delay-range", "5ms:8ms", "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    want = fractional_range_critical_stiffness(paper_hve(), 5e-3, 8e-3)
    assert d["critical_stiffness"] == want.critical_stiffness
    assert d["worst_delay_samples"] == pytest.approx(8) and d["fractional"] and d["certified"]
    r = _run("kmax", "hve", "--delay-range", "5ms:6ms")
    assert r.exit_code == 0 and "proved enclosure" in r.stdout, r.stderr
    r = _run("kmax", "peb", "--delay-range", "1:3", "--json")
    assert json.loads(r.stdout)["delays_samples"] == [2.0, 3.0, 4.0, 5.0, 6.0]
    for bad in (["--delay-range", "5"], ["--delay-range", "5:x"],
                ["--delay-range", "1:2", "--loss", "0.1"]):
        r = _run("kmax", "hve", *bad)
        assert r.exit_code == 2 and r.stderr.count("\n") == 1, r.stderr
    # peb: the same one-way delay both ways, proved over the continuum
    r = _run("kmax", "peb", "--delay-range", "1ms:2ms", "--json")
    d = json.loads(r.stdout)
    assert d["fractional"] and d["certified"] and d["same_delay_both_ways"], r.stderr
    want = fractional_range_critical_stiffness(paper_peb(), 1e-3, 2e-3)
    assert d["critical_stiffness"] == want.critical_stiffness
    r = _run("kmax", "4ch", "--delay-range", "1ms:2ms")
    assert r.exit_code == 2 and "4-channel" in r.stderr and r.stderr.count("\n") == 1, r.stderr


def test_jitter_is_the_librarys(tmp_path):
    from hapstab import jitter

    r = _run("jitter", "hve", "--delay", "1:3", "-B", "0.05", "--json",
             "--csv", str(tmp_path / "j.csv"))
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    want = jitter(paper_hve().replace(controller=paper_hve().controller.__class__(1.0, 0.05)),
                  (1, 3))
    assert d["stable_up_to_N_per_m"] == want.stable_up_to
    assert d["unstable_from_N_per_m"] == want.unstable_from
    assert d["pattern_samples"] == [list(p) for p in want.pattern]
    assert d["inputs"]["command_line"][1:3] == ["jitter", "hve"]
    assert d["inputs"]["loop"]["delay_samples"] == 1.0        # the nominal delay, lo
    assert (tmp_path / "j.csv").read_text().startswith("search,stiffness_N_per_m,value")
    # seconds: whole samples ceil(t / T) at a receiver acting at the sampling instants
    r = _run("jitter", "hve", "--delay", "0.5ms:3ms", "--json")
    s = json.loads(r.stdout)
    assert s["delay_range_samples"] == [1, 3] and s["delay_range_s"] == [5e-4, 3e-3]
    r = _run("jitter", "peb", "--delay", "1:2", "--max-length", "2", "--json")
    assert r.exit_code == 0, r.stderr
    p = json.loads(r.stdout)
    assert p["networked_terms"] == ["slave -> master", "master -> slave"]
    assert p["stable_up_to_N_per_m"] <= p["unstable_from_N_per_m"]


@pytest.mark.parametrize("args, words", [
    (("--delay", "5"), "--delay = '5'"),
    (("--delay", "3:1"), "delay"),
    (("--delay", "a:b"), "whole samples"),
    (("--delay", "1:2", "--max-length", "0"), "--max-length"),
])
def test_jitter_refusals_are_one_line(args, words):
    r = _run("jitter", "hve", *args)
    assert r.exit_code == 2 and words in r.stderr and r.stderr.count("\n") == 1, r.stderr


@pytest.mark.parametrize("kind,extra", [("hve", ["--delay", "3"]), ("hve", ["--delay-s", "3ms"]),
                                        ("peb", ["--delay-forward", "3"])])
def test_a_delay_beside_delay_range_is_refused_by_name(kind, extra):
    # the range replaces the loop's delay: a typed delay was silently ignored
    r = CliRunner().invoke(cli, ["kmax", kind, "--delay-range", "2:4", *extra])
    assert r.exit_code == 2
    assert f"--delay-range = '2:4' with {extra[0]}" in r.stderr
    assert "\n" not in r.stderr.strip()
