"""Coulomb friction in the device model and the exact stick-slip simulation (issue 14,
item 1): closed forms, the energy balance, friction-free runs unchanged, and a seeded
campaign against an independent event-driven integrator (tests/references/friction_ref.py,
scipy's solve_ivp with events, written from the physics)."""

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
import lanes
from hapstab.cli.main import cli
from hapstab.errors import ModelError
from hapstab.simulation.run import simulate
from references.friction_ref import Body, hve_run, peb_run

T = 1e-3
#: Simulator against the reference: positions within this fraction of the run's largest
#: |x|. The reference integrates each sample with rtol 1e-12 and locates its events to
#: machine precision; the two agree to 1e-14..1e-13 (measured), and the loop amplifies
#: local errors by its sensitivity over a run; a missed event, a wrong stick decision
#: or a smoothed sign(v) makes differences of 1e-4 or more.
AGREE = 1e-9


def _free(m=0.2, b=0.0, fc=0.5, op=None, K=0.0, B=0.0, n=0):
    return h.HapticLoop(h.Device(m, b, fc), h.SpringDamper(K, B), op, T, n)


def _maxwell(mz, bz, kz, km, bm):
    """Z = m_z s + b_z + k_z / s + a Maxwell element (k_m in series with b_m)."""
    a = km / bm
    num = np.polyadd(np.polymul([mz, bz, kz], [1.0, a]), [km, 0.0])
    return h.Impedance(tuple(num), (1.0, a, 0.0), label="maxwell")


# ------------------------------------------------------------------------ the model
def test_device_friction_is_checked_and_echoed():
    d = h.Device(0.2, 0.1, 0.3)
    assert d.coulomb_friction == 0.3 and d.to_dict()["coulomb_friction_N"] == 0.3
    assert "coulomb_friction_N" not in h.Device(0.2, 0.1).to_dict()   # as before
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ModelError, match="coulomb_friction"):
            h.Device(0.2, 0.1, bad)
    assert "f_c 0.3 N" in simulate(_free(fc=0.3), 0.01).model


# --------------------------------------------------------------------- closed forms
def test_a_push_below_friction_never_moves():
    res = simulate(_free(fc=0.5), 0.2, force="step:0.49", dense=8)
    assert np.all(res.position == 0) and np.all(res.velocity == 0)
    assert np.all(res.dense_position == 0) and np.all(res.dense_velocity == 0)
    assert np.all(res.friction_energy == 0)
    assert res.verdict.behaviour == "settles" and res.verdict.verdict == "bounded"


@pytest.mark.parametrize("b", [0.0, 0.3])
def test_a_push_above_friction_accelerates_at_the_excess(b):
    m, fc, F = 0.2, 0.5, 0.8
    res = simulate(_free(m, b, fc), 0.3, force=f"step:{F}", dense=5)
    t = res.dense_time
    a = (F - fc) / m
    if b == 0:
        x, v = a * t ** 2 / 2, a * t
    else:
        e = np.exp(-b * t / m)
        x, v = (F - fc) / b * (t - m / b * (1 - e)), (F - fc) / b * (1 - e)
    # both exact: rounding of the matrix exponential (~1e-15) compounded over 300 samples
    np.testing.assert_allclose(res.dense_position[:, 0], x, rtol=1e-11, atol=1e-16)
    np.testing.assert_allclose(res.dense_velocity[:, 0], v, rtol=1e-11, atol=1e-16)
    slid = float(res.position[-1, 0])
    assert res.friction_energy[-1, 0] == pytest.approx(fc * slid, rel=1e-14)   # f_c x distance


