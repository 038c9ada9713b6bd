"""JSON that tools can trust (issue #12): every command's --json output validates against
schemas/hapstab-output.schema.json; numbers are numbers (an infinity is null plus a flag);
the same key has the same type in every command; the inputs and the version are echoed;
with --json an error is a JSON object on stdout too."""

import json
import os

import pytest
from click.testing import CliRunner
from jsonschema import Draft202012Validator

import paths
from hapstab.cli.main import cli

#: one worker runs the 52 commands (the `outputs` module fixture would be built once per
#: xdist worker that runs any of its tests: ~20 s, twice without the group)
pytestmark = pytest.mark.xdist_group("json-schema")

SCHEMA_PATH = os.path.join(str(paths.ROOT),
                           "schemas", "hapstab-output.schema.json")
with open(SCHEMA_PATH) as fh:
    SCHEMA = json.load(fh)
Draft202012Validator.check_schema(SCHEMA)

RUNS = [
    ("kmax", ["kmax", "hve"]),
    ("kmax", ["kmax", "peb", "--delay", "2", "--method", "circle"]),
    ("kmax", ["kmax", "hve", "--method", "circle", "--approximation", "backward"]),   # inf
    ("kmax", ["kmax", "hve", "--method", "eq18", "--delay", "3"]),
    ("check", ["check", "hve", "-K", "5"]),
    ("check", ["check", "peb", "-K", "5", "--operator", "none", "--environment", "none",
               "--no-margins"]),     # margins' keys: `check hve -K 5`'s (these took 3 s)
    ("boundary", ["boundary", "hve", "--period", "0.001,0.002", "-n", "0,2"]),
    ("boundary", ["boundary", "peb", "--rate", "500Hz,1kHz", "--delay-s", "2ms,5ms"]),
    ("passivity", ["passivity", "hve", "-K", "5"]),
    ("passivity", ["passivity", "peb", "-K", "5", "-n", "3", "--curve", "50"]),
    ("passivity", ["passivity", "hve", "-K", "150", "--friction", "0.005", "--curve", "9"]),
    ("twoport", ["twoport", "peb", "-K", "5", "-n", "2"]),
    ("transparency", ["transparency", "peb", "-K", "5", "-n", "2", "--frequencies", "1:500:20"]),
    ("transparency", ["transparency", "peb", "-K", "0", "--environment", "none",   # nulls
                      "--frequencies", "0.1,1"]),
    ("kmax", ["kmax", "peb", "--method", "llewellyn", "-n", "2"]),
    ("passivity", ["passivity", "peb", "-K", "5", "--method", "passivity"]),
    ("audit", ["audit", "hve", "--delay", "2"]),
    ("audit", ["audit", "hve", "--friction", "0.005", "--resolution", "1e-4"]),   # + a row
    ("passivity", ["passivity", "hve", "-K", "150", "--friction", "0.005", "--resolution",
                   "1e-4"]),                                 # Abbott-Okamura beside it
    ("limit-cycle", ["limit-cycle", "hve", "-K", "18", "-n", "4", "--resolution", "1e-4",
                     "--quantizer", "nearest"]),     # the keys and nulls of -K 8 -n 10, faster
    ("limit-cycle", ["limit-cycle", "hve", "-K", "11.44", "-n", "10", "--friction", "0.01"]),
    ("region", ["region", "hve", "--K", "0:100", "--B", "0:1", "--resolution", "8"]),
    ("best-damping", ["best-damping", "hve"]),
    ("best-damping", ["best-damping", "hve", "-n", "2", "--operator", "msd:0.5,5,500",
                      "--min-damping", "0", "--operator-mass", "0.5", "--operator-damping",
                      "4.5:5", "--operator-stiffness", "500"]),
    ("robust", ["robust", "hve", "-n", "2", "--operator-mass", "0.5", "--operator-damping", "5",
                "--operator-stiffness", "490:510"]),
    ("robust", ["robust", "peb", "-n", "2", "--environment", "spring:1000",
                "--operator-mass", "0.5", "--operator-damping", "5", "--operator-stiffness",
                "500"]),
    ("simulate", ["simulate", "hve", "-K", "5", "--duration", "0.5"]),
    ("simulate", ["simulate", "hve", "-K", "5", "--duration", "0.5", "--series", "100",
                  "--wall", "0"]),
    ("simulate", ["simulate", "hve", "-K", "1e6", "--duration", "1"]),            # overflows
    ("simulate", ["simulate", "peb", "-K", "8", "-n", "4", "--duration", "1", "--tdpa"]),
    ("simulate", ["simulate", "peb", "-K", "8", "--duration", "0.5", "--jitter", "1:3",
                  "--loss", "0.05", "--seed", "2", "--tdpa"]),                  # a network
    ("simulate", ["simulate", "hve", "-K", "5", "--duration", "0.05", "--delay-trace",
                  "trace.csv"]),
    ("simulate", ["simulate", "peb", "-K", "5", "--duration", "0.5", "--master-friction", "0.01",
                  "--slave-friction", "0.02"]),                                 # stick-slip
    ("kmax", ["kmax", "hve", "--friction", "0.1"]),             # the friction-free loop, noted
    ("boundary", ["boundary", "hve", "--period", "0.001", "--friction", "0.1"]),
    ("reproduce", ["reproduce", "fig5", "--periods", "0.003"]),
    ("demo", ["demo"]),
    ("run", ["run", "study.toml"]),
    ("sweep", ["sweep", "sweep.toml", "--out", "sweep-out", "--workers", "1"]),
    ("kmax", ["kmax", "--study", "study.toml", "--variant", "stiff"]),
    ("kmax", ["kmax", "4ch", "--master-stiffness-ratio", "0", "--c4-stiffness-ratio", "0",
              "--c2", "1", "--environment", "spring:1000", "-B", "0.5", "-n", "2"]),
    ("twoport", ["twoport", "4ch", "-K", "5", "-n", "2", "--c1-stiffness-ratio", "2"]),
    ("region", ["region", "4ch", "--K", "0:100", "--B", "0:1", "--resolution", "6"]),
    ("kmax-loss", ["kmax", "hve", "--delay", "2", "--loss", "0.05"]),
    ("kmax-loss", ["kmax", "peb", "--delay", "1", "--loss", "0.1", "--burst", "3"]),
    ("kmax-loss-curve", ["kmax", "hve", "--loss", "0:0.2:3"]),
    ("kmax-fraction-range", ["kmax", "hve", "--delay-range", "5ms:8ms"]),
    ("kmax-fraction-range", ["kmax", "peb", "--delay-range", "1ms:2ms"]),
    ("kmax-delay-range", ["kmax", "peb", "--delay-range", "1:2"]),
    ("jitter", ["jitter", "hve", "--delay", "1:3", "-B", "0.05"]),
    ("jitter", ["jitter", "peb", "--delay", "0.5ms:2ms", "--max-length", "1"]),   # keys of 2
    ("identify", ["identify", "log.csv", "--resolution", "2um"]),
    ("error", ["kmax", "hve", "--delay", "x"]),
    ("error", ["simulate", "hve", "-K", "9", "--duration", "1e9"]),              # budget
]


