"""Certificate version 4 (issue 26, speed): the exclusion's angle kernel from
precomputed ball polynomials (hapstab.engine.arb_kernel) and the gap subdivision
without the fixed ladder near theta = 0; version 3 certificates still verify; the
proposer's values-only jets give the enclosing jets' centres bit for bit.

References: the forward-mode kernel of versions 1-3 and the point values of det M
from the port polynomials (ArbLoop.value: d_j, N_j and the controllers evaluated
separately, not the precomposed polynomials); the 50-digit brute-force referee
(tests/references/brute.py) for K_max's side of the truth."""

import math

import numpy as np
import pytest

import hapstab as h
from hapstab.analysis.exact import proof
from hapstab.engine.arb_loop import ArbLoop, arb_parameters, working_precision
from hapstab.engine.frequency import loop_response
from hapstab.models import Device, HapticLoop, SpringDamper, spring
from references import brute

#: a damped HVE with a virtual damper and a wall (every v-power of the kernel is used)
DAMPED = HapticLoop(Device(0.05, 0.3), SpringDamper(0, 0.7), spring(2000.0), 1e-3, 3)
LOOPS = {"hve4": h.paper_hve(delay_samples=4), "peb0": h.paper_peb(delay_samples=0),
         "peb4": h.paper_peb(delay_samples=4), "damped": DAMPED}


def _ball(a, b):
    from flint import arb
    return arb(a).union(arb(b))


@pytest.mark.parametrize("name", sorted(LOOPS))
def test_polynomial_kernel_encloses_det_m_on_boxes(name):
    from flint import arb
    al = ArbLoop(arb_parameters(LOOPS[name]))
    rng = np.random.default_rng(7)
    for a, b, ka, kb in [(0.3, 0.31, 1.0, 2.0), (1e-5, 2e-5, 1e-3, 50.0), (2.0, 2.4, 10.0, 11.0),
                         (0.0124, 0.01245, 21.0, 22.0), (3.0, math.pi, 0.5, 5.0)]:
        th, K = _ball(a, b), _ball(ka, kb)
        P, Q, F = al.box(th, K, polys=True)
        old = al.box(th, K)
        with working_precision(al.prec):
            for new_ball, old_ball in zip((P, Q, F), old, strict=True):
                assert new_ball.overlaps(old_ball)
            for t, k in zip(rng.uniform(a, b, 6), rng.uniform(ka, kb, 6), strict=True):
                # det M at a point from the port polynomials, another formula
                assert F.contains(al.value(arb(t), arb(k)))


@pytest.mark.parametrize("name", sorted(LOOPS))
def test_polynomial_kernel_derivatives_hold_the_difference_quotient(name):
    """d/dtheta over the ball holds (F(b) - F(a)) / (b - a) (mean value theorem,
    componentwise convex hull): a check of the derivative polynomials."""
    from flint import acb, arb
    al = ArbLoop(arb_parameters(LOOPS[name]))
    for a, b in [(0.3, 0.3001), (1.0, 1.01), (0.012, 0.0125)]:
        _Pm, _Qm, _Fm, _Pd, _Qd, Fd = al.kernel(_ball(a, b), polys=True)
        with working_precision(al.prec):
            for k in (0.0, 3.0):
                fd = Fd[0] + acb(k) * (Fd[1] + acb(k) * Fd[2])
                q = (al.value(arb(b), arb(k)) - al.value(arb(a), arb(k))) / (arb(b) - arb(a))
                assert fd.overlaps(q)


@pytest.mark.parametrize("n", [4, 40])     # counts by roots (n = 4) and by winding (n = 40)
def test_version_3_certificates_still_verify(monkeypatch, n):
    loop = h.paper_peb(delay_samples=n)
    new = h.critical_stiffness(loop, certify=True)
    assert new.certificate["version"] == 5
    assert h.verify_certificate(new.certificate, loop).valid
    monkeypatch.setattr(proof, "POLY_KERNEL", False)
    old = h.critical_stiffness(loop, certify=True)
    assert old.certificate["version"] == 3
    chk = h.verify_certificate(old.certificate, loop)
    assert chk.valid, chk.reason
    # the same proved K_max either way (the window does not depend on the kernel)
    assert old.critical_stiffness == new.critical_stiffness
    # a version 4 subdivision read as version 3 replays other pieces: refused
    relabelled = dict(new.certificate, version=3)
    assert not h.verify_certificate(relabelled, loop).valid


