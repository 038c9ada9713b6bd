"""Fractional and asymmetric delays: exact model against an independent fine-step
simulation with a continuous delay, integer limits, continuity, brute force."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import hapstab as h
from hapstab.engine.system import build
from hapstab.errors import ModelError
from references import brute


def test_integer_delay_in_seconds_is_exactly_the_integer_model():
    loop = h.paper_hve()
    for n in (0, 1, 10):
        a = h.critical_stiffness(loop.with_delay_s(n * 1e-3)).critical_stiffness
        b = h.critical_stiffness(h.paper_hve(delay_samples=n)).critical_stiffness
        assert a == b


@pytest.mark.parametrize("f", [-0.1, 1.0, 1.5, float("nan")])
def test_fractional_delay_must_be_a_fraction(f):
    with pytest.raises(ModelError, match="fractional_delay"):
        h.paper_hve(delay_samples=2).replace(fractional_delay=f)


def test_kmax_is_continuous_and_falls_between_two_integers():
    loop = h.paper_hve()
    d = np.linspace(10, 11, 41)
    K = np.array([h.critical_stiffness(loop.with_delay_s(x * 1e-3)).critical_stiffness for x in d])
    assert np.all(np.diff(K) < 0)
    # K_max falls ~9 % over the sample; 41 steps: no step may exceed 1 %
    assert np.max(np.abs(np.diff(K)) / K[:-1]) < 0.01
    # approaching the next integer from below
    just = h.critical_stiffness(loop.with_delay_s(10.999999e-3)).critical_stiffness
    assert just == pytest.approx(K[-1], rel=1e-5)


def _continuous_delay_simulation(m, b, k, K, B, T, td, f_ext, steps):
    """Independent reference: integrate the device finely, sample x(kT - td) from the
    stored dense output (x = 0 before t = 0), apply u through a zero-order hold."""
    segs = []

    def x_at(t):
        if t <= 0:
            return 0.0
        for t0, t1, sol in reversed(segs):
            if t0 - 1e-15 <= t <= t1 + 1e-15:
                return float(sol(t)[0])
        raise AssertionError(t)

    state = np.zeros(2)
    xs = [0.0]
    for kk in range(steps):
        t = kk * T
        y, yp = x_at(t - td), x_at(t - td - T)
        u = K * y + (B / T) * (y - yp)
        rhs = lambda _t, s, u=u: [s[1], (f_ext - u - b * s[1] - k * s[0]) / m]  # noqa: E731
        sol = solve_ivp(rhs, (t, t + T), state, rtol=1e-11, atol=1e-14, dense_output=True)
        segs.append((t, t + T, sol.sol))
        state = sol.y[:, -1]
        xs.append(state[0])
    return np.array(xs)


@pytest.mark.parametrize("td_samples,B", [(2.5, 0.0), (3.37, 0.05), (0.4, 0.02)])
def test_fractional_delay_matches_continuous_delay_simulation(td_samples, B):
    m, b, k, T, K = 0.15, 0.1, 1.0, 1e-3, 8.0
    loop = h.HapticLoop(h.Device(m, b), h.SpringDamper(K, B), h.spring(k), T).with_delay_s(td_samples * T)
    sysm = build(loop)
    A, Bx = sysm.closed_loop()[0], sysm.B_ext[0][:, 0]
    s = np.zeros(A.shape[0])
    xs = [0.0]
    for _ in range(150):
        s = A @ s + Bx * 1.0
        xs.append(float(sysm.pos[0] @ s))
    ref = _continuous_delay_simulation(m, b, k, K, B, T, td_samples * T, 1.0, 150)
    # the reference integrates with rtol 1e-11 and interpolates its dense output
    np.testing.assert_allclose(xs, ref, rtol=1e-7, atol=1e-12 * np.abs(ref).max())


def test_round_trip_decides_for_integer_delays():
    # det(I + C P) = (1 + Cm Pm)(1 + Cs Ps) - Cm Cs Pm Ps z^-(n_f + n_b): only the sum counts
    loop = h.paper_peb().replace(slave=h.Device(0.05, 0.1), environment="msd:0.1,0.2,30")
    ks = [h.critical_stiffness(loop.with_delays_s(f * 1e-3, b * 1e-3)).critical_stiffness
          for f, b in ((2, 6), (6, 2), (4, 4), (8, 0))]
    assert max(ks) == pytest.approx(min(ks), rel=1e-11)


@pytest.mark.parametrize("nf,nb", [(1, 5), (3, 0)])
def test_asymmetric_delays_against_brute_force(nf, nb):
    mm, bm, ms, bs, B, T = 0.02, 0.03, 0.08, 0.05, 0.004, 1e-3
    op, env = ((1.0,), (1.0, 0.0)), ((0.1, 0.2, 30.0), (1.0, 0.0))
    c = h.SpringDamper(1.0, B)
    loop = h.TeleoperationLoop(h.Device(mm, bm), h.Device(ms, bs), c, c, h.Impedance(*op),
                               h.Impedance(*env), T, nf, delay_backward_samples=nb)
    ports = [(mm, bm, *op), (ms, bs, *env)]
    ch = [[(0, 1.0, 0), (1, -1.0, nb)], [(1, 1.0, 0), (0, -1.0, nf)]]
    ref = brute.kmax(lambda K: brute.closed_loop_matrix(ports, ch, K, B, T))
    assert h.critical_stiffness(loop).critical_stiffness == pytest.approx(ref, rel=1e-6)


def test_asymmetric_fractional_delays_are_exact_at_integers():
    loop = h.paper_peb()
    a = h.critical_stiffness(loop.with_delays_s(3e-3, 5e-3)).critical_stiffness
    b = h.critical_stiffness(loop.replace(delay_samples=3, delay_backward_samples=5)).critical_stiffness
    assert a == b
    c = h.critical_stiffness(loop.with_delays_s(3.5e-3, 4.2e-3)).critical_stiffness
    longer = loop.replace(delay_samples=3, delay_backward_samples=4)
    assert 0 < c < h.critical_stiffness(longer).critical_stiffness


def test_paper_conditions_refuse_unequal_delays():
    with pytest.raises(h.AnalysisError, match="equal delays"):
        h.eq34(h.paper_peb().with_delays_s(2e-3, 6e-3))
