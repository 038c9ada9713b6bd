"""The enclosures the certified core rests on: on random cells every sampled value
and derivative of det M's coefficients lies in the cell's discs, and det M equals the
closed-loop characteristic polynomial (from the state-space engine) up to z^(N - q)."""

import numpy as np
import pytest

import hapstab as h
from hapstab.analysis.exact.boxes import Cells
from hapstab.engine.discs import Jet, geometric_sum_jet, one_minus_delay_jet
from hapstab.engine.frequency import loop_response
from hapstab.engine.system import build

P = h.paper_peb(delay_samples=3)
LOOPS = [h.paper_hve(delay_samples=7), P, P.replace(operator=None, environment=None),
         h.paper_hve(delay_samples=2).replace(fractional_delay=0.4),
         P.replace(fractional_delay=0.3, delay_backward_samples=1, fractional_delay_backward=0.6),
         P.replace(operator=None, environment=None, fractional_delay=0.7),
         h.HapticLoop(h.Device(0.02, 1e-4), h.SpringDamper(1.0, -5e-5),
                      h.mass_spring_damper(0.01, 1e-4, 1e5), 2e-4, 40)]


@pytest.mark.parametrize("loop", LOOPS)
def test_cell_discs_enclose_every_sampled_value(loop):
    r = loop_response(loop, [loop.period, 3.7 * loop.period])
    rng = np.random.default_rng(7)
    for item in range(r.size):
        for _ in range(20):
            rho = 10 ** rng.uniform(-7, -1)
            th = rng.uniform(0, np.pi)
            kind = 0
            c = Cells()
            c.add(r, [item], [th], [rho], kind)
            ts = th + rho * np.linspace(-1, 1, 41)
            F = r.coefficients(np.full(ts.size, item), ts, np.zeros(ts.size))
            for deg in range(3):
                dv = np.abs(F[deg].vc - c.vc[deg, 0])
                dd = np.abs(F[deg].dc - c.dc[deg, 0])
                assert np.all(dv <= c.vr[deg, 0] * (1 + 1e-9) + 1e-300), (deg, th, rho)
                assert np.all(dd <= c.dr[deg, 0] * (1 + 1e-9) + 1e-300), (deg, th, rho)


@pytest.mark.parametrize("loop", LOOPS)
def test_det_M_is_the_characteristic_polynomial(loop):
    r = loop_response(loop)
    s = build(loop)
    for K in (0.5, 7.0, 300.0):
        A = s.closed_loop(K)[0]
        N = A.shape[0]
        u = K / r.scale[0]
        for th in (0.3, 1.1, 2.5):
            z = np.exp(1j * th)
            chi = np.linalg.det(z * np.eye(N) - A)
            F = r.coefficients(np.zeros(1, int), np.array([th]), np.zeros(1))
            f = (F[0].vc + u * F[1].vc + u * u * F[2].vc)[0]
            ours = z ** (N - r.q - r.rigid) * (z - 1) ** r.rigid * f
            assert abs(ours / chi - 1) < 1e-9


def test_special_jets_against_their_sums():
    th = np.array([0.0, 1e-9, 0.001, 0.3, 2.9, np.pi])
    for n in (1, 2, 7, 100, 1000):
        for rho in (0.0, 1e-6):
            g = geometric_sum_jet(th, np.full(th.size, rho), n)
            w = one_minus_delay_jet(th, np.full(th.size, rho), n)
            k = np.arange(n)
            ref_g = np.exp(1j * np.outer(th, k)).sum(axis=1)
            ref_dg = (1j * k * np.exp(1j * np.outer(th, k))).sum(axis=1)
            np.testing.assert_allclose(g.vc, ref_g, rtol=1e-9, atol=1e-9 * n)
            np.testing.assert_allclose(g.dc, ref_dg, rtol=1e-6, atol=1e-6 * n * n)
            np.testing.assert_allclose(w.vc, 1 - np.exp(-1j * n * th), atol=1e-12)


def test_reciprocal_disc_contains_every_inverse():
    rng = np.random.default_rng(3)
    c = rng.normal(size=50) + 1j * rng.normal(size=50)
    r = 0.5 * np.abs(c) * rng.uniform(size=50)
    inv = Jet(c, r, 0 * c, 0 * r).reciprocal()
    for t in np.linspace(0, 2 * np.pi, 17):
        x = c + r * np.exp(1j * t)
        assert np.all(np.abs(1 / x - inv.vc) <= inv.vr * (1 + 1e-12))


def test_geometric_sum_jet_encloses_the_exact_derivative_at_a_point():
    """The derivative disc at a point (rho = 0) must hold G_n'(theta) exactly (50-digit
    mpmath), also where the closed form loses digits to cancellation (1e-2 <= n theta
    <~ 1: found by an independent review; its rounding allowance missed by up to 33x)."""
    import mpmath as mp

    mp.mp.dps = 50
    for n in (2, 3, 10, 200, 1000):
        for x in [*np.geomspace(1e-4, 1.0, 25), 1.5, 3.0, 0.9 * n]:
            th = x / n
            J = geometric_sum_jet(np.array([th]), np.array([0.0]), n)
            t = mp.mpf(float(th))
            d = complex(mp.fsum([1j * k * mp.expj(k * t) for k in range(n)]))
            v = complex(mp.fsum([mp.expj(k * t) for k in range(n)]))
            assert abs(complex(J.dc[0]) - d) <= J.dr[0], (n, x)
            assert abs(complex(J.vc[0]) - v) <= J.vr[0] + 1e-300, (n, x)
