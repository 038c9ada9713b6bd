"""Theorem 2.1 with a finite sector for the PEB teleoperator (issue #13, item 5).

What "inside the sector" means here. Theorem 2.1 closes G (force to velocity at the
ports) with a *memoryless* feedback f_i = -phi_i(v_i), 0 <= v phi(v) <= k_i v^2. In
hapstab's model a termination is the device's mass plus the operator's (environment's)
impedance; the only memoryless one is a damper c_i in [0, k_i] (``msd:0,c,0``) on a
device whose mass is negligible. Such a *light* device, m_i = 1e-6 (b_i + c_i) T,
settles to its velocity within a sample (e^-1e6), so the zero-order-hold loop at the
sampling instants is the forward-difference model x+ = x + T v exactly, up to O(1e-6);
that is where the theorem, and so the finite-sector K_max, is a bound. A device of the
paper's mass is not memoryless, and there the finite-sector K_max is *not* a bound (a
test below keeps the counterexample), nor are backward difference and Tustin.

The references are not this code: eq. (30) written out by hand and inverted by numpy,
the exact analysis (:func:`hapstab.stability`), the closed-loop matrix's eigenvalues,
and a closed form of the free loop's limit b/T.
"""

import itertools

import numpy as np
import pytest

import hapstab as h
from hapstab.analysis.conditions.circle import (
    APPROXIMATIONS,
    _two_port_transfer,
    circle_test,
    critical_stiffness_circle,
    loop_inverse,
    loop_transfer,
    port_scaling,
)
from hapstab.engine.device_side import DeviceSide
from hapstab.engine.structure import Channel
from hapstab.errors import AnalysisError, ModelError
from hapstab.models.controllers import SpringDamper
from hapstab.models.loops import TeleoperationLoop
from hapstab.models.parts import Device, mass_spring_damper
from lanes import PARTS, draw, part

#: a light device's mass per unit of (b + c) T (see the module notes)
LIGHT = 1e-6


def peb(b=(0.02, 0.02), B=(0.0, 0.0), ratio=1.0, T=1e-3, n=0, c=(0.0, 0.0), K=1.0, mass=None):
    """A PEB loop with dampers c at the ports; light devices unless ``mass`` is given."""
    m = [mass if mass is not None else LIGHT * (b[i] + c[i]) * T for i in (0, 1)]
    return TeleoperationLoop(Device(m[0], b[0]), Device(m[1], b[1]), SpringDamper(K, B[0]),
                             SpringDamper(K * ratio, B[1]), mass_spring_damper(0, c[0], 0),
                             mass_spring_damper(0, c[1], 0), T, n)


def kmax(loop, sector=None, a="forward"):
    return critical_stiffness_circle(loop, a, sector).critical_stiffness


def stable(loop):
    """Exact verdict, a free teleoperator's rigid-body mode aside: with no spring to
    ground a constant offset of both positions (zero velocity, the theorem's y) persists."""
    r = h.stability(loop)
    return r.verdict == "stable" or (r.verdict == "marginal" and r.rigid_body_modes == 1
                                     and r.spectral_radius < 1)


def eq30(loop, th, D=(1.0, 1.0)):
    """D G^-1(e^{j th}) of eq. (30) written out by hand (forward difference)."""
    z, T, n = np.exp(1j * th), loop.period, loop.delay_samples
    cm, cs = loop.master_controller, loop.slave_controller
    e = lambda c: c.stiffness * T / (z - 1) + c.damping / z  # noqa: E731  C(z) T/(z-1)
    g = np.array([[loop.master.damping + e(cm), -z ** -n * e(cm)],
                  [-z ** -n * e(cs), loop.slave.damping + e(cs)]])
    return np.asarray(D)[None, :, None] * np.moveaxis(g, 2, 0)


UNEQUAL = TeleoperationLoop(Device(0.015, 0.02), Device(0.03, 0.05), SpringDamper(10.0, 0.002),
                            SpringDamper(30.0, 0.004), None, None, 2e-3, 3)
