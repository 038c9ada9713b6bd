"""Characteristic polynomial pieces against numpy on known cases."""

import numpy as np
import pytest

import hapstab as h
from hapstab.charpoly import (chi_coefficients, crossing_polys, deflate, positive_real_roots,
                              unit_circle_angles)
from hapstab.engine import build


@pytest.mark.parametrize("loop,r", [(h.paper_hve(delay_samples=3, damping=0.02), 1),
                                    (h.paper_peb(delay_samples=2, damping=0.004), 2)])
def test_chi_coefficients_match_numpy_poly(loop, r):
    s = build(loop)
    A0, B1, C1 = s.A0, s.B1, s.C1
    A1 = B1 @ C1
    Ks = np.array([8.0])
    c = chi_coefficients(A0, A1, Ks, r, np.linalg.eigvals(A0), B1, C1)
    for K in (0.0, 3.0, 17.0):
        ours = sum((K / Ks[0]) ** l * c[0, l] for l in range(r + 1))[::-1]
        ref = np.poly(np.linalg.eigvals(A0[0] + K * A1[0])).real
        # both are backward-stable constructions; coefficients of size ~C(N, k)
        np.testing.assert_allclose(ours, ref, atol=1e-11 * np.abs(ref).max())


def test_unit_circle_angles_of_known_polynomials():
    angles = np.array([0.3, 1.1, 2.5])
    roots = np.concatenate([np.exp(1j * angles), np.exp(-1j * angles), [1.0, -1.0]])
    q_anti = np.poly(roots).real[::-1]                  # (z^2 - 1) * ...: anti-palindromic
    got = unit_circle_angles(q_anti[None])[0]
    np.testing.assert_allclose(got, angles, atol=1e-12)
    q_pal = np.poly(np.concatenate([np.exp(1j * angles), np.exp(-1j * angles)])).real[::-1]
    np.testing.assert_allclose(unit_circle_angles(q_pal[None])[0], angles, atol=1e-12)
    # a reciprocal pair off the circle is not a crossing
    off = np.poly([0.5, 2.0, np.exp(0.7j), np.exp(-0.7j)]).real[::-1]
    np.testing.assert_allclose(unit_circle_angles(off[None])[0], [0.7], atol=1e-12)


def test_crossing_poly_is_exactly_antisymmetric():
    c = np.random.default_rng(0).normal(size=(3, 2, 7))
    q = crossing_polys(c)
    np.testing.assert_array_equal(q, -q[:, ::-1])


def test_positive_real_roots_and_deflate():
    roots = positive_real_roots(np.array([[-6.0, 5.0, -1.0], [2.0, 1.0, 0.0], [1.0, 0.0, 1.0]]))
    np.testing.assert_allclose(np.sort(roots[0]), [2.0, 3.0])   # -6 + 5K - K^2 = -(K-2)(K-3)
    assert roots[1].size == 0 and roots[2].size == 0      # -2 and +-j are not positive real
    p = np.array([2.0, -3.0, 1.0])                        # ascending: 2 - 3z + z^2
    q = np.convolve(np.convolve(p, [-1.0, 1.0]), [-1.0, 1.0])
    np.testing.assert_allclose(deflate(q, 2)[:3], p, atol=1e-14)
