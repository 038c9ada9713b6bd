"""Position and force scaling of PEB teleoperation (issue 13, item 2).

F_m = beta C_m [alpha x_m - z^-n x_s],  F_s = C_s [x_s - alpha z^-n x_m].

References used here, none derived in hapstab's code:

* alpha = beta = 1 is today's PEB, bit for bit (matrices, every K_max, trajectories);
* the brute force of ``tests/references/brute.py`` (closed loop from scratch by
  ``scipy.signal.cont2discrete``, eigenvalue scan and bisection), with the scaled signs
  written into its controls by hand;
* a change of coordinates worked by hand: with y_s = x_s / alpha the slave's equation is
  PEB's and the master's controller becomes alpha beta C_m, so the scaled loop's K_max
  times alpha beta is the K_max of an unscaled loop whose master controller is
  alpha beta C_m (K_s/K_m = 1/(alpha beta));
* free motion: the slave settles at alpha times the master's position.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli
from hapstab.engine import build
from references import brute


def _peb(rng: np.random.Generator) -> tuple[h.TeleoperationLoop, dict]:
    p = dict(mm=float(rng.uniform(0.01, 1.0)), bm=float(rng.uniform(0.0, 2.0)),
             ms=float(rng.uniform(0.01, 1.0)), bs=float(rng.uniform(0.0, 2.0)),
             T=float(rng.choice([1e-4, 1e-3, 5e-3])), n=int(rng.integers(0, 6)),
             B=float(rng.uniform(0.0, 1.0)), ko=float(10 ** rng.uniform(-1, 3)),
             ke=float(10 ** rng.uniform(-1, 4)), a=float(10 ** rng.uniform(-1, 1)),
             b=float(10 ** rng.uniform(-1, 1)))
    loop = h.TeleoperationLoop(h.Device(p["mm"], p["bm"]), h.Device(p["ms"], p["bs"]),
                               h.SpringDamper(1.0, p["B"]), h.SpringDamper(1.0, p["B"]),
                               f"spring:{p['ko']!r}", f"spring:{p['ke']!r}", p["T"], p["n"],
                               position_scale=p["a"], force_scale=p["b"])
    return loop, p


def _brute(p: dict) -> brute.Loop:
    """The scaled PEB written into the brute force's controls by hand."""
    a, b, n = p["a"], p["b"], p["n"]
    return brute.Loop((brute.Port(p["mm"], p["bm"], p["ko"]), brute.Port(p["ms"], p["bs"], p["ke"])),
                      (brute.Control(1.0, p["B"], ((0, b * a, 0), (1, -b, n))),
                       brute.Control(1.0, p["B"], ((1, 1.0, 0), (0, -a, n)))), p["T"])


# --------------------------------------------------------------- alpha = beta = 1
def test_unit_scaling_is_todays_peb_bit_for_bit():
    base = h.paper_peb(delay_samples=3).replace(
        slave_controller=h.SpringDamper(25.0, 0.3), master_controller=h.SpringDamper(10.0, 0.1))
    one = base.replace(position_scale=1, force_scale=1.0)
    s0, s1 = build(base), build(one)
    for name in ("A0", "B1", "C1", "F_u0", "F_u1", "B_ext"):
        assert np.array_equal(getattr(s0, name), getattr(s1, name)), name
    for m in ("exact", "circle", "passivity", "llewellyn"):
        assert h.critical_stiffness(one, method=m).critical_stiffness == \
            h.critical_stiffness(base, method=m).critical_stiffness, m
    r0 = h.simulate(base.with_stiffness(5.0), 0.05, force=1.0)
    r1 = h.simulate(one.with_stiffness(5.0), 0.05, force=1.0)
    assert np.array_equal(r0.position, r1.position)
    assert not one.scaled and base.to_dict()["position_scale"] == 1.0


def test_scaling_must_be_positive_and_finite():
    base = h.paper_peb()
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(h.ModelError, match="position_scale"):
            base.replace(position_scale=bad)
    with pytest.raises(h.ModelError, match="force_scale"):
        base.replace(force_scale=0)
    with pytest.raises(TypeError, match="force_scale"):
        base.replace(force_scale="2")


# ----------------------------------------------------- against the brute force
@pytest.mark.parametrize("seed", range(12))
def test_scaled_kmax_matches_the_brute_force(seed):
    loop, p = _peb(np.random.default_rng(seed))
    res = h.critical_stiffness(loop)
    scan = brute.stable_intervals(_brute(p))
    # the scan bisects to 1e-10; hapstab certifies its crossings far tighter: 1e-7
    # relative is the campaign's comparison tolerance
    assert res.critical_stiffness == pytest.approx(scan.kmax, rel=1e-7)
    got = [b for iv in res.stable_intervals for b in iv if 0 < b < math.inf]
    assert got == pytest.approx(scan.boundaries, rel=1e-7)