@pytest.mark.parametrize("b", [0.0, 0.3])
def test_a_sliding_mass_stops_when_the_closed_form_says_and_stays(b):
    m, fc, v0 = 0.2, 0.5, 1.3037
    if b == 0:
        ts, xs = m * v0 / fc, m * v0 ** 2 / (2 * fc)
    else:
        L = math.log1p(b * v0 / fc)
        ts, xs = m / b * L, m / b * (v0 - fc / b * L)
    res = simulate(_free(m, b, fc), 1.0, initial_velocity=v0, dense=7)
    k = int(ts / T)                      # the stop falls inside sample k
    assert 0 < ts - k * T < T
    after = res.time > ts
    assert np.all(res.velocity[after, 0] == 0.0) and np.all(res.velocity[~after, 0] > 0)
    # stuck: x is exactly constant from the stop on
    assert np.all(res.position[after, 0] == res.position[-1, 0])
    assert res.position[-1, 0] == pytest.approx(xs, rel=1e-13)   # rounding of expm (~1e-15)
    td, vd = res.dense_time, res.dense_velocity[:, 0]
    moving = td < ts
    v = v0 - fc / m * td if b == 0 else (v0 + fc / b) * np.exp(-b * td / m) - fc / b
    # rounding of expm, compounded over the samples, relative to v0 (v itself falls to 0)
    np.testing.assert_allclose(vd[moving], v[moving], rtol=0, atol=1e-13 * v0)
    assert np.all(vd[~moving] == 0.0)
    assert res.friction_energy[-1, 0] == pytest.approx(fc * xs, rel=1e-13)
    assert res.verdict.behaviour == "settles"


def test_coulomb_damped_oscillator_follows_its_closed_form():
    # M x'' = -k x - f_c sign(x'): on the n-th half period (n pi <= w t <= (n+1) pi) the
    # motion is x = (-1)^n f_c/k + a_n cos(w t), a_n = A0 - (2n+1) f_c/k, and it ends at
    # the turning point (-1)^n (f_c/k - a_n); it sticks there once |k x| <= f_c, i.e. after
    # the first half period with a_n <= 2 f_c/k. Each half period restarts from an event:
    # one found late by dt would shift the phase by dt (an error of first order).
    M, k, fc, A0 = 0.25, 40.0, 0.07, 0.02
    w = math.sqrt(k / M)
    res = simulate(_free(M, 0.0, fc, op=h.spring(k)), 2.5, initial_position=A0, rest_position=0.0)
    t = res.time
    n = np.floor(w * t / math.pi)
    a = A0 - (2 * n + 1) * fc / k
    stop = int(n[np.argmax(a <= 2 * fc / k)])      # the last half period of motion
    x = np.where(n % 2 == 0, 1.0, -1.0) * fc / k + a * np.cos(w * t)
    before = n <= stop
    assert before.sum() > 500 and (~before).sum() > 500
    # rounding of expm over ~1500 samples and of the closed form's cos(w t) at t ~ 1 s
    np.testing.assert_allclose(res.position[before, 0], x[before], rtol=0, atol=1e-13 * A0)
    a_s = A0 - (2 * stop + 1) * fc / k
    x_end = (1.0 if stop % 2 == 0 else -1.0) * (fc / k - a_s)
    assert np.all(res.position[~before, 0] == res.position[-1, 0])
    assert np.all(res.velocity[~before, 0] == 0)
    assert res.position[-1, 0] == pytest.approx(x_end, abs=1e-13 * A0)
    # energy: the spring's potential energy lost is what friction dissipated
    assert res.friction_energy[-1, 0] == pytest.approx(k / 2 * (A0 ** 2 - x_end ** 2), rel=1e-12)


# ------------------------------------------------------------------- energy balance
def test_energy_balance_to_rounding():
    # no viscous damping: work in (exogenous minus controller) = kinetic + spring + friction
    M, k, fc, rest = 0.15, 30.0, 0.05, 0.0
    loop = _free(M, 0.0, fc, op=h.spring(k), K=120.0, B=0.02, n=3)
    f = 0.6 * np.sin(2 * np.pi * 2 * np.arange(3000) * T)
    res = simulate(loop, 3.0, force=f, rest_position=rest)
    x, v = res.position[:, 0], res.velocity[:, 0]
    stored = M * v ** 2 / 2 + k * (x - rest) ** 2 / 2
    work = res.exogenous_energy[:, 0] - res.port_energy[:, 0]
    assert res.friction_energy[-1, 0] > 0.01 * np.abs(work).max()
    assert (res.velocity[:, 0] == 0).sum() > 20         # it sticks now and then
    scale = np.abs(work).max()
    np.testing.assert_allclose(work, stored + res.friction_energy[:, 0], rtol=0,
                               atol=1e-12 * scale)      # rounding of sums over 3000 samples


