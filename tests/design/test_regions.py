"""K-B regions and the best virtual damping against brute force and the exact K_max."""

import numpy as np
import pytest

import hapstab as h
from hapstab.analysis.design.damping import best_damping
from hapstab.analysis.design.regions import d_decomposition, stability_region, with_gains
from hapstab.engine.system import build
from hapstab.errors import AnalysisError
from lanes import size
from references import brute

HVE10 = h.paper_hve(delay_samples=10)


def test_region_matches_brute_force_grid():
    res = stability_region(HVE10, (0, 900), (0, 20), resolution=24)
    assert _inner_points_match_brute_force(res, 900) > 400
    assert res.agreement["disagree"] == 0


def _inner_points_match_brute_force(res, K_hi):
    """Every inner grid point of the delayed HVE's region against the brute force;
    returns how many were compared."""
    checked = 0
    for i, B in enumerate(res.B_rows):
        mk = brute.hve(0.15, 0.1, (1,), (1, 0), 10, B, 1e-3)
        ends = [e for iv in res.intervals[i] for e in iv if 0 < e < K_hi]
        for j, K in enumerate(res.K_grid[1:-1], start=1):
            # within 0.1 % (relative) of an exact boundary either verdict is rounding
            if any(abs(K - e) <= 1e-3 * e for e in ends):
                continue
            assert res.stable_exact[i, j] == (brute.spectral_radius(mk, K) < 1), (K, B)
            checked += 1
    return checked


def test_region_rows_equal_exact_kmax():
    res = stability_region(HVE10, (0, 2000), (0, 20), resolution=6)
    for B, iv in zip(res.B_rows, res.intervals, strict=True):
        K = h.critical_stiffness(with_gains(HVE10, 1.0, B)).critical_stiffness
        assert iv[0][0] == 0.0 and iv[0][1] == pytest.approx(min(K, 2000), rel=1e-12)


