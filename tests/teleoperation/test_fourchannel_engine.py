"""The state-space engine and the simulator on Lawrence's 4-channel teleoperator
(FourChannelLoop): against PEB (its special case) and against the independent brute
force of references/brute.py (``four_channel_loop``, ``full_matrices``, ``step_loop``:
the force measured at kT^- derived there from the physics)."""

from __future__ import annotations

import numpy as np
import pytest

from hapstab.engine.system import build
from hapstab.errors import ModelError
from hapstab.models import Device, SpringDamper, TeleoperationLoop, mass_spring_damper, spring
from hapstab.models.fourchannel import FourChannelLoop
from hapstab.simulation.run import simulate
from references import brute

PERIODS = (5e-4, 1e-3, 2e-3)


def _nonzero(A: np.ndarray) -> np.ndarray:
    """Eigenvalues with |z| > 1e-3, sorted. The cut is that large because the shift
    registers make nilpotent blocks at z = 0 whose computed eigenvalues scatter to
    about eps^(1/m) for a block of size m (1e-3 and below for m <= 5); every other
    eigenvalue of these loops is far from 0."""
    z = np.linalg.eigvals(A)
    z = z[np.abs(z) > 1e-3]
    return z[np.lexsort((z.imag, z.real))]


def _peb_params(rng: np.random.Generator) -> dict:
    T = float(rng.choice(PERIODS))
    mm, ms = rng.uniform(0.2, 2.0, 2)
    Km = float(rng.uniform(0.005, 0.1) * min(mm, ms) / T ** 2)
    ratio = float(rng.choice([1.0, rng.uniform(0.3, 3.0)]))
    Bm, Bs = rng.uniform(0.0, 4.0, 2)          # unequal virtual dampings
    kw = dict(master=Device(mm, rng.uniform(0, 2)), slave=Device(ms, rng.uniform(0, 2)),
              master_controller=SpringDamper(Km, Bm),
              slave_controller=SpringDamper(ratio * Km, Bs), period=T)
    if rng.random() < 0.6:
        kw["operator"] = mass_spring_damper(rng.uniform(0.1, 1), rng.uniform(0, 5),
                                            rng.uniform(0, 300))
    if rng.random() < 0.6:
        kw["environment"] = spring(rng.uniform(10, 2000))
    return kw


# --------------------------------------------------------- PEB is a 4-channel loop
@pytest.mark.parametrize("seed", range(14))
def test_peb_gains_give_peb_eigenvalues(seed):
    rng = np.random.default_rng(seed)
    kw = _peb_params(rng)
    nf = seed % 7                                    # delays 0 ... 6
    nb = int(rng.integers(0, 7))
    peb = build(TeleoperationLoop(**kw, delay_samples=nf, delay_backward_samples=nb))
    four = build(FourChannelLoop(**kw, delay_samples=nf, delay_backward_samples=nb))
    assert four.stiffness[0] == peb.stiffness[0] and four.varies_with_K and four.E is None
    assert four.held_u is None and four.E_channels.shape[0] == 4
    for K in (None, 0.3 * peb.stiffness[0], 2.0 * peb.stiffness[0]):
        za, zb = _nonzero(peb.closed_loop(K)[0]), _nonzero(four.closed_loop(K)[0])
        assert za.size == zb.size
        # the same matrix up to a change of basis and extra states at z = 0: the
        # eigenvalues agree to their conditioning (a rigid pair's z = 1 is well
        # separated here); 1e-8 leaves a factor ~1e7 over eps for it
        assert np.abs(za - zb).max() < 1e-8, (K, np.abs(za - zb).max())


@pytest.mark.parametrize("seed", range(6))
def test_peb_gains_simulate_like_peb(seed):
    rng = np.random.default_rng(100 + seed)
    kw = _peb_params(rng)
    kw.update(delay_samples=int(rng.integers(0, 7)), delay_backward_samples=int(rng.integers(0, 7)))
    M = 400
    t = np.arange(M) * kw["period"]
    f = 3.0 * np.sin(2 * np.pi * 4.0 * t)
    fe = np.where(t > 0.1, -1.0, 0.0)
    run = dict(force=f, environment_force=fe, initial_position=[0.01, -0.004],
               initial_velocity=[0.0, 0.02])
    a = simulate(TeleoperationLoop(**kw), M * kw["period"], **run)
    b = simulate(FourChannelLoop(**kw), M * kw["period"], **run)
    for name in ("position", "velocity", "controller_force", "exogenous_force"):
        x, y = getattr(a, name), getattr(b, name)
        # the same arithmetic up to the order of the controllers' sums: rounding only
        assert np.abs(x - y).max() <= 1e-12 * np.abs(x).max(), name