def test_energy_balance_with_viscous_damping_against_the_reference():
    m, b, bz, kz, fc = 0.15, 0.1, 0.4, 25.0, 0.08
    loop = h.HapticLoop(h.Device(m, b, fc), h.SpringDamper(150.0, 0.05),
                        h.mass_spring_damper(0.05, bz, kz), T, 2)
    n = 500
    f = 0.5 * np.sin(2 * np.pi * 3 * np.arange(n) * T)
    res = simulate(loop, n * T, force=f)
    _X, _V, _U, _EF, EV = hve_run(Body(m + 0.05, b + bz, kz, fc), K=150.0, B=0.05, T=T, delay=2,
                              x0=0.0, v0=0.0, force=f, n=n)
    stored = (m + 0.05) * res.velocity[:, 0] ** 2 / 2 + kz * res.position[:, 0] ** 2 / 2
    work = res.exogenous_energy[:, 0] - res.port_energy[:, 0]
    np.testing.assert_allclose(work, stored + EV + res.friction_energy[:, 0], rtol=0,
                               atol=AGREE * np.abs(work).max())


# ----------------------------------------------------------------- friction-free runs
@pytest.mark.parametrize("opts", [{}, {"wall": 0.001, "resolution": 1e-5}])
def test_without_friction_nothing_changes(opts):
    a = h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(150.0, 0.02), "msd:0.1,0.5,20", T, 3)
    b = h.HapticLoop(h.Device(0.15, 0.1, 0.0), h.SpringDamper(150.0, 0.02), "msd:0.1,0.5,20",
                     T, 3)
    ra, rb = (simulate(lp, 1.0, force="sine:0.5,2", dense=4, **opts) for lp in (a, b))
    for name in ("position", "velocity", "controller_force", "states", "dense_position"):
        assert np.array_equal(getattr(ra, name), getattr(rb, name)), name
    assert rb.friction_energy is None and "coulomb_friction_N" not in rb.nonlinear
    assert ra.verdict == rb.verdict
    # a friction level below the forces' rounding changes the run by about that much
    c = h.HapticLoop(h.Device(0.15, 0.1, 1e-13), h.SpringDamper(150.0, 0.02), "msd:0.1,0.5,20",
                     T, 3)
    rc = simulate(c, 1.0, force="sine:0.5,2", **opts)
    assert np.abs(rc.position - ra.position).max() < 1e-10 * np.abs(ra.position).max()


# -------------------------------------------------------- the independent integrator
def _hve_case(seed):
    rng = np.random.default_rng(seed)
    m, b = 10 ** rng.uniform(-1.5, -0.3), rng.uniform(0, 0.8)
    kind = rng.integers(4)
    op = [(0.0, 0.0, 0.0), (0.0, 0.0, rng.uniform(1, 300)),
          (rng.uniform(0, 0.3), rng.uniform(0, 2), rng.uniform(0, 200)),
          (rng.uniform(0, 0.1), rng.uniform(0, 1), rng.uniform(0, 100))][kind]
    km, bm = (rng.uniform(20, 200), rng.uniform(0.2, 2)) if kind == 3 else (0.0, math.inf)
    Z = _maxwell(*op, km, bm) if kind == 3 else h.mass_spring_damper(*op)
    d = [0, 1, 3, 2.4, 0.6][rng.integers(5)]
    B = rng.uniform(0, 0.5) * b
    amp = rng.uniform(0.1, 1.0)
    fc = amp * 10 ** rng.uniform(-4, 0.2)
    loop = h.HapticLoop(h.Device(m, b, fc), h.SpringDamper(1.0, B), Z, T, 0).with_delay_s(d * T)
    kmax = h.critical_stiffness(loop).critical_stiffness
    K = min(rng.uniform(0.1, 0.8) * kmax, 3000.0)
    n = 400
    tt = np.arange(n) * T
    f = amp * np.sin(2 * np.pi * rng.uniform(0.5, 5) * tt) + rng.uniform(-0.3, 0.3) * amp
    opts = {}
    if rng.random() < 0.4:
        opts["wall"] = rng.uniform(0, 2e-3)
    if rng.random() < 0.3:
        opts["resolution"] = 10 ** rng.uniform(-5.5, -4)
        opts["quantizer"] = ["floor", "nearest"][rng.integers(2)]
    if rng.random() < 0.2:
        opts["saturation"] = rng.uniform(0.3, 1.0) * amp
    body = Body(m + op[0], b + op[1], op[2], fc, km=km, bm=bm)
    return loop.with_stiffness(K), body, K, B, d, f, rng.uniform(-0.05, 0.05), opts


