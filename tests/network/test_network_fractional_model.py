"""The HVE with a fractional delay as a modified z-transform (issue 30, item 1, step 1):
the characteristic polynomial's roots against the engine's closed-loop eigenvalues and
an independent brute-force closed loop (tests/references/brute_fractional.py), G(theta, f)
against mpmath at 40 digits, and the ball enclosures against points of their boxes."""

import math

import mpmath
import numpy as np
import pytest
from flint import arb
from tests.references import brute_fractional as bf

from hapstab import Device, FilteredSpringDamper, HapticLoop, SpringDamper
from hapstab.analysis.network.frac_balls import FractionBalls
from hapstab.analysis.network.modified_z import fractional_plant
from hapstab.engine.system import build
from hapstab.errors import AnalysisError


def _loop(seed: int):
    rng = np.random.default_rng(31_000 + seed)
    T = float(rng.uniform(5e-4, 3e-3))
    m, b, B = rng.uniform(0.05, 1), rng.uniform(0.05, 2), rng.uniform(0, 3)
    om, ob, ok = rng.uniform(0.01, 0.5), rng.uniform(0, 2), rng.uniform(1, 400)
    loop = HapticLoop(Device(m, b), SpringDamper(1.0, B), f"msd:{om},{ob},{ok}", T, 0)
    return loop, (m + om, b + ob, ok, T, B), rng


def _pairs(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance from a root of ``a`` to the nearest of ``b`` and back."""
    d = np.abs(a[:, None] - b[None, :])
    return float(max(d.min(axis=1).max(), d.min(axis=0).max()))


@pytest.mark.parametrize("seed", range(8))
def test_poles_against_the_engine_and_the_brute_force(seed):
    loop, (M, b, k, T, B), rng = _loop(seed)
    n, f = int(rng.integers(0, 6)), float(rng.uniform(0.01, 0.99))
    K = float(rng.uniform(1, 300))
    plant = fractional_plant(loop, n)
    roots = np.roots(plant.char_poly(K, f))
    eng = np.linalg.eigvals(build(loop.replace(delay_samples=n, fractional_delay=f)
                                  .with_stiffness(K)).closed_loop()[0])
    A0, A1 = bf.matrices(M, b, k, T, n, f, B)
    ref = np.linalg.eigvals(A0 + K * A1)
    assert len(roots) == len(eng) == len(ref) == n + 4
    assert _pairs(roots, ref) < 1e-6      # eigenvalues of a defective-free loop, doubles
    assert _pairs(roots, eng) < 1e-6


def _mp_gain(M, b, k, T, B, n, theta, f, s=1.0):
    """G(theta, f) from mpmath.expm at 40 digits, formed from the modified z-transform
    X_f / (-U) = [c (zI - Phi)^-1 Gamma + g] / z directly (no y-polynomials)."""
    with mpmath.workdps(40):
        M, b, k, T, B = (mpmath.mpf(v) for v in (M, b, k, T, B))
        aug = lambda t: mpmath.matrix([[0, t, 0], [-k / M * t, -b / M * t, t / M],  # noqa: E731
                                       [0, 0, 0]])
        X, Xf = mpmath.expm(aug(T)), mpmath.expm(aug((1 - mpmath.mpf(f)) * T))
        z = mpmath.exp(1j * mpmath.mpf(theta))
        R = mpmath.matrix([[z - X[0, 0], -X[0, 1]], [-X[1, 0], z - X[1, 1]]])
        v = R ** -1 * mpmath.matrix([[X[0, 2]], [X[1, 2]]])
        P = (Xf[0, 0] * v[0] + Xf[0, 1] * v[1] + Xf[0, 2]) / z       # X_f / (-U)
        # 1 + s z^-n P H = 0 with H = K + (B/T)(1 - 1/z)
        return -z ** n / (s * P) - B / T * (1 - 1 / z)


@pytest.mark.parametrize("seed", range(6))
def test_gain_against_mpmath_at_40_digits(seed):
    loop, (M, b, k, T, B), rng = _loop(seed)
    n = int(rng.integers(0, 8))
    balls = FractionBalls(fractional_plant(loop, n))
    for theta, f in [(float(rng.uniform(0, math.pi)), float(rng.uniform(0, 1))) for _ in range(4)]:
        ref = complex(_mp_gain(M, b, k, T, B, n, theta, f))
        g = balls.value(arb(theta), arb(f))
        assert abs(complex(float(g.real.mid()), float(g.imag.mid())) - ref) < 1e-20 * abs(ref)
        assert float(g.rad()) < 1e-30 * abs(ref)   # 320 bits: tight balls
        flt = fractional_plant(loop, n).gain(np.array([theta]), f)[0]
        assert flt == pytest.approx(ref, rel=1e-7)


@pytest.mark.parametrize("seed", range(4))
def test_box_enclosure_contains_every_point_of_its_box(seed):
    loop, _, rng = _loop(seed)
    n = int(rng.integers(0, 5))
    plant = fractional_plant(loop, n)
    balls = FractionBalls(plant)
    for _ in range(5):
        tc, rt = float(rng.uniform(0.05, 3.0)), float(rng.uniform(1e-5, 1e-2))
        fc, rf = float(rng.uniform(0.05, 0.95)), float(rng.uniform(1e-4, 0.05))
        enc = balls.box(arb(tc, rt), arb(fc, rf)).enclosure()
        for t, f in zip(rng.uniform(tc - rt, tc + rt, 20), rng.uniform(fc - rf, fc + rf, 20),
                        strict=True):
            g = complex(_mp_gain(*_loop(seed)[1], n, t, f))
            assert enc.real.contains(arb(g.real)) and enc.imag.contains(arb(g.imag))


def test_whole_sample_ends_of_the_fraction():
    loop, _, _ = _loop(0)
    plant = fractional_plant(loop, 2)
    _d, nt0 = plant.coefficients(0.0)
    _, nt1 = plant.coefficients(1.0)
    # f = 0: Nt = z N = (1 + y) N;  f = 1: Nt = N (whole delay n + 1)
    assert nt1[2] == 0.0
    assert nt0 == pytest.approx([nt1[0], nt1[0] + nt1[1], nt1[1]], rel=1e-9)
    th = np.linspace(0.1, 3.0, 7)
    assert plant.gain(th, 1.0) == pytest.approx(fractional_plant(loop, 3).gain(th, 0.0), rel=1e-9)


def test_first_crossing_is_the_engine_kmax():
    loop, (M, b, k, T, B), _ = _loop(3)
    for n, f in [(0, 0.4), (4, 0.85)]:
        K, _ = fractional_plant(loop, n).first_crossing(f, 1e-9)
        assert K == pytest.approx(bf.kmax(M, b, k, T, n + f, B), rel=1e-8)


def test_outside_the_model_is_refused_by_name():
    from hapstab import TeleoperationLoop
    peb = TeleoperationLoop(Device(0.1, 0.1), Device(0.1, 0.1), SpringDamper(1.0, 0.1),
                            SpringDamper(1.0, 0.1), "spring:1", "spring:10", 1e-3, 0)
    with pytest.raises(AnalysisError, match="peb"):
        fractional_plant(peb, 1)
    filt = HapticLoop(Device(0.1, 0.1), FilteredSpringDamper(1.0, 0.1, "lowpass:50"), None, 1e-3)
    with pytest.raises(AnalysisError, match="controller"):
        fractional_plant(filt, 1)
