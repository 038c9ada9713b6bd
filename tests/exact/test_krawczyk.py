"""The iterated Krawczyk exclusion (certificate version 5's ``"I"``,
hapstab.engine.arb_krawczyk): a box that holds a crossing -- a zero of det M at
(theta*, K*), placed by the certificate's window [K_lo, K_hi] and angle -- is never
excluded, whatever its size and wherever the zero sits in it; a box beside the window is
excluded in one piece where halving needed tens; and a certificate's piece that the test
does not exclude is refused."""

import copy
import math

import numpy as np
import pytest
from flint import arb

import hapstab as h
from hapstab.analysis.exact import proof
from hapstab.analysis.exact.winding import k_ball, theta_ball
from hapstab.engine.arb_loop import ArbLoop, arb_parameters, working_precision

LOOPS = {
    "hve-4": h.paper_hve(delay_samples=4),
    "hve-40": h.paper_hve(delay_samples=40),
    "peb-0": h.paper_peb(delay_samples=0),
    "peb-4": h.paper_peb(delay_samples=4),
    # issue 26's stiff wall on a light device (k T^2 / m ~ 640)
    "wall": h.HapticLoop(h.Device(0.0011034930256540415, 2.793119774241153e-05),
                         h.SpringDamper(0.0, 0.008156767423636477), h.spring(1e6),
                         0.0008382324672663228, 4),
}


@pytest.fixture(scope="module", params=sorted(LOOPS))
def crossing(request):
    loop = LOOPS[request.param]
    res = h.critical_stiffness(loop, certify=True)
    c = res.certificate["crossings"][0]
    assert res.certificate["version"] == 5
    return loop, ArbLoop(arb_parameters(loop)), c["theta_rad"], c["K_lo_N_per_m"], \
        c["K_hi_N_per_m"], res.certificate


def _excludes(al, a, b, ka, kb):
    with working_precision(al.prec):          # the balls as the proof forms them
        th, K = theta_ball(a, b), k_ball(ka, kb)
    return al.krawczyk_excludes(th, K, (a, b, ka, kb))


def test_a_box_holding_the_crossing_is_never_excluded(crossing):
    _, al, t, klo, khi, _ = crossing
    rng = np.random.default_rng(5_000)
    for _ in range(60):
        # the angle is the polished one rounded to a double: 1e-13 of it either side
        # holds the true one; the window [klo, khi] holds the true K*
        below, above = (10 ** rng.uniform(-13, -1, 2)) * t
        down, up = 10 ** rng.uniform(-14, -0.5, 2)
        a, b = max(t - below, 0.0), min(t + above, math.pi)
        ka, kb = klo * (1 - down), khi * (1 + up) if rng.random() < 0.8 else khi
        assert not _excludes(al, a, b, ka, kb), (a, b, ka, kb)


def test_a_box_beside_the_window_is_excluded_in_one_piece(crossing):
    _, al, t, klo, _, _ = crossing
    for rel_theta, rel_k in [(1e-4, 0.01), (1e-4, 0.5), (1e-3, 0.9)]:
        a, b = t * (1 - rel_theta), min(t * (1 + rel_theta), math.pi)
        assert _excludes(al, a, b, klo * (1 - rel_k), klo)


def test_the_version_5_certificate_has_i_pieces_and_fewer_boxes(crossing, monkeypatch):
    loop, _, _, _, _, cert = crossing
    pieces = [p for g in cert["gaps"] for p in g.get("pieces") or []]
    assert any(p[4] == "I" for p in pieces)
    assert h.verify_certificate(cert, loop).valid
    monkeypatch.setattr(proof, "KRAWCZYK", False)
    old = h.critical_stiffness(loop, certify=True)
    assert old.certificate["version"] == 4 and h.verify_certificate(old.certificate, loop).valid
    assert old.critical_stiffness == h.critical_stiffness(loop).critical_stiffness
    assert len(pieces) < len([p for g in old.certificate["gaps"] for p in g.get("pieces") or []])


@pytest.mark.parametrize("name", ["hve-4", "peb-0", "peb-4", "wall"])
def test_a_piece_relabelled_i_where_it_does_not_hold_is_refused(name):
    loop = LOOPS[name]
    cert = h.critical_stiffness(loop, certify=True).certificate
    al = ArbLoop(arb_parameters(loop))
    # an excluded piece far from the crossing whose box the Krawczyk steps do not settle
    # (det M far from 0 over a wide box: they do not converge)
    where = next((gi, pi) for gi, g in enumerate(cert["gaps"])
                 for pi, p in enumerate(g.get("pieces") or [])
                 if p[4] in "PQF" and not _excludes(al, *p[:4]))
    forged = copy.deepcopy(cert)
    forged["gaps"][where[0]]["pieces"][where[1]][4] = "I"
    chk = h.verify_certificate(forged, loop)
    assert not chk.valid and "is not excluded by 'I'" in chk.reason


def test_balls_that_do_not_hold_the_box_are_refused():
    """The Nyquist zero of the paper's HVE n = 4 (theta = pi, K ~ 5.4e9) in a box ending
    at pi: a ball that stops at the double below pi (1.2e-16 short) would miss the zero
    and let the steps pin it outside; such balls are refused, the proof's own hold pi
    (found by the review of version 5)."""
    loop = h.paper_hve(delay_samples=4)
    al = ArbLoop(arb_parameters(loop))
    ends = [c for c in h.critical_stiffness(loop, certify=True).certificate["crossings"]
            if c["theta_rad"] == math.pi]
    K = ends[0]["K_lo_N_per_m"] if ends else 5399993040.0023
    for w in (1e-8, 1e-12):
        box = (math.pi - w, math.pi, K * (1 - w), K * (1 + w))
        with working_precision(al.prec):
            short = arb(box[0]).union(arb(box[1]))
            whole = theta_ball(box[0], box[1])
            Kb = k_ball(box[2], box[3])
        assert not al.krawczyk_excludes(short, Kb, box)
        assert not al.krawczyk_excludes(whole, Kb, box)


def test_an_exclusion_ends_at_its_first_box_failed_at_the_floor():
    """A gap holding a crossing the float search cannot see (device damping 1e-100:
    K_max ~ 4e-98 N/m) fails at the floor at its lowest K; the boxes left above are
    not split to the floor K-ulp by K-ulp (they were: 1,836 failures, 12 s a call), and
    the verdict is the one the full search gave: marginal at K -> 0+, K_max 0."""
    loop = h.paper_hve(1e-3, 2).with_stiffness(5.0).replace(device=h.Device(0.1, 1e-100))
    al = ArbLoop(arb_parameters(loop))
    ex = proof.exclude(al, 1e-111, 1170818.1328650434)
    assert ex.splits.count("f") == 1 and ex.splits[-1] == "f"
    first = min(f[2] for f in ex.failed)
    assert first == 1e-111                      # nothing below the failure is claimed
    res = h.critical_stiffness(loop)
    assert res.critical_stiffness == 0.0 and res.stable_intervals == ()
    assert "marginal for K -> 0+" in res.reason
