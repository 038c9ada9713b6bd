"""The per-sample reference simulator (tests/references/simref.py) against the fine
RK4 references of test_simulate.py (written independently, Fig. 2a / Fig. 3) and
against hapstab.simulate on linear and nonlinear loops."""

from __future__ import annotations

import math

import numpy as np
import pytest

import hapstab as h
from hapstab.simulation.run import simulate
from references.simref import hve_run, peb_run, quantize
from test_simulate import rk4_hve_read_delayed, rk4_peb

T = 1e-3
DEV = dict(mass=0.15, damping=0.5, op_stiffness=1.0, op_damping=0.0, period=T)


def _sine(M: int, F: float = 2.0, hz: float = 3.0) -> np.ndarray:
    return F * np.sin(2 * np.pi * hz * T * np.arange(M))


# ------------------------------------------------------- vs the fine RK4 (HVE)
@pytest.mark.parametrize("kw", [
    dict(K=5.0, B=0.01, delay=2, x0=0.002),                                 # linear
    dict(K=40.0, B=0.02, delay=3, x0=0.0, wall=0.004, resolution=2e-4, saturation=0.3),
    dict(K=40.0, B=-0.02, delay=1, x0=0.001, wall=0.003, resolution=1e-4),   # B < 0
])
def test_hve_matches_fine_rk4(kw):
    M = 500
    fz = _sine(M)
    x, u = hve_run(**DEV, **kw, force=fz, n_samples=M, wall_pulls=True, quantizer="nearest",
                   rest=0.0)   # the RK4's spring rests at 0; it has no no-pull rule
    xs, us = rk4_hve_read_delayed(0.15, 0.5, 1.0, kw["K"], kw["B"], T, kw["delay"], kw["x0"],
                                  fz, M, sub=20, q=kw.get("resolution"),
                                  sat=kw.get("saturation"), wall=kw.get("wall"))
    if "wall" in kw:
        assert (x[:-1] > kw["wall"]).any() and (x[:-1] < kw["wall"]).any()
    # RK4 at T/20 on ~2-20 rad/s dynamics: truncation ~1e-12 m. A quantisation step
    # decided differently would jump u by K*resolution >= 4 mN, so 1e-7 m / 1e-6 N
    # says every decision matched; Python's round (half to even) differs from ours
    # only at exact ties, which a float trajectory does not hit here
    np.testing.assert_allclose(x, xs, rtol=0, atol=1e-7)
    np.testing.assert_allclose(u, us, rtol=0, atol=1e-6)


def test_peb_matches_fine_rk4():
    M, n, K = 400, 2, 10.0
    f = np.ones(M)
    xm, xs, _, _ = peb_run(master=(0.015, 0.02), slave=(0.015, 0.02), op=(1.0, 0.0),
                           env=(1.0, 0.0), K=K, B=0.0, period=T, delay=n, xm0=0.002,
                           force_m=f, n_samples=M, rest_m=0.0, rest_s=0.0)
    ref = rk4_peb(0.015, 0.02, 0.015, 0.02, 1.0, 1.0, K, T, n, 0.002, f, M, sub=20)[::20]
    # RK4 at T/20 on the fastest mode (sqrt(2K/m) ~ 37 rad/s, h*w ~ 2e-3):
    # truncation far below 1e-9 of the motion's scale
    scale = np.abs(ref).max()
    np.testing.assert_allclose(np.c_[xm, xs], ref, rtol=0, atol=1e-9 * scale)


# ------------------------------------------------------------ focused rules
def test_wall_does_not_pull():
    # the device starts 1 mm inside the wall and is pulled out hard: the damper term
    # B (e - e_prev)/T is large and negative while the penetration is still > 0
    kw = dict(DEV, K=50.0, B=2.0, delay=1, x0=0.011, wall=0.01, n_samples=300,
              force=np.full(300, -3.0))
    _xp, up = hve_run(**kw, wall_pulls=True)
    x, u = hve_run(**kw)
    e = np.r_[kw["x0"], x[:-2]] - 0.01          # delay 1: e[k] = x[k-1] - wall
    pd = 50.0 * e + 2.0 * np.diff(np.r_[e[0], e]) / T
    assert (up < 0).any()                         # the pulling wall does pull
    assert (pd[e > 0] < 0).any() and (u >= 0).all()
    # same float operations: the rule is exact
    np.testing.assert_array_equal(u, np.where(e > 0, np.maximum(pd, 0.0), 0.0))


