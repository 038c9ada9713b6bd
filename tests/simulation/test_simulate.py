"""simulate(): exact at the samples (vs the engine's own recurrence stepped here),
exact between samples (vs an independent fine-step RK4 of the physical loop written
here), verdicts vs hapstab.exact, nonlinear elements, and the simulation K_max vs
the exact K_max."""

import json
import math
from collections import deque

import numpy as np
import pytest

import hapstab as h
from hapstab.analysis.exact.core import exact_critical_stiffness, stability
from hapstab.engine.system import build
from hapstab.errors import AnalysisError, ModelError
from hapstab.simulation import critical_stiffness_simulation, force_samples, simulate


# ------------------------------------------------------------ independent references
def _rk4_held(x, v, force, m, b, k_op, h_, sub, xs):
    """Fine RK4 of m a = force - b v - k_op x over ``sub`` steps of h_ with the force
    held (the zero-order hold); appends each position to xs."""
    def acc(x_, v_):
        return (force - b * v_ - k_op * x_) / m
    for _ in range(sub):
        k1x, k1v = v, acc(x, v)
        k2x, k2v = v + h_ / 2 * k1v, acc(x + h_ / 2 * k1x, v + h_ / 2 * k1v)
        k3x, k3v = v + h_ / 2 * k2v, acc(x + h_ / 2 * k2x, v + h_ / 2 * k2v)
        k4x, k4v = v + h_ * k3v, acc(x + h_ * k3x, v + h_ * k3v)
        x += h_ / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
        v += h_ / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        xs.append(x)
    return x, v


def step_recurrence(loop, s0, F):
    """s[k+1] = A_cl s[k] + B_ext f[k], one sample at a time."""
    sysm = build(loop)
    A, B = sysm.closed_loop()[0], sysm.B_ext[0]
    S = [np.asarray(s0, float)]
    for f in F:
        S.append(A @ S[-1] + B @ f)
    return np.array(S)


def rk4_hve(m, b, k_op, K, B, T, n, x0, f_ext, M, sub=200):
    """The HVE of Fig. 2a written out: m a = f - u - b v - k_op x; sampler, n-sample
    delay line, H(z) = K + B(z-1)/(Tz) on the delayed sample, force held (ZOH).
    Returns positions at every 1/sub of a sample and the controller forces."""
    x, v = x0, 0.0
    line = deque([x0] * (n + 1), maxlen=n + 1)   # at rest at x0 before t = 0
    e_prev = x0
    h_ = T / sub
    xs, us = [x], []
    for k in range(M):
        line.append(x)
        e = line[0]
        u = K * e + B * (e - e_prev) / T
        e_prev = e
        us.append(u)
        f = f_ext[k]

        x, v = _rk4_held(x, v, f - u, m, b, k_op, h_, sub, xs)
    return np.array(xs), np.array(us)


def rk4_peb(mm, bm, ms, bs, kh, ke, K, T, n, xm0, f_h, M, sub=100):
    """The PEB teleoperator of Fig. 3 / eq. (19)-(20) with spring terminations,
    C_m = C_s = K (B = 0), delay n each way, fine RK4 between samples."""
    y = np.array([xm0, 0.0, 0.0, 0.0])   # xm, vm, xs, vs
    lm = deque([xm0] * (n + 1), maxlen=n + 1)
    ls = deque([0.0] * (n + 1), maxlen=n + 1)
    h_ = T / sub
    xs = [y[[0, 2]].copy()]
    for k in range(M):
        lm.append(y[0])
        ls.append(y[2])
        um = K * (y[0] - ls[0])
        us = K * (y[2] - lm[0])
        f = f_h[k]

        def rhs(z, f=f, um=um, us=us):   # this sample's held forces
            return np.array([z[1], (f - um - bm * z[1] - kh * z[0]) / mm,
                             z[3], (-us - bs * z[3] - ke * z[2]) / ms])
        for _ in range(sub):
            k1 = rhs(y)
            k2 = rhs(y + h_ / 2 * k1)
            k3 = rhs(y + h_ / 2 * k2)
            k4 = rhs(y + h_ * k3)
            y = y + h_ / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            xs.append(y[[0, 2]].copy())
    return np.array(xs)


