"""Poles outside the unit circle of loops with a fraction of a sample of delay, proved in
ball arithmetic (hapstab.engine.arb_fraction; issue 26: every verdict on rigorous
arithmetic), against independent brute forces (tests/references/brute_fractional*.py:
their own closed loops, numpy eigenvalues; no hapstab code) and against polynomials
whose roots are known exactly."""

import dataclasses
import functools

import mpmath
import numpy as np
import pytest
from flint import acb, acb_poly, arb
from tests.lanes import draw
from tests.references import brute_fractional as bf
from tests.references import brute_fractional_peb as bfp
from tests.references.referee_eig import DIGITS, count_outside, refined_moduli

from hapstab import Device, HapticLoop, SpringDamper, TeleoperationLoop, paper_peb, stability
from hapstab.engine.arb_fraction import (
    fractional_count,
    fractional_polynomial,
    outside_count,
)

#: The brute force's eigenvalues (a matrix of norm ~1e3 at most, 40-90 states) are
#: accurate to ~1e-11: a pole nearer the circle than this is not the brute force's to
#: decide, and the case is skipped from the comparison (counted, and bounded below).
UNDECIDED = 1e-8
BLOCK = 20


def _hve(rng):
    """A random HVE with a fractional delay: every third a stiff wall on a light device
    (k T^2 / m from 1 to 1e4), every fifth undamped, long delays on some."""
    kind = int(rng.integers(0, 3))
    T = float(10 ** rng.uniform(-4, -2.5))
    if kind == 0:                          # stiff wall on a light device
        m, k = float(10 ** rng.uniform(-3, -1.3)), float(10 ** rng.uniform(5, 6))
        T = float(rng.uniform(5e-4, 2e-3))
    else:
        m, k = float(10 ** rng.uniform(-2, 1)), float(rng.choice([0.0, 10 ** rng.uniform(0, 4)]))
    b = 0.0 if rng.random() < 0.2 else float(10 ** rng.uniform(-3, 1))
    B = float(rng.choice([0.0, 10 ** rng.uniform(-3, 0)]))
    n = int(rng.integers(0, 60 if rng.random() < 0.3 else 8))
    f = float(rng.uniform(1e-6, 1))
    return m, b, k, T, n, f, B


@pytest.mark.parametrize("block", draw(range(25), 2))
def test_hve_counts_equal_the_brute_force(block):
    rng = np.random.default_rng(2_600_000 + block)
    skipped = 0
    for _ in range(BLOCK):
        m, b, k, T, n, f, B = _hve(rng)
        A0, A1 = bf.matrices(m, b, k, T, n, f, B)
        # a K around the brute force's own K_max, where the counts change
        kref = bf.kmax(m, b, k, T, n + f, B)
        K = float(kref * 10 ** rng.uniform(-0.5, 0.5)) if np.isfinite(kref) and kref > 0 \
            else float(10 ** rng.uniform(-2, 3))
        lam = np.abs(np.linalg.eigvals(A0 + K * A1))
        loop = HapticLoop(Device(m, b), SpringDamper(K, B), f"spring:{k!r}" if k else "none",
                          T, n, fractional_delay=f)
        got = fractional_count(loop, K)
        if np.min(np.abs(lam - 1)) < UNDECIDED:
            skipped += 1
            exact = functools.partial(bf.matrices, m, b, k, T, n, f, B)
            assert got in (-1, _referee(A0, A1, exact, K))
            continue
        assert got == int(np.sum(lam > 1)), (m, b, k, T, n, f, B, K)
    assert skipped <= BLOCK // 4


