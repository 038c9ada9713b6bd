"""Simulation through a network (issue 30, item 4): a varying delay and lost packets.

- a trace of constant delay d and no loss is today's simulation at delay d: bitwise
  against today's stepped path, to rounding against its block recurrence; and it equals
  the random mode with LO = HI = d, P = 0, bitwise;
- against the analyses: below the jitter bracket's stable_up_to random admissible delay
  sequences stay bounded; the destabilising pattern hapstab.jitter reports, replayed as a
  trace, grows while both constant delays at that K are bounded; with loss P the second
  moment over seeds grows at K above the mean-square K_max (where the loss-free loop is
  stable) and decays well below it;
- TDPA through a constant-delay network is today's TDPA run;
- bad trace files are refused naming row and column; seeds reproduce.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from hapstab import jitter, paper_hve, paper_peb
from hapstab.analysis.exact.core import stability
from hapstab.analysis.network.loss import loss_critical_stiffness
from hapstab.cli.main import cli
from hapstab.errors import HapstabError, ModelError
from hapstab.simulation import simulate
from hapstab.simulation.network import NetworkLine, from_ages
from hapstab.simulation.network_trace import NetworkTraceError, read_trace
from test_network_jitter import resonant_case

#: The network run is stepped sample by sample, today's linear run by a block recurrence
#: (many samples per matrix product): they differ by rounding only, which accumulates
#: over 2000 samples to 3.1e-14 (HVE) and 1.5e-14 (PEB) of the largest state measured;
#: 1e-12 leaves room and is still 10 orders below any modelling difference.
RECURRENCE_RTOL = 1e-12

LOOPS = [paper_hve(1e-3, 3, 200.0, 0.5), paper_peb(1e-3, 2, 10.0, 0.01)]


@pytest.mark.parametrize("loop", LOOPS, ids=["hve", "peb"])
def test_a_constant_trace_is_todays_simulation(loop):
    d = loop.delay_in_samples
    M = 2000
    net = simulate(loop, M * 1e-3, force="step:1", network={"delay_samples": np.full(M + 1, d)})
    stepped = simulate(loop, M * 1e-3, force="step:1", saturation=1e300)   # today's stepping
    linear = simulate(loop, M * 1e-3, force="step:1")
    assert np.array_equal(net.states, stepped.states)
    assert np.array_equal(net.controller_force, stepped.controller_force)
    err = np.abs(net.states - linear.states).max() / np.abs(linear.states).max()
    assert err <= RECURRENCE_RTOL
    assert net.verdict.verdict == linear.verdict.verdict
    rnd = simulate(loop, M * 1e-3, force="step:1",
                   network={"jitter": (int(d), int(d)), "loss": 0.0, "seed": 11})
    assert np.array_equal(rnd.states, net.states)
    assert net.nonlinear["network"]["age_samples_range"] == [d, d]


def test_tdpa_through_a_constant_network_is_todays_tdpa():
    loop = paper_peb(1e-3, 4, 8.0, 0.0)
    today = simulate(loop, 1.0, force="step:1", tdpa=True)
    net = simulate(loop, 1.0, force="step:1", tdpa=True, network={"jitter": (4, 4)})
    assert np.array_equal(today.states, net.states)
    assert np.array_equal(today.tdpa.observed, net.tdpa.observed, equal_nan=True)


def test_tdpa_through_a_varying_network_keeps_the_observed_energy():
    """Ryu, Artigas & Preusche 2010: each PO uses the other's input energy of the newest
    sample that has arrived; the network's W stays >= 0 up to rounding (the paper's
    observer and no cap: the PC dissipates exactly the deficit)."""
    loop = paper_peb(1e-3, 0, 30.0, 0.0)
    r = simulate(loop, 2.0, force="step:1", tdpa=True,
                 network={"jitter": (1, 6), "loss": 0.1, "seed": 4})
    W = r.tdpa.observed
    assert np.nanmin(W) >= -1e-12 * np.nanmax(np.abs(W))   # rounding of the energy sums
    assert r.tdpa.dissipated[-1].max() > 0                 # the PC did act


def test_ages_replayed_from_a_trace():
    rng = np.random.default_rng(3)
    for _ in range(20):
        lo, hi = int(rng.integers(0, 3)), int(rng.integers(3, 7))
        ages = [int(rng.integers(lo, hi + 1))]
        for _ in range(300):
            ages.append(int(rng.integers(lo, min(hi, ages[-1] + 1) + 1)))
        net = from_ages(ages)
        # the history arrives with the largest delay: start the sequence there
        line = NetworkLine(net, [0], [list(range(net.hi + 1))], len(ages) - 1)
        used = line.age[0]
        k0 = net.hi              # from here on the history no longer decides the age
        assert np.array_equal(used[k0:], np.array(ages)[k0:])
    with pytest.raises(ModelError, match=r"ages\[2\] = 4 after 2"):
        from_ages([1, 2, 4])


def test_random_delays_below_stable_up_to_stay_bounded_and_the_pattern_grows():
    loop, _ref, lo, hi = resonant_case(91)
    j = jitter(loop, (lo, hi))
    assert 0 < j.stable_up_to < j.unstable_from < j.constant_worst and not j.pattern_is_constant
    M = 4000
    dur = M * loop.period
    for seed in range(3):
        r = simulate(loop.with_stiffness(0.9 * j.stable_up_to), dur, initial_position=1e-3,
                     network={"jitter": (lo, hi), "seed": seed})
        assert r.verdict.verdict == "bounded", r.verdict.reason
        assert r.nonlinear["network"]["age_samples_range"] == [lo, hi]
    K = 1.02 * j.unstable_from        # above the pattern's threshold, below the constant worst
    ages = np.array([p[0] for p in j.pattern] * (M // len(j.pattern) + 1))[:M + 1]
    grows = simulate(loop.with_stiffness(K), dur, initial_position=1e-3, network=from_ages(ages))
    assert grows.verdict.verdict == "unbounded", grows.verdict.reason
    for d in (lo, hi):                # each constant delay alone is bounded at that K
        c = simulate(loop.with_stiffness(K).with_whole_delay(d), dur, initial_position=1e-3)
        assert c.verdict.verdict == "bounded"


def _second_moment(loop, K, P, x0, seeds):
    n = int(loop.delay_in_samples)
    m2 = [np.sum(simulate(loop.with_stiffness(K), 1.0, force=0.0, initial_position=x0,
                          network={"jitter": (n, n), "loss": P, "seed": s}).states ** 2, axis=1)
          for s in seeds]
    m2 = np.mean(m2, axis=0)
    return m2[:100].mean(), m2[450:550].mean(), m2[-100:].mean()


@pytest.mark.parametrize("loop, P, x0", [(paper_hve(1e-3, 2, 1.0, 0.5), 0.8, 1e-3),
                                         (paper_peb(1e-3, 1, 1.0, 0.01), 0.6, [1e-3, 0.0])],
                         ids=["hve", "peb"])
def test_loss_second_moment_grows_above_the_mean_square_kmax_and_decays_below(loop, P, x0):
    r = loss_critical_stiffness(loop, P)
    k_ms, k0 = r.critical_stiffness, r.loss_free_critical_stiffness
    above, below = 1.6 * k_ms, 0.5 * k_ms
    assert above < 0.99 * k0          # without the losses the loop is stable there
    assert stability(loop.with_stiffness(above)).verdict == "stable"
    seeds = range(16)
    first, mid, last = _second_moment(loop, above, P, x0, seeds)
    # measured x8.4 (HVE) and x4.5 (PEB) over the run, rising in both halves
    assert first < mid < last and last > 2.5 * first
    first, mid, last = _second_moment(loop, below, P, x0, seeds)
    # measured x0.21 (HVE) and x0.29 (PEB), falling in both halves
    assert first > mid > last and last < 0.5 * first
    # without the losses the same K decays: the growth above is the losses'
    lossless = simulate(loop.with_stiffness(above), 1.0, force=0.0, initial_position=x0)
    assert lossless.verdict.verdict == "bounded"


def test_seeds_reproduce_and_differ():
    loop = paper_hve(1e-3, 2, 50.0, 0.2)
    a, b, c = (simulate(loop, 0.5, initial_position=1e-3, network={"jitter": (1, 5), "loss": 0.1, "seed": s})
               for s in (7, 7, 8))
    assert np.array_equal(a.states, b.states) and not np.array_equal(a.states, c.states)
    assert a.nonlinear["network"]["held_fraction"] > 0


def _write(tmp_path, text, name="t.csv"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


GOOD = "sample,delay_samples,arrived\n0,1,1\n1,2,0\n2,1,1\n"


@pytest.mark.parametrize("text, words", [
    ("sample,delay,arrived\n0,1,1\n", ["row 1", "'delay'"]),
    ("sample,delay_samples\n0,1\n", ["row 1", "'arrived'"]),
    ("sample,time_s,delay_samples,arrived\n0,0,1,1\n", ["row 1", "'sample' or 'time_s'"]),
    ("sample,delay_samples,arrived\n0,1,1\n2,1,1\n", ["row 3", "'sample'", "expected 1"]),
    ("sample,delay_samples,arrived\n0,1,1\n1,1.5,1\n", ["row 3", "'delay_samples'"]),
    ("sample,delay_samples,arrived\n0,-1,1\n", ["row 2", "'delay_samples'"]),
    ("sample,delay_samples,arrived\n0,1,1\n1,2,maybe\n", ["row 3", "'arrived'"]),
    ("sample,delay_samples,arrived\n0,1,1\n1,x,1\n", ["row 3", "'delay_samples'", "not a number"]),
    ("sample,delay_samples,arrived\n0,1\n", ["row 2", "2 fields"]),
    ("# a comment\nsample,delay_samples,arrived\n0,1,1\n1,1,1,1\n", ["row 4", "4 fields"]),
    ("sample,delay_samples,arrived,delay_backward_samples\n0,1,1,1\n",
     ["row 1", "arrived_backward"]),
    ("", ["empty"]),
])
def test_bad_trace_files_are_refused_by_row_and_column(tmp_path, text, words):
    with pytest.raises(NetworkTraceError) as e:
        read_trace(_write(tmp_path, text))
    assert isinstance(e.value, HapstabError)
    for w in words:
        assert w in str(e.value)


def test_trace_times_lengths_and_directions(tmp_path):
    T = 1e-3
    timed = _write(tmp_path, "time_s,delay_samples,arrived\n0,1,1\n0.001,1,1\n0.0025,1,1\n")
    with pytest.raises(NetworkTraceError, match="row 4, column 'time_s'"):
        read_trace(timed, T)
    with pytest.raises(NetworkTraceError, match="needs the sampling period"):
        read_trace(timed)
    net = read_trace(_write(tmp_path, GOOD))
    assert net.delay_samples.tolist() == [[1, 2, 1]] and net.arrived.tolist() == [[True, False, True]]
    # a spreadsheet's "CSV UTF-8" (a byte-order mark first) is the same trace
    marked = tmp_path / "marked.csv"
    marked.write_text(GOOD, encoding="utf-8-sig")
    assert read_trace(str(marked)).delay_samples.tolist() == [[1, 2, 1]]
    with pytest.raises(ModelError, match="the trace has 3 rows"):
        simulate(paper_hve(T), 10 * T, network=net)
    two = {"delay_samples": np.ones((2, 20), int)}
    with pytest.raises(ModelError, match="2 directions; this loop has 1"):
        simulate(paper_hve(T), 10 * T, network=two)
    back = simulate(paper_peb(T), 10 * T, network=two)        # PEB: one row per direction
    assert back.nonlinear["network"]["age_samples_range"] == [1, 1]
    with pytest.raises(ModelError, match=r"loss = 1\.0"):
        simulate(paper_hve(T), 10 * T, network={"jitter": (1, 2), "loss": 1.0})
    with pytest.raises(ModelError, match="unknown field"):
        simulate(paper_hve(T), 10 * T, network={"jiter": (1, 2)})


def test_cli_simulate_through_a_network(tmp_path):
    rows = "".join(f"{k},{1 + k % 3},{int(k % 5 != 2)}\n" for k in range(201))
    path = _write(tmp_path, "sample,delay_samples,arrived\n" + rows)
    r = CliRunner().invoke(cli, ["simulate", "hve", "-K", "20", "--duration", "0.2",
                                 "--delay-trace", path, "--json"])
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    want = simulate(paper_hve(1e-3).with_stiffness(20.0), 0.2, force="step:1",
                    network=read_trace(path))
    assert d["verdict"] == want.verdict.verdict
    assert d["max_abs_position_device"] == float(np.abs(want.position).max())
    assert d["nonlinear"]["network"]["mode"] == "trace" and "constant delay 3" in d["linear_loop"]
    r = CliRunner().invoke(cli, ["simulate", "peb", "-K", "5", "--duration", "0.2",
                                 "--jitter", "1:4", "--loss", "0.1", "--seed", "9", "--json"])
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["nonlinear"]["network"]["seed"] == 9
    bad = _write(tmp_path, "sample,delay_samples,arrived\n0,1,1\n1,1,2\n", "bad.csv")
    r = CliRunner().invoke(cli, ["simulate", "hve", "-K", "20", "--delay-trace", bad])
    assert r.exit_code == 2 and "row 3, column 'arrived'" in r.stderr


def test_what_is_not_simulated_is_refused_and_a_long_run_is_budgeted():
    from hapstab import Device, SpringDamper
    from hapstab.budget import BudgetError
    from hapstab.models.fourchannel import FourChannelLoop

    four = FourChannelLoop(Device(0.015, 0.02), Device(0.015, 0.02), SpringDamper(1, 0),
                           SpringDamper(1, 0), None, None, 1e-3, 2)
    with pytest.raises(ModelError, match="4-channel"):
        simulate(four, 0.1, network={"jitter": (1, 2)})
    # stepped in Python: 3e6 samples are refused before any work (about 4 min estimated)
    with pytest.raises(BudgetError, match="3000000 samples"):
        simulate(paper_hve(1e-3), 3000.0, network={"jitter": (1, 3)})