def test_d_decomposition_points_put_a_pole_on_the_circle():
    dd = d_decomposition(HVE10, n_theta=400)
    c = dd["curves"][0]
    pts = c[(c[:, 0] > 1) & (c[:, 0] < 800) & (c[:, 1] > 0) & (c[:, 1] < 20)]
    assert len(pts) > 10
    for K, B in pts[:: max(1, len(pts) // 10)]:
        eig = np.linalg.eigvals(build(with_gains(HVE10, K, B)).closed_loop()[0])
        # the curve is computed from G(e^{j theta}) by one linear solve: |z| = 1 to ~1e-9
        assert np.min(np.abs(np.abs(eig) - 1)) < 1e-7


def test_peb_region_cross_check_agrees():
    res = stability_region(h.paper_peb(delay_samples=4), (0, 700), (0, 8), resolution=40)
    assert res.agreement["disagree"] == 0 and res.agreement["compared"] > 1400
    assert res.kmax()[0] == pytest.approx(4.0074008646, rel=1e-9)


def test_best_damping_is_a_maximum_confirmed_by_brute_force():
    bd = best_damping(HVE10)
    assert bd.damping == pytest.approx(12.61, rel=1e-3) and bd.critical_stiffness > 600
    assert bd.critical_stiffness >= bd.K_curve.max() * (1 - 1e-12)
    for dB in (-0.05, 0.05):
        K = h.critical_stiffness(with_gains(HVE10, 1.0, bd.damping + dB)).critical_stiffness
        assert K < bd.critical_stiffness
    ref = brute.kmax(brute.hve(0.15, 0.1, (1,), (1, 0), 10, bd.damping, 1e-3))
    assert bd.critical_stiffness == pytest.approx(ref, rel=1e-6)
    assert bd.critical_stiffness_at_zero_damping == pytest.approx(9.536097554689, rel=1e-9)


def test_region_refuses_unequal_controllers_and_empty_windows():
    loop = h.paper_peb().replace(slave_controller=h.SpringDamper(1.0, 0.3))
    with pytest.raises(AnalysisError, match="C_m = C_s"):
        stability_region(loop, (0, 10), (0, 1))
    with pytest.raises(AnalysisError, match="empty"):
        stability_region(HVE10, (10, 5), (0, 1))


def test_region_plot_and_csv(tmp_path):
    res = stability_region(HVE10, (0, 900), (0, 20), resolution=20, overlays=["paper"])
    ax = res.plot()
    png = tmp_path / "r.png"
    ax.figure.savefig(png)
    assert png.stat().st_size > 5000
    res.to_csv(str(tmp_path / "r.csv"))
    assert (tmp_path / "r.csv").read_text().count("\n") == 401
    assert np.isfinite(res.overlays["paper"]).all()


# ------------------------------------------------ negative virtual damping B < 0
def test_region_through_zero_matches_brute_force_and_its_grid_check():
    res = stability_region(HVE10, (0, 20), (-0.12, 0.1), resolution=23)
    assert res.B_rows[0] < -0.1 < 0 < res.B_rows[-1]
    assert res.agreement["disagree"] == 0 and res.agreement["compared"] > 450
    assert _inner_points_match_brute_force(res, 20) > 400
    # rows below B = -b: unstable for every K; rows just above: a small stable interval
    kmax = res.kmax()
    assert np.all(kmax[res.B_rows < -0.1] == 0.0) and np.all(kmax[res.B_rows > -0.09] > 0)


def test_region_wide_b_window_through_zero():
    # the issue's --B -2:20 on the delayed HVE: the grid check agrees everywhere
    res = stability_region(HVE10, (0, 900), (-2, 20), resolution=40)
    assert res.agreement["disagree"] == 0
    assert res.kmax()[0] == 0.0 and res.kmax().max() > 600


@pytest.mark.parametrize("n", [0, 10])
def test_region_overlays_with_negative_b_are_the_papers_lines(n):
    loop = h.paper_hve(delay_samples=n)
    res = stability_region(loop, (0, 300), (-0.15, 0.05), resolution=9,
                           overlays=["paper", "passivity", "circle"])
    neg = res.B_rows <= 0
    B = res.B_rows[neg]
    # n = 0: Colgate-Schenkel 2(b - |B|)/T; n = 10: (18) = (b + B)/(T/2 + t_d), both = passivity
    line = (2 * (0.1 - np.abs(B)) / 1e-3 if n == 0 else (0.1 + B) / (0.5e-3 + n * 1e-3)).clip(0)
    np.testing.assert_allclose(res.overlays["paper"][neg], line, rtol=1e-12, atol=1e-9)
    for name in ("passivity", "circle"):
        # frequency sweeps: rounding slack ~1e-12 of the damping scale -> ~1e-9 N/m
        np.testing.assert_allclose(res.overlays[name][neg], line, rtol=1e-9, atol=1e-9)
    # sufficient conditions: never above the exact boundary
    assert np.all(res.overlays["passivity"] <= res.kmax() * (1 + 1e-9) + 1e-9)


def test_d_decomposition_points_with_negative_b_put_a_pole_on_the_circle():
    dd = d_decomposition(HVE10, n_theta=400)
    pts = np.vstack([c[(c[:, 0] > 0.01) & (c[:, 0] < 50) & (c[:, 1] < 0) & (c[:, 1] > -0.1)]
                     for c in dd["curves"]])
    assert len(pts) > 5
    for K, B in pts[:: max(1, len(pts) // 8)]:
        eig = np.linalg.eigvals(build(with_gains(HVE10, K, B)).closed_loop()[0])
        assert np.min(np.abs(np.abs(eig) - 1)) < 1e-7


def test_best_damping_searches_negative_b_and_can_find_it_best():
    # a 10 g device on a 100 N/m operator with n = 6: the delay's phase makes B < 0 damp
    m, b, k, T, n = 0.0103, 0.0251, 100.0, 0.00452, 6
    loop = h.HapticLoop(h.Device(m, b), h.SpringDamper(1.0), h.spring(k), T, n)
    bd = best_damping(loop)
    assert bd.damping < -b and bd.B_curve[0] < bd.damping and "B* < 0" in bd.reason
    ref = brute.kmax(brute.hve(m, b, (k,), (1, 0), n, bd.damping, T))
    assert bd.critical_stiffness == pytest.approx(ref, rel=1e-6)
    assert bd.critical_stiffness > 4 * bd.critical_stiffness_at_zero_damping
    for dB in (-0.05, 0.05):   # a maximum: 0.1 % below K*, brute force is unstable on both sides
        make = brute.hve(m, b, (k,), (1, 0), n, bd.damping + dB, T)
        assert brute.spectral_radius(make, 0.999 * ref) > 1
    only_pos = best_damping(loop, B_min=0.0, B_max=0.05, resolution=16)   # K_max = 0 from 0.03 on
    assert only_pos.B_curve[0] == 0.0 and only_pos.damping >= 0.0
    assert only_pos.critical_stiffness < bd.critical_stiffness


def test_best_damping_bounds_are_validated():
    with pytest.raises(AnalysisError, match=r"B_min = 0\.5: must be <= 0"):
        best_damping(HVE10, B_min=0.5)
    with pytest.raises(h.ModelError, match="B_max"):
        best_damping(HVE10, B_max=-1.0)


def test_best_damping_unstable_everywhere_says_so():
    # no device damping, no operator, delay: with B in [-0.5, 1e-12] no K > 0 is stable
    loop = h.HapticLoop(h.Device(0.15, 0.0), h.SpringDamper(1.0), None, 1e-3, 10)
    bd = best_damping(loop, B_max=1e-12, B_min=-0.5, resolution=8)
    assert bd.critical_stiffness == 0.0 and bd.damping == 0.0 and np.all(bd.K_curve == 0)
    assert "unstable for every K > 0 at every B" in bd.reason
    assert brute.kmax(brute.hve(0.15, 0.0, (0,), (1,), 10, -0.25, 1e-3), lo=1e-8) == 0.0


def test_the_K_zero_column_is_the_exact_verdict_at_K_zero():
    # issue #9 item 6: at K = 0 the paper's delayed HVE rests on the operator spring
    # (stable); the intervals are for K > 0, so K = 0 is judged on its own
    res = stability_region(h.paper_hve(delay_samples=10), K=(0, 900), B=(0, 20), resolution=5)
    assert res.stable_exact[:, 0].all() and res.stable_grid[:, 0].all()
    free = h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(1.0), None, 1e-3, 2)
    res = stability_region(free, K=(0, 50), B=(0, 0.05), resolution=4)
    assert not res.stable_exact[:, 0].any()          # a free mass at K = 0: pole at z = 1


def test_best_damping_says_for_which_operator_and_whether_passivity_is_lost():
    # issue #12: "render at most K* ... with B*" came with no caveat, though at B* the loop
    # without its operator was unstable for the stiffness promised
    loop = h.paper_hve(1e-3, 5).replace(operator=h.mass_spring_damper(0.1, 5, 500))
    res = best_damping(loop, resolution=16)
    assert res.holds_for == "for operator " + loop.operator.label
    bare = h.critical_stiffness(loop.replace(operator=None).replace(
        controller=h.SpringDamper(0.0, res.damping))).critical_stiffness
    assert res.critical_stiffness_without_operator == pytest.approx(bare, rel=1e-12)
    assert bare < res.critical_stiffness and "a hand that lets go" in res.reason
    assert res.passive_up_to == 0.0 and "passive for no K" in res.reason


def test_the_boundary_is_drawn_wherever_it_crosses_the_window():
    """Issue #12: a stiff-environment PEB region's boundary turns fast with theta near
    B = 0; the first sweep left it from B ~ 0.7 up. Refined, it reaches the window's
    bottom at the exact K_max of B = 0 (an independent point: the row's own analysis)."""
    loop = h.TeleoperationLoop(h.Device(0.3, 2.0), h.Device(1.0, 5.0),
                               operator=h.mass_spring_damper(0.5, 5.0, 500.0),
                               environment=h.spring(20000.0), period=1e-3, delay_samples=5)
    res = h.stability_region(loop, (0.0, 8000.0), (0.0, 60.0), resolution=24)
    pts = np.concatenate([c[(c[:, 0] >= 0) & (c[:, 0] <= 8000) & (c[:, 1] >= 0) & (c[:, 1] <= 60)]
                          for c in res.boundary["curves"]])
    low = pts[np.argmin(pts[:, 1])]
    assert low[1] < 60 * 0.004                    # within one refinement step of B = 0
    kmax0 = h.critical_stiffness(loop.replace(
        master_controller=h.SpringDamper(1.0, 0.0), slave_controller=h.SpringDamper(1.0, 0.0)))
    assert low[0] == pytest.approx(kmax0.critical_stiffness, rel=0.01)
    steps = np.hypot(np.diff(pts[:, 0]) / 8000, np.diff(pts[:, 1]) / 60)
    assert np.median(steps) < 0.004


def _overlay_loops():
    """Seeded loops of every kind the overlays take: HVE with and without an operator and
    a velocity filter, PEB with unequal devices; masses, dampings and periods over
    decades, delays 0-11."""
    rng = np.random.default_rng(2026_12_07)
    out = []
    for i in range(9):
        m, b = 10 ** rng.uniform(-2, 1), 10 ** rng.uniform(-2, 1)
        T, n = 10 ** rng.uniform(-4, -2), int(rng.integers(0, 12))
        if i % 3 == 0:
            out.append(h.HapticLoop(h.Device(m, b), h.SpringDamper(1.0, 0.0),
                                    h.mass_spring_damper(0.5, 5, 500), T, n))
        elif i % 3 == 1:
            out.append(h.TeleoperationLoop(
                master=h.Device(m, b), slave=h.Device(2 * m, 0.7 * b),
                operator=h.mass_spring_damper(0.5, 5.0, 500.0), environment=h.spring(2000.0),
                period=T, delay_samples=n))
        else:
            vf = h.VelocityFilter("average", samples=3) if i % 2 else \
                h.VelocityFilter("lowpass", cutoff_hz=0.1 / T)
            out.append(h.HapticLoop(h.Device(m, b), h.FilteredSpringDamper(1.0, 0.0, vf),
                                    None, T, n))
    return out


@pytest.mark.parametrize("loop", _overlay_loops(), ids=lambda lp: f"{lp.kind}-n{lp.delay_samples}")
def test_overlay_rows_at_once_are_each_rows_own_k_max(loop):
    # the batched rows (regions._affine_rows: the matrix affine in K and B) against
    # critical_stiffness(method=...) of each row's own loop, over B from -b to 2b
    from hapstab.analysis.design.regions import _affine_rows, _overlay
    from hapstab.analysis.methods import critical_stiffness
    b = min(p.damping for p in (getattr(loop, "device", None), getattr(loop, "master", None),
                                getattr(loop, "slave", None)) if p is not None)
    Bs = np.linspace(-b, 2 * b, size(5, 13))      # the rows' ends and middle, 13 in full
    for name in ("passivity", "circle"):
        got = _overlay(loop, name, Bs)
        # the batched path answers every loop but the circle's filtered ones (refused)
        assert (_affine_rows(loop, name, Bs) is None) == (name == "circle" and np.isnan(got).all())
        for B, k in zip(Bs, got, strict=True):
            try:
                want = critical_stiffness(with_gains(loop, 1.0, float(B)), method=name)
            except AnalysisError:
                assert np.isnan(k)
                continue
            K = want.critical_stiffness
            # the same sums in another order: ~1e-15 relative; where the damping cancels
            # (B = -b) both are rounding noise about 0: the PSD slack (1e-12 of the
            # matrix's scale, b) over the K-part's scale (T b) puts them at ~1e-12/T
            # (measured: up to 3e-11 N/m); 1e-9/T is a thousand times that
            assert k == pytest.approx(K, rel=1e-9, abs=1e-9 / loop.period), (name, B)
