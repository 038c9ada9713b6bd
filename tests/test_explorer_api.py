"""The explorer's HTTP JSON API (hapstab.explorer): every endpoint, the same answers as
the CLI's --json, and malformed requests answered with a 4xx JSON error."""

from __future__ import annotations

import json
import warnings

import pytest
from click.testing import CliRunner

pytest.importorskip("starlette")
pytest.importorskip("httpx")

from hapstab.cli.main import cli
from hapstab.explorer.app import create_app


@pytest.fixture(scope="module")
def client():
    with warnings.catch_warnings():    # starlette 1.x: "httpx with TestClient is deprecated"
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient

        with TestClient(create_app(), raise_server_exceptions=False) as c:
            yield c


def cli_json(argv: list[str]) -> dict:
    r = CliRunner().invoke(cli, argv)
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


def test_info(client):
    r = client.get("/api/v1")
    assert r.status_code == 200
    d = r.json()
    assert d["kinds"] == ["hve", "peb"]
    assert "kmax" in d["commands"] and "robust" not in d["commands"]
    assert "POST /api/v1/{command}" in d["endpoints"]


def test_schema_follows_the_cli(client):
    d = client.get("/api/v1/schema").json()
    assert d["study"] is None
    kmax = {o["name"]: o for o in d["kinds"]["hve"]["commands"]["kmax"]}
    assert kmax["virtual-damping"]["flags"] == ["--virtual-damping", "-B"]
    assert kmax["virtual-damping"]["type"] == "float" and kmax["virtual-damping"]["default"] == 0.0
    assert kmax["delay"]["type"] == "int"
    assert "json" not in kmax
    check = {o["name"]: o for o in d["kinds"]["peb"]["commands"]["check"]}
    assert check["stiffness"]["required"] is True


@pytest.mark.parametrize("kind,command,options", [
    ("hve", "kmax", {"mass": 0.3, "rate": "1kHz", "delay": 4, "virtual-damping": 1.5}),
    ("peb", "kmax", {"delay_s": "3ms", "operator": "msd:0.5,5,500"}),
    ("hve", "check", {"stiffness": 30, "delay": 2}),
])
def test_same_answer_as_the_cli(client, kind, command, options):
    r = client.post(f"/api/v1/{command}", json={"kind": kind, "options": options})
    assert r.status_code == 200, r.text
    answer = r.json()
    argv = answer["inputs"]["command_line"][1:]
    assert argv[:2] == [command, kind] and argv[-1] == "--json"
    assert answer == cli_json(argv)
