"""The observations of issue #11 on files and stdout, through the CLI: a bad target is
refused before any work and leaves nothing behind; no silent success on an empty path,
a full device, a closed stdout or an overflowed run; no external program for plots."""

import os
import subprocess
import sys

import pytest
from click.testing import CliRunner

from hapstab.cli.main import cli

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")


def run(*args):
    return CliRunner().invoke(cli, list(args))


def _one_line_error(r, needle):
    assert r.exit_code == 2, (r.exit_code, r.stderr)
    assert r.stderr.count("\n") == 1 and needle in r.stderr, r.stderr


def test_a_bad_plot_target_leaves_no_csv_behind(tmp_path):
    csv = tmp_path / "run.csv"
    r = run("simulate", "hve", "-K", "9", "--duration", "1", "--csv", str(csv), "--plot",
            str(tmp_path / "bad.xyz"))
    _one_line_error(r, "--plot = ")
    assert "'xyz' is not a format" in r.stderr and not csv.exists()


@pytest.mark.parametrize("args,needle", [
    (("simulate", "hve", "-K", "9", "--csv", ""), "--csv = '': must be a file path"),
    (("simulate", "hve", "-K", "9", "--plot", ""), "--plot = '': must be a file path"),
    (("region", "hve", "--K", "0:9", "--B", "0:1", "--csv", ""), "--csv = '': must be a file path"),
    (("boundary", "hve", "--csv", ""), "--csv = '': must be a file path"),
    (("reproduce", "fig5", "--out", ""), "--out = '': must be a folder path"),
])
def test_an_empty_target_is_an_error(args, needle):
    _one_line_error(run(*args), needle)


@pytest.mark.parametrize("ext", ["pgf", "tex", "html"])
def test_plot_formats_that_need_an_external_program_are_refused_up_front(tmp_path, ext):
    r = run("simulate", "hve", "-K", "9", "--plot", str(tmp_path / f"o.{ext}"))
    _one_line_error(r, f"'{ext}' is not a format hapstab writes")
    assert os.listdir(tmp_path) == []


def test_a_plot_on_a_full_device_is_an_error():
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    r = run("region", "hve", "--K", "0:900", "--B", "0:20", "--resolution", "20", "--plot",
            "/dev/full")
    _one_line_error(r, "'(none)' is not a format")     # a device has no extension
    r = run("region", "hve", "--K", "0:900", "--B", "0:20", "--resolution", "20", "--csv",
            "/dev/full")
    _one_line_error(r, "--csv = '/dev/full': cannot write (No space left on device)")


def test_an_overflowed_run_writes_no_csv_of_inf(tmp_path):
    csv = tmp_path / "o.csv"
    r = run("simulate", "hve", "-K", "1e6", "--duration", "1", "--csv", str(csv), "--plot",
            str(tmp_path / "o.png"))
    _one_line_error(r, "CSV not written: the run overflowed double precision at t = ")
    assert os.listdir(tmp_path) == []


def test_the_plot_of_an_overflowed_run_shows_what_was_finite(tmp_path):
    r = run("simulate", "hve", "-K", "1e6", "--duration", "1", "--plot", str(tmp_path / "o.png"))
    assert r.exit_code == 0, r.stderr
    assert (tmp_path / "o.png").stat().st_size > 1000


def test_a_closed_stdout_is_an_error_not_a_lost_answer():
    env = {**os.environ, "PYTHONPATH": SRC}
    r = subprocess.run(f"'{sys.executable}' -m hapstab kmax hve >&-", shell=True, env=env,
                       capture_output=False, stderr=subprocess.PIPE, timeout=60)
    assert r.returncode == 2 and b"stdout is closed" in r.stderr


def test_an_answer_that_cannot_be_written_is_an_error():
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    env = {**os.environ, "PYTHONPATH": SRC}
    with open("/dev/full", "w") as full:
        r = subprocess.run([sys.executable, "-m", "hapstab", "kmax", "hve"], env=env, stdout=full,
                           stderr=subprocess.PIPE, timeout=60)
    assert r.returncode == 2 and b"No space left on device" in r.stderr
