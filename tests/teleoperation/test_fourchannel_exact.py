"""Lawrence's 4-channel teleoperator in the exact core (issue 13, item 3).

* With PEB gains (C_1 = C_s, C_4' = C_m, no force channel) the 4-channel loop is
  analysed by the generic channel expansion (engine/expansion.py), a different code
  path from PEB's own two-port determinant: its K_max and stable intervals must equal
  PEB's to 1e-12 relative (both are certified to ~1e-15; 1e-12 leaves room for the
  Newton polish of a crossing in two differently rounded functions).
* The model's rules: K's reference controller, what is refused and why.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hapstab import (
    AnalysisError,
    Device,
    DiscreteController,
    ModelError,
    SpringDamper,
    TeleoperationLoop,
    critical_stiffness,
    mass_spring_damper,
    spring,
    transparency,
)
from hapstab.analysis.exact.core import exact_kmax_batch
from hapstab.engine.frequency import loop_response
from hapstab.models.fourchannel import FourChannelLoop
from lanes import draw

#: Both paths certify each crossing to ~1e-15 relative; the polish of a crossing in
#: two differently rounded characteristic functions leaves a few ulps more.
REL = 1e-12


def _random_peb(rng: np.random.Generator) -> dict:
    term = [None, lambda: spring(float(rng.uniform(10, 3000))),
            lambda: mass_spring_damper(float(rng.uniform(0, 1)), float(rng.uniform(0, 10)),
                                       float(rng.uniform(0, 500)))]
    op = term[int(rng.integers(3))]
    env = term[int(rng.integers(3))]
    Km = float(rng.uniform(10, 500))
    return dict(master=Device(float(rng.uniform(0.05, 2)), float(rng.uniform(0, 3))),
                slave=Device(float(rng.uniform(0.05, 2)), float(rng.uniform(0, 3))),
                master_controller=SpringDamper(Km, float(rng.uniform(-0.2, 3))),
                slave_controller=SpringDamper(Km * float(rng.choice([1.0, rng.uniform(0.2, 4)])),
                                              float(rng.uniform(-0.2, 3))),
                operator=op() if op else None, environment=env() if env else None,
                period=float(rng.choice([1e-3, 5e-4, 2e-3])),
                delay_samples=int(rng.integers(0, 9)),
                delay_backward_samples=int(rng.integers(0, 9)) if rng.random() < 0.3 else None)


def _close(a: float, b: float) -> bool:
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a - b) <= REL * max(abs(a), abs(b), 1e-300)


# 8 of the 24 seeds by default (each the same comparison on another random PEB; every
# kind of termination, unequal delays and ratios among them), the rest -m campaign
@pytest.mark.parametrize("seed", draw(range(24), 8))
def test_peb_gains_reproduce_peb(seed: int) -> None:
    kw = _random_peb(np.random.default_rng(1300 + seed))
    peb = critical_stiffness(TeleoperationLoop(**kw))
    four = critical_stiffness(FourChannelLoop(**kw))
    assert _close(four.critical_stiffness, peb.critical_stiffness), (four, peb)
    assert len(four.stable_intervals) == len(peb.stable_intervals)
    for (a0, a1), (b0, b1) in zip(four.stable_intervals, peb.stable_intervals, strict=True):
        assert _close(a0, b0) and _close(a1, b1)


def test_peb_gains_reproduce_peb_over_periods() -> None:
    kw = _random_peb(np.random.default_rng(77))
    periods = np.geomspace(1e-4, 1e-2, 9)
    a = exact_kmax_batch(TeleoperationLoop(**kw), periods)
    b = exact_kmax_batch(FourChannelLoop(**kw), periods)
    for sa, sb in zip(a, b, strict=True):
        assert _close(sb.kmax, sa.kmax) and len(sb.intervals) == len(sa.intervals)


def test_free_ports_with_peb_gains_have_the_rigid_mode() -> None:
    kw = dict(master=Device(0.3, 0.5), slave=Device(0.2, 0.8),
              master_controller=SpringDamper(100, 1), slave_controller=SpringDamper(100, 2),
              delay_samples=4)
    assert loop_response(FourChannelLoop(**kw)).rigid == 1
    r = critical_stiffness(FourChannelLoop(**kw))
    assert "rigid-body mode" in r.reason
    assert _close(r.critical_stiffness, critical_stiffness(TeleoperationLoop(**kw)).critical_stiffness)


def test_unequal_transmitted_gain_has_no_rigid_mode_and_differs_from_peb() -> None:
    kw = dict(master=Device(0.3, 0.5), slave=Device(0.2, 0.8),
              master_controller=SpringDamper(100, 1), slave_controller=SpringDamper(100, 2),
              delay_samples=2)
    four = FourChannelLoop(**kw, slave_from_master=SpringDamper(50, 2))
    assert loop_response(four).rigid == 0
    assert critical_stiffness(four).critical_stiffness != \
        critical_stiffness(TeleoperationLoop(**kw)).critical_stiffness


def test_k_is_the_slave_stiffness_when_the_master_has_none() -> None:
    loop = FourChannelLoop(Device(0.3, 0.5), Device(0.2, 0.8), SpringDamper(0, 1),
                           SpringDamper(80, 2), master_from_slave=SpringDamper(0, 0),
                           slave_from_master=SpringDamper(40, 2), force_to_master=1.0,
                           environment=spring(1000))
    assert loop.stiffness_reference == 1
    moved = loop.with_stiffness(200.0)
    assert moved.slave_controller.stiffness == 200.0
    assert moved.slave_from_master.stiffness == 100.0     # its ratio 1/2 kept
    assert moved.master_controller.stiffness == 0.0
    r = critical_stiffness(loop)
    assert 0 < r.critical_stiffness < math.inf


@pytest.mark.parametrize("field, value", [("fractional_delay", 0.5), ("position_scale", 2.0),
                                          ("force_scale", 0.5)])
def test_refused_parameters_name_themselves(field: str, value: float) -> None:
    with pytest.raises(ModelError, match=field):
        FourChannelLoop(Device(0.3, 0.5), Device(0.2, 0.8), **{field: value})


def test_force_gain_must_be_a_number() -> None:
    with pytest.raises(ModelError, match="force_to_master"):
        FourChannelLoop(Device(0.3, 0.5), Device(0.2, 0.8), force_to_master="1")


def test_a_general_position_controller_has_no_k_to_vary() -> None:
    loop = FourChannelLoop(Device(0.3, 0.5), Device(0.2, 0.8), SpringDamper(10, 1),
                           SpringDamper(10, 1), slave_from_master=DiscreteController((1.0,), (1.0,)))
    with pytest.raises(AnalysisError, match="SpringDamper"):
        critical_stiffness(loop)


def test_frequency_methods_refuse_force_channels_and_name_them() -> None:
    loop = FourChannelLoop(Device(0.3, 0.5), Device(0.2, 0.8), SpringDamper(10, 1),
                           SpringDamper(10, 1), force_to_master=1.0, environment=spring(100))
    for method in ("circle", "passivity"):
        with pytest.raises(AnalysisError, match="force"):
            critical_stiffness(loop, method)


@pytest.mark.parametrize("Ks", [100.0, 50.0])
def test_device_side_methods_match_peb_with_peb_gains(Ks: float) -> None:
    # the device side sums a port's channels: C_m x_m - C_4' z^-n x_s is PEB's row
    kw = dict(master=Device(0.3, 2), slave=Device(0.2, 3), master_controller=SpringDamper(100, 0.5),
              slave_controller=SpringDamper(Ks, 0.3), delay_samples=2)
    for method in ("passivity", "circle", "llewellyn"):
        a = critical_stiffness(TeleoperationLoop(**kw), method).critical_stiffness
        b = critical_stiffness(FourChannelLoop(**kw), method).critical_stiffness
        assert 0 < a < math.inf and _close(a, b), (method, a, b)
    ta, tb = transparency(TeleoperationLoop(**kw)), transparency(FourChannelLoop(**kw))
    assert np.allclose(ta.hybrid, tb.hybrid, rtol=REL, atol=0)


def test_a_transmitted_gain_changes_the_device_side() -> None:
    kw = dict(master=Device(0.3, 2), slave=Device(0.2, 3), master_controller=SpringDamper(100, 0.5),
              slave_controller=SpringDamper(100, 0.3), delay_samples=2)
    weak = FourChannelLoop(**kw, slave_from_master=SpringDamper(60, 0.3))
    assert not _close(critical_stiffness(weak, "passivity").critical_stiffness,
                      critical_stiffness(TeleoperationLoop(**kw), "passivity").critical_stiffness)


def test_to_dict_carries_every_gain() -> None:
    loop = FourChannelLoop(Device(0.3, 0.5), Device(0.2, 0.8), force_to_slave=0.5,
                           slave_force_feedback=-0.25)
    d = loop.to_dict()
    assert d["kind"] == "4ch" and d["force_to_slave"] == 0.5 and d["slave_force_feedback"] == -0.25
    assert d["slave_from_master"]["type"] == "spring-damper" and "position_scale" not in d


# ------------------------------------------------ force channels against the brute force
from references import brute  # noqa: E402  (the tests' own reference, no hapstab code)
from test_fourchannel_engine import _four_channel  # noqa: E402  (hapstab's + brute's loop)


@pytest.mark.parametrize("full", [False, True], ids=["force-reflection", "full"])
# 3 of the 6 seeds of each architecture by default, the rest -m campaign
@pytest.mark.parametrize("seed", draw(range(6), 3))
def test_force_channel_k_max_matches_the_brute_scan(seed: int, full: bool) -> None:
    """The exact core's K_max with force channels (termination force numerators, the held
    input, unequal delays) against the brute force's eigenvalue scan and bisection of its
    own closed loop. 1e-6: the scan brackets to 1e-10 but the eigenvalues of a loop whose
    poles crowd z = 1 carry ~1e-8 of rounding."""
    loop, bl, ref = _four_channel(np.random.default_rng(4000 + 100 * full + seed), full)
    ex = critical_stiffness(loop).stable_intervals
    scan = brute.stable_intervals(bl).intervals
    assert len(ex) == len(scan), (ex, scan)
    for (a0, a1), (b0, b1) in zip(ex, scan, strict=True):
        for a, b in ((a0, b0), (a1, b1)):
            assert (a == b == 0.0) or (math.isinf(a) and b > 1e12 * ref) or \
                a == pytest.approx(float(b), rel=1e-6)


def _second_radius(bl, K: float) -> float:
    """Largest |z| but the eigenvalue nearest z = 1 (the rigid mode, which the brute
    force does not deflate for 4-channel loops)."""
    A0, A1, _ = brute.full_matrices(bl)
    e = np.linalg.eigvals(A0 + K * A1)
    return float(np.sort(np.abs(np.delete(e, np.argmin(np.abs(e - 1.0)))))[-1])


@pytest.mark.parametrize("seed", range(4))
def test_free_ports_with_a_force_channel_divide_the_rigid_mode(seed: int) -> None:
    """No operator, a damper as environment: both ports free, so force reflection has a
    rigid mode (x_m = x_s); det M is divided by z - 1 with Rhat, the force numerator over
    y. The brute force's other eigenvalues cross |z| = 1 at the exact K_max."""
    rng = np.random.default_rng(4400 + seed)
    mm, ms = rng.uniform(0.1, 1, 2)
    bm, bs = rng.uniform(0.1, 2, 2)
    eb, kf, Bm, Bs = rng.uniform(0.5, 5), rng.uniform(0.2, 1.5), rng.uniform(0, 2), rng.uniform(0, 3)
    nf, nb = (int(v) for v in rng.integers(0, 5, 2))
    loop = FourChannelLoop(Device(mm, bm), Device(ms, bs), SpringDamper(0, Bm),
                           SpringDamper(100, Bs), None, mass_spring_damper(0.0, eb, 0.0), 1e-3,
                           nf, delay_backward_samples=nb, master_from_slave=SpringDamper(0, 0),
                           force_to_master=kf)
    assert loop_response(loop).rigid == 1
    r = critical_stiffness(loop)
    assert "rigid-body mode" in r.reason and 0 < r.critical_stiffness < math.inf
    bl = brute.four_channel_loop((mm, bm), (ms, bs), 1e-3, nf, nb, (0.0, Bm), (1.0, Bs),
                                 (1.0, Bs), (0.0, 0.0), c2=kf, environment=("msd", 0.0, eb, 0.0))
    K = r.critical_stiffness
    # 1e-4 either side: the eigenvalues next to the rigid mode at z = 1 are accurate to
    # ~1e-8 here, the crossing's |z| moves by ~1e-6 over that step
    assert _second_radius(bl, K * (1 - 1e-4)) < 1.0 < _second_radius(bl, K * (1 + 1e-4))
