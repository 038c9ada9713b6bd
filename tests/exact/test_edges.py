"""Issue #8, item 5: answers at the edges of the documented range (T from 1e-7 to
1e3 s, heavy devices) are right, checked against the tests' own brute force and its
50-digit referee (tests/references/brute.py), and through the CLI runner."""

import json
import math

import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli as main
from references import brute


def run(*args):
    return CliRunner().invoke(main, list(args))


def test_hve_at_period_1000_s():
    # a slow loop: K_max = 1.0 N/m (not inf), and K = 5 is unstable
    loop = h.paper_hve(period=1e3)
    assert h.critical_stiffness(loop).critical_stiffness == pytest.approx(1.0, rel=1e-9)
    assert h.stability(loop.with_stiffness(5.0)).verdict == "unstable"
    ref = brute.hve_loop(0.15, 0.1, 1e3, 0, operator=("spring", 1.0))
    assert brute.robust(ref, 0.999).stable and not brute.robust(ref, 1.001).stable
    d = json.loads(run("kmax", "hve", "--period", "1000", "--json").stdout)
    assert d["critical_stiffness"] == pytest.approx(1.0, rel=1e-9)


def test_peb_at_one_microsecond_is_finite():
    K = h.critical_stiffness(h.paper_peb(period=1e-6)).critical_stiffness
    assert K == pytest.approx(2e4, rel=1e-3)
    d = json.loads(run("kmax", "peb", "--period", "1e-6", "--json").stdout)
    assert d["critical_stiffness"] == pytest.approx(K, rel=1e-12)


def test_peb_at_100_ns_is_not_called_stable_with_rho_above_one():
    loop = h.paper_peb(period=1e-7).with_stiffness(1e6)
    st = h.stability(loop)
    assert st.verdict == "unstable" and st.spectral_radius > 1
    ref = brute.peb_loop(0.015, 0.02, 0.015, 0.02, 1e-7, 0, operator=("spring", 1.0),
                         environment=("spring", 1.0))
    v = brute.robust(ref, 1e6)
    assert v.stable is False and v.rho > 1
    d = json.loads(run("check", "peb", "--period", "1e-7", "--stiffness", "1e6", "--json").stdout)
    assert d["verdict"] == "unstable"


def test_heavy_device_has_no_phantom_rigid_mode():
    loop = h.HapticLoop(h.Device(1e5, 0.1), h.SpringDamper(100.0), h.spring(1.0), 1e-3, 0)
    res = h.critical_stiffness(loop)
    assert res.critical_stiffness == pytest.approx(200.0, rel=1e-6)
    assert "rigid" not in res.reason and h.stability(loop).verdict == "stable"
    ref = brute.hve_loop(1e5, 0.1, 1e-3, 0, operator=("spring", 1.0))
    assert brute.robust(ref, 0.999 * res.critical_stiffness).stable
    assert not brute.robust(ref, 1.001 * res.critical_stiffness).stable


def test_gil2004_agrees_with_exact_at_tiny_bT_over_m():
    loop = h.HapticLoop(h.Device(5.0, 0.001), h.SpringDamper(1.0), None, 1e-4, 0)
    exact = h.critical_stiffness(loop).critical_stiffness
    assert exact == pytest.approx(20.0000000666667, rel=1e-12)
    assert h.critical_stiffness(loop, method="gil2004").critical_stiffness == \
        pytest.approx(exact, rel=1e-12)


def test_B_equal_to_minus_b_leaves_a_tiny_stable_range():
    # the old core did not look below 1e-6 of its stiffness scale and said 0
    loop = h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(1.0, -0.1), h.spring(1.0), 1e-3, 0)
    K = h.critical_stiffness(loop).critical_stiffness
    assert 0 < K < 1e-3 and math.isfinite(K)
    ref = brute.hve_loop(0.15, 0.1, 1e-3, 0, B=-0.1, operator=("spring", 1.0))
    assert brute.robust(ref, 0.99 * K).stable and not brute.robust(ref, 1.01 * K).stable
