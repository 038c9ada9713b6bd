# ruff: noqa: RUF001 - the unicode digits are the point of these tests
"""Issue 27: hostile but accepted inputs -- each observed item a test (the command lines
and calls of the issue, reproduced before the fix), and the class they belong to: an input
that passes validation and then runs away, or an error outside the HapstabError family."""

import math
import os
import warnings
from fractions import Fraction

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli
from hapstab.errors import HapstabError, ascii_float


def run(*args):
    return CliRunner().invoke(cli, list(args))


def refused(r, *needles):
    """Exit 2, one line "hapstab: error: ..." naming each needle; no traceback."""
    lines = r.stderr.strip().splitlines()
    assert r.exit_code == 2, (r.exit_code, r.stderr, r.exception)
    assert len(lines) == 1 and lines[0].startswith("hapstab: error: "), lines
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


# ------------------------------------------------------------ 1. a tiny filter cutoff
@pytest.mark.parametrize("cutoff", ["1e-320", "5e-324", "1e-12"])
def test_a_cutoff_below_any_representable_pole_is_refused(cutoff):
    refused(run("kmax", "hve", "--velocity-filter", f"lowpass:{cutoff}", "--json"),
            "velocity filter cutoff", "too low")


def test_the_cutoff_bound_is_where_the_pole_leaves_one():
    """1 - exp(-2 pi f_c T) against the bound, at the period the loop has: just above
    it the loop is built and analysed (a K_max), just below it is refused."""
    from hapstab.models.controllers import MIN_FILTER_GAIN

    T = 1e-3
    edge = MIN_FILTER_GAIN / (2 * math.pi * T)
    ok = h.HapticLoop(h.Device(0.15, 0.1), h.FilteredSpringDamper(
        1.0, 0.1, velocity_filter=h.VelocityFilter("lowpass", cutoff_hz=edge * 1.01)), period=T)
    assert h.critical_stiffness(ok).critical_stiffness > 0
    with pytest.raises(HapstabError, match="cutoff"):
        ok.replace(controller=h.FilteredSpringDamper(
            1.0, 0.1, velocity_filter=h.VelocityFilter("lowpass", cutoff_hz=edge * 0.99)))
    with pytest.raises(HapstabError, match="too low for the period 1e-06"):
        ok.replace(period=1e-6)      # the same filter, degenerate at a shorter period


# ------------------------------------------------------------ 2, 3. special and deep study files
@pytest.mark.parametrize("path", ["/dev/zero", "/dev/urandom", "/dev/null", "."])
def test_a_study_that_is_not_a_regular_file_is_refused(path):
    refused(run("--study", path, "kmax", "hve"), "not a regular file")


def test_a_fifo_study_is_refused_without_waiting(tmp_path):
    fifo = tmp_path / "study.toml"
    os.mkfifo(fifo)                  # no writer: a blocking open would wait forever
    refused(run("--study", str(fifo), "kmax", "hve"), "not a regular file")


@pytest.mark.parametrize("args", [("simulate", "hve", "-K", "1", "--delay-trace"),
                                  ("identify",)])
@pytest.mark.parametrize("path", ["/dev/zero", "/dev/urandom", "fifo"])
def test_a_trace_or_log_that_is_not_a_regular_file_is_refused(args, path, tmp_path):
    # every reader of a user's file goes through hapstab.reading.read_bounded: /dev/zero
    # as a delay trace or an identification log read forever before
    if path == "fifo":
        path = str(tmp_path / "log.csv")
        os.mkfifo(path)
    refused(run(*args, path), "not a regular file")


def test_a_huge_trace_is_refused_before_it_is_read(tmp_path):
    from hapstab.simulation.network_trace import MAX_TRACE_BYTES
    p = tmp_path / "trace.csv"
    with open(p, "wb") as fh:
        fh.truncate(MAX_TRACE_BYTES + 1)        # sparse: no disk used
    refused(run("simulate", "hve", "-K", "1", "--delay-trace", str(p)), "bytes")


