"""Definition 1 (positive realness) on functions whose answer is known by hand, a
narrow dip checked against an independent brute-force sweep written here, and
the circle criterion (Theorem 2.1) with a finite sector."""

import math

import numpy as np
import pytest

from hapstab.analysis.conditions.positive_real import (
    RationalMatrix,
    circle_criterion,
    positive_real,
)
from hapstab.errors import AnalysisError, ModelError


def scalar(num, den):
    return RationalMatrix.scalar(num, den)


# ------------------------------------------------------------- known by hand
@pytest.mark.parametrize("num,den", [
    ([1.0], [1.0]),                 # a resistor
    ([1.0, 1.0], [1.0, -1.0]),      # (z+1)/(z-1): image of 1/s, Re = 0 on the circle
    ([1.0, -1.0], [1.0, 1.0]),      # (z-1)/(z+1): image of s; raw residue -2 at z = -1
    ([1.0, 0.5], [1.0, -0.5]),      # stable, Re > 0
])
def test_positive_real_functions(num, den):
    r = positive_real(scalar(num, den))
    assert r.positive_real and r.failed_condition is None
    # Re{G} >= 0 everywhere and = 0 for the lossless ones: margin ~ 0 up to the rounding
    # of G + G^H 1e-6 rad from a unit-circle pole, eps * |G| ~ 2e-16 * 2e6
    assert r.margin >= -1e-8


@pytest.mark.parametrize("num,den,cond", [
    ([1.0, 0.0], [1.0, -2.0], "poles"),             # pole at z = 2
    ([1.0, 0.0, 0.0], [1.0, -2.0, 1.0], "unit-circle poles"),  # double pole at z = 1
    ([-1.0], [1.0, -1.0], "unit-circle poles"),     # residue -1 at z = 1
    ([1.0, 1.0], [1.0, 1.0, 0.0], "unit-circle poles"),  # 1/z after cancellation? no: (z+1)/(z(z+1)) = 1/z
])
def test_not_positive_real(num, den, cond):
    r = positive_real(scalar(num, den))
    if num == [1.0, 1.0]:
        # (z+1)/(z^2+z) cancels to 1/z: Re{e^{-jw}} = cos w < 0 for w > pi/2; margin -2 at w = pi
        assert r.failed_condition == "hermitian part"
        assert r.margin == pytest.approx(-2.0, abs=1e-9)
        assert r.worst_frequency_rad_s == pytest.approx(math.pi, abs=1e-6)
    else:
        assert not r.positive_real and r.failed_condition == cond


def test_margin_and_worst_frequency_in_hz():
    # G = 0.2 + z^-1 (as z-polynomials): 2 Re = 0.4 + 2 cos w, min -1.6 at w = pi
    T = 1e-3
    r = positive_real(scalar([0.2, 1.0], [1.0, 0.0]), period=T)
    assert not r.positive_real
    assert r.margin == pytest.approx(-1.6, abs=1e-9)
    assert r.worst_frequency_rad_s == pytest.approx(math.pi / T, rel=1e-6)
    assert r.worst_frequency_hz == pytest.approx(1 / (2 * T), rel=1e-6)


def test_no_spurious_failure_near_zero_frequency():
    # b + KT/(z-1) at K = 2b/T: Re = b - KT/2 = 0 for every w, with |G| ~ 1/w near w = 0
    b, T = 0.1, 1e-3
    at = positive_real(scalar([b, -b + 2 * b], [1.0, -1.0]), period=T)
    assert at.positive_real
    over = positive_real(scalar([b, -b + 2 * b * (1 + 1e-6)], [1.0, -1.0]), period=T)
    # 1e-6 relative too much stiffness is -2e-7 of margin: detected, not lost in rounding
    assert not over.positive_real and over.margin == pytest.approx(-2e-7, rel=1e-3)


def _resonator(r, th0):
    """(1-r)(z^2-1)/(z^2 - 2 r cos(th0) z + r^2): a band-pass of width ~ 1 - r at th0."""
    return (1 - r) * np.array([1.0, 0.0, -1.0]), np.array([1.0, -2 * r * math.cos(th0), r * r])


@pytest.mark.parametrize("depth", [1.001, 0.999])
def test_narrow_dip_is_found(depth):
    # 1 - c * resonator, scaled so the dip reaches 1 - depth: a notch ~1e-4 rad wide
    rn, rd = _resonator(0.99995, 1.2345678)
    th = np.linspace(1.2340, 1.2352, 2_000_001)  # brute force, independent of hapstab
    z = np.exp(1j * th)
    peak = np.max(np.real(np.polyval(rn, z) / np.polyval(rd, z)))
    c = depth / peak
    num = np.polysub(rd, c * rn)
    brute = 2 * np.min(np.real(np.polyval(num, z) / np.polyval(rd, z)))
    r = positive_real(scalar(num, rd))
    assert r.positive_real == (depth < 1)
    # the brute grid spacing (6e-10 rad) bounds its error far below this
    assert r.margin == pytest.approx(brute, abs=1e-7)
    worst = th[np.argmin(np.real(np.polyval(num, z) / np.polyval(rd, z)))]
    assert r.worst_frequency_rad_s == pytest.approx(worst, abs=1e-6)


