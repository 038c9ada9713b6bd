"""The explorer's "copy as CLI" and "copy as Python" (POST /api/v1/code): the command
line, run, prints the API's answer; the script, run by Python, builds the same loop with
the public models and prints the same headline number."""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys

import pytest
from click.testing import CliRunner

pytest.importorskip("starlette")
pytest.importorskip("httpx")

import paths
from hapstab.cli.main import cli

#: one worker builds the answers (a module fixture is built once per xdist worker that
#: runs any of its tests: ~30 s of API calls and scripts, twice without the group)
pytestmark = pytest.mark.xdist_group("explorer-code")

SRC = str(paths.SRC)

CASES = [
    ("kmax", "hve", {"mass": 0.3, "damping": 0.5, "rate": "1kHz", "delay-s": "20ms",
                     "virtual-damping": 1.5, "operator": "msd:0.5,5,500"}),
    ("kmax", "peb", {"delay": 3, "B": 0.01, "environment": "spring:1000", "rate": "500Hz"}),
    ("kmax", "hve", {"delay": 4, "velocity-filter": "lowpass:100", "virtual_damping": 2}),
    ("kmax", "peb", {"delay-forward": 1.5, "delay-backward": 2, "slave-stiffness-ratio": 2,
                     "scaling-force": 0.5, "operator": "msd:0.5,5,500"}),
    ("check", "hve", {"stiffness": 20, "delay": 2, "B": 0.5, "period": "2ms"}),
    ("check", "peb", {"K": 4, "delay-s": "3ms", "operator": "msd:0.5,5,500",
                      "slave-virtual-damping": 0.02}),
    ("passivity", "hve", {"stiffness": 30, "delay": 2, "B": 0.05, "curve": 16}),
    ("passivity", "peb", {"stiffness": 3, "delay": 1, "rate": "2kHz"}),
    ("passivity", "hve", {"stiffness": 150, "friction": 0.005, "resolution": 1e-4}),
    ("simulate", "hve", {"stiffness": 40, "delay": 2, "B": 0.2, "duration": 0.3,
                         "wall": 0.0, "operator": "msd:0.5,5,500"}),
    ("simulate", "peb", {"stiffness": 5, "delay-s": "4ms", "duration": "0.3",
                         "environment": "spring:1000", "tdpa": True}),
    ("audit", "hve", {"delay": 2, "rate": "1kHz"}),
    ("boundary", "hve", {"period": "0.001,0.002", "delay": "0,10"}),
    ("region", "peb", {"K": "0:50", "B": "0:1", "resolution": 8, "delay": 2}),
]
#: The answer's headline: what the script prints first.
HEADLINE = {"kmax": "critical_stiffness", "check": "verdict", "passivity": "verdict",
            "simulate": "verdict"}




@pytest.fixture(scope="module")
def answers(client):
    """Per case: the API's answer, its code and what the script printed (all scripts in
    one Python process, each in a fresh namespace)."""
    out = []
    for command, kind, options in CASES:
        r = client.post(f"/api/v1/{command}", json={"kind": kind, "options": options})
        assert r.status_code == 200, r.text
        c = client.post("/api/v1/code", json={"kind": kind, "command": command,
                                              "options": options})
        assert c.status_code == 200, c.text
        out.append((command, kind, r.json(), c.json()))
    driver = ("import contextlib, io, json, sys\nout = []\n"
              "for src in json.load(sys.stdin):\n"
              "    buf = io.StringIO()\n"
              "    with contextlib.redirect_stdout(buf):\n"
              "        try:\n"
              "            exec(compile(src, 'script', 'exec'), {'__name__': '__main__'})\n"
              "        except SystemExit as e:\n"      # (the CLI's main ends with exit 0)
              "            assert not e.code, e.code\n"
              "    out.append(buf.getvalue())\n"
              "print(json.dumps(out))\n")
    p = subprocess.run([sys.executable, "-c", driver], input=json.dumps([o[3]["python"] for o in out]),
                       capture_output=True, text=True, env={**os.environ, "PYTHONPATH": SRC},
                       timeout=120)
    assert p.returncode == 0, p.stderr
    printed = json.loads(p.stdout)
    return [(*o, printed[i]) for i, o in enumerate(out)]


@pytest.mark.parametrize("i", range(len(CASES)), ids=[f"{c}-{k}" for c, k, _ in CASES])
def test_the_cli_line_prints_the_api_answer(answers, i):
    command, kind, answer, code, _ = answers[i]
    argv = shlex.split(code["cli"])
    assert argv[:3] == ["hapstab", command, kind] and argv[-1] == "--json"
    r = CliRunner().invoke(cli, argv[1:])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout) == answer


@pytest.mark.parametrize("i", range(len(CASES)), ids=[f"{c}-{k}" for c, k, _ in CASES])
def test_the_python_script_prints_the_same_headline(answers, i):
    command, _, answer, code, printed = answers[i]
    lines = printed.splitlines()
    if command == "audit":
        rows = [(r["label"], r["critical_stiffness"]) for r in answer["rows"]]
        assert len(lines) == len(rows)
        for line, (label, k) in zip(lines, rows, strict=True):
            assert line.startswith(label)
            assert (float(line.rsplit(" ", 1)[1]) == k) if k is not None \
                else line.endswith(" inf")
        return
    if command not in HEADLINE:                   # the script runs the command itself
        assert json.loads(printed) == answer
        return
    assert code["python"].startswith("import hapstab as h\n")
    key = HEADLINE[command]
    value = answer[key]
    assert lines[0] == (repr(value) if isinstance(value, float) else str(value))
    if command == "passivity":
        assert float(lines[1]) == answer["margin"]


def test_code_errors(client):
    r = client.post("/api/v1/code", json={"kind": "hve", "options": {}})
    assert r.status_code == 400 and r.json()["parameter"] == "command"
    r = client.post("/api/v1/code", json={"kind": "hve", "command": "check", "options": {}})
    assert r.status_code == 422 and r.json()["parameter"] == "stiffness"
    r = client.post("/api/v1/code", json={"kind": "hve", "command": "kmax",
                                          "options": {"mass": "heavy"}})
    assert r.status_code == 422 and r.json()["parameter"] == "mass"
    r = client.post("/api/v1/code", json={"kind": "hve", "command": "kmax",
                                          "options": {"mass": -1}})
    assert r.json() == client.post("/api/v1/kmax", json={"kind": "hve",
                                                         "options": {"mass": -1}}).json()
    r = client.post("/api/v1/code", json={"kind": "hve", "command": "nope", "options": {}})
    assert r.status_code == 404