# ------------------------------------------------------ against the brute force
def _four_channel(rng: np.random.Generator, full: bool):
    """A random force-reflection (``full=False``) or full 4-channel loop, hapstab's
    and the brute force's."""
    T = float(rng.choice(PERIODS))
    mm, ms = rng.uniform(0.2, 2.0, 2)
    bm, bs = rng.uniform(0, 2, 2)
    nf, nb = (int(v) for v in rng.integers(0, 5, 2))
    Ks = float(rng.uniform(0.005, 0.05) * min(mm, ms) / T ** 2)
    om, ob, ok = rng.uniform(0.1, 1.0), rng.uniform(0, 5), rng.uniform(10, 300)
    operator = mass_spring_damper(om, ob, ok)
    if full:
        em, eb, ek = rng.uniform(0.1, 1.0), rng.uniform(0, 10), rng.uniform(50, 2000)
        environment = mass_spring_damper(em, eb, ek)
        env_spec = ("msd", em, eb, ek)
        r = rng.uniform(0.3, 2.0, 3)                  # C_s, C_1, C_4' per unit C_m
        B = rng.uniform(0, 3, 4)
        ctl = [SpringDamper(Ks, B[0]), SpringDamper(r[0] * Ks, B[1]),
               SpringDamper(r[1] * Ks, B[2]), SpringDamper(r[2] * Ks, B[3])]
        gains = dict(force_to_master=rng.uniform(0.2, 1.5), force_to_slave=rng.uniform(0.2, 1.5),
                     slave_force_feedback=rng.uniform(-0.5, 0.5),
                     master_force_feedback=rng.uniform(-0.5, 0.5))
    else:
        ek, eb = rng.uniform(50, 3000), float(rng.choice([0.0, rng.uniform(0, 10)]))
        environment = mass_spring_damper(0.0, eb, ek)
        env_spec = ("msd", 0.0, eb, ek)
        Bs = rng.uniform(0, 3)
        ctl = [SpringDamper(0.0, rng.uniform(0.5, 5)), SpringDamper(Ks, Bs),
               SpringDamper(Ks, Bs), SpringDamper(0.0, 0.0)]
        gains = dict(force_to_master=rng.uniform(0.2, 2.0))
    loop = FourChannelLoop(master=Device(mm, bm), slave=Device(ms, bs), master_controller=ctl[0],
                           slave_controller=ctl[1], slave_from_master=ctl[2],
                           master_from_slave=ctl[3], operator=operator, environment=environment,
                           period=T, delay_samples=nf, delay_backward_samples=nb, **gains)
    ref = ctl[0].stiffness or ctl[1].stiffness
    g = [(c.stiffness / ref, c.damping) for c in ctl]
    bl = brute.four_channel_loop((mm, bm), (ms, bs), T, nf, nb, g[0], g[1], g[2], g[3],
                                 c2=gains.get("force_to_master", 0.0),
                                 c3=gains.get("force_to_slave", 0.0),
                                 c5=gains.get("slave_force_feedback", 0.0),
                                 c6=gains.get("master_force_feedback", 0.0),
                                 operator=("msd", om, ob, ok), environment=env_spec)
    return loop, bl, ref


@pytest.mark.parametrize("full", [False, True], ids=["force-reflection", "full"])
@pytest.mark.parametrize("seed", range(18))
def test_spectral_radius_matches_brute_force(seed, full):
    loop, bl, ref = _four_channel(np.random.default_rng(1000 * full + seed), full)
    sysm = build(loop)
    assert sysm.varies_with_K and sysm.stiffness[0] == ref
    assert sysm.held_u is not None and np.all(sysm.held_u >= 0) == full
    for K in ref * np.array([0.05, 0.5, 1.0, 4.0, 20.0]):
        rho = np.abs(np.linalg.eigvals(sysm.closed_loop(K)[0])).max()
        rho_b = float(brute.radius(bl, K)[0])
        # two realisations of one loop (states ordered and discretised differently:
        # hapstab's Pade exponential vs scipy's expm): the dominant eigenvalue agrees
        # to eps times its condition number; 1e-9 leaves ~1e6 for it
        assert abs(rho - rho_b) <= 1e-9 * rho_b, (K, rho, rho_b)


@pytest.mark.parametrize("full", [False, True], ids=["force-reflection", "full"])
@pytest.mark.parametrize("seed", range(4))
def test_simulate_matches_brute_stepping(seed, full):
    """Exogenous operator (and environment) force: f_old and u_old enter the measured
    force at kT^- (an operator with mass)."""
    loop, bl, ref = _four_channel(np.random.default_rng(5000 + 10 * full + seed), full)
    M, T = 600, loop.period
    t = np.arange(M) * T
    f = np.zeros((M, 2))
    f[:, 0] = 2.0 * np.sin(2 * np.pi * 3.0 * t) + (t > 0.05)
    f[:, 1] = np.where(t > 0.2, -0.5, 0.0) if full else 0.0
    X, U = brute.step_loop(bl, ref, f)
    r = simulate(loop, M * T, force=f[:, 0], environment_force=f[:, 1] if full else None)
    for name, mine, theirs in (("position", r.position, X), ("force", r.controller_force, U)):
        scale = np.abs(theirs).max()
        # a bounded or growing run: rounding accumulates over the 600 samples at the
        # loop's own rate; 1e-9 of the run's largest value covers a growth x1e3
        assert np.abs(mine - theirs).max() <= 1e-9 * scale, (name, np.abs(mine - theirs).max())