TH = np.array([1e-5, 0.01, 0.3, 1.7, 3.1])


# ------------------------------------------------------------------ G itself
@pytest.mark.parametrize("loop", [h.paper_peb(delay_samples=4, damping=0.003), UNEQUAL])
def test_g_is_the_inverse_of_eq30(loop):
    D = port_scaling(loop)
    G = loop_transfer(loop)
    raw = np.array([[np.polyval(G.num[i][j], np.exp(1j * TH)) / np.polyval(G.den[i][j], np.exp(1j * TH))
                     for j in (0, 1)] for i in (0, 1)])
    ref = np.linalg.inv(eq30(loop, TH, D))
    # the polynomials as built: rounding only (1e-9 leaves 1e3 x for the 1/w growth)
    assert np.allclose(np.moveaxis(raw, 2, 0), ref, rtol=1e-9, atol=0)
    # the product form the PR test evaluates cancels pole/zero pairs closer than 1e-7
    # (a closed-loop pole next to a controller zero): agreement to 1e-6 relative
    assert np.abs(G(TH) - ref).max() <= 1e-6 * np.abs(ref).max()


@pytest.mark.parametrize("signs", [(-1.0, -1.0), (-0.3, -1 / 0.3), (-0.5, -1.0)])
def test_g_for_other_channel_signs(signs):
    # a scaled position error (s_12 s_21 = 1 up to rounding: z - 1 still divides det M)
    # and one with det S(1) != 0 (no such factor): G against numpy's inverse of
    # diag(b) + Hc X written out here
    T, n, b = 1e-3, 2, (0.02, 0.05)
    cm, cs = SpringDamper(8.0, 0.003), SpringDamper(5.0, 0.001)
    side = DeviceSide(T, ("master", "slave"), np.array(b),
                      (Channel(0, cm, ((0, 1.0, 0.0), (1, signs[0], float(n)))),
                       Channel(1, cs, ((1, 1.0, 0.0), (0, signs[1], float(n))))), (1.0, 1.0))
    G = _two_port_transfer(side, "forward", (1.0, 1.0))
    z = np.exp(1j * TH)
    X = T / (z - 1)
    H = [c.stiffness + c.damping * (z - 1) / (T * z) for c in (cm, cs)]
    gi = np.array([[b[0] + H[0] * X, signs[0] * z ** -n * H[0] * X],
                   [signs[1] * z ** -n * H[1] * X, b[1] + H[1] * X]])
    raw = np.array([[np.polyval(G.num[i][j], z) / np.polyval(G.den[i][j], z) for j in (0, 1)]
                    for i in (0, 1)])
    # rounding only, as above
    assert np.allclose(np.moveaxis(raw, 2, 0), np.linalg.inv(np.moveaxis(gi, 2, 0)), rtol=1e-9, atol=0)
    # z = 1 is a root of every numerator exactly when det S(1) != 0
    has = [abs(np.polyval(G.num[i][j], 1.0)) <= 1e-12 * np.abs(G.num[i][j]).sum()  # rounding
           for i in (0, 1) for j in (0, 1)]
    assert all(has) == (abs(1 - signs[0] * signs[1]) > 1e-12)  # the same rounding


@pytest.mark.parametrize("a", APPROXIMATIONS)
def test_g_inverts_loop_inverse_for_every_approximation(a):
    for loop in (h.paper_peb(delay_samples=2, damping=0.004), UNEQUAL):
        G, ref = loop_transfer(loop, a)(TH), np.linalg.inv(loop_inverse(loop, a)(TH))
        # 1e-6: the product form's cancellation of near pairs, as above
        assert np.abs(G - ref).max() <= 1e-6 * np.abs(ref).max()