def _write_log(path):
    """A short identification log: a 0.25 kg, 0.8 N*s/m device under a multisine (exact
    ZOH positions from hapstab's simulator, read by a 2 um encoder)."""
    import numpy as np

    import hapstab
    from hapstab.models.parts import quantize

    t = np.arange(600) * 5e-4
    F = 0.4 * np.sin(2 * np.pi * 3 * t) + 0.2 * np.sin(2 * np.pi * 17 * t)
    loop = hapstab.HapticLoop(hapstab.Device(0.25, 0.8), operator=None, period=5e-4)
    x = hapstab.simulate(loop, 599 * 5e-4, force=F[:-1]).position[:, 0]
    with open(path, "w") as fh:
        fh.write("time_s,force_N,position_m\n")
        fh.writelines(f"{a:.17g},{b:.17g},{c:.17g}\n" for a, b, c in zip(t, F, quantize(x, 2e-6),
                                                                  strict=True))


def _validator(name):
    return Draft202012Validator({**SCHEMA, "$ref": f"#/$defs/{name}"})


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    os.chdir(tmp_path_factory.mktemp("json"))       # reproduce writes ./out
    with open("study.toml", "w") as fh:
        fh.write('kind = "peb"\n[loop]\ndelay = 2\n[[variant]]\nname = "stiff"\n'
                 'environment = "spring:2000"\n[run.kmax]\n[run.check]\nK = 3\n'
                 'margins = false\n')    # check's margins: validated by `check hve -K 5`
    _write_log("log.csv")
    with open("trace.csv", "w") as fh:              # a network trace: delays 1-2, a loss
        fh.write("sample,delay_samples,arrived\n" + "".join(
            f"{k},{1 + k % 2},{int(k != 7)}\n" for k in range(51)))
    with open("sweep.toml", "w") as fh:
        fh.write('kind = "hve"\n[sweep]\nquantities = ["kmax", "closed-form", "check"]\n'
                 '[sweep.check]\nstiffness = 20\n[sweep.axes]\nperiod = "1ms:2ms:2"\n'
                 'delay = [0, 2]\n')
    out = []
    for name, args in RUNS:
        r = CliRunner().invoke(cli, [*args, "--json"])
        assert r.exit_code == (2 if name == "error" else 0), (args, r.stderr)
        out.append((name, args, json.loads(r.stdout)))
    return out


