"""The CLI's 4ch loop kind (Lawrence's 4-channel teleoperator) through click's runner:
PEB's options reproduce PEB, the 4ch options build the loop the library is given,
what the library refuses for force channels is one line and exit 2, and a study file
can describe a 4ch loop."""

import json
import os

import pytest
from click.testing import CliRunner
from jsonschema import Draft202012Validator

import hapstab as h
import paths
from hapstab.cli.main import cli
from hapstab.models.fourchannel import FourChannelLoop

SCHEMA_PATH = os.path.join(str(paths.ROOT),
                           "schemas", "hapstab-output.schema.json")
with open(SCHEMA_PATH) as fh:
    SCHEMA = json.load(fh)


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _validate(name, d):
    errors = sorted(Draft202012Validator({**SCHEMA, "$ref": f"#/$defs/{name}"}).iter_errors(d),
                    key=str)
    assert not errors, [e.message for e in errors][:5]


def _one_line_error(r, *needles):
    assert r.exit_code == 2, (r.exit_code, r.stderr, r.exception)
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("hapstab: error: "), r.stderr
    assert "Traceback" not in r.stderr
    for n in needles:
        assert n in r.stderr, r.stderr


#: PEB parameter sets (the options both kinds share), with delay
PEB_SETS = [
    ["--delay", "2"],
    ["--delay", "4", "-B", "0.5", "--environment", "spring:1000", "--operator", "msd:0.5,5,500"],
    ["--delay", "3", "--slave-stiffness-ratio", "2.5", "--slave-virtual-damping", "1.5",
     "--master-mass", "0.3", "--slave-mass", "0.8", "--master-damping", "1",
     "--slave-damping", "0.2", "-T", "0.5ms"],
    ["--delay-forward", "1", "--delay-backward", "5", "-B", "2", "--environment", "none"],
    ["--delay-s", "6ms", "--rate", "500Hz", "--environment", "msd:0.1,2,300"],
]


@pytest.mark.parametrize("opts", PEB_SETS, ids=range(len(PEB_SETS)))
def test_kmax_4ch_with_pebs_options_equals_kmax_peb(opts):
    # 4ch is outside the ball proof (float enclosures alone): compared with PEB's float
    # search (--no-certify); PEB's proved K_max is the safe end, at most the float one
    r4, rp = run("kmax", "4ch", *opts, "--json"), run("kmax", "peb", *opts, "--no-certify", "--json")
    rc = run("kmax", "peb", *opts, "--json")
    assert r4.exit_code == 0 and rp.exit_code == 0 and rc.exit_code == 0, (r4.stderr, rp.stderr)
    k4, kp = json.loads(r4.stdout)["critical_stiffness"], json.loads(rp.stdout)["critical_stiffness"]
    assert k4 > 0 and k4 == pytest.approx(kp, rel=1e-12)
    assert json.loads(rc.stdout)["critical_stiffness"] <= kp


FORCE_REFLECTION = ["--master-stiffness-ratio", "0", "--c4-stiffness-ratio", "0", "--c2", "1",
                    "--environment", "spring:1000", "-B", "0.5", "--slave-virtual-damping", "0.8",
                    "--delay", "2", "--operator", "msd:0.5,5,500"]


def _force_reflection_loop():
    """FORCE_REFLECTION built in Python (K = the slave's stiffness = 1)."""
    return FourChannelLoop(h.Device(0.015, 0.02), h.Device(0.015, 0.02),
                           h.SpringDamper(0.0, 0.5), h.SpringDamper(1.0, 0.8),
                           h.parse_impedance("msd:0.5,5,500"), h.spring(1000.0), 1e-3, 2,
                           slave_from_master=h.SpringDamper(1.0, 0.8),
                           master_from_slave=h.SpringDamper(0.0, 0.5), force_to_master=1.0)