def _check_hve(seed):
    loop, body, K, B, d, f, v0, opts = _hve_case(seed)
    n = f.size
    res = simulate(loop, n * T, force=f, initial_velocity=v0, **opts)
    X, V, U, EF, _EV = hve_run(body, K=K, B=B, T=T, delay=d, x0=0.0, v0=v0, force=f, n=n, **opts)
    scale = np.abs(X).max()
    np.testing.assert_allclose(res.position[:, 0], X, rtol=0, atol=AGREE * scale)
    np.testing.assert_allclose(res.velocity[:, 0], V, rtol=0, atol=AGREE * np.abs(V).max())
    np.testing.assert_allclose(res.controller_force[:-1, 0], U, rtol=0,
                               atol=AGREE * max(np.abs(U).max(), 1e-12))
    np.testing.assert_allclose(res.friction_energy[:, 0], EF, rtol=0,
                               atol=AGREE * max(EF.max(), 1e-18))
    return int((V[1:] == 0).sum())


def _peb_case(seed):
    rng = np.random.default_rng(seed)
    ms = [(10 ** rng.uniform(-2, -1), rng.uniform(0, 0.1)) for _ in range(2)]
    terms = [(rng.uniform(0, 0.02), rng.uniform(0, 0.3), rng.uniform(0, 60)) for _ in range(2)]
    n_d = int(rng.choice([0, 2, 5]))
    B = rng.uniform(0, 0.5) * min(b for _, b in ms)
    amp = rng.uniform(0.05, 0.5)
    fcs = [amp * 10 ** rng.uniform(-4, 0) for _ in range(2)]
    c = h.SpringDamper(1.0, B)
    loop = h.TeleoperationLoop(h.Device(*ms[0], fcs[0]), h.Device(*ms[1], fcs[1]), c, c,
                               h.mass_spring_damper(*terms[0]), h.mass_spring_damper(*terms[1]),
                               T, n_d)
    K = rng.uniform(0.1, 0.8) * h.critical_stiffness(loop).critical_stiffness
    n = 400
    tt = np.arange(n) * T
    fm = amp * np.sin(2 * np.pi * rng.uniform(0.5, 5) * tt)
    fs = rng.uniform(0, 0.5) * amp * np.sin(2 * np.pi * rng.uniform(0.5, 5) * tt)
    opts = {}
    if rng.random() < 0.3:
        opts["resolution"] = 10 ** rng.uniform(-5.5, -4)
    if rng.random() < 0.2:
        opts["saturation"] = rng.uniform(0.3, 1.0) * amp
    x0 = rng.uniform(-1e-3, 1e-3, 2)
    bodies = [Body(m + z[0], b + z[1], z[2], fc, rest=r)
              for (m, b), z, fc, r in zip(ms, terms, fcs, x0, strict=True)]
    return loop.with_stiffness(K), bodies, K, B, n_d, fm, fs, x0, opts


