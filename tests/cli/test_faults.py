"""Fault injection on the writing commands (issue #11): SIGINT and SIGKILL at seeded
moments, a full disk (a file-size limit), and four concurrent writers. Each run must
leave either the old file or the complete new one, byte for byte the file of an
uninterrupted run; Ctrl-C exits 130 saying "interrupted"."""

import os
import random
import resource
import signal
import subprocess
import sys
import time

import pytest

import paths
from lanes import draw

SRC = str(paths.SRC)
OLD = b"the previous file\n"

#: writing commands, each with a target of its own (the {out} placeholder). Sized so that
#: the computation still fills most of a run after the ~0.3-0.4 s of imports, so the
#: seeded moments (0.2-1.0 of the run) land mid-computation or mid-write: region at 120
#: rows (was 200) and boundary at 20 periods (was 40) still compute for ~70 % of their
#: run; reproduce's 2 periods (was 3) still commit several pending files together.
COMMANDS = {
    "simulate-csv": ["simulate", "hve", "-K", "9", "--duration", "60", "--csv", "{out}"],
    "simulate-plot": ["simulate", "hve", "-K", "9", "--duration", "20", "--plot", "{out}.png"],
    "region-csv": ["region", "hve", "--K", "0:900", "--B", "0:20", "--resolution", "120",
                   "--csv", "{out}"],
    "boundary-csv": ["boundary", "hve", "--period", "0.001:0.01:20", "-n", "0,1,2,5,10",
                     "--csv", "{out}"],
    "reproduce-folder": ["reproduce", "fig5", "--periods", "0.002,0.006", "--out", "{out}"],
}


def _argv(name, out):
    return [sys.executable, "-m", "hapstab", *[a.format(out=out) for a in COMMANDS[name]]]


def _target(name, out):
    if name.endswith("folder"):
        os.makedirs(out, exist_ok=True)
        return os.path.join(out, "fig5.csv")       # the folder's table (its SVG has a date)
    return out + ".png" if name.endswith("plot") else out


def _env():
    return {**os.environ, "PYTHONPATH": SRC, "OPENBLAS_NUM_THREADS": "1"}


@pytest.fixture(scope="module")
def references(tmp_path_factory):
    """Each command's file from an uninterrupted run, and how long the run took."""
    d = tmp_path_factory.mktemp("ref")
    refs = {}
    for name in COMMANDS:
        out = str(d / name)
        t0 = time.monotonic()
        r = subprocess.run(_argv(name, out), env=_env(), capture_output=True, timeout=120)
        assert r.returncode == 0, r.stderr.decode()
        with open(_target(name, out), "rb") as fh:
            refs[name] = (fh.read(), time.monotonic() - t0)
    return refs




#: every writing command under each signal; the default lane runs 5 of the 15, evenly
#: spaced (indices 0, 4, 7, 10, 14: each command once, SIGINT and SIGTERM once, SIGKILL
#: three times), the rest -m campaign (tests/lanes.py)
SIGNAL_CASES = [(name, sig) for name in COMMANDS
                for sig in (signal.SIGINT, signal.SIGKILL, signal.SIGTERM)]


#: the tests of `references` on one worker: it is built once per xdist worker
@pytest.mark.xdist_group("faults-references")
@pytest.mark.parametrize("name,sig", draw(SIGNAL_CASES, 5, ids=lambda c: f"{c[0]}-{c[1].name}"))
def test_a_signal_leaves_the_old_file_or_the_whole_new_one(references, tmp_path, name, sig):
    ref, took = references[name]
    rng = random.Random(f"{name}-{sig}")      # seeded moments, spread over the run
    for frac in (rng.uniform(0.2, 0.6), rng.uniform(0.6, 1.0)):
        out = str(tmp_path / f"{name}-{frac:.3f}")
        target = _target(name, out)
        with open(target, "wb") as fh:
            fh.write(OLD)
        p = subprocess.Popen(_argv(name, out), env=_env(), stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE)
        time.sleep(frac * took)
        p.send_signal(sig)
        _, err = p.communicate(timeout=120)
        with open(target, "rb") as fh:
            got = fh.read()
        assert got in (OLD, ref), f"{name}: a partial or different file after {sig!r}"
        if p.returncode != 0 and sig == signal.SIGINT:
            # 130 and one line once hapstab runs; during Python's start-up (importing
            # numpy) the interpreter itself dies by SIGINT, which a shell reports as 130 too
            assert (p.returncode == 130 and b"interrupted" in err) or p.returncode == -2, \
                err.decode()      # (the file may be the new one: interrupted after the rename)
        if p.returncode != 0 and sig == signal.SIGTERM:
            assert (p.returncode == 143 and b"terminated" in err) or p.returncode == -15, \
                err.decode()
        if sig != signal.SIGKILL:          # an interrupt or SIGTERM cleans up; SIGKILL cannot
            folder = os.path.dirname(target)
            assert not [f for f in os.listdir(folder) if f.endswith(".part")]