def test_every_output_validates_against_the_schema(outputs):
    for name, args, d in outputs:
        errors = sorted(_validator(name).iter_errors(d), key=str)
        assert not errors, (args, [e.message for e in errors][:5])


def test_the_schema_can_fail():
    bad = {"critical_stiffness": "inf", "method": "exact", "stable_intervals": [], "reason": "",
           "period_s": 1e-3, "delay_samples": 0, "crossing_frequency_hz": None,
           "hapstab_version": "0", "inputs": {"command_line": []}}
    assert not _validator("kmax").is_valid(bad)           # the string "inf" is not a number
    assert _validator("kmax").is_valid({**bad, "critical_stiffness": None,
                                        "infinite": {"critical_stiffness": 1}})


def test_an_infinite_value_is_null_with_its_flag(outputs):
    d = next(d for n, a, d in outputs if "backward" in a)
    assert d["critical_stiffness"] is None and d["infinite"]["critical_stiffness"] == 1


def test_inputs_and_version_are_echoed(outputs):
    from hapstab import __version__

    for _, args, d in outputs:
        assert d["hapstab_version"] == __version__
        assert d["inputs"]["command_line"] == ["hapstab", *args, "--json"]
    kmax = outputs[0][2]["inputs"]["loop"]
    assert kmax["device"] == {"mass_kg": 0.15, "damping_N_s_per_m": 0.1}
    assert kmax["operator"]["stiffness_N_per_m"] == 1.0 and kmax["period_s"] == 0.001


def _types(v, path, seen):
    if isinstance(v, dict):
        for k, x in v.items():
            _types(x, k, seen)
    elif isinstance(v, list):
        for x in v:
            _types(x, path + "[]", seen)
    elif v is not None:
        kind = "number" if isinstance(v, (int, float)) and not isinstance(v, bool) else \
            type(v).__name__
        seen.setdefault(path, set()).add(kind)


def test_the_same_key_has_the_same_type_everywhere(outputs):
    seen: dict[str, set] = {}
    for _, _, d in outputs:
        _types(d, "", seen)
    mixed = {k: v for k, v in seen.items() if len(v) > 1}
    assert not mixed, mixed
    # numbers that are whole are still floats where the key is a measurement
    for _, _, d in outputs:
        if "delay_samples" in d and not isinstance(d["delay_samples"], list):
            assert isinstance(d["delay_samples"], float)


def test_a_studys_network_answers_validate_as_the_commands_do(tmp_path):
    """hapstab run's kmax.json (with loss) and jitter.json: the kmax-loss and jitter
    definitions, like the commands' own --json (the run adds nothing the schema forbids)."""
    p = tmp_path / "net.toml"
    p.write_text('kind = "peb"\n[loop]\ndelay = 1\n[run.kmax]\nloss = 0.05\nburst = 2\n'
                 '[run.jitter]\ndelay = "1:2"\nmax-length = 2\n')
    r = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "out"), "--json"])
    assert r.exit_code == 0, r.stderr
    assert _validator("run").is_valid(json.loads(r.stdout))
    for name, file in (("kmax-loss", "kmax.json"), ("jitter", "jitter.json")):
        d = json.loads((tmp_path / "out" / "base" / file).read_text())
        errors = sorted(_validator(name).iter_errors(d), key=str)
        assert not errors, (file, [e.message for e in errors][:5])
    assert not _validator("jitter").is_valid(
        json.loads((tmp_path / "out" / "base" / "kmax.json").read_text()))   # it can fail
