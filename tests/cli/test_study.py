"""Issue #12: study files -- a TOML file describing a loop, its variants and the analyses
`hapstab run` produces; usable by every loop command with --study; checked with one-line
errors naming the file, line and key; parsed by tomllib, never evaluated."""

import json
import os

import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli

STUDY = '''kind = "hve"
title = "My 1 kHz device behind 20 ms of network"

[loop]
mass = 0.3
damping = 0.5
operator = "msd:0.5,5,500"
rate = "1kHz"
delay-s = "20ms"

[[variant]]
name = "damped"
virtual-damping = 2

[run.kmax]

[run.boundary]
rate = "250Hz:4kHz:3"
delay-s = "0,20ms"

[run.simulate]
K = 20
duration = 0.5
'''


def run(*args):
    return CliRunner().invoke(cli, list(args))


@pytest.fixture
def study(tmp_path):
    p = tmp_path / "dev.toml"
    p.write_text(STUDY)
    return p


def _loop(B=0.0):
    return h.HapticLoop(h.Device(0.3, 0.5), h.SpringDamper(0.0, B),
                        h.parse_impedance("msd:0.5,5,500"), 1e-3).with_delay_s(0.02)


def test_a_study_gives_a_command_its_loop_and_the_command_line_overrides_it(study):
    r = run("kmax", "hve", "--study", str(study), "--json")
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["critical_stiffness"] == pytest.approx(
        h.critical_stiffness(_loop()).critical_stiffness, rel=1e-12)
    r = run("kmax", "--study", str(study), "--variant", "damped", "--json")   # kind from the file
    assert json.loads(r.stdout)["critical_stiffness"] == pytest.approx(
        h.critical_stiffness(_loop(2.0)).critical_stiffness, rel=1e-12)
    r = run("kmax", "hve", "--study", str(study), "--delay", "3", "-T", "2ms", "--json")
    d = json.loads(r.stdout)          # --delay drops the study's delay-s, -T its rate
    assert (d["delay_samples"], d["period_s"]) == (3.0, 0.002)


def test_hapstab_run_writes_every_variant_and_analysis_with_a_manifest_last(study, tmp_path):
    out = tmp_path / "results"
    r = run("run", str(study), "--out", str(out), "--json")
    assert r.exit_code == 0, r.stderr
    man = json.loads((out / "manifest.json").read_text())
    assert man["variants"] == ["base", "damped"] and man["analyses"] == ["kmax", "boundary", "simulate"]
    expected = {f"{v}/{c}" for v in ("base", "damped")
                for c in ("kmax.json", "boundary.json", "boundary.csv", "boundary.png",
                          "simulate.json", "simulate.csv", "simulate.png")}
    assert set(man["files"]) == expected | {"study.toml"}
    assert {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()} == \
        expected | {"study.toml", "manifest.json"}
    assert (out / "study.toml").read_text() == STUDY
    kmax = json.loads((out / "damped" / "kmax.json").read_text())
    assert kmax["critical_stiffness"] == pytest.approx(
        h.critical_stiffness(_loop(2.0)).critical_stiffness, rel=1e-12)
    assert kmax["inputs"]["command_line"][-4:] == ["--study", str(study), "--variant", "damped"][-4:] \
        or "--variant" in kmax["inputs"]["command_line"]
    sim = json.loads((out / "base" / "simulate.json").read_text())
    assert sim["files"] == ["base/simulate.csv", "base/simulate.png"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".hapstab-run")]


def test_a_failing_analysis_leaves_the_previous_results(study, tmp_path):
    out = tmp_path / "results"
    assert run("run", str(study), "--out", str(out)).exit_code == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    study.write_text(STUDY.replace("duration = 0.5", "duration = 1e9"))     # over the budget
    r = run("run", str(study), "--out", str(out))
    assert r.exit_code == 2 and "variant 'base', simulate: " in r.stderr
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


@pytest.mark.parametrize("edit,needle", [
    (("mass = 0.3", "mas = 0.3"),
     "dev.toml line 5: mas: not an option of kmax hve (did you mean mass?); allowed:"),
    (("mass = 0.3", "mass = \"heavy\""), "dev.toml line 5: mass = 'heavy': 'heavy' is not a number"),
    (("mass = 0.3", "mass = -1"), "dev.toml line 5: mass = -1: -1: must be > 0"),
    (("kind = \"hve\"", "kind = \"haptic\""), "dev.toml line 1: kind = 'haptic': allowed"),
    (("name = \"damped\"", "name = \"base\""), "dev.toml line 12: variant name = 'base'"),
    (("[run.kmax]", "[run.kmax]\njson = true"), "line 16: json: where the answer goes"),
    (("title =", "titel ="), "dev.toml line 2: unknown key 'titel'"),
    (("mass = 0.3", "mass = [0.3]"), "line 5: mass = [0.3]: must be a number or a string"),
    (("[loop]", "[loop\n"), "not a valid TOML file"),
    # a helper's fuzz: a switch given a number, an integer beyond doubles (were internal errors)
    (("[run.kmax]", "[run.kmax]\ncertify = 1"), "line 16: certify = 1: must be true or false"),
    (("rate = \"1kHz\"", "rate = 1" + "0" * 400), "line 8: rate = 1000"),
])
def test_study_mistakes_are_one_line_naming_the_file_line_and_key(study, edit, needle):
    study.write_text(STUDY.replace(*edit))
    r = run("kmax", "hve", "--study", str(study))
    assert r.exit_code == 2 and r.stderr.count("\n") == 1, r.stderr
    assert needle in r.stderr.replace(str(study.parent) + os.sep, ""), r.stderr