def test_a_huge_study_is_refused_before_it_is_read(tmp_path):
    from hapstab.cli.study import MAX_STUDY_BYTES

    p = tmp_path / "big.toml"
    with open(p, "wb") as fh:
        fh.truncate(MAX_STUDY_BYTES + 1)          # sparse: no disk used
    refused(run("--study", str(p), "kmax", "hve"), "bytes")


@pytest.mark.parametrize("depth", [17, 3000])
@pytest.mark.parametrize("shape", ["[", "{a="])
@pytest.mark.parametrize("command", ["kmax", "run", "sweep"])
def test_deep_nesting_is_a_user_error(tmp_path, depth, shape, command):
    close = {"[": "]", "{a=": "}"}[shape]
    p = tmp_path / "deep.toml"
    p.write_text('kind = "hve"\nx = ' + shape * depth + "1" + close * depth + "\n")
    args = {"kmax": ["--study", str(p), "kmax", "hve"], "run": ["run", str(p)],
            "sweep": ["sweep", str(p), "--out", str(tmp_path / "o")]}[command]
    refused(run(*args), "nested")


# ------------------------------------------------------------ 4. an extreme rest position
@pytest.mark.parametrize("rest", ["1e308", "-1e308", "1e12"])
def test_an_extreme_rest_position_is_refused(rest):
    refused(run("limit-cycle", "hve", "-K", "20", "--resolution", "1e-4", "--rest", rest),
            "rest_position_m")


def test_a_far_but_representable_rest_is_analysed():
    loop = h.paper_hve(1e-3, 0).with_stiffness(20.0)
    r = h.limit_cycles(loop, resolution_m=1e-4, rest_position_m=1.0)
    assert r.rest_position_m == 1.0
    with pytest.raises(HapstabError, match="rest_position_m"):
        h.limit_cycles(loop, coulomb_friction_N=0.1, rest_position_m=1e300)


# ------------------------------------------------------------ 7. errors outside the family
with warnings.catch_warnings():
    warnings.simplefilter("ignore")       # (numpy warns making these longdoubles themselves)
    TINY, HUGE = np.longdouble("1e-4940"), np.longdouble("1e5000")


@pytest.mark.parametrize("call", [
    lambda: h.paper_hve(delay_samples=TINY),
    lambda: h.NO_IMPEDANCE(None), lambda: h.NO_IMPEDANCE("x"), lambda: h.NO_IMPEDANCE(b"1"),
    lambda: h.NO_IMPEDANCE([None]), lambda: h.NO_IMPEDANCE({}),
    lambda: h.paper_hve(delay_samples=HUGE)])
def test_errors_stay_in_the_family(call):
    with pytest.raises(HapstabError):
        call()


@pytest.mark.parametrize("call,what", [
    (lambda: h.build(h.paper_hve(1e-3, 2), periods=[HUGE]), "period"),
    (lambda: h.build(h.paper_hve(1e-3, 2), periods=Fraction(10 ** 400, 3)), "periods"),
    (lambda: h.stability_region(h.paper_hve(1e-3, 2), (0, 5e-324), (0, 1), 5), "too narrow"),
    (lambda: h.stability_region(h.paper_hve(1e-3, 2), (0, 1), (1e300, 1e300 * (1 + 1e-15)),
                                5), "B = ")])
def test_values_found_by_the_api_fuzz_are_refused(call, what):
    """tests/cli/test_fuzz.py's draw of issue 27's kinds of values found these: an overflow
    warning or an OverflowError (numbers beyond a double), a divide overflow (a window
    narrower than its grid's steps)."""
    with pytest.raises(HapstabError, match=what):
        call()


def test_far_boundary_points_of_a_tiny_window_are_quietly_outside():
    r = h.stability_region(h.paper_hve(1e-3, 2), (0, 1e-300), (0, 1), 5)   # warnings: errors
    assert r.stable_exact.shape == (5, 5) and r.stable_exact.all()     # (K < 1e-300 N/m)
    assert np.isnan(h.NO_IMPEDANCE(complex(math.nan, 0)))


