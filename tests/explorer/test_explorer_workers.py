"""The explorer's worker processes (:mod:`hapstab.explorer.workers`): workers wait before
requests come and serve one after another; one still computing a superseded request is
ended at once; one that met a bug, or served its quota, is replaced; a Ctrl-C at the
terminal leaves the waiting ones to the explorer."""

import json
import os
import signal
import time

import pytest

pytest.importorskip("starlette")

from hapstab.explorer import workers
from hapstab.explorer.api import ApiError, check_request

PEB = check_request("kmax", {"kind": "peb", "options": {"delay": 4}})
#: ~16 s in-process on this machine (within the explorer's budget): still computing
#: when the test ends it
LONG = ["region", "peb", "--K", "0:50", "--B", "0:1", "--resolution", "200", "--delay", "20",
        "--json"]


def _answer(job: workers.Job, timeout_s: float = 60.0) -> str:
    end = time.monotonic() + timeout_s
    while not job.ready():
        assert time.monotonic() < end, "no answer"
        time.sleep(0.005)
    return job.result()


def test_a_worker_serves_one_request_after_another():
    pids = []
    for _ in range(3):
        job = workers.Job("command", PEB)
        pids.append(job.process.pid)
        assert json.loads(_answer(job))["critical_stiffness"] > 0
        job.stop()
    # each answered worker is a spare again: the three requests found one of them
    waiting = {w[0].pid for w in workers._SPARE}
    assert set(pids) <= waiting and len(waiting) <= workers.MAX_IDLE
    assert all(w[0].is_alive() for w in workers._SPARE)


def test_a_refusal_leaves_the_worker_serving():
    job = workers.Job("command", ["kmax", "hve", "--mass", "-1", "--json"])
    with pytest.raises(ApiError) as e:
        _answer(job)
    assert e.value.parameter == "mass"
    pid, process = job.process.pid, job.process
    job.stop()
    assert process.is_alive() and pid in {w[0].pid for w in workers._SPARE}


def test_a_superseded_computation_is_ended_at_once():
    job = workers.Job("command", LONG)
    process = job.process
    time.sleep(0.3)
    assert not job.ready()
    t = time.monotonic()
    job.stop()
    assert time.monotonic() - t < 2.0
    assert process._closed or not process.is_alive()   # ended and reaped
    assert all(w[0] is not process for w in workers._SPARE)


def test_a_bug_ends_its_worker():
    job = workers.Job("code", None)           # not a request body: a bug, reported as such
    process = job.process
    with pytest.raises(RuntimeError, match="AttributeError in the worker process"):
        _answer(job)
    job.stop()
    assert all(w[0] is not process for w in workers._SPARE)


def test_a_worker_is_replaced_after_its_quota(monkeypatch):
    monkeypatch.setattr(workers, "MAX_REQUESTS", 1)
    job = workers.Job("command", PEB)
    process = job.process
    _answer(job)
    job.stop()
    assert all(w[0] is not process for w in workers._SPARE)


def test_ctrl_c_leaves_the_waiting_workers_to_the_explorer():
    workers.warm()
    w = workers._SPARE[0]
    os.kill(w[0].pid, signal.SIGINT)
    time.sleep(0.3)
    assert w[0].is_alive()
    job = workers.Job("command", PEB)      # and they still answer
    assert json.loads(_answer(job))["critical_stiffness"] > 0
    job.stop()