@pytest.mark.parametrize("block", draw(range(25), 2))
def test_peb_counts_equal_the_brute_force(block):
    rng = np.random.default_rng(2_610_000 + block)
    for _ in range(BLOCK // 2):
        T, dev, term, B, rho, n, f = _peb(rng)
        ports = [(d[0] + t[0], d[1], t[2]) for d, t in zip(dev, term, strict=True)]
        A0, A1 = bfp.matrices(ports, T, n, f, B, rho)
        K = float(10 ** rng.uniform(-1, 3))
        lam = np.abs(np.linalg.eigvals(A0 + K * A1))
        loop = TeleoperationLoop(Device(*dev[0]), Device(*dev[1]), SpringDamper(K, B[0]),
                                 SpringDamper(K * rho, B[1]),
                                 f"msd:{term[0][0]!r},0.0,{term[0][2]!r}",
                                 f"msd:{term[1][0]!r},0.0,{term[1][2]!r}", T, n,
                                 fractional_delay=f)
        got = fractional_count(loop, K)
        if np.min(np.abs(lam - 1)) < UNDECIDED:
            summed = [(mpmath.mpf(d[0]) + t[0], d[1], t[2])
                      for d, t in zip(dev, term, strict=True)]
            exact = functools.partial(bfp.matrices, summed, T, n, f, B, rho)
            assert got in (-1, _referee(A0, A1, exact, K))
            continue
        assert got == int(np.sum(lam > 1)), (dev, term, B, rho, T, n, f, K)


def _referee(A0, A1, exact, K):
    """The 40-digit referee's count of poles outside (``exact(digits=...)``: the closed
    loop in mpmath), or the float one where the referee abstains."""
    with mpmath.workdps(DIGITS):
        X0, X1 = exact(digits=DIGITS)
    moduli = refined_moduli(A0, A1, X0, X1, K)
    if moduli is None:
        return int(np.sum(np.abs(np.linalg.eigvals(A0 + K * A1)) > 1))
    return count_outside(moduli, ON_THE_CIRCLE)[0]


#: A pole this near the circle is on it for the referee: its matrices hold the loop's
#: doubles exactly and its eigenvalues are refined to ~1e-40.
ON_THE_CIRCLE = 1e-30


def _peb(rng):
    """A random PEB with a fractional delay: (T, devices, terminations, B's, force
    ratio, whole delay, fraction); about a third with undamped devices."""
    T = float(rng.uniform(5e-4, 3e-3))
    light = rng.random() < 0.3
    dev = [(float(rng.uniform(0.02, 1)), 0.0 if light else float(rng.uniform(0.05, 2)))
           for _ in range(2)]
    term = [(float(rng.uniform(0.01, 0.5)), 0.0, float(10 ** rng.uniform(0, 4.5)))
            for _ in range(2)]
    B = (float(rng.uniform(0, 2)), float(rng.uniform(0, 2)))
    rho = float(rng.uniform(0.3, 3)) if rng.random() < 0.3 else 1.0
    return T, dev, term, B, rho, int(rng.integers(0, 12)), float(rng.uniform(1e-6, 1))


def _next_to_the_circle(rng, kind):
    """(loop at K, A0, A1, exact A0, exact A1, K): a loop drawn at the brute force's
    K_max nudged by a relative 1e-12..1e-8 either way, where a pole is that near the
    circle; None when the loop has no finite K_max."""
    if kind == "hve":
        m, b, k, T, n, f, B = _hve(rng)
        kref = bf.kmax(m, b, k, T, n + f, B)
        mats = lambda d=None: bf.matrices(m, b, k, T, n, f, B, digits=d)  # noqa: E731
    else:
        T, dev, term, B, rho, n, f = _peb(rng)
        ports = [(d[0] + t[0], d[1], t[2]) for d, t in zip(dev, term, strict=True)]
        kref = float(bfp.kmax_many(ports, T, [n + f], B, rho)[0])

        def mats(d=None):           # the exact referee sums the masses exactly
            p = ports if d is None else [(mpmath.mpf(a[0]) + t[0], a[1], t[2])
                                         for a, t in zip(dev, term, strict=True)]
            return bfp.matrices(p, T, n, f, B, rho, digits=d)
    if not (np.isfinite(kref) and kref > 0):
        return None
    K = float(kref * (1 + rng.choice([-1, 1]) * 10 ** rng.uniform(-12, -8)))
    A0, A1 = mats()
    with mpmath.workdps(DIGITS):
        X0, X1 = mats(DIGITS)
    if kind == "hve":
        loop = HapticLoop(Device(m, b), SpringDamper(K, B), f"spring:{k!r}" if k else "none",
                          T, n, fractional_delay=f)
    else:
        loop = TeleoperationLoop(Device(*dev[0]), Device(*dev[1]), SpringDamper(K, B[0]),
                                 SpringDamper(K * rho, B[1]),
                                 f"msd:{term[0][0]!r},0.0,{term[0][2]!r}",
                                 f"msd:{term[1][0]!r},0.0,{term[1][2]!r}", T, n,
                                 fractional_delay=f)
    return loop, A0, A1, X0, X1, K


@pytest.mark.parametrize("block", draw(range(12), 1))
def test_counts_next_to_the_circle_equal_a_40_digit_referee(block):
    """Next to the circle the float brute force cannot decide (its eigenvalues are good
    to ~1e-11): the count is -1 (not decided) or the count of the 40-digit referee
    (tests/references/referee_eig.py: the brute force's own closed loop in mpmath, the
    poles near the circle refined by Rayleigh-quotient iteration), never another."""
    rng = np.random.default_rng(2_630_000 + block)
    seen = decided = 0
    for i in range(8):
        got = _next_to_the_circle(rng, ("hve", "peb")[i % 2])
        if got is None:
            continue
        loop, A0, A1, X0, X1, K = got
        moduli = refined_moduli(A0, A1, X0, X1, K)
        if moduli is None:            # the referee abstains (module docstring): rare
            continue
        want, _ = count_outside(moduli, ON_THE_CIRCLE)
        count = fractional_count(loop, K)
        assert count in (-1, want), (block, i, K, count, want)
        seen += 1
        decided += count != -1
    assert seen >= 4 and decided >= seen // 2, (seen, decided)


def test_different_fractions_each_way_equal_the_closed_loop_eigenvalues():
    # no reference builds unequal fractions: the engine's closed loop (float) on loops far
    # from the circle, where its eigenvalues decide
    from hapstab.engine.system import build
    rng = np.random.default_rng(2_620_000)
    seen = set()
    for _ in range(30):
        loop = dataclasses.replace(
            paper_peb(delay_samples=int(rng.integers(0, 6)), stiffness=float(10 ** rng.uniform(-1, 1))),
            fractional_delay=float(rng.uniform(0, 1)),
            delay_backward_samples=int(rng.integers(0, 6)),
            fractional_delay_backward=float(rng.uniform(1e-3, 1)))
        K = float(build(loop).stiffness[0])
        lam = np.abs(np.linalg.eigvals(build(loop).closed_loop()[0]))
        if np.min(np.abs(lam - 1)) < 1e-6:
            continue
        want = int(np.sum(lam > 1))
        assert fractional_count(loop, K) == want
        seen.add(want)
    assert seen >= {0, 2}           # stable and unstable loops both met


def test_the_polynomial_is_the_modified_z_transforms():
    # chi of the PEB (the same delay both ways) against modified_z_peb's, formed apart
    from hapstab.analysis.network.modified_z_peb import peb_fractional_plant
    loop = dataclasses.replace(paper_peb(delay_samples=3, stiffness=2.0), fractional_delay=0.3)
    chi, _prec = fractional_polynomial(loop, 2.0)
    mine = np.roots([complex(c.real.mid()) for c in chi.coeffs()][::-1])
    theirs = np.roots(peb_fractional_plant(loop, 3).char_poly(2.0, 0.3))
    theirs = theirs[np.abs(theirs) > 1e-9]          # modified_z_peb's chi has z^2 more
    assert mine.size == theirs.size == 2 * 3 + 6
    # each root the other's (numpy's roots of poles crowding z = 1: ~1e-9)
    assert np.abs(mine[:, None] - theirs[None, :]).min(axis=1).max() < 1e-7
    assert np.abs(theirs[:, None] - mine[None, :]).min(axis=1).max() < 1e-7


@pytest.mark.parametrize(("roots", "outside"), [
    ([0.5, -0.25j, 0.25j, 2.0, -3.0], 2),
    ([0.3, 0.3 + 1e-12, 0.9, 1.5], 1),                 # a close pair inside
    ([1.0 + 1e-6, 1.0 - 1e-6, 0.1], 1),                # a pair straddling the circle
    ([0.999999999999, 0.2], 0),                        # a pole 1e-12 inside
    ([1e-6, 1e6, 0.5, 2.0, -1e3, 3e-4j, -3e-4j], 3),   # widely scaled roots
])
def test_counts_of_known_roots(roots, outside):
    chi = acb_poly.from_roots([acb(complex(r).real, complex(r).imag) for r in roots])
    assert outside_count(chi, 320) == outside
    # the inclusion discs alone (the first route): the right count or undecided
    from hapstab.engine.arb_fraction import _inclusion_count
    for newton in (0, 3):
        got = _inclusion_count(chi, chi.degree(), newton)
        assert got is None or got[0] == outside


@pytest.mark.parametrize("roots", [[1.0, 0.5], [1j, -1j, 0.3], [np.exp(0.7j), np.exp(-0.7j)]])
def test_a_root_on_the_circle_is_undecided(roots):
    chi = acb_poly.from_roots([acb(complex(r).real, complex(r).imag) for r in roots])
    assert outside_count(chi, 320) is None


def test_wide_coefficient_balls_are_undecided():
    # coefficients known only to 1e-3: a root at 0.9995 may be outside for some of them
    chi = acb_poly([acb(arb(-0.9995, 1e-3)), acb(1)])
    assert outside_count(chi, 320) is None


def test_stability_of_a_fractional_loop_says_how_it_is_proved():
    loop = dataclasses.replace(paper_peb(delay_samples=3, stiffness=0.5), fractional_delay=0.25)
    res = stability(loop)
    assert res.verdict == "stable"
    assert "isolating the characteristic polynomial's roots in ball arithmetic" in res.reason
    loop = dataclasses.replace(paper_peb(delay_samples=3, stiffness=5.0), fractional_delay=0.25)
    assert stability(loop).verdict == "unstable"