def test_whole_delays_of_any_real_type_still_work():
    from fractions import Fraction

    for n in (Fraction(3), np.float32(3), np.longdouble(3), np.int8(3), 3.0):
        assert h.paper_hve(delay_samples=n).delay_samples == 3
    assert h.NO_IMPEDANCE(np.array([1j, 2.0])).shape == (2,)


# ------------------------------------------------------------ 8. numbers and conflicting options
@pytest.mark.parametrize("text", ["𝟐", "１", "1_000", "٣", "0x10", "1e", "²"])
def test_ascii_float_refuses_what_python_float_takes(text):
    with pytest.raises(ValueError):
        ascii_float(text)


@pytest.mark.parametrize("args", [
    ["kmax", "hve", "-m", "𝟐"], ["kmax", "hve", "-T", "１"], ["kmax", "hve", "-m", "1_000"],
    ["kmax", "hve", "-n", "３"], ["kmax", "hve", "--rate", "１kHz"],
    ["kmax", "hve", "--operator", "msd:1,𝟐,3"], ["kmax", "hve", "--velocity-filter", "average:𝟐"],
    ["boundary", "hve", "-T", "1ms:2ms:𝟐"], ["boundary", "hve", "-n", "0,1_0"],
    ["region", "hve", "--K", "0:100", "--B", "0:1", "--resolution", "1_2"],
    ["region", "hve", "--B", "0:1", "--K", "0:１00"]])
def test_unicode_digits_and_separators_are_not_numbers(args):
    refused(run(*args), args[-1])           # the message quotes what was refused


def test_plain_numbers_still_read():
    assert [ascii_float(t) for t in ("2", " -1.5e3 ", ".5", "5.", "+1E-3")] == \
        [2.0, -1500.0, 0.5, 5.0, 1e-3]
    assert run("kmax", "hve", "-m", "2", "-T", "1ms").exit_code == 0