def _limit_file_size():
    resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # a write past the limit fails with EFBIG


@pytest.mark.parametrize("name", ["simulate-csv", "region-csv"])
def test_a_full_disk_is_an_error_naming_the_file_and_leaves_the_old_one(tmp_path, name):
    out = str(tmp_path / name)
    with open(out, "wb") as fh:
        fh.write(OLD)
    r = subprocess.run(_argv(name, out), env=_env(), capture_output=True, timeout=120,
                       preexec_fn=_limit_file_size)
    err = r.stderr.decode()
    # one error line; a long computation's piped progress lines may come before it
    lines = [ln for ln in err.splitlines() if not ln.startswith("hapstab: progress:")]
    assert r.returncode == 2 and len(lines) == 1, err
    assert f"--csv = '{out}': cannot write" in err
    with open(out, "rb") as fh:
        assert fh.read() == OLD
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".part")]


@pytest.mark.xdist_group("faults-references")
def test_four_concurrent_writers_leave_one_complete_file(references, tmp_path):
    name = "simulate-csv"
    out = str(tmp_path / "shared.csv")
    procs = [subprocess.Popen(_argv(name, out), env=_env(), stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE) for _ in range(4)]
    errs = [p.communicate(timeout=120)[1] for p in procs]
    assert [p.returncode for p in procs] == [0] * 4, errs
    with open(out, "rb") as fh:
        assert fh.read() == references[name][0]


def test_a_ctrl_c_that_an_extension_module_turned_into_an_import_error_exits_130():
    """pybind11 (scipy.optimize's HiGHS) re-raises a Ctrl-C during its initialisation as
    ``ImportError: initialization failed`` from the KeyboardInterrupt: still an interrupt."""
    code = (
        "import builtins, sys\n"
        "real = builtins.__import__\n"
        "def fake(name, *a, **k):\n"
        "    if name == 'hapstab.cli.main':\n"
        "        try:\n"
        "            raise KeyboardInterrupt()\n"
        "        except KeyboardInterrupt as e:\n"
        "            raise ImportError('initialization failed') from e\n"
        "    return real(name, *a, **k)\n"
        "builtins.__import__ = fake\n"
        "from hapstab.cli import main\n"
        "main(['simulate', 'hve', '-K', '9'])\n")
    r = subprocess.run([sys.executable, "-c", code], env=_env(), capture_output=True,
                       timeout=60)
    assert r.returncode == 130 and r.stderr.decode().strip() == "hapstab: interrupted", \
        r.stderr.decode()


def test_a_ctrl_c_that_ended_a_string_exec_exits_130_under_python_m(tmp_path):
    """CPython marks a KeyboardInterrupt that ended an ``exec`` of source text (as
    dataclasses and namedtuples do while a module imports) as unhandled even when it is
    caught, and under ``python -m`` then ends the process by SIGINT (-2) whatever
    ``sys.exit`` says: seen under load, a Ctrl-C during a sweep's start. The CLI's exit
    clears the mark (``hapstab.cli.main._exit_interrupted``)."""
    (tmp_path / "ctrl_c_probe.py").write_text(
        "import click\n"
        "def interrupted(self, ctx):\n"
        "    exec('raise KeyboardInterrupt', {})\n"
        "click.Command.invoke = interrupted\n"
        "from hapstab.cli import main\n"
        "main(['simulate', 'hve', '-K', '9'])\n")
    r = subprocess.run([sys.executable, "-m", "ctrl_c_probe"], env=_env(), cwd=tmp_path,
                       capture_output=True, timeout=60)
    assert r.returncode == 130 and r.stderr.decode().strip() == "hapstab: interrupted", \
        (r.returncode, r.stderr.decode())


def test_an_import_error_without_an_interrupt_is_not_called_one():
    code = (
        "import builtins\n"
        "real = builtins.__import__\n"
        "def fake(name, *a, **k):\n"
        "    if name == 'hapstab.cli.main':\n"
        "        raise ImportError('a broken install')\n"
        "    return real(name, *a, **k)\n"
        "builtins.__import__ = fake\n"
        "from hapstab.cli import main\n"
        "main(['simulate', 'hve', '-K', '9'])\n")
    r = subprocess.run([sys.executable, "-c", code], env=_env(), capture_output=True,
                       timeout=60)
    assert r.returncode == 1 and b"a broken install" in r.stderr and \
        b"interrupted" not in r.stderr, r.stderr.decode()