def _check_peb(seed):
    loop, (bm_, bs_), K, B, n_d, fm, fs, x0, opts = _peb_case(seed)
    n = fm.size
    res = simulate(loop, n * T, force=fm, environment_force=fs, initial_position=list(x0), **opts)
    XM, XS, UM, US, FM, FS = peb_run(bm_, bs_, K=K, B=B, T=T, delay=n_d, xm0=x0[0], xs0=x0[1],
                                     force_m=fm, force_s=fs, n=n, **opts)
    P = np.c_[XM, XS]
    np.testing.assert_allclose(res.position, P, rtol=0, atol=AGREE * np.abs(P).max())
    np.testing.assert_allclose(res.controller_force[:-1], np.c_[UM, US], rtol=0,
                               atol=AGREE * max(np.abs(np.c_[UM, US]).max(), 1e-12))
    E = np.c_[FM, FS]
    np.testing.assert_allclose(res.friction_energy, E, rtol=0, atol=AGREE * max(E.max(), 1e-18))
    return int((res.velocity[1:] == 0).sum())


#: the short campaign's cases: (check, seed); the ones that stick and slip (measured: HVE
#: seed 4 sticks 391 samples, PEB 0 and 1 stick 19 and 63; the other five never stick)
_STICKING = [(_check_hve, 4), (_check_peb, 0), (_check_peb, 1)]
_SLIDING = [(_check_hve, s) for s in range(4)] + [(_check_peb, 2)]


@pytest.mark.parametrize("rest", lanes.PARTS)
def test_campaign_against_the_event_driven_reference(rest):
    # the default lane the three cases that stick and slip (the events the reference is
    # for, both loops; 1.3 of the campaign's 3 s), -m campaign the five that only slide
    # (tests/lanes.py): together the same 8 cases, each checked against the reference
    stuck = [check(s) for check, s in (_SLIDING if rest else _STICKING)]
    if not rest:
        assert sum(s > 0 for s in stuck) >= 3, stuck    # the campaign does stick and slip


@pytest.mark.slow
def test_campaign_against_the_event_driven_reference_long():
    stuck = [_check_hve(s) for s in range(5, 65)] + [_check_peb(s) for s in range(3, 33)]
    assert sum(s > 0 for s in stuck) >= 30, stuck


def test_leaving_stick_inside_a_sample_with_a_relaxing_operator():
    # a Maxwell element (spring in series with a damper) on the device: while it sticks the
    # element's force relaxes, and the body breaks away inside a sample, at the instant
    # |N| reaches f_c
    loop = h.HapticLoop(h.Device(0.1, 0.0, 0.2), h.SpringDamper(0.0, 0.0),
                        _maxwell(0, 0, 0, 200.0, 2.0), T, 0)
    f = np.r_[np.full(100, 0.25), np.zeros(20), np.full(280, 0.205)]
    res = simulate(loop, 0.4, force=f, dense=10)
    X, _V, _U, _EF, _EV, track = hve_run(Body(0.1, 0.0, 0.0, 0.2, km=200.0, bm=2.0), K=0.0, B=0.0,
                                     T=T, delay=0, x0=0.0, v0=0.0, force=f, n=400, track=True)
    v = res.velocity[:, 0]
    stuck = np.flatnonzero(v == 0)
    assert stuck.size > 5 and stuck[-1] < 399 and v[stuck[-1] + 1] > 0   # it broke away
    np.testing.assert_allclose(res.position[:, 0], X, rtol=0, atol=AGREE * np.abs(X).max())
    xd = np.array([track.x(t, 0.0) for t in res.dense_time])
    np.testing.assert_allclose(res.dense_position[:, 0], xd, rtol=0, atol=AGREE * np.abs(X).max())


def test_dense_output_is_the_exact_trajectory():
    loop, body, K, B, d, f, v0, opts = _hve_case(1)
    res = simulate(loop, f.size * T, force=f, initial_velocity=v0, dense=9, **opts)
    *_, track = hve_run(body, K=K, B=B, T=T, delay=d, x0=0.0, v0=v0, force=f, n=f.size,
                        track=True, **opts)
    xd = np.array([track.x(t, 0.0) for t in res.dense_time])
    np.testing.assert_allclose(res.dense_position[:, 0], xd, rtol=0,
                               atol=AGREE * np.abs(xd).max())
    at_samples = res.dense_position[::9, 0]
    assert np.array_equal(at_samples, res.position[:, 0])