def test_an_empty_overlay_lets_no_warning_through(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = run("region", "hve", "--K", "0:100", "--B", "0:1", "--resolution", "12",
                "--overlay", "", "--plot", str(tmp_path / "r.png"))
    assert r.exit_code == 0 and "warning" not in r.stderr.lower(), r.stderr


# ------------------------------------------------------------ 9. symbolic links in a sweep
SWEEP = 'kind = "hve"\n[loop]\ndelay = 2\n[sweep.axes]\nperiod = [0.001, 0.002]\n'


@pytest.mark.parametrize("force", [False, True])
def test_a_sweep_never_writes_or_deletes_through_a_linked_chunks_folder(tmp_path, force):
    (tmp_path / "s.toml").write_text(SWEEP)
    target, out = tmp_path / "elsewhere", tmp_path / "out"
    target.mkdir()
    out.mkdir()
    (target / "chunk-000000.parquet").write_bytes(b"someone else's")
    (out / "chunks").symlink_to(target)
    r = run("sweep", str(tmp_path / "s.toml"), "--out", str(out), "--workers", "1",
            *(["--force"] if force else []))
    refused(r, "symbolic link")
    assert sorted(os.listdir(target)) == ["chunk-000000.parquet"]
    assert (target / "chunk-000000.parquet").read_bytes() == b"someone else's"


@pytest.mark.parametrize("name", ["manifest.json", "summary.json", "chunks/chunk-000000.parquet"])
def test_a_sweep_refuses_a_linked_file_of_its_own(tmp_path, name):
    (tmp_path / "s.toml").write_text(SWEEP)
    victim, out = tmp_path / "victim", tmp_path / "out"
    victim.write_text("keep me")
    (out / "chunks").mkdir(parents=True)
    (out / name).symlink_to(victim)
    refused(run("sweep", str(tmp_path / "s.toml"), "--out", str(out), "--workers", "1",
                "--force"), "symbolic link")
    assert victim.read_text() == "keep me"


def test_a_run_never_writes_through_a_linked_variant_folder(tmp_path):
    """The class of item 9 in ``hapstab run``: a variant's folder linked elsewhere got the
    run's kmax.json written into its target (tests/cli/test_fuzz.py's linked-folder draw
    catches it too)."""
    (tmp_path / "s.toml").write_text('kind = "hve"\n[loop]\ndelay = 2\n[[variant]]\n'
                                     'name = "b"\nvirtual-damping = 1\n[run.kmax]\n')
    victim, out = tmp_path / "victim", tmp_path / "out"
    victim.mkdir()
    out.mkdir()
    (victim / "kmax.json").write_text("keep me")
    (out / "b").symlink_to(victim)
    refused(run("run", str(tmp_path / "s.toml"), "--out", str(out)), "b is a symbolic link")
    assert os.listdir(victim) == ["kmax.json"] and (victim / "kmax.json").read_text() == "keep me"
    assert sorted(os.listdir(out)) == ["b"]             # refused before any work or folder


# ------------------------------------------------------------ 5. robust stops at its budget
def test_robust_stops_at_the_time_budget_with_a_sound_gap():
    """The issue's box ran 478 s; with a 1 s budget it stops after about 1 s (plus one
    batch), and its bounds enclose the exact K_max of the operator it names. (The budget
    was 3 s: its stop gave the same bounds as at 1 s, 0 <= 105.105 <= 105.105 N/m, so
    the shorter run asks the same question of the same answer.)"""
    import time

    from hapstab.analysis.robust.robust import robust_critical_stiffness
    from hapstab.models.operators import operator_box

    loop = h.paper_hve(1e-3, 10)
    box = operator_box(mass=(0.2, 1), damping=(1, 10), stiffness=(100, 1000))
    t = time.perf_counter()
    r = robust_critical_stiffness(loop, box, max_seconds=1.0)
    took = time.perf_counter() - t
    assert not r.converged and r.stopped == "time" and "time budget" in r.reason
    assert took < 30                  # 1 s and the batch under way (a few s on a busy machine)
    assert 0 <= r.critical_stiffness <= r.operator_critical_stiffness <= r.upper_bound * (1 + 1e-9)
    assert r.to_dict()["stopped"] == "time"


# ------------------------------------------------------------ 6. API calls refused up front
@pytest.mark.parametrize("call,what", [
    (lambda: h.boundary(h.paper_hve(1e-3, 2), periods=np.linspace(1e-4, 1e-2, 10 ** 6),
                        delays=range(100)), "boundary"),
    (lambda: h.boundary(h.paper_hve(1e-3, 2), periods=[1e-3], delays=np.arange(10 ** 7)),
     "delay"),
    (lambda: h.build(h.paper_hve(1e-3, 2), periods=np.full(10 ** 7, 1e-3)), "build"),
    (lambda: h.build(h.paper_hve(1e-3, 2), periods=np.full(10 ** 6, 1e-3)), "build")])
def test_huge_api_arrays_are_refused_in_seconds(call, what):
    import time

    t = time.perf_counter()
    with pytest.raises(HapstabError, match=what):
        call()
    assert time.perf_counter() - t < 10       # was 13-24 s of checking, then minutes of work


def test_a_bad_period_among_many_is_still_named():
    T = np.full(10 ** 5, 1e-3)
    T[777] = -1.0
    with pytest.raises(HapstabError, match="period = -1"):
        h.build(h.paper_hve(1e-3, 2), periods=T)
    with pytest.raises(HapstabError, match="period = -1"):
        h.boundary(h.paper_hve(1e-3, 2), periods=T, delays=[0])


# ------------------------------------------------------------ 12. TDPA on the true port energy
def _held_terms(r):
    x, u, T = r.position[:, 0], r.controller_force[:, 0], r.period
    v = np.concatenate([[0.0], np.diff(x)]) / T
    dx = np.concatenate([np.diff(x), [0.0]])
    err = np.abs(u * (dx - v * T))               # sample j's prediction error
    S = np.concatenate([[0.0], np.cumsum(err)[:-1]])
    return u * v * T, S


def test_the_paper_observer_guarantees_nothing_about_the_true_energy_below_b_over_T():
    """The issue's run: K = 2 K_max = 19.07 N/m, far below b/T = 100 N/m; the observed
    energy stays >= 0 while the true port energy falls to about -17.5 mJ."""
    loop = h.paper_hve(1e-3, 10).with_stiffness(19.07)
    r = h.simulate(loop, 40.0, force="step:1", tdpa=True)
    assert r.tdpa.observed.min() > -1e-15          # rounding only (the PC resets W)
    assert r.port_energy.min() < -0.01             # -17.5 mJ measured


@pytest.mark.parametrize("n,K,duration", [(10, 19.07, 40.0), (10, 140.0, 20.0),
                                          (10, 2e4, 10.0), (2, 60.0, 20.0)])
def test_the_held_observer_bounds_the_true_energy_by_its_prediction_errors(n, K, duration):
    """docs/guide/tdpa.md: E[k] >= -(S[k] + max(p[k], 0)), S the summed one-sample
    prediction errors; the allowance 1e-12 J is rounding of sums of ~1e4 terms of 1e-3 J."""
    r = h.simulate(h.paper_hve(1e-3, n).with_stiffness(K), duration, force="step:1",
                   tdpa={"observer": "held"})
    p, S = _held_terms(r)
    E = r.port_energy[:, 0]
    assert np.all(E >= -(S + np.maximum(p, 0)) - 1e-12)
    if K < 100:                                       # the case: E >= 0 to rounding
        assert E.min() > -1e-15


# ------------------------------------------------------------ 10. a hang-up mid-body
def test_a_client_hanging_up_mid_body_is_not_an_internal_error(capfd):
    """The ASGI receive channel says http.disconnect after part of the body: the server
    answers (to nobody) without logging an internal error or a traceback."""
    import anyio

    from hapstab.explorer.app import create_app

    app = create_app()
    sent = []

    async def main():
        msgs = [{"type": "http.request", "body": b'{"kind": "hve", "opt', "more_body": True},
                {"type": "http.disconnect"}]

        async def receive():
            return msgs.pop(0) if msgs else {"type": "http.disconnect"}

        async def send(m):
            sent.append(m)

        scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1",
                 "method": "POST", "scheme": "http", "path": "/api/v1/kmax", "raw_path":
                 b"/api/v1/kmax", "query_string": b"", "root_path": "",
                 "headers": [(b"host", b"127.0.0.1"), (b"content-type", b"application/json"),
                             (b"content-length", b"400")],
                 "client": ("127.0.0.1", 5555), "server": ("127.0.0.1", 8765)}
        await app(scope, receive, send)

    anyio.run(main)
    err = capfd.readouterr().err
    assert "internal error" not in err and "Traceback" not in err, err
    starts = [m for m in sent if m["type"] == "http.response.start"]
    assert not starts or starts[0]["status"] == 400


