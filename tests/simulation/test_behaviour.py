"""The nonlinear verdict on synthetic trajectories whose behaviour is known in
closed form (not from hapstab)."""

import math

import numpy as np
import pytest

from hapstab.simulation.behaviour import CLEAR, assess_nonlinear

T = 1e-3
t = np.arange(10001) * T                       # 10 s


def judge(x, **kw):
    X = np.asarray(x, float)[:, None]
    with np.errstate(invalid="ignore"):          # inf - inf in the overflow case
        S = np.column_stack([X[:, 0], np.gradient(X[:, 0], T)])
    return assess_nonlinear(S, X, T, **kw)


def test_decaying_oscillation_settles_at_its_rate():
    v = judge(np.exp(-0.8 * t) * np.sin(2 * np.pi * 5 * t))
    assert v.verdict == "bounded" and v.behaviour == "settles" and v.confidence == "high"
    # peak-to-peak over whole cycles decays like exp(-0.8 t); a cycle's ptp is its
    # first peak's, so the fit is within a few % of the rate
    assert v.growth_rate == pytest.approx(-0.8, rel=0.05)


def test_sustained_oscillation_is_a_limit_cycle_with_amplitude_and_period():
    v = judge(0.01 * np.sin(2 * np.pi * 4 * t + 0.3) + 0.002)
    assert v.verdict == "bounded" and v.behaviour == "limit cycle" and v.confidence == "high"
    # sampled at 1 kHz, a 4 Hz sine's peaks are missed by at most (pi 4e-3)^2/2 of it
    assert v.amplitude_m == pytest.approx(0.01, rel=1e-4)
    # period from upward crossings, each located to one sample (1e-3 s over 20 cycles)
    assert v.period_s == pytest.approx(1 / 4, abs=1e-3 / 10)


def test_growing_oscillation_grows_at_its_rate():
    v = judge(1e-4 * np.exp(0.6 * t) * np.sin(2 * np.pi * 4 * t))
    assert v.verdict == "unbounded" and v.behaviour == "grows" and v.confidence == "high"
    assert v.growth_rate == pytest.approx(0.6, rel=0.05)


def test_slow_growth_is_medium_and_slower_is_undecided():
    v = judge(np.exp(0.2 * t) * np.sin(2 * np.pi * 4 * t))   # x2.7 over the 5 s window
    assert v.verdict == "unbounded" and v.confidence == "medium"
    # x1.24 over the window, every stretch above the last: not yet a trend, not a cycle
    v = judge(np.exp(0.05 * t) * np.sin(2 * np.pi * 4 * t))
    assert v.verdict == "undecided" and v.duration_hint_s >= 20


def test_flat_envelope_is_undecided_when_the_linearised_loop_grows_too_slowly_to_show():
    x = 0.01 * np.sin(2 * np.pi * 3 * t)
    v = judge(x, linear_rate=0.01)
    assert v.verdict == "undecided" and v.confidence == "low"
    assert v.duration_hint_s >= 2 * math.log(CLEAR) / 0.01
    # growth at 1 1/s would have shown as x150 in the window: the cycle is real
    assert judge(x, linear_rate=1.0).behaviour == "limit cycle"


def test_a_bound_makes_growth_bounded_and_says_why():
    v = judge(1e-4 * np.exp(0.6 * t) * np.sin(2 * np.pi * 4 * t), bound="saturated")
    assert v.verdict == "bounded" and v.basis == "bound" and "saturated" in v.reason
    assert v.duration_hint_s > 10


def test_drift_settled_exactly_and_overflow():
    v = judge(0.01 * t, can_drift=True)
    assert v.verdict == "marginal" and v.behaviour == "drifts"
    # a steady one-way motion where every port has a spring is a slow creep, not a drift
    assert judge(0.01 * t).verdict == "undecided"
    # a slow exponential approach to rest is no drift either
    assert judge(0.01 * np.exp(-t / 12), can_drift=True).verdict == "undecided"
    x = np.exp(-3 * t)
    x[6000:] = x[6000]
    v = judge(x)
    assert v.behaviour == "settles" and v.basis == "observed" and "6" in v.reason
    x = np.exp(3 * t)
    x[-10:] = np.inf
    v = judge(x)
    assert v.verdict == "unbounded" and v.basis == "observed"


def test_motion_at_rounding_level_has_settled():
    x = 0.01 * np.exp(-8 * t)               # ptp at the end: 1e-37 of the start
    v = judge(x)
    assert v.behaviour == "settles" and v.confidence == "high"