def test_four_channel_force_feedback_sees_the_friction():
    # C_6 local force feedback: the force the operator's mass applies at kT^- depends on
    # the acceleration friction leaves; the reference computes it from its own ODE
    mz, bz, kz, c6, fc = 0.1, 0.4, 30.0, 0.5, 0.3
    loop = h.FourChannelLoop(h.Device(0.15, 0.1, fc), h.Device(0.1, 0.1),
                             h.SpringDamper(100.0, 0.05), h.SpringDamper(100.0, 0.05),
                             h.mass_spring_damper(mz, bz, kz), h.spring(10.0), T, 0,
                             slave_from_master=h.SpringDamper(0, 0),
                             master_from_slave=h.SpringDamper(0, 0), master_force_feedback=c6)
    n = 600
    f = 0.5 * np.sin(2 * np.pi * 3 * np.arange(n) * T)
    res = simulate(loop, n * T, force=f)
    X, V, U, _EF, _EV = hve_run(Body(0.15 + mz, 0.1 + bz, kz, fc), K=100.0, B=0.05, T=T, delay=0,
                              x0=0.0, v0=0.0, force=f, n=n, force_feedback=(c6, mz, bz))
    assert (V == 0).sum() > 10
    np.testing.assert_allclose(res.position[:, 0], X, rtol=0, atol=AGREE * np.abs(X).max())
    np.testing.assert_allclose(res.controller_force[:-1, 0], U, rtol=0,
                               atol=AGREE * np.abs(U).max())


# ------------------------------------------------------------------------- verdicts
def test_friction_holds_a_linearly_unstable_loop_at_rest():
    loop = h.HapticLoop(h.Device(0.15, 0.1, 0.2), h.SpringDamper(1.0, 0.0), "spring:1", T, 10)
    K = 8 * h.critical_stiffness(loop).critical_stiffness
    res = simulate(loop.with_stiffness(K), 2.0, force="pulse:0.1,0.05")
    assert res.verdict.behaviour == "settles" and np.all(res.position == 0)
    big = simulate(loop.with_stiffness(K), 3.0, force="pulse:5,0.05")   # a large one grows
    x = np.abs(big.position[:, 0])
    assert big.verdict.verdict != "bounded" and x[-1000:].max() > 10 * x[:1000].max()
    assert "linear" in h.stability(loop.with_stiffness(K)).note    # the note, said once


def test_a_stable_loop_with_friction_is_bounded_by_the_model():
    loop = h.HapticLoop(h.Device(0.15, 0.1, 0.05), h.SpringDamper(150.0, 0.0), "spring:1", T, 0)
    res = simulate(loop, 3.0, force="sine:1,2")
    assert res.verdict.verdict == "bounded" and res.verdict.basis == "bound"
    assert "Coulomb friction is a force of at most f_c" in res.verdict.reason


def test_linear_analyses_say_they_are_friction_free():
    a = h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(9.0, 0.0), "spring:1", T, 10)
    b = h.HapticLoop(h.Device(0.15, 0.1, 0.05), h.SpringDamper(9.0, 0.0), "spring:1", T, 10)
    for method in ("exact", "circle", "passivity", "eq18"):
        ra, rb = h.critical_stiffness(a, method), h.critical_stiffness(b, method)
        assert ra.critical_stiffness == rb.critical_stiffness
        # said once, in its own field, not in every reason (issue 29, item 2)
        assert ra.reason == rb.reason and not ra.note and "friction-free loop" in rb.note
        assert rb.to_dict()["friction_note"] == rb.note
    sa, sb = h.stability(a), h.stability(b)
    assert sa.verdict == sb.verdict and sa.spectral_radius == sb.spectral_radius
    assert "conservative" in sb.note and "Abbott & Okamura" in sb.note
    assert sa.reason == sb.reason


# ---------------------------------------------------------------------------- CLI
def _json(args):
    r = CliRunner().invoke(cli, [*args, "--json"])
    assert r.exit_code == 0, r.stderr
    return json.loads(r.stdout)