@pytest.mark.parametrize("args,needle", [
    (("kmax", "peb", "--study", "S"), "its kind is 'hve', not 'peb'"),
    (("kmax", "--study", "S", "--variant", "nope"), "--variant = 'nope': "),
    (("kmax", "hve", "--variant", "damped"), "--variant: names a variant of a study"),
    (("reproduce", "fig5", "--study", "S"), "--study: applies to the loop commands"),
    (("kmax", "--study", "missing.toml"), "--study = 'missing.toml': cannot read it"),
    (("run", "S", "--only", "nope"), "--only = 'nope'"),
])
def test_study_options_used_wrongly_are_one_line(study, args, needle):
    r = run(*[str(study) if a == "S" else a for a in args])
    assert r.exit_code == 2 and needle in r.stderr and r.stderr.count("\n") == 1, r.stderr


def test_a_study_without_analyses_says_what_to_add(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('kind = "peb"\n[loop]\nenvironment = "spring:20000"\n')
    r = run("run", str(p))
    assert r.exit_code == 2 and "no [run.<command>] table: nothing to run; e.g. [run.kmax]" in r.stderr
    r = run("kmax", "--study", str(p), "--json")       # but the loop commands use it
    assert r.exit_code == 0 and json.loads(r.stdout)["inputs"]["loop"]["environment"] == \
        h.parse_impedance("spring:20000").to_dict()


def test_region_ignores_a_variants_virtual_damping_and_refuses_it_in_its_own_table(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(STUDY.replace("[run.kmax]", "[run.region]\nK = \"0:100\"\nB = \"0:5\"\n"
                                             "resolution = 8\n\n[run.kmax]"))
    r = run("region", "--study", str(p), "--variant", "damped", "--json")
    assert r.exit_code == 0, r.stderr
    p.write_text(STUDY.replace("[run.kmax]", "[run.region]\nvirtual-damping = 1\n\n[run.kmax]"))
    r = run("region", "--study", str(p))
    assert r.exit_code == 2 and "region varies it itself" in r.stderr


def test_long_computations_report_their_progress_to_a_listener():
    """Issue #12: a grid of K_max reports its progress (the CLI draws a bar on a terminal);
    with no listener nothing is reported, and the numbers do not change."""
    from hapstab import progress

    seen = []

    def listener(what, total):
        seen.append((what, total))
        return lambda k: seen.append(k)

    with progress.listening(listener):
        a = h.boundary(h.paper_hve(), [1e-3, 2e-3, 3e-3], [0, 2])
        b = h.boundary(h.paper_hve(), [1e-3, 2e-3], delays_s=[0.004], method="circle")
    assert seen[0] == ("boundary, exact: 6 points", 6) and seen[1:3] == [3, 3]
    assert seen[3] == ("boundary, circle: 2 points", 2) and seen[4:] == [1, 1]
    assert (a.critical_stiffness == h.boundary(h.paper_hve(), [1e-3, 2e-3, 3e-3],
                                               [0, 2]).critical_stiffness).all()
    assert b.critical_stiffness.shape == (1, 2)


@pytest.mark.parametrize("edit,needle", [
    (("mass = 0.3", "mass = 0.3\nm = 2"), "m and mass in [loop]: give one of them, not both"),
    (("rate = \"1kHz\"", "rate = \"1kHz\"\nperiod = \"2ms\""), "period and rate in [loop]: give one"),
    (("delay-s = \"20ms\"", "delay-s = \"20ms\"\ndelay = 3"), "delay and delay-s in [loop]: give one"),
    (("mass = 0.3", "mass = 1" + "0" * 5000), "not a valid TOML file"),
    (("title = \"My", "title = [1]\n#"), "title = [1]: must be a string"),
    (("name = \"damped\"", "name = \"manifest.json\""), "nor the run's manifest.json"),
])
def test_more_study_mistakes_are_one_line(study, edit, needle):
    study.write_text(STUDY.replace(*edit, 1))
    r = run("kmax", "hve", "--study", str(study))
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and needle in r.stderr, r.stderr
    assert len(r.stderr) < 700


def test_a_study_that_is_not_utf8_is_refused_and_a_good_one_is_copied_byte_for_byte(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b'kind = "hve"  # caf\xe9\n[run.kmax]\n')
    r = run("run", str(bad), "--out", str(tmp_path / "o"))
    assert r.exit_code == 2 and "not UTF-8 at byte 19" in r.stderr
    assert bad.read_bytes() == b'kind = "hve"  # caf\xe9\n[run.kmax]\n'
    good = tmp_path / "good.toml"
    good.write_bytes('kind = "hve"  # café\r\n[run.kmax]\r\n'.encode())
    r = run("run", str(good), "--out", str(tmp_path / "o"), "--json")
    assert r.exit_code == 0, r.stderr
    import hashlib

    assert (tmp_path / "o" / "study.toml").read_bytes() == good.read_bytes()
    assert json.loads(r.stdout)["study_sha256"] == hashlib.sha256(good.read_bytes()).hexdigest()


def test_run_stages_inside_its_output_folder_and_refuses_an_empty_one(study, tmp_path):
    out = tmp_path / "deep" / "results"
    r = run("run", str(study), "--out", str(out), "--only", "base")
    assert r.exit_code == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["base", "manifest.json", "study.toml"]
    assert [p.name for p in (tmp_path / "deep").iterdir()] == ["results"]
    r = run("run", str(study), "--out", "")
    assert r.exit_code == 2 and "--out = '': must be a folder path" in r.stderr


def test_regions_and_the_best_damping_report_progress_too():
    from hapstab import progress

    seen = []
    with progress.listening(lambda what, total: (seen.append((what, total)),
                                                 lambda k: seen.append(k))[1]):
        h.stability_region(h.paper_hve(), (0, 300), (0, 1), resolution=8)
        h.best_damping(h.paper_hve(), resolution=8)
    assert seen[:5] == [("region: 8 x 8", 4), 1, 1, 1, 1]
    assert seen[5][0] == "best damping" and sum(k for k in seen[6:] if isinstance(k, int)) > 9


NETWORK_STUDY = '''kind = "hve"
[loop]
mass = 0.3
damping = 0.5
rate = "1kHz"
delay-s = "5ms"

[[variant]]
name = "late"
delay = 8

[run.kmax]
loss = 0.02
burst = 3

[run.jitter]
delay = "2:4"
max-length = 3
'''


def test_a_study_asks_for_loss_and_jitter_answers_and_they_are_the_commands_own(tmp_path):
    """[run.kmax] with loss/burst and [run.jitter] with its range: the run's answers are the
    ones the command line gives for the same options; jitter's range replaces the [loop]'s
    and each variant's constant delay (the late variant's jitter answer equals the base's),
    while kmax keeps each variant's delay."""
    p = tmp_path / "net.toml"
    p.write_text(NETWORK_STUDY)
    r = run("run", str(p), "--out", str(tmp_path / "out"), "--json")
    assert r.exit_code == 0, r.stderr
    got = {(v, c): json.loads((tmp_path / "out" / v / f"{c}.json").read_text())
           for v in ("base", "late") for c in ("kmax", "jitter")}
    common = ["--mass", "0.3", "--damping", "0.5", "--rate", "1kHz", "--json"]
    for v, delay in (("base", ["--delay-s", "5ms"]), ("late", ["--delay", "8"])):
        direct = json.loads(run("kmax", "hve", *common, *delay, "--loss", "0.02", "--burst",
                                "3").stdout)
        assert got[(v, "kmax")]["critical_stiffness"] == direct["critical_stiffness"]
        assert got[(v, "kmax")]["burst_samples"] == 3
    assert got[("late", "kmax")]["critical_stiffness"] < got[("base", "kmax")][
        "critical_stiffness"]                 # 8 samples of delay are not 5: the variant counts
    direct = json.loads(run("jitter", "hve", *common, "--delay", "2:4", "--max-length",
                            "3").stdout)
    for v in ("base", "late"):
        assert got[(v, "jitter")]["stable_up_to_N_per_m"] == direct["stable_up_to_N_per_m"]
        assert got[(v, "jitter")]["delay_range_samples"] == [2, 4]


@pytest.mark.parametrize("edit,needle", [
    # a helper's fuzz (seed 20261207): each ran (a key silently merged or truncated, a file
    # written outside --out, escape codes printed) or was an internal error
    (("damping = 0.5", "damping = 0.5\nvirtual-damping = 1\nvirtual_damping = 2"),
     "virtual-damping and virtual_damping in [loop]: the same option spelt twice"),
    (("[run.kmax]", "[run.region]\nK = \"0:100\"\nB = \"0:10\"\nresolution = 2.9\n[run.kmax]"),
     "resolution = 2.9: must be a whole number"),
    (("[run.kmax]", "[run.region]\nK = \"0:100\"\nB = \"0:10\"\nresolution = \"\u0663\"\n"
      "[run.kmax]"), "must be a whole number (ASCII digits)"),
    (("title = \"My", "title = \"\\u001b[2J My"), "must be a string without control characters"),
    (("damping = 0.5", "damping = 0.5\ncertificate = \"c.json\""),
     "certificate: where the answer goes is chosen on the command line"),
    (("name = \"damped\"", "name = \"damped\\n\""), "variant name = 'damped\\n'"),
])
def test_run_refuses_what_the_command_line_refuses(study, tmp_path, edit, needle):
    study.write_text(STUDY.replace(*edit))
    r = run("run", str(study), "--out", str(tmp_path / "o"))
    assert r.exit_code == 2 and needle in r.stderr, r.stderr
    assert not (tmp_path / "c.json").exists() and not os.path.exists("c.json")