# ------------------------------------------------------------------ matrices
def test_matrix_positive_real_and_margin():
    G = RationalMatrix([[[1.0, 1.0], [0.0]], [[0.0], [1.0]]], [[[1.0, -1.0], [1.0]], [[1.0], [1.0]]])
    assert positive_real(G).positive_real
    # constant [[1, 2], [2, 1]]: G + G^T = [[2, 4], [4, 2]], eigenvalues 6 and -2
    C = RationalMatrix([[[1.0], [2.0]], [[2.0], [1.0]]], [[[1.0], [1.0]], [[1.0], [1.0]]])
    r = positive_real(C)
    assert r.failed_condition == "hermitian part" and r.margin == pytest.approx(-2.0, abs=1e-12)


def test_non_hermitian_residue_fails_condition_ii():
    # residue T [[Km, -Km], [-Ks, Ks]] of eq. (25) with Km != Ks: not Hermitian
    num = [[[2.0], [-2.0]], [[-1.0], [1.0]]]
    den = [[[1.0, -1.0]] * 2, [[1.0, -1.0]] * 2]
    r = positive_real(RationalMatrix(num, den))
    assert r.failed_condition == "unit-circle poles" and "Hermitian" in r.reason


def test_inverse_of_2x2():
    G = RationalMatrix([[[1.0, 0.3], [0.2]], [[0.1, 0.0], [2.0, -0.5]]],
                       [[[1.0, -0.5], [1.0, 0.1]], [[1.0, 0.2], [1.0, 0.0]]])
    th = np.array([0.3, 1.1, 2.5])
    prod = G(th) @ G.inverse()(th)
    assert np.allclose(prod, np.eye(2), atol=1e-10)


# ------------------------------------------------------------- circle criterion
def test_circle_criterion_finite_sector():
    # G = -0.5: K^-1 + G = 1/k - 0.5 is PR iff k <= 2; the passive limit is not PR
    G = scalar([-0.5], [1.0])
    assert circle_criterion(G, 1.9).positive_real
    assert not circle_criterion(G, 2.1).positive_real
    assert not circle_criterion(G, None).positive_real
    assert not circle_criterion(G, math.inf).positive_real


def test_bad_input():
    with pytest.raises(ModelError, match="proper"):
        scalar([1.0, 0.0, 0.0], [1.0, 0.0])
    with pytest.raises(ModelError, match="square"):
        RationalMatrix([[[1.0], [1.0]]], [[[1.0], [1.0]]])
    with pytest.raises(ModelError, match="finite"):
        scalar([float("nan")], [1.0])
    with pytest.raises(ModelError, match="sector"):
        circle_criterion(scalar([1.0], [1.0]), -1.0)
    with pytest.raises(ModelError, match="sector"):
        circle_criterion(scalar([1.0], [1.0]), [1.0, 2.0])
    with pytest.raises(AnalysisError, match="singular"):
        RationalMatrix([[[1.0], [1.0]], [[1.0], [1.0]]], [[[1.0], [1.0]], [[1.0], [1.0]]]).inverse()


def test_plot_of_the_hermitian_part():
    import matplotlib

    matplotlib.use("Agg")
    r = positive_real(scalar([0.2, 1.0], [1.0, 0.0]), period=1e-3)
    ax = r.plot()
    # the curve drawn is the swept smallest eigenvalue, reaching the reported margin
    y = ax.lines[0].get_ydata()
    assert min(y) == pytest.approx(r.margin, abs=1e-6)


# ------------------------------------------------ many unit-circle poles, any degree
@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 10, 13, 20, 32, 60])
def test_unit_circle_poles_at_any_degree(n):
    zn, one = [1.0] + [0.0] * n, [1.0] + [0.0] * (n - 1)
    # G = 1/(z^n - 1): Re G = -1/2 on the circle, so G + G^H = -1 (issue: degree 10
    # was "positive real" with "min eig -4.2 >= 0": the refinement walked onto a pole)
    r = positive_real(scalar([1.0], [*one, -1.0]))
    assert not r.positive_real and r.failed_conditions == ("hermitian part",)
    # G + G^H = -1 exactly; within 1e-9 rad of the n poles rounding adds ~1e-6
    assert r.margin == pytest.approx(-1.0, abs=1e-5)
    # (z^n + 1)/(z^n - 1) = -j cot(n w / 2): lossless, residues 2/n > 0 -> PR, margin 0
    r = positive_real(scalar([*one, 1.0], [*one, -1.0]))
    assert r.positive_real and abs(r.margin) < 1e-7
    # z^n/(z^n - 1) = 1/2 + lossless part: PR with margin 1
    r = positive_real(scalar(zn, [*one, -1.0]))
    assert r.positive_real and r.margin == pytest.approx(1.0, abs=1e-5)
    # 1/(z^n + 1): Re = 1/2, but the normalised residues are -1/n: (ii) fails
    r = positive_real(scalar([1.0], [*one, 1.0]))
    assert not r.positive_real and r.failed_condition == "unit-circle poles"

