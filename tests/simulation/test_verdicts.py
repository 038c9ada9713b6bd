"""The simulation verdict (issue #9): each reported false alarm is a test with the
right verdict; the wall only pushes; the encoder and the rest position are what a
haptics user expects."""

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli
from hapstab.simulation.run import quantize, simulate

CONFIDENT = ("high", "medium")


def run_json(args):
    r = CliRunner().invoke(cli, ["simulate", *args, "--json"])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


# ------------------------------------------------- 1. a force that starts late
@pytest.mark.parametrize("args", [
    "hve -K 150 --force step:1,0.5",
    "hve -K 150 --force step:1,0.45",
    "hve -K 100 -b 2 --force pulse:1,0.1,0.5",
    "peb -K 3 -n 4 --force step:1,1",
])
def test_late_force_on_a_loop_at_rest_is_bounded(args):
    d = run_json(args.split())
    assert d["linear_loop_verdict"] == "stable"
    assert d["verdict"] == "bounded" and d["confidence"] == "high"
    assert math.isfinite(d["growth_rate_per_s"]) and d["growth_rate_per_s"] < 0
    assert "1e+12" not in d["reason"]


# --------------------------------------------------------- 2. sine forcing
@pytest.mark.parametrize("hz", [1.0, 1.5, 2.0, 2.5, 3.0])
@pytest.mark.parametrize("seconds", ["5", "20"])
def test_sine_forcing_on_a_stable_loop_is_bounded(hz, seconds):
    d = run_json(["hve", "-K", "150", "--force", f"sine:1,{hz}", "-t", seconds])
    assert d["verdict"] == "bounded" and d["confidence"] == "high"
    # the verdict's rate is the loop's own (ln rho / T, -0.083 1/s), not a fit of
    # the forced steady state
    assert d["growth_rate_per_s"] == pytest.approx(d["linear_loop_growth_rate_per_s"], rel=1e-6)


def test_sine_forcing_on_an_unstable_loop_grows():
    d = run_json(["hve", "-K", "230", "--force", "sine:1,2"])
    assert d["linear_loop_verdict"] == "unstable"
    assert d["verdict"] == "unbounded" and d["confidence"] == "high"


# ------------------------------------------- 3. quantisation on an unstable loop
def test_quantised_unstable_loop_is_never_called_bounded():
    long = run_json(["hve", "-K", "210", "--resolution", "0.001", "-t", "100"])
    assert long["linear_loop_verdict"] == "unstable"
    assert long["verdict"] == "unbounded" and long["behaviour"] == "grows"
    assert long["confidence"] in CONFIDENT and long["growth_rate_per_s"] > 0
    short = run_json(["hve", "-K", "210", "--resolution", "0.001", "-t", "5"])
    # 5 s cannot show growth at the linearised rate (~0.017 1/s): say so, and how long
    assert short["verdict"] == "undecided" and short["confidence"] == "low"
    assert short["duration_hint_s"] >= 100


# ------------------------------------------------ 4. nonlinear runs in words
def test_a_run_that_settles_exactly_settles():
    d = run_json(["hve", "-K", "100", "-n", "3", "-b", "2", "-B", "0.5", "--wall", "0.001"])
    assert d["verdict"] == "bounded" and d["behaviour"] == "settles" and d["confidence"] == "high"


def test_bouncing_on_an_unstable_wall_is_a_limit_cycle_and_the_exact_verdict_says_linearised():
    d = run_json(["hve", "-K", "800", "-n", "5", "-b", "2", "--wall", "0.001"])
    assert d["verdict"] == "bounded" and d["behaviour"] == "limit cycle"
    assert d["limit_cycle_amplitude_m"] > 0 and 0 < d["limit_cycle_period_s"] < 5
    assert d["linear_loop_verdict"] == "unstable" and "linearised" in d["linear_loop"]
    assert "pole" not in d["reason"]


def test_linear_run_names_its_exact_verdict_for_this_loop():
    d = run_json(["hve", "-K", "100"])
    assert d["linear_loop"] == "this loop"


@pytest.mark.parametrize("args", ["hve -K 800 -n 5 -b 2 --wall 0.001",
                                  "hve -K 210 --resolution 0.001 -t 5",
                                  "hve -K 300 --saturation 0.5"])
def test_nonlinear_reasons_do_not_speak_of_poles(args):
    d = run_json(args.split())
    assert "pole" not in d["reason"] and "unit circle" not in d["reason"]


def test_table_shows_behaviour_limit_cycle_and_linearised_label():
    r = CliRunner().invoke(cli, ["simulate", "hve", "-K", "800", "-n", "5", "-b", "2", "--wall", "0.001"])
    assert r.exit_code == 0
    assert "limit cycle" in r.output and "linearised" in r.output


# -------------------------------------------------------------- 5. the wall
def _leaving_wall(**kw):
    # the device starts 2 mm inside a stiff, heavily damped wall and springs back
    # out: K e + B de/dt < 0 on the way out, so an unclamped damper pulls
    loop = h.HapticLoop(h.Device(0.1, 0.1), h.SpringDamper(500.0, 5.0), "spring:1", 1e-3, 0)
    return simulate(loop, 0.3, initial_position=0.002, rest_position=0.0, wall=0.0, **kw)


def test_the_wall_only_pushes_unless_asked_to_pull():
    pushes = _leaving_wall()
    u, c = pushes.controller_force[:, 0], pushes.contact
    assert np.all(u >= 0) and np.all(u[~c] == 0)
    pulls = _leaving_wall(wall_pulls=True)
    assert pulls.controller_force[:, 0].min() < -0.1     # the damper pulls by > 0.1 N
    assert pulls.nonlinear["wall_pulls"] is True and "wall_pulls" not in pushes.nonlinear