def test_force_channels_in_the_engine():
    loop, _, ref = _four_channel(np.random.default_rng(7), True)
    sysm = build(loop)
    st_n = sysm.order
    assert sysm.held_u.shape == (2,) and sysm.held_f.shape == (2,)
    # u_old takes the port's controller force; f_old the exogenous one
    A = sysm.closed_loop()[0]
    for j in range(2):
        assert np.array_equal(A[sysm.held_u[j]], sysm.force_matrix()[0][j])
        assert not A[sysm.held_f[j]].any() and sysm.B_ext[0, sysm.held_f[j], j] == 1.0
    assert np.array_equal(sysm.A0[0] + ref * sysm.B1[0] @ sysm.C1[0], A)
    assert st_n == sysm.A0.shape[-1]


def test_quantised_force_measurement_is_refused():
    loop, _, _ = _four_channel(np.random.default_rng(3), False)
    with pytest.raises(ModelError, match="resolution"):
        simulate(loop, 0.05, force=1.0, resolution=1e-5)


def test_saturation_applies_the_clipped_force_to_the_held_state():
    loop, _, _ = _four_channel(np.random.default_rng(4), True)
    r = simulate(loop, 0.2, force=5.0, saturation=0.5)
    sysm = build(loop)
    S, U = r.states, r.controller_force
    assert np.abs(U).max() <= 0.5
    for j in range(2):
        assert np.array_equal(S[1:, sysm.held_u[j]], U[:-1, j])


def test_force_reflection_steady_contact_scales_the_environment_force():
    """The sign convention, from the physics alone: in steady contact the master's
    device is at rest, so F_h + F_cm = 0 with F_cm = -C_2 F_e: the operator pushes
    with k_f times the force the slave applies to the environment; and the slave,
    C_s (x_m - x_s) = F_e, follows the master into the wall."""
    kf, ke, kop, F = 0.5, 400.0, 50.0, 2.0
    loop = FourChannelLoop(master=Device(0.5, 2.0), slave=Device(0.8, 3.0),
                           master_controller=SpringDamper(0.0, 4.0),
                           slave_controller=SpringDamper(2000.0, 20.0),
                           master_from_slave=SpringDamper(0.0, 0.0),
                           operator=mass_spring_damper(0.3, 5.0, kop),
                           environment=mass_spring_damper(0.0, 2.0, ke), period=1e-3,
                           delay_samples=1, force_to_master=kf)
    assert np.abs(np.linalg.eigvals(build(loop).closed_loop()[0])).max() < 1
    r = simulate(loop, 20.0, force=F)
    xm, xs = r.position[-1]
    Fh, Fe = F - kop * xm, ke * xs
    assert Fe > 0.1 and abs(Fh - kf * Fe) < 1e-6 * F
    assert abs(2000.0 * (xm - xs) - Fe) < 1e-6 * F


@pytest.mark.parametrize("full", [False, True], ids=["force-reflection", "full"])
def test_simulate_matches_brute_stepping_on_stable_loops(full):
    """The same comparison on loops at a K inside their exact stable set (the random
    draws above mostly grow): 3 loops each, after 1,500 samples the run has settled, so
    rounding cannot hide behind growth. 1e-10 of the run's largest value: a stable run's
    rounding stays near eps times its condition."""
    from hapstab import critical_stiffness

    rng, done = np.random.default_rng(6000 + full), 0
    while done < 3:
        loop, bl, _ref = _four_channel(rng, full)
        ivs = critical_stiffness(loop).stable_intervals
        if not ivs or not np.isfinite(ivs[0][1]):
            continue
        K = 0.5 * (ivs[0][0] + ivs[0][1])
        done += 1
        M, T = 1500, loop.period
        t = np.arange(M) * T
        f = np.zeros((M, 2))
        f[:, 0] = np.sin(2 * np.pi * 2.0 * t) + (t > 0.05)
        X, U = brute.step_loop(bl, K, f)
        r = simulate(loop.with_stiffness(K), M * T, force=f[:, 0])
        assert r.verdict.verdict in ("bounded", "marginal"), r.verdict
        for mine, theirs in ((r.position, X), (r.controller_force, U)):
            assert np.abs(mine - theirs).max() <= 1e-10 * np.abs(theirs).max()
