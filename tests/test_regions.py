"""K-B regions and the best virtual damping against brute force and the exact K_max."""

import numpy as np
import pytest

import hapstab as h
from hapstab.engine import build
from hapstab.errors import AnalysisError
from hapstab.regions import best_damping, d_decomposition, stability_region, with_gains

from references import brute

HVE10 = h.paper_hve(delay_samples=10)


def test_region_matches_brute_force_grid():
    res = stability_region(HVE10, (0, 900), (0, 20), resolution=24)
    make = lambda B: brute.hve(0.15, 0.1, (1,), (1, 0), 10, B, 1e-3)  # noqa: E731
    checked = 0
    for i, B in enumerate(res.B_rows):
        mk = make(B)
        ends = [e for iv in res.intervals[i] for e in iv if 0 < e < 900]
        for j, K in enumerate(res.K_grid[1:-1], start=1):
            # within 0.1 % (relative) of an exact boundary either verdict is rounding
            if any(abs(K - e) <= 1e-3 * e for e in ends):
                continue
            assert res.stable_exact[i, j] == (brute.spectral_radius(mk, K) < 1), (K, B)
            checked += 1
    assert checked > 400
    assert res.agreement["disagree"] == 0


def test_region_rows_equal_exact_kmax():
    res = stability_region(HVE10, (0, 2000), (0, 20), resolution=6)
    for B, iv in zip(res.B_rows, res.intervals):
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