@pytest.mark.parametrize("n", [0, 2, 4])
def test_no_spurious_poles_below_the_passive_limit(n):
    # inverting the 2x2 G^-1 by root-finding left poles at |z| = 1.0002 here (refused before)
    loop = h.paper_peb(delay_samples=n)
    for f in (0.5, 0.99):
        r = circle_test(loop.with_stiffness(f * kmax(loop)), sector=1e9)
        assert r.positive_real and max(abs(p) for p in r.poles) < 1


@pytest.mark.parametrize("loop", [peb(n=2, K=5.0), peb(b=(0.02, 0.05), B=(0.002, 0.004), ratio=3.0,
                                                      T=2e-3, n=3, K=4.0)])
def test_poles_are_those_of_the_closed_loop_with_light_devices(loop):
    # G's poles (zeros of det G^-1) against the engine's closed-loop eigenvalues of the
    # same loop with light devices and nothing attached; left out: the rigid-body mode
    # at z = 1 and the settled velocities / delay registers at |z| < 1e-3
    poles = np.array(circle_test(loop, sector=0.1).poles)
    eig = np.linalg.eigvals(h.build(loop).closed_loop()[0])
    rigid = np.argmin(np.abs(eig - 1))
    # nothing grounds the pair: 1, to the eigensolver's accuracy on a light loop's matrix
    # (entries up to T / m ~ 1e6 times the rest: ~1e-9 observed)
    assert abs(eig[rigid] - 1) < 1e-7
    eig = np.delete(eig, rigid)
    eig, poles = eig[np.abs(eig) > 1e-3], poles[np.abs(poles) > 1e-3]
    # a light device moves each pole by O(1e-6); every distinct pole of G is a closed-loop
    # pole and vice versa
    assert all(np.min(np.abs(poles - e)) < 1e-5 for e in eig)
    assert all(np.min(np.abs(eig - p)) < 1e-5 for p in poles)


# ------------------------------------------------------------------ K_max
@pytest.mark.parametrize("loop", [h.paper_peb(), h.paper_peb(delay_samples=2),
                                  h.paper_peb(delay_samples=4, damping=0.003), UNEQUAL])
def test_a_large_sector_tends_to_the_passive_limit(loop):
    passive, large = kmax(loop), kmax(loop, 1e9)
    assert large >= passive * (1 - 1e-6)  # bisection to 1e-6 relative
    # Re G ~ w^2 near w = 0: the PR test of G resolves the passive limit to ~1e-4
    assert large == pytest.approx(passive, rel=1e-4)


# n = 1 and 4 by default (the same claim at another delay), n = 2 -m campaign
@pytest.mark.parametrize("n", draw([1, 2, 4], 2))
def test_a_smaller_sector_allows_more_stiffness_up_to_the_free_loop_limit(n):
    # with nothing attached (c = 0 is in every sector) the light loop's determinant at
    # K = b/T is, by hand, b^2 (1 + z + ... + z^(2n+1)): all its roots on the circle, so
    # no sector allows K >= b/T = 20 N/m, and a vanishing sector approaches it
    loop = h.paper_peb(delay_samples=n)
    ks = [kmax(loop, k) for k in (10.0, 1.0, 0.1, 0.01, 1e-5)]
    passive = kmax(loop)
    assert passive * (1 - 1e-6) <= ks[0]  # bisection to 1e-6 relative
    assert all(a <= b for a, b in itertools.pairwise(ks))
    assert ks[2] > 1.3 * passive and ks[-1] < 20.0
    assert ks[-1] == pytest.approx(20.0, rel=1e-3)


def test_the_papers_peb_number():
    # the README's example: n = 2, dampers of at most 0.1 N*s/m at both ports
    assert kmax(h.paper_peb(delay_samples=2), 0.1) == pytest.approx(10.7762, rel=1e-4)
    assert kmax(h.paper_peb(delay_samples=2)) == pytest.approx(20 / 3, rel=1e-9)  # eq. (34)