def test_wall_pulls_option_on_the_cli():
    base = "hve -K 500 -B 5 -m 0.1 -b 0.1 --x0 0.002 --rest 0 --wall 0 -t 0.3 --force none"
    assert run_json(base.split())["max_abs_force_device"] > 0
    r = CliRunner().invoke(cli, ["simulate", *base.split(), "--wall-pulls", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["nonlinear"]["wall_pulls"] is True


# ------------------------------------------------- 5. encoder, rest position
def test_encoder_reads_floor_by_default_and_nearest_on_request():
    x = np.array([-1.5e-3, -1e-3, -0.2e-3, 0.0, 0.5e-3, 0.9999e-3, 1e-3, 2.5e-3])
    np.testing.assert_array_equal(quantize(x, 1e-3) / 1e-3, [-2, -1, -1, 0, 0, 0, 1, 2])
    # ties away from zero, not to even (np.round would give -2, 0, 2)
    got = quantize(np.array([-1.5e-3, 0.5e-3, 2.5e-3]), 1e-3, "nearest") / 1e-3
    np.testing.assert_allclose(got, [-2, 1, 3])


def test_quantizer_is_checked():
    with pytest.raises(h.ModelError, match="quantizer"):
        simulate(h.paper_hve(), 0.1, resolution=1e-3, quantizer="round")


def test_springs_rest_where_the_ports_start():
    # at rest at x0 with nothing pushing: nothing moves (before: the operator's
    # spring pulled the device back to x = 0)
    res = simulate(h.paper_hve(1e-3, 3, 100.0, 0.02), 1.0, initial_position=0.01, wall=0.02)
    assert np.all(res.position == 0.01) and res.verdict.behaviour == "settles"
    assert not res.contact.any()
    peb = simulate(h.paper_peb(1e-3, 2, 5.0), 1.0, initial_position=[0.01, 0.01])
    # -k x and +k r enter through different ZOH products: equal up to rounding of 0.01
    np.testing.assert_allclose(peb.position, 0.01, rtol=0, atol=1e-15)
    assert peb.verdict.bounded
    # rest_position moves it: the same as a constant push k r
    a = simulate(h.paper_hve(1e-3, 3, 100.0), 1.0, rest_position=0.02)
    b = simulate(h.paper_hve(1e-3, 3, 100.0), 1.0, force=1.0 * 0.02, rest_position=0.0)
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-15)
    assert a.summary()["rest_position_m"] == [0.02]


def test_rest_position_is_checked():
    with pytest.raises(h.ModelError, match="rest_position"):
        simulate(h.paper_peb(), 0.1, rest_position=[0.0, 1.0, 2.0])


# ------------------------------------- the independent review's reproducers
@pytest.mark.parametrize("args", ["hve -n 100 -K 1 -t 0.068", "hve -n 200 -K 0.47 -t 0.1"])
def test_a_run_too_short_for_its_fit_is_undecided(args):
    # fewer snapshots than the state has entries: least squares fits anything
    d = run_json(args.split())
    assert d["linear_loop_verdict"] == "stable"
    assert d["verdict"] == "undecided" and d["confidence"] == "low"
    assert d["duration_hint_s"] > float(args.split()[-1])


def test_a_short_quantised_run_of_an_unstable_loop_is_not_bounded_by_proof():
    d = run_json(["hve", "-n", "20", "-K", "9.8", "--resolution", "1e-4", "-t", "0.022"])
    assert d["linear_loop_verdict"] == "unstable"
    assert d["verdict"] != "bounded"


@pytest.mark.parametrize("args", [
    "hve -K 100 --wall 0 --force sine:1,0.15",                  # a slow force: an excursion
    "hve -K 100 --wall 0 --x0 0.01 --rest 0 --force none -t 1",  # pushed out, still moving
    "hve -K 300 --wall 0.001 --x0 0.0043343333 --force step:1 -t 60",   # levels off by 600 s
])
def test_slow_or_levelling_motion_is_not_confident_growth(args):
    d = run_json(args.split())
    assert not (d["verdict"] == "unbounded" and d["confidence"] in CONFIDENT), d["reason"]


def test_slow_creep_is_not_a_drift_and_an_ulp_creep_has_settled():
    d = run_json(["hve", "-K", "5", "-B", "60", "--wall", "0", "--force", "step:1"])
    assert d["behaviour"] != "drifts"
    d = run_json(["hve", "-K", "100", "--operator", "none", "--wall", "0", "--x0", "0.01",
                  "--force", "none", "-t", "100"])
    assert d["verdict"] == "bounded" and d["behaviour"] == "settles"


def test_quantisation_bound_needs_an_asymptotically_stable_loop():
    # a free pair (rigid-body mode at z = 1) pushed by a step drifts away
    d = run_json(["peb", "-K", "3", "--operator", "none", "--environment", "none", "--resolution", "1e-5"])
    assert d["linear_loop_verdict"] == "marginal"
    assert d["verdict"] != "bounded" and d["basis"] != "bound"


@pytest.mark.parametrize("sat", [None, 5.0])
def test_a_growing_force_is_no_bounded_input(sat):
    res = simulate(h.paper_hve(stiffness=100.0), 20.0, force=lambda t: 0.5 * t, saturation=sat)
    v = res.verdict
    assert v.confidence == "low" and "force itself keeps growing" in v.reason
    assert v.basis != "bound"


def test_a_slow_ring_down_is_not_called_a_limit_cycle():
    d = run_json(["hve", "-K", "100", "--wall", "0.01", "--force", "sine:1,0.08"])
    assert d["behaviour"] != "limit cycle"