# ------------------------------------------------------------ exactness
@pytest.mark.parametrize("loop,force,env", [
    (h.paper_hve(1e-3, 10, 8.0, 0.02), "step:1.5", None),
    (h.HapticLoop(h.Device(0.2, 0.3), h.SpringDamper(150.0, 0.01), "msd:0.1,0.5,40", 2e-3, 3),
     "sine:2,3", None),
    (h.paper_peb(2e-3, 4, 1.5, 0.003), "pulse:1,0.05,0.01", "sine:0.5,7"),
])
def test_samples_equal_exact_recurrence(loop, force, env):
    res = simulate(loop, 3.0, force=force, environment_force=env, initial_position=0.01, rest_position=0.0)
    M = res.time.size - 1
    F = res.exogenous_force[:-1]
    ref = step_recurrence(loop, res.states[0], F)
    # block products reorder the same arithmetic: agreement to rounding (1e-10 of the scale)
    scale = np.abs(ref).max(axis=0) + 1e-300
    assert np.max(np.abs(res.states - ref) / scale) < 1e-10
    assert M == 1500 if loop.period == 2e-3 else M == 3000


def test_hve_matches_fine_rk4_between_samples():
    m, b, K, B, T, n = 0.15, 0.1, 6.0, 0.01, 1e-3, 10
    loop = h.paper_hve(T, n, K, B)
    sub = 50
    res = simulate(loop, 0.5, force="step:2", initial_position=0.003, dense=sub, rest_position=0.0)
    M = res.time.size - 1
    xs, us = rk4_hve(m, b, 1.0, K, B, T, n, 0.003, np.full(M, 2.0), M, sub=sub)
    # RK4 at T/50 has local error ~ (w h)^5 with w ~ 10 rad/s: ~1e-16; 1e-9 relative is rounding
    assert res.dense_position.shape == (M * sub + 1, 1)
    np.testing.assert_allclose(res.dense_position[:, 0], xs, rtol=0, atol=1e-9 * np.abs(xs).max())
    np.testing.assert_allclose(res.controller_force[:-1, 0], us, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(res.dense_time[::sub], res.time, atol=1e-15)


@pytest.mark.parametrize("B,K,n", [(-0.05, 40.0, 0), (-0.03, 5.0, 10), (-0.12, 2.0, 3)])
def test_hve_with_negative_virtual_damping_matches_fine_rk4(B, K, n):
    # B < 0 enters u = K e + B (e - e_prev)/T as written, stable or not (B = -0.12 < -b grows)
    m, b, T, sub = 0.15, 0.1, 1e-3, 20
    loop = h.paper_hve(T, n, K, B)
    res = simulate(loop, 0.5, force="step:2", initial_position=0.003, dense=sub, rest_position=0.0)
    M = res.time.size - 1
    xs, us = rk4_hve(m, b, 1.0, K, B, T, n, 0.003, np.full(M, 2.0), M, sub=sub)
    # RK4 at T/20 on modes below ~20 rad/s: truncation far below 1e-9 of the scale
    np.testing.assert_allclose(res.dense_position[:, 0], xs, rtol=0, atol=1e-9 * np.abs(xs).max())
    np.testing.assert_allclose(res.controller_force[:-1, 0], us, rtol=1e-9,
                               atol=1e-12 * np.abs(us).max())


def test_peb_matches_fine_rk4_between_samples():
    T, n, K = 2e-3, 4, 0.7
    loop = h.paper_peb(T, n, K)
    res = simulate(loop, 0.4, force="sine:1,5", initial_position=[0.002, 0.0], dense=20, rest_position=0.0)
    M = res.time.size - 1
    f = force_samples("sine:1,5", res.time[:-1])
    xs = rk4_peb(0.015, 0.02, 0.015, 0.02, 1.0, 1.0, K, T, n, 0.002, f, M, sub=20)
    # RK4 at T/20 = 0.1 ms on modes below ~100 rad/s: error far below 1e-8 of the scale
    np.testing.assert_allclose(res.dense_position, xs, rtol=0, atol=1e-8 * np.abs(xs).max())


def test_port_energy_is_integral_of_force_times_velocity():
    res = simulate(h.paper_hve(1e-3, 2, 60.0, 0.02), 1.0, force="sine:1,4", dense=40)
    # independent: trapezoid of u(t) v(t) on the dense grid (u held over each sample)
    M = res.time.size - 1
    u = np.repeat(res.controller_force[:-1, 0], 40)
    t, v = res.dense_time, res.dense_velocity[:, 0]
    e = np.concatenate([[0.0], np.cumsum(u * 0.5 * (v[1:] + v[:-1]) * np.diff(t))])[::40]
    # trapezoid error O((T/40)^2 * max|a'|) per sample: 1e-4 of the energy scale
    assert np.max(np.abs(e - res.port_energy[:, 0])) < 1e-4 * np.abs(e).max()
    assert M == 1000


# ------------------------------------------------------------ verdicts
@pytest.mark.parametrize("loop", [
    h.paper_hve(1e-3, 0), h.paper_hve(5e-3, 10), h.paper_hve(2e-3, 3, damping=0.05),
    h.paper_peb(1e-3, 0), h.paper_peb(4e-3, 4, damping=0.002),
    h.HapticLoop(h.Device(0.4, 0.5), h.SpringDamper(1.0, 0.02), "msd:0.2,1,100", 1e-3, 6),
])
@pytest.mark.parametrize("factor", [0.7, 1.3])
def test_verdict_agrees_with_stability_away_from_boundary(loop, factor):
    kmax = exact_critical_stiffness(loop).critical_stiffness
    lp = loop.with_stiffness(factor * kmax)
    res = simulate(lp, 3000 * lp.period, initial_position=0.001, force="step:0.5")
    ex = stability(lp)
    assert res.verdict.bounded == (ex.verdict == "stable")
    assert res.verdict.confidence == "high"
    # the fitted rate is the dominant pole's: ln(rho)/T, to 1e-6 of the rate itself
    # (noise-free data; the fit's only error is rounding)
    assert res.verdict.growth_rate == pytest.approx(math.log(ex.spectral_radius) / lp.period,
                                                    rel=1e-6)


def test_stable_decays_unstable_grows():
    kmax = exact_critical_stiffness(h.paper_hve(1e-3, 10)).critical_stiffness
    lo = simulate(h.paper_hve(1e-3, 10, 0.5 * kmax), 20.0, initial_position=0.01, rest_position=0.0)
    hi = simulate(h.paper_hve(1e-3, 10, 1.5 * kmax), 20.0, initial_position=0.01, rest_position=0.0)
    env = lambda x: np.abs(x[-2000:]).max() / np.abs(x[:2000]).max()  # noqa: E731
    assert env(lo.position[:, 0]) < 0.2 and env(hi.position[:, 0]) > 5
    assert lo.bounded and not hi.bounded


def test_explosion_is_observed():
    # net damping b - KT/2 = -19.9 N s/m: growth ~ exp(66 t), far past 1e12 in 2 s
    res = simulate(h.paper_hve(1e-3, 0, 40000.0), 2.0, initial_position=0.01, rest_position=0.0)
    assert not res.bounded and res.verdict.basis == "observed" and res.verdict.confidence == "high"


# ------------------------------------------------------------ nonlinear elements
def test_far_wall_huge_saturation_fine_resolution_equal_linear():
    loop = h.paper_hve(1e-3, 3, 80.0, 0.02)
    lin = simulate(loop, 1.0, force="step:1", initial_position=0.01)
    # wall far below (w = -1): always in contact; u = K (x - w) = K x + 80 N, so a
    # push of 1 + 80 N reproduces the linear run
    wall = simulate(loop, 1.0, force=lambda t: 81.0, initial_position=0.01, wall=-1.0)
    np.testing.assert_allclose(wall.position, lin.position, rtol=0, atol=1e-12)
    assert wall.contact.all()
    sat = simulate(loop, 1.0, force="step:1", initial_position=0.01, saturation=1e9)
    np.testing.assert_allclose(sat.position, lin.position, rtol=0, atol=1e-14)
    q = simulate(loop, 1.0, force="step:1", initial_position=0.01, resolution=1e-13)
    # quantising to 1e-13 m perturbs the force by <= K*5e-14 N: positions by ~1e-12
    np.testing.assert_allclose(q.position, lin.position, rtol=0, atol=1e-10)


def test_unilateral_wall_pushes_only_in_contact():
    # well damped (b = 2) so it settles; K = 300 is below K_max ~ b/(T/2 + 2T) = 800
    loop = h.HapticLoop(h.Device(0.15, 2.0), h.SpringDamper(300.0), "spring:1", 1e-3, 2)
    res = simulate(loop, 3.0, force="step:1", wall=0.001)
    u, c = res.controller_force[:, 0], res.contact
    assert not c[0] and c.any()
    assert np.all(u[~c] == 0.0)
    assert np.all(u[c] > 0)          # B = 0: K times a positive penetration
    # it settles where wall and operator spring balance the push: K (x - w) = 1 - x
    # (decay exp(-6.7 t): settled to ~1e-8 after 3 s)
    assert res.position[-1, 0] == pytest.approx((1 + 300 * 0.001) / 301, rel=1e-5)


def test_saturation_and_quantisation_act():
    loop = h.paper_hve(1e-3, 0, 100.0)
    res = simulate(loop, 0.5, initial_position=0.05, saturation=2.0, resolution=1e-3)
    u = res.controller_force[:, 0]
    assert np.abs(u).max() == pytest.approx(2.0)
    unsat = u[np.abs(u) < 2.0]
    # B = 0, n = 0: u = K * (quantised x), a multiple of K * 1e-3 = 0.1 N
    np.testing.assert_allclose(unsat / 0.1, np.round(unsat / 0.1), atol=1e-9)


# ------------------------------------------------------------ inputs, outputs, errors
def test_force_specs():
    t = np.arange(10) * 0.1
    np.testing.assert_array_equal(force_samples("step:2,0.3", t), np.where(t >= 0.3, 2.0, 0.0))
    np.testing.assert_array_equal(force_samples("pulse:1,0.2", t), [1, 1] + [0] * 8)
    np.testing.assert_allclose(force_samples("sine:1,2", t), np.sin(4 * np.pi * t))
    np.testing.assert_array_equal(force_samples(3, t), np.full(10, 3.0))
    np.testing.assert_array_equal(force_samples(np.arange(10), t), np.arange(10))
    for bad in ("sine:1", "ramp:1", "step:x", np.arange(3), "pulse:1,-1"):
        with pytest.raises(ModelError, match="force"):
            force_samples(bad, t)


@pytest.mark.parametrize("kw,match", [
    ({"duration": -1}, "duration"), ({"duration": 1e-3}, "samples"),
    ({"environment_force": "step:1"}, "environment_force"), ({"wall": 0.0, "peb": True}, "wall"),
    ({"saturation": 0.0}, "saturation"), ({"resolution": -1.0}, "resolution"),
    ({"initial_position": [1, 2, 3]}, "initial_position"), ({"initial_state": [0.0]}, "initial_state"),
    ({"dense": -2}, "dense"),
])
def test_errors_name_the_parameter(kw, match):
    kw = dict(kw)
    loop = h.paper_peb() if kw.pop("peb", False) else h.paper_hve()
    kw.setdefault("duration", 0.1)
    with pytest.raises(ModelError, match=match):
        simulate(loop, **kw)


def test_outputs_csv_dict_plot(tmp_path):
    res = simulate(h.paper_peb(1e-3, 4, 2.0), 0.2, force="step:1", dense=4)
    p = tmp_path / "run.csv"
    res.to_csv(str(p))
    data = np.genfromtxt(p, delimiter=",", names=True)
    assert data.shape == (201,)
    np.testing.assert_array_equal(data["x_slave_m"], res.position[:, 1])
    res.to_csv(str(tmp_path / "dense.csv"), dense=True)
    assert (tmp_path / "dense.csv").stat().st_size > 0
    json.dumps(res.to_dict(series=True))
    from hapstab.plotting import save_plot
    assert len(res.plot()) == 3
    save_plot(res, str(tmp_path / "run.png"))
    assert (tmp_path / "run.png").stat().st_size > 1000
    with pytest.raises(ValueError):
        res.position[0, 0] = 1.0     # frozen arrays


# ------------------------------------------------------------ K_max by simulation
@pytest.mark.parametrize("loop", [
    h.paper_hve(1e-3, 0), h.paper_hve(7e-3, 10), h.paper_peb(3e-3, 0), h.paper_peb(1e-2, 4),
    h.HapticLoop(h.Device(0.5, 0.3), h.SpringDamper(1.0), "spring:1", 2e-3, 3),
    h.paper_hve(1e-3, 10, damping=0.05), h.paper_hve(2e-3, 2, damping=0.2),
    h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(1.0, 0.01), "msd:0.3,2,300", 1e-3, 5),
    h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(1.0), None, 1e-3, 1),
    h.TeleoperationLoop(h.Device(0.05, 0.1), h.Device(0.02, 0.05), h.SpringDamper(1, 0.002),
                        h.SpringDamper(1, 0.002), "msd:0.2,1,100", None, 1e-3, 3),
    h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(1, 0.01), "spring:1", 1e-3, 2,
                 fractional_delay=0.5),
    h.TeleoperationLoop(h.Device(0.015, 0.02), h.Device(0.03, 0.05), h.SpringDamper(1),
                        h.SpringDamper(1), "spring:1", "msd:0.01,0.1,50", 2e-3, 3,
                        fractional_delay=0.3, fractional_delay_backward=0.8),
    # negative virtual damping, down to b + B = 1e-4 (K_max ~ 0.01 N/m, below the scan's start)
    h.paper_hve(1e-3, 4, damping=-0.05), h.paper_hve(1e-3, 10, damping=-0.0999),
    h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(1.0, -0.0999), None, 1e-3, 3),
    h.paper_peb(1e-3, 4, damping=-0.004),
    h.TeleoperationLoop(h.Device(0.015, 0.02), h.Device(0.015, 0.02), h.SpringDamper(1, 0.002),
                        h.SpringDamper(2, -0.006), "spring:1", "spring:1", 1e-3, 2),
])
def test_simulation_kmax_within_one_percent_of_exact(loop):
    ex = exact_critical_stiffness(loop).critical_stiffness
    sim = h.critical_stiffness(loop, method="simulation")
    assert sim.method == "simulation"
    # the acceptance: 1 %; the bisection stops at 1e-4 so this has margin
    assert abs(sim.critical_stiffness / ex - 1) < 0.01