def test_per_port_sectors_and_bad_input():
    loop = h.paper_peb(delay_samples=2)
    both = kmax(loop, 0.1)
    assert kmax(loop, (0.1, 10.0)) < both < kmax(loop, (0.1, 0.01))
    with pytest.raises(ModelError, match="sector"):
        circle_test(loop, sector=(0.1, 0.2, 0.3))
    for bad in (0.0, -1.0, float("nan"), (0.1, -1.0)):
        with pytest.raises((AnalysisError, ModelError), match="sector"):
            kmax(loop, bad)
    with pytest.raises(AnalysisError, match="proper"):   # no device damping: G^-1(inf) = 0
        circle_test(peb(b=(0.0, 0.0), mass=0.01), sector=1.0)
    r = h.critical_stiffness(loop, method="circle", sector=0.1)
    assert r.critical_stiffness == pytest.approx(both, rel=1e-12) and r.details["sector"] == [0.1]


# ------------------------------------------------ Theorem 2.1, by hand and exactly
def test_the_port_weighted_test_is_theorem_21_with_a_diagonal_multiplier():
    # with C_s = 3 C_m the master port is weighted by D = 3; phi diagonal commutes with D,
    # so K^-1 + G PR with the right multiplier D^-1 proves it: (K^-1 + G) D^-1 + h.c. by hand
    loop, k = UNEQUAL.with_stiffness(4.0), np.array([0.05, 0.2])
    D = np.array(port_scaling(loop))
    assert D.tolist() == [3.0, 1.0]
    r = circle_test(loop, sector=k)
    th = np.concatenate([np.linspace(1e-4, np.pi, 20001), [r.worst_frequency_rad_s * loop.period]])
    P = (np.diag(1 / k) + np.linalg.inv(eq30(loop, th))) / D[None, None, :]
    lam = np.linalg.eigvalsh(P + np.conj(np.swapaxes(P, 1, 2)))[:, 0]
    assert lam[-1] == pytest.approx(r.margin, rel=1e-6)   # at the reported worst frequency
    assert lam.min() >= r.margin - 1e-9 * abs(r.margin)   # and it is the least one


@pytest.mark.parametrize("n,k", [(1, 0.1), (2, 0.1), (2, 1.0)])
def test_eigenvalue_scan_below_k_max(n, k):
    # brute force: the closed-loop matrix's eigenvalues on 150 stiffnesses up to K_max
    Km = kmax(h.paper_peb(delay_samples=n), k)
    for c in ((0.0, 0.0), (k, k), (k, 0.0)):
        sysm = h.build(peb(n=n, c=c))
        for K in np.linspace(0, Km, 150)[1:]:
            eig = np.linalg.eigvals(sysm.closed_loop(K)[0])
            eig = np.delete(eig, np.argmin(np.abs(eig - 1)))   # the rigid-body mode
            assert np.abs(eig).max() < 1, (c, K)
    # the scan can fail: with nothing attached the loop is unstable just above b/T
    eig = np.linalg.eigvals(h.build(peb(n=n)).closed_loop(20.0 * 1.01)[0])
    assert np.abs(eig).max() > 1


def _random_peb(rng):
    b = 10 ** rng.uniform(-2.3, -0.3, 2)
    kw = dict(b=tuple(b), B=tuple(rng.uniform(-0.3, 0.3, 2) * b), ratio=float(10 ** rng.uniform(-0.6, 0.6)),
              T=float(10 ** rng.uniform(-4, -2)), n=int(rng.integers(0, 7)))
    return kw, b * 10 ** rng.uniform(-2, 1, 2)   # the sector: 0.01 to 10 times the damping


def _forward_campaign():
    """The seeded campaign's 6 loops: (loop, sector, a damper pair inside the sector)."""
    rng = np.random.default_rng(20260513)
    cases = []
    for _ in range(6):
        kw, k = _random_peb(rng)
        cases.append((kw, k, tuple(rng.uniform(0, 1, 2) * k)))
    return cases


