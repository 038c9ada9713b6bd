"""The explorer behind a real server: ``hapstab explore`` as a process (the address line,
Ctrl-C exits 0), uvicorn in a thread answering raw, malformed HTTP from a socket, and the
command's own errors (--study of another kind, the missing extra)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest
from click.testing import CliRunner

import paths
from hapstab.cli.main import cli

# one worker runs every test holding a server or a browser (pytest -n --dist loadgroup)
pytestmark = pytest.mark.xdist_group("explorer-server")

pytest.importorskip("uvicorn")
httpx = pytest.importorskip("httpx")
SRC = str(paths.SRC)


def test_hapstab_explore_prints_its_address_and_stops_on_ctrl_c(tmp_path):
    study = tmp_path / "s.toml"
    study.write_text('kind = "hve"\n[loop]\nmass = 0.3\ndelay-s = "20ms"\n')
    p = subprocess.Popen([sys.executable, "-m", "hapstab", "explore", "--port", "0",
                          "--study", str(study)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONPATH": SRC})
    try:
        line = p.stdout.readline()          # printed once listening (flushed)
        assert line.startswith("hapstab explorer: http://127.0.0.1:"), (line, p.stderr.read())
        url = line.split(": ", 1)[1].strip()
        port = int(url.rsplit(":", 1)[1].strip("/"))
        assert port > 0
        r = httpx.get(url + "api/v1", timeout=10)
        assert r.status_code == 200 and r.json()["kinds"] == ["hve", "peb"]
        s = httpx.get(url + "api/v1/schema", timeout=10).json()["study"]
        assert s == {"kind": "hve", "options": {"mass": 0.3, "delay-s": "20ms"}}
        r = httpx.post(url + "api/v1/kmax", json={"kind": "hve", "options": s["options"]},
                       timeout=30)
        assert r.status_code == 200 and r.json()["critical_stiffness"] > 0
    finally:
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=20)
    assert p.returncode == 0, err
    assert "Traceback" not in err


@pytest.fixture(scope="module")
def server():
    import uvicorn

    from hapstab.explorer.app import create_app

    srv = uvicorn.Server(uvicorn.Config(create_app(), host="127.0.0.1", port=0,
                                        log_level="critical", lifespan="off"))
    t = threading.Thread(target=srv.run, daemon=True)
    t.start()
    deadline = time.monotonic() + 20
    while not srv.started:
        assert time.monotonic() < deadline, "the server did not start"
        time.sleep(0.02)
    port = srv.servers[0].sockets[0].getsockname()[1]
    yield port
    srv.should_exit = True
    t.join(10)


def _raw(port: int, data: bytes) -> bytes:
    """What the server answers to ``data`` (it may close the connection before reading all
    of it: what it sent before is the answer)."""
    out = b""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        try:
            s.sendall(data)
            s.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        try:
            while chunk := s.recv(65536):
                out += chunk
        except OSError:
            pass
    return out


RAW = [
    b"GARBAGE\r\n\r\n",
    b"\x00\x01\x02\xff\r\n\r\n",
    b"GET /api/v1 HTTP/1.1\r\nHost: x\r\nBadHeaderWithoutColon\r\n\r\n",
    b"GET /api/v1 HTTP/1.1\r\nHost: x\r\nContent-Length: -5\r\n\r\n",
    b"GET /static/../../../etc/passwd HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
    b"GET /static/..%2f..%2f..%2fetc%2fpasswd HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
    b"POST /api/v1/kmax HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
    b"Content-Length: 99999999\r\nConnection: close\r\n\r\n{\"kind\":",
    b"POST /api/v1/kmax HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
    b"Content-Length: 5\r\nConnection: close\r\n\r\n{\"kin",
    b"POST /api/v1/kmax HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
    b"Transfer-Encoding: chunked\r\nConnection: close\r\n\r\n" + b"ffff\r\n" + b"x" * 70000,
    b"POST /api/v1/kmax HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
    b"Content-Length: abc\r\nConnection: close\r\n\r\n{}",
    b"GET /api/v1 HTTP/1.1\r\nHost: x\r\n" + b"X-Long: " + b"a" * 1_000_000 + b"\r\n\r\n",
]


@pytest.mark.parametrize("data", RAW, ids=range(len(RAW)))
def test_raw_malformed_http(server, data):
    reply = _raw(server, data)
    if reply:                          # (a connection closed without a word is allowed)
        status = int(reply.split(b" ", 2)[1])
        assert 400 <= status < 500, reply[:300]
        assert b"Traceback" not in reply
        head, _, body = reply.partition(b"\r\n\r\n")
        if b"application/json" in head and body:
            d = json.loads(body)
            assert set(d) == {"error", "parameter", "status"}
    r = httpx.get(f"http://127.0.0.1:{server}/api/v1", timeout=10)   # still serving
    assert r.status_code == 200


def test_a_real_request_over_http(server):
    r = httpx.post(f"http://127.0.0.1:{server}/api/v1/check",
                   json={"kind": "peb", "options": {"K": 5, "delay": 2}}, timeout=30)
    assert r.status_code == 200 and r.json()["verdict"] in ("stable", "unstable", "marginal")


def test_a_study_of_another_kind_is_one_line(tmp_path):
    study = tmp_path / "f.toml"
    study.write_text('kind = "4ch"\n[loop]\ndelay = 1\n')
    r = CliRunner().invoke(cli, ["explore", "--study", str(study), "--port", "0"])
    assert r.exit_code == 2
    assert r.stderr.count("\n") == 1 and "hve or peb" in r.stderr


def test_a_bad_study_loop_is_one_line(tmp_path):
    study = tmp_path / "f.toml"
    study.write_text('kind = "hve"\n[loop]\nmass = -1\nwhatever = 3\n')
    r = CliRunner().invoke(cli, ["explore", "--study", str(study), "--port", "0"])
    assert r.exit_code == 2 and "whatever" in r.stderr and r.stderr.count("\n") == 1


def test_without_the_extra_it_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "uvicorn", None)      # import uvicorn -> ImportError
    r = CliRunner().invoke(cli, ["explore", "--port", "0"])
    assert r.exit_code == 2
    assert "pip install 'hapstab[explore]'" in r.stderr and r.stderr.count("\n") == 1


def test_import_hapstab_does_not_import_the_web_stack():
    code = "import sys, hapstab, hapstab.cli.main; print(any(m.split('.')[0] in " \
           "('starlette', 'uvicorn', 'httpx', 'anyio') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": SRC}, timeout=60)
    assert out.stdout.strip() == "False", out.stderr


def test_another_host_warns(monkeypatch):
    import uvicorn

    from hapstab.cli import explore

    seen = {}

    def fake_serve(server, host, open_browser):
        seen.update(host=host, port=server.config.port, open=open_browser)

    monkeypatch.setattr(explore, "_serve", fake_serve)
    assert uvicorn.Server
    r = CliRunner().invoke(cli, ["explore", "--host", "0.0.0.0", "--port", "0", "--open"])
    assert r.exit_code == 0, r.output
    assert r.stderr.startswith("hapstab: warning: --host = 0.0.0.0") and r.stderr.count("\n") == 1
    assert seen == {"host": "0.0.0.0", "port": 0, "open": True}


@pytest.mark.parametrize("args,named", [
    (["--port", "-1"], "--port"), (["--port", "65536"], "--port"), (["--port", "abc"], "--port"),
    (["--port", "1e3"], "--port"), (["--host", "1_000"], "--host"),
    (["--host", "no.such.host.invalid"], "--host"), (["--host", "\udcff"], "--host"),
    (["--host", ""], "--host"), (["--host", "256.1.1.1"], "--host"),
    (["--study", "/nonexistent.toml"], "--study"), (["--study", ""], "--study"),
])
def test_hostile_options_are_one_line(args, named):
    r = CliRunner().invoke(cli, ["explore", *args])
    assert r.exit_code == 2, (args, r.output)
    lines = [ln for ln in r.stderr.splitlines() if not ln.startswith("hapstab: warning: ")]
    assert len(lines) == 1 and lines[0].startswith("hapstab: error: ") and named in lines[0]
    assert "Traceback" not in r.stderr


def test_a_port_in_use_is_one_line():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        r = CliRunner().invoke(cli, ["explore", "--port", str(port)])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and "cannot listen" in r.stderr


@pytest.mark.parametrize("host", ["localhost", "::1", "[::1]", "127.0.0.1", "127.0.0.2"])
def test_a_loopback_host_does_not_warn(monkeypatch, host):
    """--host localhost / ::1 / 127.x is this machine only: no 'other machines' warning."""
    from hapstab.cli import explore

    monkeypatch.setattr(explore, "_serve", lambda server, h, open_browser: None)
    monkeypatch.setattr(explore, "_check_listen", lambda h, port: None)   # (::1 may be absent)
    r = CliRunner().invoke(cli, ["explore", "--host", host, "--port", "0"])
    assert r.exit_code == 0, r.output
    assert r.stderr == ""
    assert explore.is_loopback(host)
    assert not explore.is_loopback("0.0.0.0") and not explore.is_loopback("192.168.1.2")
    assert not explore.is_loopback("localhost.example.com")