def test_simulation_kmax_options_validated():
    with pytest.raises(AnalysisError, match="n_samples"):
        critical_stiffness_simulation(h.paper_hve(), n_samples=3)
    with pytest.raises(AnalysisError, match="SpringDamper"):
        critical_stiffness_simulation(h.HapticLoop(h.Device(0.1, 0.1),
                                                   h.DiscreteController((1.0,), (1.0,))))


# ------------------------------------------------------------ fractional delay, nonlinear
def rk4_hve_read_delayed(m, b, k_op, K, B, T, d, x0, f_ext, M, sub, q=None, sat=None, wall=None):
    """Fig. 2a written out with a delay of d samples (not necessarily whole): the
    controller reads x(kT - dT) from the fine trajectory, quantises it (q), acts on
    the penetration beyond ``wall`` only while positive, clips to ``sat``."""
    h_ = T / sub
    lag = round(d * sub)            # d * sub must be whole: reading on the grid
    xs, x, v = [x0], x0, 0.0
    e_prev = None
    us = []
    for k in range(M):
        i = k * sub - lag
        xd = xs[i] if i >= 0 else x0     # at rest at x0 before t = 0
        if q:
            xd = q * round(xd / q)
        e = xd - (wall or 0.0)
        if e_prev is None:
            e_prev = e
        u = K * e + B * (e - e_prev) / T
        e_prev = e
        if wall is not None and e <= 0:
            u = 0.0
        if sat is not None:
            u = min(max(u, -sat), sat)
        us.append(u)
        f = f_ext[k]

        x, v = _rk4_held(x, v, f - u, m, b, k_op, h_, sub, xs)
    return np.array(xs[::sub]), np.array(us)