# 3 of the 6 loops by default (tests/lanes.py: part), the other 3 -m campaign
@pytest.mark.parametrize("rest", PARTS)
def test_forward_is_a_bound_for_light_devices_in_a_seeded_campaign(rest):
    # dampers at the corners of the sector and one inside; K up to K_max (1 - 1e-5): the
    # light devices move the exact limit by O(1e-6) (measured: the tightest of 40 loops,
    # where nothing attached binds, is 4e-6 above K_max)
    for kw, k, inside in part(_forward_campaign(), 3, rest):
        Km = kmax(peb(**kw), k)
        assert Km >= kmax(peb(**kw)) * (1 - 1e-6)   # bisection to 1e-6 relative
        for c in ((0.0, 0.0), (k[0], 0.0), (0.0, k[1]), tuple(k), inside):
            for K in (0.3 * Km, 0.8 * Km, Km * (1 - 1e-5)):
                assert stable(peb(**kw, c=c, K=K)), (kw, k, c, K)


def test_a_device_of_the_papers_mass_is_outside_the_sector():
    # the device mass is not memoryless: with the paper's m = 0.015 kg the finite-sector
    # K_max (14.31 N/m at n = 1, dampers <= 0.1) exceeds the exact limit with the lightest
    # dampers (10.004 N/m with c = 0, 12.5 with c_m = 0.01; 20.0 with c = 0.02 at both);
    # only the passive limit (10 N/m) is a bound there
    Km = kmax(h.paper_peb(delay_samples=1), 0.1)
    assert Km == pytest.approx(14.31, rel=1e-3)
    for c in ((0.0, 0.0), (0.01, 0.0)):
        assert not stable(peb(n=1, c=c, mass=0.015, K=Km))
        assert stable(peb(n=1, c=c, mass=0.015, K=10.0))
    # the same for the HVE (m = 0.15 kg): 51.78 N/m at n = 2, sector 0.5; exact 40.01, c = 0
    hve = h.paper_hve(delay_samples=2).replace(operator=mass_spring_damper(0, 0, 0))
    Kh = kmax(hve, 0.5)
    assert Kh == pytest.approx(51.78, rel=1e-3)
    assert not h.stability(hve.with_stiffness(Kh)).stable
    assert h.stability(hve.with_stiffness(40.0)).stable


def test_a_singular_part_per_unit_k_is_no_limit():
    # backward difference, n = 1, B = 0: by hand the Hermitian part of G^-1 is
    # 2 diag(b) + K T [[1, 1], [1, 1]], PSD for every K; the 2x2 determinant of the part
    # per unit K is 0 only to rounding, which used to put K_max at 4.2e16 N/m
    loop = h.paper_peb(delay_samples=1)
    assert kmax(loop, a="backward") == np.inf
    assert kmax(loop, 0.1, "backward") == np.inf


@pytest.mark.parametrize("a,expected", [("backward", 1671.4), ("tustin", 22.948)])
def test_backward_and_tustin_are_not_bounds(a, expected):
    # paper's PEB with light devices, n = 2, dampers <= 0.1: both promise more than the
    # free loop's b/T = 20 N/m, where the light loop with nothing attached goes unstable
    Km = kmax(h.paper_peb(delay_samples=2), 0.1, a)
    assert Km == pytest.approx(expected, rel=1e-3)
    assert not stable(peb(n=2, K=Km))


def test_the_result_says_when_it_is_not_a_bound():
    # the cases above: the reason says so, naming m/(bT) (750 for the paper's PEB devices)
    res = h.critical_stiffness(h.paper_peb(delay_samples=1), method="circle", sector=0.1)
    assert "NOT a stability bound for this loop" in res.reason and "750" in res.reason
    light = h.critical_stiffness(peb(n=1), method="circle", sector=0.1)
    assert "NOT" not in light.reason and "negligible mass" in light.reason
