"""The explorer's network card (issue 30 item 5): static/network.js, run here under node,
turns the card's inputs into requests and the API's answers into what the card reads.

The requests: a delay range and a jitter range replace the loop's constant delay (its
delay options are not sent); the loss keeps it; an empty input asks nothing. The
readings, on the answers the explorer's API gives for the paper's HVE: the numbers are
the answer's own, the model says "exact" / "sufficient", and the comparison is with the
constant-delay K_max. The page itself is driven in tests/explorer/test_explorer_browser.py."""

from __future__ import annotations

import json
import shutil
import subprocess

import pytest

pytest.importorskip("starlette")

import paths
from hapstab.explorer.api import ApiError, check_request, command_kinds, run_command

STATIC = paths.ROOT / "src" / "hapstab" / "explorer" / "static"
NODE = shutil.which("node")


def node(expr: str, data: object) -> object:
    """``expr`` evaluated with ``N`` = network.js's HapstabNetwork and ``o`` = ``data``."""
    if NODE is None:
        pytest.skip("node is not installed: network.js is run by the page's browser only")
    code = ("const N = require(process.argv[1]);"
            "const o = JSON.parse(require('fs').readFileSync(0, 'utf8'));"
            f"console.log(JSON.stringify({expr}));")
    out = subprocess.run([NODE, "-e", code, str(STATIC / "network.js")], check=True,
                         input=json.dumps(data), capture_output=True, text=True)
    return json.loads(out.stdout)


def api(command: str, options: dict) -> dict:
    return json.loads(run_command(check_request(command, {"kind": "hve", "options": options})))


def test_the_inputs_become_the_requests():
    r = node("N.requests(o)", {"_range": " 5ms:15ms ", "_jitter": "5:15", "_loss": "0.02",
                               "_burst": "3", "delay": "10"})
    assert r["net-range"] == {"command": "kmax", "extra": {"delay-range": "5ms:15ms"},
                              "drop": ["delay", "delay-s", "delay-forward", "delay-backward"]}
    assert r["net-jitter"]["command"] == "jitter" and r["net-jitter"]["extra"] == {"delay": "5:15"}
    assert r["net-loss"] == {"command": "kmax", "extra": {"loss": "0.02", "burst": "3"},
                             "drop": []}
    empty = node("N.requests(o)", {"_burst": "3"})
    assert all(set(v) == {"hint"} for v in empty.values())
    assert "loss probability" in empty["net-loss"]["hint"]


def test_the_readings_are_the_answers_own():
    rng = api("kmax", {"delay-range": "5ms:15ms"})
    jit = api("jitter", {"delay": "1:3"})
    loss = api("kmax", {"delay": 2, "loss": 0.05})
    ref = api("kmax", {"delay": 2})["critical_stiffness"]
    out = node("['net-range', 'net-jitter', 'net-loss'].map((c, i) => N.read[c](o.a[i], o.ref))",
               {"a": [rng, jit, loss], "ref": ref})
    r, j, s = out
    assert r["values"] == {"kmax": rng["critical_stiffness"], "worst": rng["worst_delay_samples"]}
    assert r["model"].startswith("exact: the certified minimum") and "5\u201315 ms" in r["model"]
    assert "between the samples" in r["model"] and "minimum in [" in r["detail"]   # seconds
    assert j["values"]["stable"] == jit["stable_up_to_N_per_m"]
    assert j["values"]["unstable"] == jit["unstable_from_N_per_m"]
    assert "sufficient" in j["model"] and "exact for its pattern" in j["model"]
    assert s["values"]["kmax"] == loss["critical_stiffness"]
    assert "mean-square: exact criterion" in s["model"] and "independently" in s["model"]
    # against the constant-delay K_max: the loss answer's own loss-free K_max is the page's
    assert loss["loss_free_critical_stiffness"] == ref
    for reading, k in ((s, loss["critical_stiffness"]), (r, rng["critical_stiffness"])):
        assert reading["cmp"].startswith(f"{_three(k / ref)} \u00d7 ")


def _three(x: float) -> str:
    """``x`` to 3 significant digits, as the page writes it (``+x.toPrecision(3)``)."""
    return f"{float(f'{x:.3g}'):g}"


def test_a_commands_loop_kinds_come_from_the_clis_table():
    """Issue 28: the explorer asks the CLI's command table which kinds a command takes
    (app.py no longer names twoport and transparency)."""
    assert command_kinds("kmax") == ("hve", "peb")
    assert command_kinds("twoport") == ("peb",) and command_kinds("transparency") == ("peb",)
    assert command_kinds("limit-cycle") == ("hve",) and command_kinds("jitter") == ("hve", "peb")
    for name, status in (("robust", 422), ("nonsense", 404)):
        with pytest.raises(ApiError) as e:
            command_kinds(name)
        assert e.value.status == status