def test_fractional_delay_matches_fine_rk4():
    T, K, B = 1e-3, 5.0, 0.01
    loop = h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(K, B), "spring:1", T, 2,
                        fractional_delay=0.5)
    res = simulate(loop, 0.3, force="step:1", initial_position=0.002, rest_position=0.0)
    M = res.time.size - 1
    xs, us = rk4_hve_read_delayed(0.15, 0.1, 1.0, K, B, T, 2.5, 0.002, np.ones(M), M, sub=40)
    # RK4 at T/40 on ~6 rad/s dynamics: truncation far below 1e-9 of the scale
    np.testing.assert_allclose(res.position[:, 0], xs, rtol=0, atol=1e-9 * np.abs(xs).max())
    np.testing.assert_allclose(res.controller_force[:-1, 0], us, rtol=0, atol=1e-9)


@pytest.mark.parametrize("d", [3.0, 1.5])
def test_nonlinear_stepping_matches_fine_rk4(d):
    # quantisation, saturation and a wall together, whole and fractional delay
    T, K, B = 1e-3, 40.0, 0.02
    n, f = int(d), d - int(d)
    loop = h.HapticLoop(h.Device(0.15, 0.5), h.SpringDamper(K, B), "spring:1", T, n,
                        fractional_delay=f)
    # the RK4 reference rounds to the nearest step (no ties occur here) and lets the
    # wall's damper pull: the same options here
    kw = dict(resolution=2e-4, quantizer="nearest", saturation=0.3, wall=0.004, wall_pulls=True)
    res = simulate(loop, 0.5, force="sine:2,3", initial_position=0.0, **kw)
    M = res.time.size - 1
    fz = force_samples("sine:2,3", res.time[:-1])
    xs, us = rk4_hve_read_delayed(0.15, 0.5, 1.0, K, B, T, d, 0.0, fz, M, sub=20,
                                  q=2e-4, sat=0.3, wall=0.004)
    assert res.contact.any() and not res.contact.all()
    assert np.abs(res.controller_force).max() == pytest.approx(0.3)
    # a quantisation step decided differently would show as a jump of K*2e-4 = 8 mN;
    # RK4 truncation is ~1e-12, so 1e-7 m / 1e-6 N says every decision matched
    np.testing.assert_allclose(res.position[:, 0], xs, rtol=0, atol=1e-7)
    np.testing.assert_allclose(res.controller_force[:-1, 0], us, rtol=0, atol=1e-6)