# ------------------------------------------------------------ 10. a superseded computation ends
def test_a_superseded_running_computation_is_ended_at_once():
    """A slow region (seconds) of channel "slider", then a kmax of the same channel: the
    region's worker process is ended, its request answered 409 within about a second of
    the kmax's arrival (before: it ran to its end and answered 200), the kmax 200."""
    import time

    import anyio
    import httpx

    from hapstab.explorer.app import create_app

    app = create_app()
    # ~8 s on the 2-core dev machine (the CLI's region at these options), so that no
    # runner, however fast, ends it within the 1.5 s before the kmax arrives (CI's did at
    # delay 10, resolution 300).
    slow = {"kind": "hve", "options": {"K": "0:100", "B": "0:5", "delay": 40,
                                       "resolution": 600}}
    fast = {"kind": "hve", "options": {"delay": 1}}
    out = {}

    async def main():
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://127.0.0.1",
                                     timeout=120) as c:
            async def post(name, cmd, body, seq):
                r = await c.post(f"/api/v1/{cmd}", json=body, headers={
                    "X-Hapstab-Channel": "slider", "X-Hapstab-Seq": str(seq)})
                out[name] = (r.status_code, time.perf_counter(), r.text)

            async with anyio.create_task_group() as tg:
                tg.start_soon(post, "region", "region", slow, 1)
                await anyio.sleep(1.5)                 # the region's worker is computing
                out["sent"] = time.perf_counter()
                tg.start_soon(post, "kmax", "kmax", fast, 2)

    anyio.run(main)
    assert out["region"][0] == 409, out["region"]
    assert out["kmax"][0] == 200, out["kmax"]
    assert out["region"][1] - out["sent"] < 1.0        # polled every 20 ms, then ended