def test_cli_simulate_with_friction():
    d = _json(["simulate", "hve", "-K", "100", "--friction", "0.05", "--duration", "1",
               "--force", "sine:1,2"])
    assert d["nonlinear"]["coulomb_friction_N"] == [0.05]
    assert d["friction_dissipated_J_device"] > 0
    assert d["inputs"]["loop"]["device"]["coulomb_friction_N"] == 0.05
    assert "friction" in d["linear_loop"]
    p = _json(["simulate", "peb", "-K", "5", "--master-friction", "0.01", "--slave-friction",
               "0.02", "--duration", "0.5"])
    assert p["nonlinear"]["coulomb_friction_N"] == [0.01, 0.02]
    q = _json(["simulate", "4ch", "-K", "5", "--slave-friction", "0.02", "--duration", "0.5"])
    assert q["nonlinear"]["coulomb_friction_N"] == [0.0, 0.02]
    r = CliRunner().invoke(cli, ["simulate", "hve", "-K", "5", "--friction", "-1"])
    assert r.exit_code == 2 and "--friction" in r.stderr and ">= 0" in r.stderr


def test_cli_linear_commands_note_friction(tmp_path):
    plain, fr = (_json(["kmax", "hve", "-n", "3", *x]) for x in ([], ["--friction", "0.1"]))
    assert plain["critical_stiffness"] == fr["critical_stiffness"]
    assert "friction-free loop" in fr["friction_note"] and "friction" not in fr["reason"]
    b = _json(["boundary", "hve", "--period", "0.001", "--friction", "0.1"])
    assert "friction-free loop" in b["friction_note"]
    r = CliRunner().invoke(cli, ["boundary", "hve", "--period", "0.001", "--friction", "0.1"])
    assert r.exit_code == 0 and "friction-free loop" in r.stdout
    study = tmp_path / "s.toml"
    study.write_text('kind = "hve"\n[loop]\nfriction = 0.05\n[run.simulate]\nK = 50\n'
                     'duration = 0.5\n')
    s = _json(["simulate", "--study", str(study)])
    assert s["nonlinear"]["coulomb_friction_N"] == [0.05]
    k = _json(["kmax", "--study", str(study)])
    assert "friction-free loop" in k["friction_note"]


def test_a_run_that_overflows_says_so():
    # far beyond K_max the motion grows until double precision runs out: overflowed, not
    # (as an uncertified event search on inf would make it) a body that stuck
    loop = h.HapticLoop(h.Device(0.15, 0.1, 0.05), h.SpringDamper(1e6, 0.0), "spring:1", T, 0)
    res = simulate(loop, 1.0, force="step:1")
    assert not np.all(np.isfinite(res.position)) and res.verdict.verdict == "unbounded"
    assert "overflowed" in res.verdict.reason


def test_a_run_whose_stick_slip_outruns_its_budget_stops_saying_so():
    """Stick-slip at every sample costs up to ~1 ms a sample (each event located on the
    exact flow), 30x the estimate a run is admitted with: a helper's seeded fuzz ran
    180,728 such samples for over a minute under the 1-minute budget. The stepping now
    stops with BudgetError once the run has taken its budget."""
    import time

    from hapstab.budget import BudgetError

    loop = h.HapticLoop(h.Device(0.09047136421781875, 0.0, coulomb_friction=3.2225e-4),
                        h.SpringDamper(17586.10524801639, 0.0),
                        operator=h.spring(1386.0041342422087),
                        period=0.01).with_delay_s(0.0037455939079418243)
    kw = dict(force="step:-18.709558696121533,0", initial_position=1e10, rest_position=-1e6,
              saturation=0.01)
    t0 = time.monotonic()
    with pytest.raises(BudgetError, match=r"of 5000 samples with Coulomb friction: \d+ samples"):
        h.simulate(loop, 50.0, max_seconds=0.3, **kw)
    assert time.monotonic() - t0 < 3.0       # stopped near its budget (~0.8 s for the run)
    assert h.simulate(loop, 0.5, max_seconds=30.0, **kw).verdict is not None   # within it