def test_drift_of_free_masses_is_marginal_like_exact():
    # no terminations: a rigid-body mode; a constant push makes the pair drift
    loop = h.paper_peb(1e-3, 2, 5.0).replace(operator=None, environment=None)
    assert stability(loop).verdict == "marginal"
    res = simulate(loop, 5.0, force="step:1")
    assert res.verdict.verdict == "marginal" and not res.bounded
    # released from an offset instead: the offset persists, the motion decays
    free = simulate(loop, 5.0, initial_position=[0.01, 0.0])
    assert free.bounded
    # equal devices: x_m + x_s obeys m a + b v + K (x - x[k-n]) = 0 on its own, every
    # constant is an equilibrium and it starts (with its history) at rest at 0.01
    assert free.position[-1].sum() == pytest.approx(0.01, rel=1e-9)


def test_simulation_kmax_zero_when_unstable_for_every_k():
    # large virtual damping with a long delay: unstable as K -> 0+ (exact says so too)
    loop = h.paper_hve(1e-3, 30, 1.0, 10.0)
    assert exact_critical_stiffness(loop).critical_stiffness == 0.0
    res = critical_stiffness_simulation(loop)
    assert res.critical_stiffness == 0.0 and "unbounded already" in res.reason


@pytest.mark.parametrize("B,op,n", [(-0.12, None, 0), (-0.2, "spring:1", 10)])
def test_simulation_kmax_zero_when_negative_b_exceeds_device_damping(B, op, n):
    loop = h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(1.0, B), op, 1e-3, n)
    assert exact_critical_stiffness(loop).critical_stiffness == 0.0
    res = critical_stiffness_simulation(loop)
    assert res.critical_stiffness == 0.0 and "unbounded already" in res.reason
    # the downward scan went below the usual start (1e-6 m/T^2 = 0.15 N/m)
    assert float(res.reason.split("K = ")[1].split()[0]) < 1e-4