# ------------------------------------------------------------ 6. a whole study run's budget
def _many_variants(tmp_path, n):
    p = tmp_path / "many.toml"
    p.write_text('kind = "hve"\n[loop]\ndelay = 2\n' + "".join(
        f'[[variant]]\nname = "v{i}"\nvirtual-damping = {i * 1e-3}\n' for i in range(n))
        + "[run.kmax]\n")
    return p


def test_a_whole_study_run_is_charged_before_any_work(tmp_path):
    """20,000 variants x kmax is 20,001 analyses of at least 40 ms: 13 min, refused in one
    line before a folder is made (the budget of 1 s here stands for the 5 min: 30 variants
    need 1.24 s)."""
    from hapstab import budget

    p = _many_variants(tmp_path, 30)
    with budget.limits(seconds=1.0):
        r = run("run", str(p), "--out", str(tmp_path / "o"))
    refused(r, "run: 31 analyses", "would need about")
    assert not (tmp_path / "o").exists()
    with budget.limits(seconds=1.0):
        r = run("--yes", "run", str(p), "--out", str(tmp_path / "o"), "--only", "v1")
    assert r.exit_code == 0, r.stderr


# ------------------------------------------------------------ 5. robust's progress when piped
def test_robust_says_its_progress_when_piped_and_stops_at_the_budget(monkeypatch):
    """stderr not a terminal (CliRunner's): plain progress lines at the piped rate (here
    quiet 0 s, one every 0.25 s, standing for 10 s and 10 s), then the budgeted stop's
    answer with its gap; the 1 s budget stands for the default 5 min. (It was 3 s and a
    line every 0.5 s: the same ~4-6 lines, and the search is as far from converging.)"""
    import json

    from hapstab import budget
    from hapstab.cli import output

    monkeypatch.setattr(output, "PIPED_QUIET_S", 0.0)
    monkeypatch.setattr(output, "PIPED_EVERY_S", 0.25)
    args = ["robust", "hve", "--mass", "0.25", "--damping", "0.8", "--rate", "2kHz",
            "--delay-s", "10ms", "--operator-mass", "0.2:1", "--operator-damping", "1:10",
            "--operator-stiffness", "100:1000"]
    with budget.limits(seconds=1.0):
        r = run(*args)
    assert r.exit_code == 0, r.stderr
    lines = r.stderr.strip().splitlines()
    assert lines and all(ln.startswith("hapstab: progress: robust K_max: ") for ln in lines), lines
    assert "time budget" in r.stdout and "NOT converged" in r.stdout
    with budget.limits(seconds=1.0):
        r = run(*args, "--json")                   # --json: no progress, the stop in the JSON
    assert r.exit_code == 0 and r.stderr == "", r.stderr
    d = json.loads(r.stdout)
    assert d["stopped"] == "time" and d["critical_stiffness"] <= d["operator_critical_stiffness"]


def test_a_quick_piped_command_prints_no_progress():
    r = run("boundary", "hve", "-T", "1ms:2ms:3", "-n", "0,1,2")
    assert r.exit_code == 0 and r.stderr == "", r.stderr
