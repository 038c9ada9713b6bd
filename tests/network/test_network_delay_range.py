"""Unknown constant delay in a range (issue 30, item 1), sample-synchronous receiver
(a delay acting between the samples: test_network_fraction_range.py):
the certified minimum over the range against the brute-force reference at every delay
of a >= 1000-point grid of transport delays (tests/references/brute.py, no hapstab)."""

import math

import numpy as np
import pytest
from tests.references import brute

from hapstab import Device, HapticLoop, SpringDamper, TeleoperationLoop, critical_stiffness
from hapstab.analysis.network.delay_range import delay_range_critical_stiffness, whole_delays
from hapstab.errors import ModelError

#: the reference's scan bisects to 1e-10 and the exact core's enclosure is tighter: 1e-6
#: is the acceptance's tolerance, with margin
RTOL = 1e-6


def _case(seed: int):
    rng = np.random.default_rng(20_000 + seed)
    T = float(rng.uniform(5e-4, 3e-3))
    lo = float(rng.uniform(0, 4)) * T
    hi = lo + float(rng.uniform(0.5, 4)) * T
    op = f"msd:{rng.uniform(0.01, 0.5):.6g},{rng.uniform(0, 2):.6g},{rng.uniform(1, 400):.6g}"
    if seed % 2:
        m, b, B = rng.uniform(0.05, 1), rng.uniform(0.05, 2), rng.uniform(0, 3)
        loop = HapticLoop(Device(m, b), SpringDamper(1.0, B), op, T, 0)
        ref = lambda n, _: brute.hve_loop(m, b, T, n, B, op)  # noqa: E731
    else:
        mm, ms, bm, bs = rng.uniform(0.01, 0.3, 4)
        B, env = rng.uniform(0, 0.5), f"spring:{rng.uniform(1, 300):.6g}"
        loop = TeleoperationLoop(Device(mm, bm), Device(ms, bs), SpringDamper(1.0, B),
                                 SpringDamper(1.0, B), op, env, T, 0)
        ref = lambda nf, nb: brute.peb_loop(mm, bm, ms, bs, T, nf, nb, B, B, 1.0, op,  # noqa: E731
                                            env)
    return loop, ref, lo, hi


def _check(seed: int) -> None:
    loop, ref, lo, hi = _case(seed)
    res = delay_range_critical_stiffness(loop, lo, hi)
    grid = np.linspace(lo, hi, 1000)
    # the receiver uses a sample from the first instant at or after its arrival
    ns = sorted({max(0, math.ceil(t / loop.period - 1e-9)) for t in grid})
    two = len(loop.controllers) == 2
    # PEB: each direction's delay anywhere on the grid, independently
    pairs = [(f, b) for f in ns for b in ns] if two else [(n, 0) for n in ns]
    kref = {pr: brute.stable_intervals(ref(*pr)).kmax for pr in pairs}
    for pr in pairs:                  # never above K_max at any delay of the grid
        assert (pr[0] + pr[1] if two else pr[0]) in res.delays_samples
        assert res.critical_stiffness <= kref[pr] * (1 + RTOL)
    assert res.critical_stiffness == pytest.approx(min(kref.values()), rel=RTOL)


@pytest.mark.parametrize("seed", range(10))
def test_range_minimum_against_the_brute_force_grid(seed):
    _check(seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(10, 60))
def test_range_campaign(seed):
    _check(seed)


def test_peb_round_trip_covers_every_pair_of_directions():
    # each direction anywhere in 1..3 samples: the minimum over all nine (n_f, n_b)
    # equals the minimum over the round trips 2..6
    loop = TeleoperationLoop(Device(0.02, 0.05), Device(0.05, 0.1), SpringDamper(1.0, 0.05),
                             SpringDamper(2.0, 0.02), "spring:1", "msd:0.01,0.1,200", 1e-3, 0)
    res = delay_range_critical_stiffness(loop, 1, 3, seconds=False)
    pairs = [critical_stiffness(loop.replace(delay_samples=f, delay_backward_samples=b))
             .critical_stiffness for f in range(1, 4) for b in range(1, 4)]
    assert res.critical_stiffness == pytest.approx(min(pairs), rel=1e-12)


def test_a_delay_on_an_instant_is_in_time():
    assert whole_delays(5e-3, 15e-3, 1e-3) == (5, 15)
    assert whole_delays(4.2e-3, 5.01e-3, 1e-3) == (5, 6)
    with pytest.raises(ModelError, match="end"):
        whole_delays(2e-3, 1e-3, 1e-3)
