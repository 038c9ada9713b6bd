"""Llewellyn's K scan (llewellyn_scan.first_failure): the screen that skips the K every angle
surely passes never changes the K found. References: the plain scan (every K of the grid,
margins by ``margin_of`` in large chunks, as before the screen) written here, and the
margin itself on random two-ports (the screen's claim, pair by pair)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hapstab as h
import lanes
from hapstab.analysis.teleoperation import llewellyn_scan as scan
from hapstab.analysis.teleoperation import twoport as tp


def _plain_first_failure(A, C, tol):
    """Every K of the scan, in order, the margin at every angle (no screen)."""
    Ks = np.exp(np.arange(math.log(scan.SCAN_START), math.log(1e12), math.log(scan.SCAN_STEP)))
    # chunks of ~65,536 pairs (fast in cache; the chunking does not change the K found)
    for chunk in np.array_split(Ks, max(1, Ks.size * A.shape[0] // 65_536)):
        m = scan.margin_of(A[None] + chunk[:, None, None, None] * C[None]).min(axis=1)
        bad = np.flatnonzero(m < -tol)
        if bad.size:
            return float(chunk[bad[0]])
    return None


def _loops():
    rng = np.random.default_rng(31_07)
    out = [h.paper_peb(1e-3, n) for n in (0, 2, 20)]
    for i in range(6):
        light = i % 3 == 0
        dev = [h.Device(float(rng.uniform(0.02, 1)),
                        float(0.0 if light else rng.uniform(0.01, 2))) for _ in range(2)]
        B = [float(rng.uniform(0, 1)) if i % 4 else 0.0 for _ in range(2)]
        out.append(h.TeleoperationLoop(dev[0], dev[1], h.SpringDamper(1.0, B[0]),
                                       h.SpringDamper(float(rng.uniform(0.3, 3)), B[1]),
                                       period=float(rng.uniform(2e-4, 3e-3)),
                                       delay_samples=int(rng.integers(0, 12))))
    return out


#: the loops of `_loops` a default-lane case checks, one of each kind: the paper's PEB
#: (n = 0), a light (b = 0) pair with B = 0, a damped pair, a damped pair with B = 0
#: (measured: 40 % of the plain scan's time, every part finds failures); the other five
#: (the paper's PEB at n = 2 and 20, with 1,000-2,000-angle grids, three more random
#: pairs) under ``rest``, -m campaign (tests/lanes.py)
DEFAULT_LOOPS = (0, 3, 4, 7)


@pytest.mark.parametrize("rest", lanes.PARTS)
@pytest.mark.parametrize("approximation, bounds", lanes.draw(
    [(a, b) for b in ((0.0, 0.0), (0.3, 2.0)) for a in ("forward", "backward", "tustin")], 2))
def test_the_screened_scan_finds_the_plain_scans_k(approximation, bounds, rest):
    found = []
    for i, loop in enumerate(_loops()):
        if (i in DEFAULT_LOOPS) == rest:
            continue
        side, a = tp._side(loop, approximation, bounds)
        A, C = tp._parts(side, a, tp.theta_grid(side.oscillations))
        got, want = scan.first_failure(A, C, 0.0), _plain_first_failure(A, C, 0.0)
        assert got == want, (loop, approximation, bounds)
        found.append(got is not None)
    assert any(found)          # the draw has failures to find


def _near_the_edge(rng, n):
    """n two-ports P whose cross term sqrt(r11 r22) - q is a relative delta from 0
    (delta from -1e-9 to 1e-3, log-spread), the entries over 12 decades, p12 p21 near
    the negative real axis on half (where (|w| + Re w) / 2 cancels)."""
    mag = 10.0 ** rng.uniform(-6, 6, (n, 2))
    ph = rng.uniform(-np.pi, np.pi, (n, 2))
    p12, p21 = mag[:, 0] * np.exp(1j * ph[:, 0]), mag[:, 1] * np.exp(1j * ph[:, 1])
    flip = rng.uniform(size=n) < 0.5          # w = p12 p21 within 1e-6 rad of -|w|
    p21 = np.where(flip, -np.conj(p12) / np.abs(p12) * mag[:, 1] * np.exp(1j * rng.normal(0, 1e-6, n)), p21)
    q = np.abs((np.sqrt(p12) * np.sqrt(p21)).real)
    delta = np.where(rng.uniform(size=n) < 0.8, 10.0 ** rng.uniform(-14, -3, n),
                     -(10.0 ** rng.uniform(-14, -9, n)))
    t = 10.0 ** rng.uniform(-3, 3, n)         # r11 / r22 apart by up to 1e6
    r11 = np.maximum(q, 1e-300) * t
    r22 = np.maximum(q, 1e-300) * (1 + delta) ** 2 / t
    P = np.empty((n, 2, 2), complex)
    P[:, 0, 0], P[:, 1, 1] = r11 + 1j * rng.normal(size=n), r22 + 1j * rng.normal(size=n)
    P[:, 0, 1], P[:, 1, 0] = p12, p21
    return P


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_a_pair_the_screen_passes_has_a_positive_margin(seed):
    rng = np.random.default_rng(seed)
    P = _near_the_edge(rng, 256)
    K = np.array([0.0])                        # P = A + 0 C: the pairs themselves
    sure = scan.Screen(P, np.zeros_like(P)).sure(K)[0]
    margin = scan.margin_of(P)
    assert np.all(margin[sure] > 0), seed
    assert sure.sum() >= 40      # ~1/3 are clear of the band (measured 85 of 256 at seed 0)


def test_an_undamped_pair_without_virtual_damping_is_zero_at_once():
    """b = 0 and B = 0: every margin is 0 at K = 0 and negative above, and the bisection
    toward K = 0 had no floor (zero = 1e-12 b/T = 0): ~1,100 refined minima down to the
    denormals (minutes, a session-13 hostile run). Now it stops at 1e-12 of the scan's
    first K: 0 and the reason."""
    loop = h.TeleoperationLoop(h.Device(0.015, 0.0), h.Device(0.015, 0.0),
                               h.SpringDamper(1.0, 0.0), h.SpringDamper(1.0, 0.0),
                               period=1e-3)
    res = tp.critical_stiffness_llewellyn(loop)
    assert res.critical_stiffness == 0.0
    assert "not absolutely stable for any K > 0" in res.reason