@pytest.mark.parametrize("quantizer", ["floor", "nearest"])
def test_quantizer_is_what_the_controller_reads(quantizer):
    res, K = 1e-3, 20.0
    x, u = hve_run(**DEV, K=K, B=0.0, delay=0, x0=-0.0043, force=_sine(400, 0.5),
                   n_samples=400, resolution=res, quantizer=quantizer)
    c = np.floor(x[:-1] / res) if quantizer == "floor" else \
        np.sign(x[:-1]) * np.floor(np.abs(x[:-1]) / res + 0.5)
    assert (x < 0).any() and (x > 0).any()
    # the counts are integers: K*res*count equals u up to one rounding of K*res*count
    np.testing.assert_allclose(u, K * res * c, rtol=1e-15, atol=0)
    assert quantize(-2.5e-3, res, "nearest") == -3e-3 and quantize(2.5e-3, res, "nearest") == 3e-3
    assert quantize(-1e-4, res, "floor") == -1e-3


def test_rest_defaults_to_initial_position_and_overflow_guard():
    # rest at x0 and a wall beyond it: nothing moves
    x, u = hve_run(**DEV, K=100.0, B=0.1, delay=2, x0=0.01, force=None, n_samples=50, wall=0.02)
    assert (x == 0.01).all() and (u == 0.0).all()
    x, u = hve_run(**DEV, K=1e6, B=0.0, delay=4, x0=0.001, force=None, n_samples=5000)
    stop = np.argmax(np.isinf(x))
    assert 0 < stop < 5000 and np.isfinite(x[:stop]).all() and np.isinf(x[stop:]).all()
    assert np.isinf(u[stop:]).all()


# ----------------------------------------------------------- vs hapstab.simulate
def test_hve_matches_hapstab_linear():
    M, x0 = 3000, 0.003
    loop = h.HapticLoop(h.Device(0.2, 0.3), h.SpringDamper(150.0, 0.01), "msd:0,0.5,40", 2e-3, 3)
    fz = _sine(M, 1.0, 2.0)
    res = simulate(loop, M * 2e-3, force=fz, initial_position=x0)
    x, u = hve_run(mass=0.2, damping=0.3, op_stiffness=40.0, op_damping=0.5, K=150.0, B=0.01,
                   period=2e-3, delay=3, x0=x0, force=fz, n_samples=M)   # spring rests at x0
    # both exact ZOH, different matrix exponentials and summation orders: rounding
    # only, amplified by at most the loop's decay over the run
    np.testing.assert_allclose(x, res.position[:, 0], rtol=0, atol=1e-9 * np.abs(x).max())
    np.testing.assert_allclose(u, res.controller_force[:-1, 0], rtol=0,
                               atol=1e-9 * np.abs(u).max())