def test_version_4_gap_starts_without_the_ladder_and_proves_fewer_boxes(monkeypatch):
    loop = h.paper_hve(delay_samples=4)
    cert = h.critical_stiffness(loop, certify=True).certificate
    gap = next(g for g in cert["gaps"] if g["excluded"])
    near_zero = [p for p in gap["pieces"] if p[1] <= math.pi / 8 * 2.0 ** -30]
    assert len(near_zero) <= 2          # the fixed ladder had 11 pieces below there
    monkeypatch.setattr(proof, "POLY_KERNEL", False)
    old = h.critical_stiffness(loop, certify=True).certificate
    old_gap = next(g for g in old["gaps"] if g["excluded"])
    assert len(gap["splits"]) < len(old_gap["splits"])


@pytest.mark.parametrize("name", ["hve4", "peb4"])
def test_kmax_stays_on_the_safe_side_of_the_referee(name):
    loop = LOOPS[name]
    K = h.critical_stiffness(loop, certify=True).critical_stiffness
    L = brute.hve_loop(0.15, 0.1, 1e-3, 4, operator=("spring", 1.0)) if name == "hve4" else \
        brute.peb_loop(0.015, 0.02, 0.015, 0.02, 1e-3, 4, 4, operator=("spring", 1.0),
                       environment=("spring", 1.0))
    assert brute.robust(L, K, dps=50).stable
    assert not brute.robust(L, K * (1 + 1e-9), dps=50).stable


@pytest.mark.parametrize("name", sorted(LOOPS))
def test_values_only_jets_have_the_enclosing_jets_centres(name):
    resp = loop_response(LOOPS[name])
    th = np.concatenate([np.geomspace(1e-9, 1e-2, 40), np.linspace(0.01, math.pi - 1e-3, 300)])
    idx = np.zeros(th.size, int)
    full = resp.coefficients(idx, th, np.zeros(th.size))
    fast = resp.coefficients(idx, th, np.zeros(th.size), values_only=True)
    for a, b in zip(full, fast, strict=True):
        assert np.array_equal(a.vc, b.vc) and np.array_equal(a.dc, b.dc)


def _stale_case():
    # found by the review of certificate version 4: an HVE without virtual damper at 40
    # samples whose crossing (50-digit referee: theta = 0.01074971441827977512,
    # K = 12.74454305395425689) lies 7.7e-19 inside a piece of version 4's subdivision
    loop = HapticLoop(Device(0.1, 0.5000000000000329), SpringDamper(0, 0.0), None, 1e-3, 40)
    return arb_parameters(loop), (0.010749714418279764, 0.010749714418279776), \
        (12.744543053952981, 12.74454305395553)


def test_a_kernel_is_served_only_for_the_ball_it_was_made_for():
    # a count formed the piece's ball at 53 bits and cached its kernel under the piece's
    # ends; the exclusion then asked with the ball at 320 bits and took the 53-bit centre
    # with the 320-bit radius: the box holding the crossing was excluded ('N')
    import mpmath
    from flint import arb

    from hapstab.analysis.exact.proof import box_status
    from hapstab.analysis.exact.winding import piece_increment, theta_ball

    params, (a, b), (k0, k1) = _stale_case()
    ref = brute.hve_loop(0.1, 0.5000000000000329, 1e-3, 40)
    mpmath.mp.dps = 50

    def eqs(t, K):
        g, _ = brute.char_fn(ref, K, mpmath.exp(mpmath.mpc(0, 1) * t), dps=50)
        return [mpmath.re(g), mpmath.im(g)]

    tc, Kc = mpmath.findroot(eqs, (mpmath.mpf("0.0107497144182797751"),
                                   mpmath.mpf("12.7445430539542569")))
    assert a < tc < b and k0 < Kc < k1                   # the box holds a crossing
    al = ArbLoop(params)
    with working_precision(53):                          # a count's ball, another precision
        piece_increment(al, a, b, arb(k0), {}, True)
        al.box(theta_ball(a, b), arb(k0), key=(a, b), polys=True)
    with working_precision(al.prec):
        assert box_status(al, a, b, k0, k1)[0] is None   # never excluded
        fresh = ArbLoop(params)
        assert box_status(fresh, a, b, k0, k1)[0] is None
