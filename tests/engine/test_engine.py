"""Engine: exact ZOH, the affine dependence on K, and the closed loop against an
independent construction (tests/references/brute.py)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import hapstab as h
from hapstab.engine.structure import structure_of
from hapstab.engine.system import build
from hapstab.engine.zoh import discretize, port_matrices
from references import brute


def test_zoh_matches_fine_ode_integration():
    # device + msd operator driven by a held force: integrate the ODE finely
    port = structure_of(h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(1.0),
                                     "msd:0.05,0.3,200", 2e-3, 0)).ports[0]
    A, B, _ = port_matrices(port)
    T = 2e-3
    Ad, Bd = discretize(A, B, np.array([T]))
    x0 = np.array([0.01, -0.2])
    sol = solve_ivp(lambda t, x: A @ x + B[:, 0] * 1.5, (0, T), x0, rtol=1e-12, atol=1e-15)
    # rtol 1e-12 integration: agreement to ~1e-10 relative is what it can show
    np.testing.assert_allclose(Ad[0] @ x0 + Bd[0, :, 0] * 1.5, sol.y[:, -1], rtol=1e-9, atol=1e-14)


def test_closed_loop_is_affine_in_stiffness():
    loop = h.paper_peb(delay_samples=3, damping=0.01)
    sysm = build(loop)
    for K in (0.5, 7.0, 33.0):
        direct = build(loop.with_stiffness(K)).closed_loop()
        np.testing.assert_allclose(sysm.closed_loop(K), direct, rtol=0, atol=1e-13)


@pytest.mark.parametrize("n,B,op", [(0, 0.0, "spring:1"), (10, 0.05, "spring:1"), (3, 0.02, "none"),
                                    (2, 0.0, "msd:0.1,0.5,50")])
def test_hve_spectrum_matches_independent_construction(n, B, op):
    loop = h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(40.0, B), op, 1e-3, n)
    z = h.parse_impedance(op)
    ours = np.sort_complex(np.linalg.eigvals(build(loop).closed_loop()[0]))
    theirs = brute.closed_loop_matrix([(0.15, 0.1, z.num, z.den)], [[(0, 1.0, n)]], 40.0, B, 1e-3)
    theirs = np.sort_complex(np.linalg.eigvals(theirs))
    # the independent model keeps one extra register (poles at z = 0) when B = 0
    big = lambda e: np.sort(np.abs(e[np.abs(e) > 1e-6]))  # noqa: E731
    np.testing.assert_allclose(big(ours), big(theirs), rtol=1e-9)


def test_peb_spectrum_matches_independent_construction():
    loop = h.TeleoperationLoop(h.Device(0.015, 0.02), h.Device(0.03, 0.05), h.SpringDamper(8.0, 0.004),
                               h.SpringDamper(8.0, 0.004), "spring:1", "msd:0.1,0.2,30", 1e-3, 4)
    ours = np.linalg.eigvals(build(loop).closed_loop()[0])
    ports = [(0.015, 0.02, (1.0,), (1.0, 0.0)), (0.03, 0.05, (0.1, 0.2, 30.0), (1.0, 0.0))]
    ch = [[(0, 1.0, 0), (1, -1.0, 4)], [(1, 1.0, 0), (0, -1.0, 4)]]
    theirs = np.linalg.eigvals(brute.closed_loop_matrix(ports, ch, 8.0, 0.004, 1e-3))
    big = lambda e: np.sort(np.abs(e[np.abs(e) > 1e-6]))  # noqa: E731
    np.testing.assert_allclose(big(ours), big(theirs), rtol=1e-9)


def test_build_is_batched_over_periods():
    T = np.array([1e-3, 2e-3, 5e-3])
    batch = build(h.paper_hve(delay_samples=4), T)
    for i, t in enumerate(T):
        single = build(h.paper_hve(period=t, delay_samples=4))
        np.testing.assert_allclose(batch.closed_loop(10.0)[i], single.closed_loop(10.0)[0], atol=1e-15)


def test_zero_master_stiffness_keeps_the_slave_spring():
    # K_m = 0 < K_s: the slave's spring must stay in the loop (same as a plain-gain H(z))
    base = h.paper_peb(delay_samples=4).replace(master_controller=h.SpringDamper(0.0))
    a = build(base.replace(slave_controller=h.SpringDamper(50.0))).closed_loop()[0]
    b = build(base.replace(slave_controller=h.DiscreteController((50.0,), (1.0,)))).closed_loop()[0]
    np.testing.assert_allclose(np.sort(np.abs(np.linalg.eigvals(a))), np.sort(np.abs(np.linalg.eigvals(b))),
                               atol=1e-12)
    with pytest.raises(h.AnalysisError, match="K_s/K_m is undefined"):
        h.critical_stiffness(base.replace(slave_controller=h.SpringDamper(50.0)))
