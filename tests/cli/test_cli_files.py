"""The observations of issue #11 on files and stdout, through the CLI: a bad target is
refused before any work and leaves nothing behind; no silent success on an empty path,
a full device, a closed stdout or an overflowed run; no external program for plots."""

import os
import subprocess
import sys

import pytest
from click.testing import CliRunner

import paths
from hapstab.cli.main import cli

SRC = str(paths.SRC)


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


def _closed_pipe(*args):
    """Run hapstab with stdout a pipe whose reader has gone (``hapstab ... | head -c 0``)."""
    env = {**os.environ, "PYTHONPATH": SRC}
    r_fd, w_fd = os.pipe()
    os.close(r_fd)
    try:
        return subprocess.run([sys.executable, "-m", "hapstab", *args], env=env, stdout=w_fd,
                              stderr=subprocess.PIPE, timeout=120)
    finally:
        os.close(w_fd)


@pytest.mark.parametrize("args", [
    ("kmax", "hve"),                                   # a rich table
    ("kmax", "hve", "--json"),                         # click.echo
    ("simulate", "hve", "-K", "9", "--duration", "1", "--csv", "-"),
    ("simulate", "hve", "-K", "9", "--duration", "1", "--csv", "/dev/stdout"),
])
def test_a_reader_that_closed_the_pipe_is_one_error_with_exit_2(args):
    r = _closed_pipe(*args)
    err = r.stderr.decode()
    assert r.returncode == 2, (r.returncode, err)
    assert err.count("\n") == 1 and "Broken pipe" in err.replace("broken pipe", "Broken pipe")


def test_csv_dash_is_standard_output_and_the_table_goes_to_stderr():
    r = run("region", "hve", "--K", "0:50", "--B", "0:2", "--resolution", "3", "--csv", "-")
    assert r.exit_code == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0] == "stiffness,virtual_damping,stable_exact,stable_grid" and len(lines) == 1 + 3 * 3
    assert "K-B stability region" in r.stderr and not os.path.exists("-")


@pytest.mark.parametrize("args,needle", [
    (("region", "hve", "--K", "0:50", "--B", "0:2", "--csv", "-", "--json"),
     "--csv and --json would both write to standard output"),
    (("simulate", "hve", "-K", "9", "--csv", "/dev/stdout", "--json"),
     "--csv and --json would both write to standard output"),
    (("simulate", "hve", "-K", "9", "--plot", "-"), "--plot = '-': a figure is written to a file"),
    (("boundary", "hve", "--csv", "-", "--json"), "would both write to standard output"),
])
def test_two_outputs_on_standard_output_are_refused(args, needle):
    _one_line_error(run(*args), needle)


def test_csv_and_plot_naming_one_file_are_refused_before_any_work(tmp_path):
    p = tmp_path / "out.svg"
    r = run("simulate", "hve", "-K", "9", "--csv", str(p), "--plot", str(tmp_path / "." / "out.svg"))
    _one_line_error(r, "the same file as --csv")
    assert not p.exists()