@pytest.mark.parametrize("opts", [{}, {"quantizer": "nearest", "wall_pulls": True}])
def test_hve_matches_hapstab_nonlinear(opts):
    # defaults: the wall only pushes, the encoder reads floor(x / resolution); and
    # the other choices
    M = 2000
    loop = h.HapticLoop(h.Device(0.15, 0.5), h.SpringDamper(40.0, 0.02), "spring:1", T, 2)
    fz = _sine(M)
    kw = dict(wall=0.004, resolution=2e-4, saturation=0.3, **opts)
    res = simulate(loop, M * T, force=fz, initial_position=0.0, **kw)
    x, u = hve_run(**DEV, K=40.0, B=0.02, delay=2, x0=0.0, force=fz, n_samples=M,
                   **kw)
    assert res.contact.any() and not res.contact.all()
    # rounding-level differences unless a quantisation decision differs (a jump of
    # K*resolution = 8 mN); no position lands on a tie in this run
    np.testing.assert_allclose(x, res.position[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(u, res.controller_force[:-1, 0], rtol=0, atol=1e-10)


@pytest.mark.parametrize("n,B", [(0, 0.0), (4, 0.0), (3, 0.002)])
def test_peb_matches_hapstab_linear(n, B):
    M, xm0, xs0 = 3000, 0.002, -0.001
    c = h.SpringDamper(10.0, B)
    loop = h.TeleoperationLoop(h.Device(0.015, 0.02), h.Device(0.02, 0.03), c, c,
                               "msd:0,0.1,1", "msd:0,0.05,3", T, n)
    fm, fs = _sine(M, 0.5, 2.0), _sine(M, 0.2, 5.0)
    res = simulate(loop, M * T, force=fm, environment_force=fs, initial_position=[xm0, xs0])
    xm, xs, um, us = peb_run(master=(0.015, 0.02), slave=(0.02, 0.03), op=(1.0, 0.1),
                             env=(3.0, 0.05), K=10.0, B=B, period=T, delay=n, xm0=xm0, xs0=xs0,
                             force_m=fm, force_s=fs, n_samples=M)   # springs rest where they start
    assert np.isfinite(res.position).all() and np.abs(xm).max() < 1.0
    # exact ZOH both: rounding only, relative to the run's own scale
    np.testing.assert_allclose(np.c_[xm, xs], res.position, rtol=0,
                               atol=1e-9 * np.abs(res.position).max())
    np.testing.assert_allclose(np.c_[um, us], res.controller_force[:-1], rtol=0,
                               atol=1e-9 * np.abs(res.controller_force).max())


def test_peb_delay_enters_only_the_remote_position():
    # e_m[k] = x_m[k] - x_s[k-n]: the local position is read undelayed
    M, n = 60, 5
    xm, xs, um, us = peb_run(master=(0.015, 0.02), slave=(0.015, 0.02), op=(1.0, 0.0),
                             env=(1.0, 0.0), K=10.0, B=0.0, period=T, delay=n, xm0=0.0,
                             force_m=np.ones(M), n_samples=M)
    xs_d = np.r_[np.zeros(n), xs[:M - n]]
    xm_d = np.r_[np.zeros(n), xm[:M - n]]
    np.testing.assert_array_equal(um, 10.0 * (xm[:-1] - xs_d))
    np.testing.assert_array_equal(us, 10.0 * (xs[:-1] - xm_d))
    assert math.isclose(xs[n], 0.0, abs_tol=0) and xs[n + 2] != 0.0


def test_peb_matches_hapstab_nonlinear():
    # encoder on both robots (floor, the default) and saturated actuators
    M, n = 2000, 3
    c = h.SpringDamper(10.0, 0.002)
    loop = h.TeleoperationLoop(h.Device(0.015, 0.02), h.Device(0.015, 0.02), c, c,
                               "spring:1", "spring:1", T, n)
    fm = _sine(M, 0.5, 2.0)
    kw = dict(resolution=1e-3, saturation=0.2)
    res = simulate(loop, M * T, force=fm, initial_position=[0.0, 0.0], **kw)
    xm, xs, um, us = peb_run(master=(0.015, 0.02), slave=(0.015, 0.02), op=(1.0, 0.0),
                             env=(1.0, 0.0), K=10.0, B=0.002, period=T, delay=n, xm0=0.0,
                             force_m=fm, n_samples=M, **kw)
    U = np.c_[um, us]
    assert (np.abs(U) == 0.2).any() and len(np.unique(np.round(xs / 1e-3))) > 5
    # rounding-level unless a quantisation decision differs (a jump of K*resolution
    # = 10 mN); no position lands on a tie in this run
    np.testing.assert_allclose(np.c_[xm, xs], res.position, rtol=0, atol=1e-12)
    np.testing.assert_allclose(U, res.controller_force[:-1], rtol=0, atol=1e-10)