def test_simulation_kmax_finds_the_first_boundary_of_a_split_stable_set():
    # the exact stable set is (0, 36.14] U (91.15, 125.49] (tests/exact/test_exact.py); the
    # paper's procedure must stop at the first boundary, not the island's end
    loop = h.TeleoperationLoop(h.Device(0.19928093469739114, 0.05458898739705752),
                               h.Device(0.13333897384215598, 0.6481864867733761),
                               h.SpringDamper(1, 0.04703274312655707),
                               h.SpringDamper(1, 0.04703274312655707),
                               "spring:1", "msd:0.5,1,500", 0.00697194123846404, 0)
    ex = exact_critical_stiffness(loop)
    assert len(ex.stable_intervals) == 2
    sim = critical_stiffness_simulation(loop)
    assert abs(sim.critical_stiffness / ex.critical_stiffness - 1) < 0.01


def test_simulation_kmax_with_a_long_delay_sizes_its_window_to_the_state():
    # n = 100: 103 states, more than the default 500-snapshot window can fit three
    # times over; the search widens it (4 per state) and stays within its rtol 1e-4
    loop = h.paper_hve(1e-3, 100)
    exact = exact_critical_stiffness(loop).critical_stiffness
    r = critical_stiffness_simulation(loop)
    assert 0 <= 1 - r.critical_stiffness / exact < 1e-4


@pytest.mark.parametrize("kw", [dict(resolution=1e-6), dict(saturation=1.0),
                                dict(tdpa=h.TDPA())], ids=["encoder", "saturation", "tdpa"])
def test_a_run_that_overflows_ends_quietly_with_its_verdict(kw):
    """The nonlinear stepper's overflow check (s . s, 1e320 at |x| = 1e160, the entries
    finite) warned 'overflow' (warnings are errors here; a helper's seeded fuzz, 45 of 455
    runs); an overflowed run's summary warned 'invalid value' (inf - inf). Both are quiet:
    the first run is judged on its finite entries, the second's swings are null."""
    r = h.simulate(h.paper_hve(), 1.0, initial_position=1e160, **kw)
    assert np.isfinite(r.position).all() and r.verdict.verdict != "unbounded"
    grown = h.simulate(h.paper_hve(stiffness=1e10), 5.0, force="step:1")
    assert grown.verdict.verdict == "unbounded" and np.isinf(grown.position[-1]).all()
    assert grown.summary()["swing_end_m_device"] is None
