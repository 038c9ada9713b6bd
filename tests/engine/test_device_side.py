"""The loop cut at its terminations (engine.device_side), the one K_s/K_m convention
(models.stiffness_ratios) and the one rigid-body rule (engine.structure.rigid_modes),
each against a reference written independently here: the controller matrix against
eq. (20)/(23) written out by hand, the K- and B-parts against the whole H, and the
structural rigid-body rule against the null space of the closed-loop matrices."""

import numpy as np
import pytest

import hapstab as h
from hapstab.engine.device_side import device_side
from hapstab.engine.structure import rigid_modes, structure_of
from hapstab.engine.system import build
from hapstab.errors import AnalysisError
from hapstab.models.controllers import DiscreteController, SpringDamper, stiffness_ratios
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.models.parts import Device, mass_spring_damper

TH = np.array([1e-6, 0.3, 1.1, 2.5, np.pi])


def _peb(km=40.0, ks=100.0, bm=0.02, bs=0.03, n=3, op=None, env=None, T=2e-3):
    return TeleoperationLoop(Device(0.5, bm), Device(1.0, bs), SpringDamper(km, 0.01),
                             SpringDamper(ks, 0.04), op, env, T, n)


def test_stiffness_ratios_is_the_one_convention():
    assert stiffness_ratios([40.0, 100.0]) == (1.0, 2.5)
    assert stiffness_ratios([0.0, 0.0]) == (1.0, 1.0)
    assert stiffness_ratios([0.0, 5.0]) is None
    assert stiffness_ratios([7.0]) == (1.0,)
    # with_stiffness follows it: K_s/K_m kept
    lp = _peb().with_stiffness(80.0)
    assert (lp.master_controller.stiffness, lp.slave_controller.stiffness) == (80.0, 200.0)
    with pytest.raises(AnalysisError, match="K_s/K_m undefined"):
        _peb(km=0.0).with_stiffness(1.0)


def test_controller_matrix_is_eq20_with_eq23_by_hand():
    T, n = 2e-3, 3
    side = device_side(_peb(T=T, n=n), "test")
    z = np.exp(1j * TH)
    Hm = 40.0 + 0.01 * (z - 1) / (T * z)     # eq. (23), written out
    Hs = 100.0 + 0.04 * (z - 1) / (T * z)
    ref = np.array([[Hm, -z ** -n * Hm], [-z ** -n * Hs, Hs]])   # eq. (20): u = Hc x
    got = side.controller_matrix(TH)
    assert np.allclose(got, np.moveaxis(ref, 2, 0), rtol=1e-13, atol=0)
    assert side.damping.tolist() == [0.02, 0.03]
    assert side.names == ("master", "slave")


def test_parts_add_up_to_the_whole_controller_at_the_own_stiffness():
    for loop in (_peb(), h.paper_hve(delay_samples=4), _peb(km=40.0, ks=40.0, n=0)):
        side = device_side(loop, "test")
        K = loop.controllers[0].stiffness
        whole = side.controller_matrix(TH)
        parts = side.controller_matrix(TH, "B") + K * side.controller_matrix(TH, "K")
        assert np.allclose(parts, whole, rtol=1e-13, atol=1e-13 * np.abs(whole).max())


def test_polynomials_agree_with_the_matrix():
    side = device_side(_peb(n=5), "test")
    nums, dens = side.controller_polynomials()
    z = np.exp(1j * TH)
    for i in range(2):
        for j in range(2):
            val = np.polyval(nums[i][j], z) / np.polyval(dens[i][j], z)
            assert np.allclose(val, side.controller_matrix(TH)[:, i, j], rtol=1e-12)


def test_port_weights_make_the_stiffness_residue_hermitian():
    side = device_side(_peb(km=40.0, ks=100.0), "test")
    D = np.array(side.port_weights("auto"))
    k = np.array(side.ratios)
    residue = np.diag(D) @ np.array([[k[0], -k[0]], [-k[1], k[1]]])  # (25) per unit K T
    assert np.allclose(residue, residue.T)
    assert side.port_weights(None) == (1.0, 1.0)
    assert device_side(h.paper_hve(), "test").port_weights("auto") == (1.0,)
    with pytest.raises(AnalysisError, match="scaling = 'x'"):
        side.port_weights("x")


def test_a_general_controller_has_no_K_part():
    loop = HapticLoop(Device(0.1, 0.1), DiscreteController((1.0, -0.5), (1.0, 0.2)), None, 1e-3, 2)
    side = device_side(loop, "test")
    assert side.ratios is None
    z = np.exp(1j * TH)
    assert np.allclose(side.controller_matrix(TH)[:, 0, 0], z ** -2 * (z - 0.5) / (z + 0.2))
    with pytest.raises(AnalysisError, match="K cannot be varied"):
        side.controller_matrix(TH, "K")


def test_fractional_delays_are_refused_by_name():
    with pytest.raises(AnalysisError, match="the test: derived for a whole number"):
        device_side(h.paper_hve().with_delay_s(2.5e-3), "the test")


# ------------------------------------------------------------- the rigid-body rule
def _null_dim(A0, A1):
    """Reference: modes at z = 1 that no K moves, dim null([I - A0; A1]) by SVD."""
    S = np.linalg.svd(np.vstack([np.eye(A0.shape[0]) - A0, A1]), compute_uv=False)
    return int(np.sum(S < 1e-10 * max(1.0, S[0])))


@pytest.mark.parametrize("seed", range(40))
def test_rigid_rule_matches_the_null_space(seed):
    rng = np.random.default_rng(seed)
    T, n = 10 ** rng.uniform(-4, -2), int(rng.integers(0, 6))
    spring = lambda: mass_spring_damper(  # noqa: E731
        rng.uniform(0, 1), rng.uniform(0, 2), rng.choice([0.0, rng.uniform(10, 1e3)]))
    kind = seed % 3
    if kind == 0:
        loop = HapticLoop(Device(rng.uniform(0.1, 2), rng.uniform(0, 1)),
                          SpringDamper(rng.uniform(1, 100), rng.uniform(-0.05, 0.5)),
                          spring() if rng.random() < 0.5 else None, T, n)
    else:
        loop = TeleoperationLoop(Device(rng.uniform(0.1, 2), rng.uniform(0, 1)),
                                 Device(rng.uniform(0.1, 2), rng.uniform(0, 1)),
                                 SpringDamper(rng.uniform(1, 100), rng.uniform(0, 0.5)),
                                 SpringDamper(rng.uniform(1, 100), rng.uniform(0, 0.5)),
                                 spring() if kind == 2 else None, spring() if kind == 2 else None,
                                 T, n)
    sysm = build(loop)
    ref = _null_dim(sysm.A0[0], sysm.A1()[0])
    assert rigid_modes(structure_of(loop), T) == sysm.rigid_modes == ref


def test_free_peb_has_one_rigid_mode_and_the_hve_none():
    free = _peb(op=None, env=None)
    assert build(free).rigid_modes == 1
    assert build(h.paper_hve()).rigid_modes == 0
    grounded = _peb(env=mass_spring_damper(0.0, 0.0, 100.0))
    assert build(grounded).rigid_modes == 0
