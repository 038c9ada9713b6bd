"""Exact sampled-data passivity (Colgate & Schenkel 1997) against eq. (1), the
issue's 732.05 N/m, an independent brute-force evaluation of the literal
Colgate-Schenkel inequality written here, and the invariant that passivity (and
the forward circle test) never promise more than the exact stability limit."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hapstab as h
from hapstab.analysis.conditions.passivity import critical_stiffness_passivity, sampled_passivity
from hapstab.errors import AnalysisError
from hapstab.models.controllers import DiscreteController, SpringDamper
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.models.parts import Device, mass_spring_damper, spring


def kmax(loop, method="passivity", **kw):
    return h.critical_stiffness(loop, method=method, **kw).critical_stiffness


@pytest.mark.parametrize("b,B,T", [(0.1, 0.0, 1e-3), (0.1, 0.03, 1e-3), (1.0, 0.5, 5e-3),
                                   (0.3, 0.29, 2e-4), (0.05, 0.08, 1e-3),
                                   (0.1, -0.03, 1e-3), (1.0, -0.5, 5e-3), (0.3, -0.29, 2e-4),
                                   (0.05, -0.08, 1e-3), (0.2, -1e-6, 1e-4)])
def test_no_delay_is_eq1_exactly(b, B, T):
    # eq. (1): b > KT/2 + |B|  ->  K_max = 2 (b - |B|)/T (0 when |B| >= b), either sign of B
    loop = HapticLoop(Device(0.15, b), SpringDamper(1.0, B), "spring:1", T, 0)
    assert kmax(loop) == pytest.approx(max(0.0, 2 * (b - abs(B)) / T), rel=1e-12, abs=1e-9)


@pytest.mark.parametrize("B", [-0.02, -0.06])
def test_negative_b_verdict_flips_at_eq1(B):
    # n = 0, B < 0: margin = b - |B| - KT/2, worst at w -> 0 (not at Nyquist as for B > 0)
    K = 2 * (0.1 - abs(B)) / 1e-3
    loop = HapticLoop(Device(0.15, 0.1), SpringDamper(K * (1 - 1e-6), B), None, 1e-3, 0)
    r = sampled_passivity(loop)
    assert r.passive and r.margin == pytest.approx(K * 1e-6 * 1e-3 / 2, rel=1e-3)
    assert r.worst_frequency_hz < 1e-3
    assert not sampled_passivity(loop.with_stiffness(K * (1 + 1e-6))).passive


@pytest.mark.parametrize("loop", [
    HapticLoop(Device(0.15, 0.1), SpringDamper(1.0, -0.15), "spring:1", 1e-3, 0),
    HapticLoop(Device(0.15, 0.1), SpringDamper(1.0, -0.12), None, 1e-3, 5),
    h.paper_peb(delay_samples=2, damping=-0.011),
])
def test_negative_b_beyond_device_damping_is_not_passive_for_any_k(loop):
    res = h.critical_stiffness(loop, method="passivity")
    assert res.critical_stiffness == 0.0 and res.stable_intervals == ()
    assert "not passive for any K >= 0" in res.reason and "missing" in res.reason
    assert not sampled_passivity(loop.with_stiffness(0.0)).passive


def test_issue_number_732():
    # n = 1, b = 1, T = 1 ms, B = 0.5: the boundary is not the straight line (18)
    loop = HapticLoop(Device(0.15, 1.0), SpringDamper(1.0, 0.5), "spring:1", 1e-3, 1)
    K = kmax(loop)
    assert K == pytest.approx(732.05, abs=0.005)  # the issue quotes two decimals
    assert K < h.eq18(loop).critical_stiffness  # (18) promises (b+B)/(1.5T) = 1000
    # the literal inequality is tight (to rounding) at the reported worst frequency
    res = h.critical_stiffness(loop, method="passivity")
    w = res.details["worst_frequency_rad_s"] * 1e-3
    H = K + 0.5 * (1 - np.exp(-1j * w)) / 1e-3
    rhs = (1e-3 / 2) * np.real((1 - np.exp(-1j * w)) * H * np.exp(-1j * w)) / (1 - np.cos(w))
    assert w > 0.1 and rhs == pytest.approx(1.0, abs=1e-9)


def _brute_kmax(b, B, T, n):
    """Literal Colgate-Schenkel inequality, bisection on K over a fine grid of w;
    w >= 1e-3/T keeps 1 - cos wT free of cancellation at 1e-10 relative."""
    th = np.linspace(1e-3, math.pi, 400_001)
    z = np.exp(1j * th)

    def rhs(K, B):
        H = K + B * (1 - 1 / z) / T
        return (T / 2) * np.real((1 - np.exp(-1j * th)) * H * np.exp(-1j * n * th)) / (1 - np.cos(th))

    per_k, from_b = rhs(1.0, 0.0), rhs(0.0, B)  # the right-hand side is linear in K

    def passive(K):
        return np.all(b >= K * per_k + from_b)

    lo, hi = 0.0, 10 * b / T
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if passive(mid) else (lo, mid)
    return lo


@pytest.mark.parametrize("b,B,T,n", [(1.0, 0.5, 1e-3, 1), (0.1, 0.02, 2e-3, 4), (0.2, 0.3, 1e-3, 2),
                                     (0.1, 0.0, 1e-3, 10), (0.2, -0.05, 1e-3, 3),
                                     (1.0, -0.5, 1e-3, 1)])
def test_matches_brute_force(b, B, T, n):
    loop = HapticLoop(Device(0.1, b), SpringDamper(1.0, B), None, T, n)
    got, brute = kmax(loop), _brute_kmax(b, B, T, n)     # each once (both deterministic)
    # the brute grid stops at w = 1e-3/T: its K can only be larger, by O((n w)^2) ~ 1e-4
    assert got == pytest.approx(brute, rel=2e-4)
    assert got <= brute * (1 + 1e-9)


def test_verdict_margin_and_frequency():
    # n = 0: margin = b - B - KT/2 (damping to spare), worst at Nyquist because of B
    loop = HapticLoop(Device(0.15, 0.1), SpringDamper(100.0, 0.02), None, 1e-3, 0)
    r = sampled_passivity(loop)
    assert r.passive and r.margin == pytest.approx(0.1 - 0.02 - 0.05, abs=1e-12)
    assert r.worst_frequency_hz == pytest.approx(500.0, rel=1e-6)
    bad = sampled_passivity(loop.with_stiffness(200.0))
    assert not bad.passive and bad.failed_condition == "colgate-schenkel"
    assert bad.margin == pytest.approx(0.1 - 0.02 - 0.1, abs=1e-12)


def test_peb_no_delay_is_b_over_T():
    # two-port, C_m = C_s, B = 0, n = 0: eigenvalues b and b - KT  ->  K_max = b/T = eq. (29)
    for T in (1e-3, 4e-3):
        loop = h.paper_peb(period=T)
        assert kmax(loop) == pytest.approx(h.eq29(loop).critical_stiffness, rel=1e-9)


def test_discrete_controller_verdict_only():
    # H(z) = 50 - 25 z^-1 is K = 25 N/m, B = 0.025 N*s/m: b = 0.1 > KT/2 + B = 0.0375, passive
    # (spare 0.0625); H = 300 - 150 z^-1 is K = 150, B = 0.15: 0.075 + 0.15 = 0.225 > 0.1, not
    loop = HapticLoop(Device(0.15, 0.1), DiscreteController((50.0, -25.0), (1.0, 0.0)), None, 1e-3, 0)
    r = sampled_passivity(loop)
    assert r.passive is True and r.margin == pytest.approx(0.0625, abs=1e-12)
    r2 = sampled_passivity(loop.replace(controller=DiscreteController((300.0, -150.0), (1.0, 0.0))))
    assert r2.passive is False and r2.margin == pytest.approx(-0.125, abs=1e-12)
    with pytest.raises(AnalysisError):
        critical_stiffness_passivity(loop)
    unstable = loop.replace(controller=DiscreteController((1.0,), (1.0, -1.5)))
    with pytest.raises(AnalysisError, match="pole"):
        sampled_passivity(unstable)


def test_approximation_is_rejected():
    with pytest.raises(AnalysisError, match="circle"):
        kmax(h.paper_hve(), approximation="forward")


# ------------------------------------------- passivity is sufficient for stability
def passive_impedance():
    return st.one_of(st.just(None), st.floats(0.1, 1000).map(spring),
                     st.tuples(st.floats(0, 0.5), st.floats(0, 2), st.floats(0, 1000))
                     .map(lambda a: mass_spring_damper(*a)))


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(m=st.floats(0.01, 1.0), b=st.floats(0.01, 1.0), B=st.floats(0.0, 0.3),
       T=st.floats(2e-4, 1e-2), n=st.integers(0, 8), op=passive_impedance())
def test_hve_bounds_never_exceed_exact(m, b, B, T, n, op):
    loop = HapticLoop(Device(m, b), SpringDamper(1.0, B), op, T, n)
    exact = kmax(loop, "exact")
    # 1e-6: the exact K_max is computed to ~1e-9 relative, the bounds to rounding
    assert kmax(loop, "passivity") <= exact * (1 + 1e-6) + 1e-9
    assert kmax(loop, "circle") <= exact * (1 + 1e-6) + 1e-9


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(m=st.floats(0.01, 1.0), b=st.floats(0.01, 1.0), f=st.floats(0.0, 0.9),
       T=st.floats(2e-4, 1e-2), n=st.integers(0, 8), op=passive_impedance())
def test_hve_bounds_never_exceed_exact_with_negative_b(m, b, f, T, n, op):
    # B = -f b: b + B >= 0.1 b keeps K_max well above the exact analysis' smallest
    # resolved K (near b + B = 0 it tends to 0, below that resolution)
    loop = HapticLoop(Device(m, b), SpringDamper(1.0, -f * b), op, T, n)
    exact, passive = kmax(loop, "exact"), kmax(loop, "passivity")   # each once
    assert passive <= exact * (1 + 1e-6) + 1e-9
    assert kmax(loop, "circle") <= exact * (1 + 1e-6) + 1e-9
    # and for B <= 0 both are eq. (18) exactly (the worst case is w -> 0)
    line = h.eq18(loop).critical_stiffness
    assert passive == pytest.approx(line, rel=1e-7)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mm=st.floats(0.005, 0.5), ms=st.floats(0.005, 0.5), bm=st.floats(0.005, 0.5),
       bs=st.floats(0.005, 0.5), Bm=st.floats(-0.4, 0.05), Bs=st.floats(-0.4, 0.05),
       ratio=st.floats(0.25, 4.0), T=st.floats(5e-4, 1e-2), n=st.integers(0, 5),
       op=passive_impedance(), env=passive_impedance())
def test_peb_bounds_never_exceed_exact(mm, ms, bm, bs, Bm, Bs, ratio, T, n, op, env):
    # negative B_m, B_s scaled to at most 0.4 of the port's damping (see the HVE test)
    Bm, Bs = (Bm * bm if Bm < 0 else Bm), (Bs * bs if Bs < 0 else Bs)
    loop = TeleoperationLoop(Device(mm, bm), Device(ms, bs), SpringDamper(1.0, Bm),
                             SpringDamper(ratio, Bs), op, env, T, n)
    exact = kmax(loop, "exact")
    assert kmax(loop, "passivity") <= exact * (1 + 1e-6) + 1e-9
    assert kmax(loop, "circle") <= exact * (1 + 1e-6) + 1e-9


def test_the_rows_golden_search_is_each_rows_own_bit_for_bit():
    # frequency_grid.refine_minimum_rows (the K-B region's overlays, every row at once)
    # against refine_minimum on each row alone: the same candidates, the same golden
    # steps, the same pick among ties, the same w -> 0 rule
    from hapstab.analysis.conditions.frequency_grid import (
        refine_minimum,
        refine_minimum_rows,
        theta_grid,
    )
    rng = np.random.default_rng(16)
    th = theta_grid(6)
    a, w, c = rng.uniform(0.5, 2, (3, 12)), rng.uniform(1, 9, (3, 12)), rng.uniform(0, 3, (3, 12))

    def f(rows, t):
        val = np.sum(a[:, rows] * np.cos(w[:, rows] * t + c[:, rows]), axis=0)
        return np.where(rows == 5, np.nan, np.where(rows == 7, val[0] * 0 + 4.0, val))

    vals = np.array([f(np.full(th.size, r), th) for r in range(12)])
    vals[3, :40] = vals[3, :40].min() - 1.0          # a flat minimum at the w -> 0 end
    got_t, got_v = refine_minimum_rows(f, th, vals)
    for r in range(12):
        want = refine_minimum(lambda t, r=r: f(np.full(t.size, r), t), th, vals[r])
        assert (got_t[r], got_v[r]) == want or (np.isnan(got_t[r]) and np.isnan(want[0])), r
