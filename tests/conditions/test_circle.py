"""The circle criterion on the paper's loops, against the paper's closed forms
inside their range (13), (18), (28), (29), (34), the generic positive-real test
(a different code path: product-form rational evaluation), and invariants."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hapstab as h
from hapstab.analysis.conditions.circle import (
    APPROXIMATIONS,
    circle_test,
    critical_stiffness_circle,
    loop_inverse,
)
from hapstab.errors import AnalysisError
from hapstab.models.controllers import DiscreteController, SpringDamper
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.models.parts import Device

PERIODS = np.arange(1, 11) * 1e-3


def kmax(loop, **kw):
    return h.critical_stiffness(loop, method="circle", **kw).critical_stiffness


# ---------------------------------------------------------- the paper's numbers
def test_eq18_number_from_the_issue():
    # b = 0.1, T = 1 ms, n = 10, B = 0: (18) gives b / (T/2 + nT) = 9.5238 N/m
    res = h.critical_stiffness(h.paper_hve(delay_samples=10), method="circle")
    assert res.critical_stiffness == pytest.approx(9.5238, abs=5e-5)
    # (16)-(18): the worst case is the limit cos(wT) -> 1
    assert res.crossing_frequency_hz == 0.0


@pytest.mark.parametrize("make,n,line", [
    (h.paper_hve, 0, h.colgate), (h.paper_hve, 10, h.eq18),
    (h.paper_peb, 0, h.eq29), (h.paper_peb, 4, h.eq34)])
def test_forward_reproduces_the_closed_forms_at_B0(make, n, line):
    # at B = 0 the closed forms are exact consequences of the forward circle test;
    # 1e-9: the numerical minimum over w is refined far below that
    for T in PERIODS:
        loop = make(period=T, delay_samples=n)
        assert kmax(loop) == pytest.approx(line(loop).critical_stiffness, rel=1e-9)


@pytest.mark.parametrize("bm,bs", [(0.02, 0.05), (0.1, 0.03)])
def test_unequal_dampings_follow_eq28(bm, bs):
    # eq. (28) at B = 0, n = 0: b_m b_s/(b_m + b_s) > KT/2 (no b = min(b_m, b_s) bound)
    loop = h.paper_peb().replace(master=Device(0.015, bm), slave=Device(0.015, bs))
    assert kmax(loop) == pytest.approx(2 * bm * bs / ((bm + bs) * 1e-3), rel=1e-9)


@pytest.mark.parametrize("r", [0.5, 2.0, 3.0])
def test_unequal_stiffness_with_port_scaling(r):
    # K_s = r K_m, n = 0, B = 0, master row weighted by r: by hand,
    # det(diag(2 r b_m, 2 b_s) - K r T [[1, -1], [-1, 1]]) = 0 at K = 2 b_m b_s / (T (r b_m + b_s))
    bm, bs, T = 0.02, 0.05, 1e-3
    loop = TeleoperationLoop(Device(0.015, bm), Device(0.015, bs), SpringDamper(1.0),
                             SpringDamper(r), "spring:1", "spring:1", T, 0)
    assert kmax(loop) == pytest.approx(2 * bm * bs / (T * (r * bm + bs)), rel=1e-9)


def test_eq13_with_virtual_damping():
    # (13) b > KT/2 + B is exact for the forward test at n = 0 for every B
    for B in (0.0, 0.01, 0.05, 0.099):
        loop = h.paper_hve(damping=B)
        assert kmax(loop) == pytest.approx(2 * (0.1 - B) / 1e-3, rel=1e-9)
    assert kmax(h.paper_hve(damping=0.2)) == 0.0  # b < B: not PR for any K


@pytest.mark.parametrize("make,n", [(h.paper_hve, 0), (h.paper_hve, 10), (h.paper_peb, 0),
                                    (h.paper_peb, 4)])
def test_forward_is_the_most_conservative(make, n):
    for T in PERIODS:
        loop = make(period=T, delay_samples=n)
        f, b, t = (kmax(loop, approximation=a) for a in APPROXIMATIONS)
        assert f <= b * (1 + 1e-12) and f <= t * (1 + 1e-12)


def test_backward_and_tustin_give_no_bound_without_delay():
    for make in (h.paper_hve, h.paper_peb):
        for a in ("backward", "tustin"):
            assert math.isinf(kmax(make(), approximation=a))
    # ... although the exact loop does go unstable
    assert math.isfinite(h.critical_stiffness(h.paper_hve()).critical_stiffness)


# ---------------------------------------------- cross-check with the generic PR test
LOOPS = [
    h.paper_hve(), h.paper_hve(delay_samples=10), h.paper_hve(delay_samples=3, damping=0.04),
    HapticLoop(Device(0.15, 1.0), SpringDamper(1.0, 0.5), "spring:1", 1e-3, 1),
    h.paper_peb(), h.paper_peb(delay_samples=4), h.paper_peb(delay_samples=2, damping=0.005),
    TeleoperationLoop(Device(0.015, 0.02), Device(0.03, 0.05), SpringDamper(1.0, 0.002),
                      SpringDamper(3.0, 0.004), "spring:1", "spring:1", 2e-3, 3),
]


@pytest.mark.parametrize("loop", LOOPS)
@pytest.mark.parametrize("a", APPROXIMATIONS)
def test_kmax_is_where_the_pr_test_flips(loop, a):
    K = kmax(loop, approximation=a)
    if math.isinf(K):
        assert circle_test(loop.with_stiffness(1e6), a).positive_real
        return
    # 1e-5 either side: well above the rounding slack of the generic test
    assert circle_test(loop.with_stiffness(K * (1 - 1e-5)), a).positive_real
    bad = circle_test(loop.with_stiffness(K * (1 + 1e-5)), a)
    assert not bad.positive_real and bad.failed_condition == "hermitian part"


def test_pr_test_reports_the_worst_frequency_at_nyquist():
    # n = 0, B > 0: Re G^-1 = b + B cos w - KT/2, least at w = pi (Nyquist)
    loop = h.paper_hve(damping=0.05, stiffness=150.0)
    r = circle_test(loop)
    assert not r.positive_real
    assert r.margin == pytest.approx(2 * (0.1 - 0.05 - 150 * 1e-3 / 2), abs=1e-9)
    assert r.worst_frequency_hz == pytest.approx(500.0, rel=1e-6)


def test_unequal_controllers_need_port_scaling():
    loop = LOOPS[-1]
    assert critical_stiffness_circle(loop, scaling=None).critical_stiffness == 0.0
    assert circle_test(loop.with_stiffness(0.5), scaling=None).failed_condition == "unit-circle poles"
    assert critical_stiffness_circle(loop).critical_stiffness > 0


def test_inverse_matches_eq15_and_eq30():
    # eq. (15) and (30) written out by hand, evaluated on a few angles
    T, n, b, K, B = 2e-3, 3, 0.1, 40.0, 0.01
    th = np.array([0.1, 0.7, 2.9])
    z = np.exp(1j * th)
    g15 = b + z ** -n * (K + B * (z - 1) / (T * z)) * T / (z - 1)
    loop = HapticLoop(Device(0.1, b), SpringDamper(K, B), None, T, n)
    assert np.allclose(loop_inverse(loop)(th)[:, 0, 0], g15, rtol=1e-12)
    pe = TeleoperationLoop(Device(1, 0.02), Device(1, 0.03), SpringDamper(K, B), SpringDamper(K, 2 * B),
                           None, None, T, n)
    e = lambda Kx, Bx: Kx * T / (z - 1) + Bx / z  # noqa: E731
    g30 = np.array([[0.02 + e(K, B), -z ** -n * e(K, B)], [-z ** -n * e(K, 2 * B), 0.03 + e(K, 2 * B)]])
    assert np.allclose(loop_inverse(pe)(th), np.moveaxis(g30, 2, 0), rtol=1e-12)


# ------------------------------------------------------------------ sector
def test_finite_sector_is_less_conservative_and_tends_to_the_passive_limit():
    loop = h.paper_hve(delay_samples=2)
    passive = kmax(loop)
    small = kmax(loop, sector=0.5)
    mid, large = kmax(loop, sector=1e3), kmax(loop, sector=1e9)
    # bisection to 1e-6 relative
    assert small >= mid >= large >= passive * (1 - 1e-6)
    # G = 1/G^-1 has Re G ~ w^2 near w = 0, which the PR test of G resolves only down
    # to w ~ 1e-7: the passive limit is approached to ~1e-4, not to rounding
    assert large == pytest.approx(passive, rel=1e-4)
    assert small > passive * 1.01  # a damper of at most 0.5 Ns/m allows more stiffness


# ------------------------------------------------------------- invariants
@settings(max_examples=25, deadline=None)
@given(b=st.floats(0.01, 1.0), B=st.floats(-0.5, 0.5), T=st.floats(1e-4, 1e-2),
       n=st.integers(0, 12))
def test_forward_circle_equals_sampled_passivity(b, B, T, n):
    # two formulas (G^-1 of eq. 15 vs Colgate-Schenkel's (1 - e^-jw)/(1 - cos w))
    loop = HapticLoop(Device(0.1, b), SpringDamper(1.0, B), None, T, n)
    c = kmax(loop)
    p = h.critical_stiffness(loop, method="passivity").critical_stiffness
    assert c == pytest.approx(p, rel=1e-7, abs=1e-9)


@settings(max_examples=15, deadline=None)
@given(bm=st.floats(0.005, 0.5), bs=st.floats(0.005, 0.5), Bm=st.floats(-0.05, 0.05),
       Bs=st.floats(-0.05, 0.05), ratio=st.floats(0.25, 4.0), T=st.floats(1e-4, 1e-2),
       n=st.integers(0, 6))
def test_forward_circle_equals_multiport_passivity(bm, bs, Bm, Bs, ratio, T, n):
    loop = TeleoperationLoop(Device(0.1, bm), Device(0.1, bs), SpringDamper(1.0, Bm),
                             SpringDamper(ratio, Bs), None, None, T, n)
    c = kmax(loop)
    p = h.critical_stiffness(loop, method="passivity").critical_stiffness
    # 2x2 determinant roots on both sides: agreement to 1e-7 relative
    assert c == pytest.approx(p, rel=1e-7, abs=1e-9)


@pytest.mark.parametrize("n", [0, 3])
def test_forward_with_negative_b_beyond_device_damping_says_not_pr_for_any_k(n):
    loop = HapticLoop(Device(0.15, 0.1), SpringDamper(1.0, -0.13), "spring:1", 1e-3, n)
    res = h.critical_stiffness(loop, method="circle")
    assert res.critical_stiffness == 0.0 and res.stable_intervals == ()
    assert "not PR for any K >= 0" in res.reason
    assert not circle_test(loop.with_stiffness(0.0)).positive_real


@pytest.mark.parametrize("n", [0, 4])
def test_forward_with_negative_b_is_eq34_for_peb(n):
    loop = h.paper_peb(delay_samples=n, damping=-0.003)
    assert kmax(loop) == pytest.approx((0.02 - 0.006) / ((n + 1) * 1e-3), rel=1e-9)


def test_bad_input():
    with pytest.raises(AnalysisError, match="approximation"):
        kmax(h.paper_hve(), approximation="euler")
    with pytest.raises(AnalysisError, match="SpringDamper"):
        kmax(HapticLoop(Device(0.1, 0.1), DiscreteController((1.0,), (1.0,)), None, 1e-3, 0))
    with pytest.raises(AnalysisError, match="scaling"):
        kmax(h.paper_peb(), scaling="magic")
    for bad in (0.0, -1.0, "x", float("nan")):
        with pytest.raises(AnalysisError, match="sector"):
            kmax(h.paper_hve(), sector=bad)


def test_discrete_controller_equals_its_spring_damper():
    # H(z) = K + B(z-1)/(Tz) given as a general DiscreteController: same PR verdict and margin
    K, B, T, n = 8.0, 0.01, 1e-3, 3
    sd = HapticLoop(Device(0.15, 0.1), SpringDamper(K, B), None, T, n)
    dc = sd.replace(controller=DiscreteController(((K * T + B) / T, -B / T), (1.0, 0.0)))
    for a in APPROXIMATIONS:
        r1, r2 = circle_test(sd, a), circle_test(dc, a)
        assert r1.positive_real == r2.positive_real
        assert r1.margin == pytest.approx(r2.margin, abs=1e-9)  # same G^-1 to rounding