@pytest.mark.parametrize("seed", range(6))
def test_only_alpha_beta_matters_for_stability(seed):
    loop, p = _peb(np.random.default_rng(100 + seed))
    ab = p["a"] * p["b"]
    equiv = loop.replace(position_scale=1.0, force_scale=1.0,
                         master_controller=h.SpringDamper(ab, ab * p["B"]))
    k = h.critical_stiffness(loop).critical_stiffness
    k_equiv = h.critical_stiffness(equiv).critical_stiffness   # master's K = ab * K
    # two different structures (signs vs. gains) of one characteristic polynomial:
    # rounding only, a few ulps of the certified crossings
    assert k * ab == pytest.approx(k_equiv, rel=1e-9)


@pytest.mark.parametrize("a, b", [(3.0, 0.5), (0.1, 3.0)])   # 0.1 * 3 is not exact in binary
def test_free_scaled_teleoperator_has_its_rigid_mode_at_alpha(a, b):
    loop = h.paper_peb(delay_samples=4).replace(operator=None, environment=None,
                                                position_scale=a, force_scale=b)
    sysm = build(loop)
    assert sysm.rigid_modes == 1
    res = h.critical_stiffness(loop)
    # brute force: eigenvalues with the one at z = 1 (the rigid mode) removed
    def rho(K):
        ev = np.linalg.eigvals(sysm.closed_loop(K)[0])
        i = np.argmin(np.abs(ev - 1.0))
        assert abs(ev[i] - 1.0) < 1e-9          # the rigid mode, for every K
        return np.abs(np.delete(ev, i)).max()
    K = res.critical_stiffness
    assert rho(K * 0.999) < 1 < rho(K * 1.001)
    assert h.stability(loop.with_stiffness(0.5 * K)).verdict == "marginal"
    # only alpha beta matters: the same as position scaling alone by alpha beta (the
    # certified crossings of two loops whose signs differ in rounding only)
    alone = loop.replace(position_scale=a * b, force_scale=1.0)
    assert h.critical_stiffness(alone).critical_stiffness == pytest.approx(K, rel=1e-9)


def test_slave_follows_alpha_times_the_master():
    loop = h.paper_peb(damping=0.2).replace(environment=None, position_scale=2.5,
                                            force_scale=0.4)
    r = h.simulate(loop.with_stiffness(5.0), 40.0, force=0.2)
    xm, xs = r.position[-1]
    # settled: the slowest pole (|z| = 0.9993 at T = 1 ms) decays with a time constant
    # of 1.43 s; 40 s is 28 of them (e^-28 ~ 1e-12)
    assert xs == pytest.approx(2.5 * xm, rel=1e-9)
    # the master holds the operator's force: spring 1 N/m, and beta C_m on the error
    assert xm == pytest.approx(0.2, rel=1e-9)


# ------------------------------------------------------------ sufficient methods
@pytest.mark.parametrize("seed", range(8))
def test_forward_circle_passivity_and_llewellyn_stay_below_exact(seed):
    loop, _ = _peb(np.random.default_rng(200 + seed))
    exact = h.critical_stiffness(loop).critical_stiffness
    for m in ("circle", "passivity", "llewellyn"):
        k = h.critical_stiffness(loop, method=m).critical_stiffness
        # forward approximations are bounds: below the exact K_max (bisection 1e-9)
        assert k <= exact * (1 + 1e-9), m


def test_closed_forms_refuse_scaled_loops():
    loop = h.paper_peb().replace(position_scale=2.0)
    with pytest.raises(h.AnalysisError, match="position_scale = 2"):
        h.critical_stiffness(loop, method="eq29")


# --------------------------------------------------------------------------- CLI
def test_cli_scaling_options():
    out = CliRunner().invoke(cli, ["kmax", "peb", "--scaling-position", "2",
                                   "--scaling-force", "0.5", "--json"])
    assert out.exit_code == 0, out.output
    import json
    d = json.loads(out.stdout)
    assert d["inputs"]["loop"]["position_scale"] == 2.0
    assert d["inputs"]["loop"]["force_scale"] == 0.5
    want = h.critical_stiffness(h.paper_peb(stiffness=1.0).replace(position_scale=2.0,
                                                                   force_scale=0.5))
    assert d["critical_stiffness"] == want.critical_stiffness
    bad = CliRunner().invoke(cli, ["kmax", "peb", "--scaling-force", "-1"])
    assert bad.exit_code == 2 and "--scaling-force" in bad.output


def test_scaled_teleoperator_displays_alpha_beta_times_the_environment():
    """Statics by hand: x_s = alpha x_m and F_h = beta F_e in steady contact with a stiff
    controller, so the operator feels alpha beta k_e; with C_m = C_s = K and a spring k_e
    the slave settles where K (alpha x_m - x_s) = k_e x_s: K_felt = alpha beta K k_e /
    (K + k_e), tracking x_s / x_m = alpha K / (K + k_e)."""
    a, b, K, ke = 2.0, 0.25, 400.0, 50.0
    loop = h.paper_peb(stiffness=K).replace(position_scale=a, force_scale=b,
                                           environment=h.spring(ke))
    res = h.transparency(loop)
    assert res.felt_stiffness_environment == pytest.approx(a * b * K * ke / (K + ke), rel=1e-9)
    assert res.felt_stiffness_rigid == pytest.approx(a * b * K, rel=1e-9)
    assert res.static_tracking == pytest.approx(a * K / (K + ke), rel=1e-9)