def test_force_reflection_equals_the_library_and_its_echo_validates():
    r = run("kmax", "4ch", *FORCE_REFLECTION, "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    loop = _force_reflection_loop()
    assert d["critical_stiffness"] == pytest.approx(h.critical_stiffness(loop).critical_stiffness,
                                                    rel=1e-12)
    echo = d["inputs"]["loop"]
    assert echo["kind"] == "4ch" and "position_scale" not in echo
    assert (echo["force_to_master"], echo["force_to_slave"], echo["slave_force_feedback"],
            echo["master_force_feedback"]) == (1.0, 0.0, 0.0, 0.0)
    assert echo["master_from_slave"]["stiffness_N_per_m"] == 0.0
    assert echo["slave_from_master"]["virtual_damping_N_s_per_m"] == 0.8
    _validate("kmax", d)
    _validate("loop", echo)
    assert not Draft202012Validator({**SCHEMA, "$ref": "#/$defs/loop"}).is_valid(
        {**echo, "position_scale": 1.0})          # a 4ch loop has no scaling


def test_every_4ch_option_reaches_the_loop():
    r = run("kmax", "4ch", "--c1-stiffness-ratio", "0.5", "--c1-virtual-damping", "0.3",
            "--c4-stiffness-ratio", "2", "--c4-virtual-damping", "0.4", "--c2", "0.1",
            "--c3", "0.2", "--c5", "-0.3", "--c6", "0.4", "--slave-stiffness-ratio", "3",
            "-B", "1", "--delay", "1", "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    echo = d["inputs"]["loop"]
    gains = [echo[k] for k in ("force_to_master", "force_to_slave", "slave_force_feedback",
                               "master_force_feedback")]
    ctl = {k: (echo[k]["stiffness_N_per_m"], echo[k]["virtual_damping_N_s_per_m"])
           for k in ("master_controller", "slave_controller", "slave_from_master",
                     "master_from_slave")}
    assert gains == [0.1, 0.2, -0.3, 0.4]
    assert ctl == {"master_controller": (1.0, 1.0), "slave_controller": (3.0, 1.0),
                   "slave_from_master": (0.5, 0.3), "master_from_slave": (2.0, 0.4)}
    _validate("kmax", d)


def test_boundary_of_a_force_reflecting_loop_validates():
    r = run("boundary", "4ch", *[o for o in FORCE_REFLECTION if o not in ("--delay", "2")],
            "--period", "1ms,2ms", "-n", "0,2", "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["loop"] == "4ch" and len(d["critical_stiffness"]) == 2
    _validate("boundary", d)


def test_twoport_takes_force_gains_with_its_caveat_and_equals_peb_without():
    r = run("twoport", "4ch", "-K", "5", "--c2", "1", "--json")
    assert r.exit_code == 0, r.stderr
    assert "NOT a stability bound" in json.loads(r.stdout)["reason"]
    _one_line_error(run("passivity", "4ch", "-K", "5", "--c2", "1"), "C_2", "force")
    r = run("twoport", "4ch", "-K", "5", "-n", "2", "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    p = json.loads(run("twoport", "peb", "-K", "5", "-n", "2", "--json").stdout)
    assert d["verdict"] == p["verdict"] and d["margin"] == pytest.approx(p["margin"], rel=1e-9)
    _validate("twoport", d)


def test_position_only_analyses_run_and_force_gains_are_refused():
    for args, name in [(["transparency", "4ch", "-K", "5", "-n", "2", "--frequencies", "1,10"],
                        "transparency"),
                       (["passivity", "4ch", "-K", "5"], "passivity"),
                       (["kmax", "4ch", "--method", "circle", "-n", "2"], "kmax")]:
        r = run(*args, "--json")
        assert r.exit_code == 0, (args, r.stderr)
        _validate(name, json.loads(r.stdout))
        if name == "transparency":       # the two-port at the force sensors
            assert run(*args, "--c3", "0.5").exit_code == 0
        else:
            _one_line_error(run(*args, "--c3", "0.5"), "C_3")


@pytest.mark.parametrize("args, needles", [
    (["--master-stiffness-ratio", "0.5"], ["--master-stiffness-ratio", "0.5", "allowed: 1", "0"]),
    (["--c2", "abc"], ["--c2", "abc"]),
    (["--scaling-position", "2"], ["--scaling-position", "no scaling"]),
    (["--scaling-force", "2"], ["--scaling-force"]),
    (["--master-stiffness-ratio", "0", "--slave-stiffness-ratio", "2"],
     ["--slave-stiffness-ratio", "not given"]),
    (["--delay-forward", "1.5"], ["fractional", "whole samples"]),
    (["--c1-stiffness-ratio", "-1"], ["--c1-stiffness-ratio"]),
    (["--method", "eq29"], ["eq29", "allowed"]),
    (["--method", "circle", "--c2", "1"], ["--c2", "allowed here: 0"]),
])
def test_bad_values_are_one_line_and_exit_2(args, needles):
    _one_line_error(run("kmax", "4ch", *args), *needles)


def test_commands_without_4ch_say_which_kinds_they_take():
    for cmd in (["audit", "4ch"], ["reproduce", "4ch"]):
        assert run(*cmd).exit_code == 2
    _one_line_error(run("audit", "4ch"), "hve or peb")
    _one_line_error(run("kmax", "--c2", "1"), "hapstab kmax 4ch --c2 1")


def test_region_and_best_damping():
    r = run("region", "4ch", "--K", "0:100", "--B", "0:1", "--resolution", "6", "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    p = json.loads(run("region", "peb", "--K", "0:100", "--B", "0:1", "--resolution", "6",
                       "--json").stdout)
    assert d["loop"] == "4ch" and d["rows"][0]["stable_intervals"][0][1] == pytest.approx(
        p["rows"][0]["stable_intervals"][0][1], rel=1e-9)
    _validate("region", d)
    _one_line_error(run("region", "4ch", "--K", "0:100", "--B", "0:1", "--overlay", "paper"),
                    "paper", "allowed: passivity, circle")
    _one_line_error(run("region", "4ch", "--K", "0:100", "--B", "0:1", "--c4-stiffness-ratio",
                        "2"), "--c4-stiffness-ratio")
    r = run("region", "4ch", "--K", "0:100", "--B", "0:1", "--resolution", "6", "--c2", "1",
            "--json")
    assert r.exit_code == 0, r.stderr
    r = run("best-damping", "4ch", "--c2", "0.5", "--environment", "spring:1000", "-n", "2",
            "--json")
    assert r.exit_code == 0, r.stderr
    _validate("best-damping", json.loads(r.stdout))


def test_no_paper_condition_for_a_4ch_loop():
    loop = FourChannelLoop(h.Device(0.015, 0.02), h.Device(0.015, 0.02), h.SpringDamper(1, 0),
                           h.SpringDamper(1, 0), None, None, 1e-3, 2)
    from hapstab.analysis.conditions.closed_forms import paper_condition

    with pytest.raises(h.AnalysisError, match="no paper condition applies"):
        paper_condition(loop)
    with pytest.raises(h.AnalysisError, match="no paper condition applies"):
        h.stability_region(loop, (0, 10), (0, 1), 4, overlays=["paper"])


STUDY = '''kind = "4ch"
title = "force reflection"

[loop]
master-stiffness-ratio = 0
c4-stiffness-ratio = 0
c2 = 1
environment = "spring:1000"
virtual-damping = 0.5
slave-virtual-damping = 0.8
operator = "msd:0.5,5,500"
delay = 2

[[variant]]
name = "half"
c2 = 0.5

[run.kmax]
[run.boundary]
period = "1ms,2ms"
delay = "0,2"
'''


def test_a_study_file_describes_a_4ch_loop(tmp_path):
    p = tmp_path / "fr.toml"
    p.write_text(STUDY)
    r = run("kmax", "--study", p, "--json")
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["critical_stiffness"] == pytest.approx(json.loads(
        run("kmax", "4ch", *FORCE_REFLECTION, "--json").stdout)["critical_stiffness"], rel=1e-12)
    out = tmp_path / "out"
    r = run("run", p, "--out", out, "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["kind"] == "4ch" and d["variants"] == ["base", "half"]
    _validate("run", d)
    half = json.loads((out / "half" / "kmax.json").read_text())
    assert half["inputs"]["loop"]["force_to_master"] == 0.5
    # an analysis without a 4ch loop is named, before any work
    p.write_text(STUDY + "[run.audit]\n")
    _one_line_error(run("run", p, "--out", out), "audit", "4ch")
    p.write_text(STUDY + "[run.check]\nK = 5\n")
    # --no-margins: the question is that check reads a 4ch study; its margins (a 10 s
    # delay search here, ~6 s of the test) are a 4ch check's in
    # test_check_and_simulate_take_force_gains, which computes them by default
    assert run("check", "--study", p, "-K", "5", "--no-margins").exit_code == 0
    p.write_text(STUDY.replace('c2 = 1', 'scaling-position = 2'))
    _one_line_error(run("kmax", "--study", p), "scaling-position")


@pytest.mark.parametrize("kind", ['"5ch"', '["4ch"]', "{a = 1}", "4"])
def test_a_study_of_an_unknown_kind_is_one_line(tmp_path, kind):
    p = tmp_path / "k.toml"
    p.write_text(f"kind = {kind}\n[run.kmax]\n")
    _one_line_error(run("kmax", "--study", p), "kind", '"4ch"')


def test_check_and_simulate_take_force_gains():
    """check 4ch agrees with the library's stability() of the same loop, and simulate
    4ch gives the same verdict on both sides of the exact K_max (force reflection)."""
    from hapstab import stability

    d = json.loads(run("kmax", "4ch", *FORCE_REFLECTION, "--json").stdout)
    K = d["critical_stiffness"]
    for factor, verdict, seen in ((0.5, "stable", "bounded"), (1.5, "unstable", "unbounded")):
        r = run("check", "4ch", *FORCE_REFLECTION, "-K", K * factor, "--json")
        assert r.exit_code == 0, r.stderr
        c = json.loads(r.stdout)
        loop = _force_reflection_loop().with_stiffness(K * factor)
        assert c["verdict"] == stability(loop).verdict == verdict
        s = run("simulate", "4ch", *FORCE_REFLECTION, "-K", K * factor, "--duration", "3",
                "--json")
        assert s.exit_code == 0, s.stderr
        assert json.loads(s.stdout)["verdict"] == seen
