"""The passivity margin over frequency (sampled_passivity(..., curve_points=N), CLI
``passivity --curve N``): the Colgate-Schenkel condition written out by hand for the HVE,
its minimum against the reported margin, seeded random loops over the documented range."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli
from hapstab.errors import AnalysisError


def colgate_schenkel(b: float, K: float, B: float, T: float, n: int, f_hz: np.ndarray
                     ) -> np.ndarray:
    """Colgate & Schenkel (1997) eq. (1) / the paper's eq. (13) for the HVE, by hand:
    b - (T/2) Re{(1 - e^{-jwT}) H(e^{jwT}) e^{-jnwT}} / (1 - cos wT), with
    H(z) = K + B (z - 1)/(T z) (the paper's eq. 23); 1 - cos wT = 2 sin^2(wT/2)."""
    w = 2 * np.pi * f_hz * T
    z = np.exp(1j * w)
    H = K + B * (z - 1) / (T * z)
    num = np.real((1 - np.exp(-1j * w)) * H * np.exp(-1j * n * w))
    return b - (T / 2) * num / (2 * np.sin(w / 2) ** 2)


def _loop(m, b, B, T, n, K):
    return h.HapticLoop(h.Device(m, b), h.SpringDamper(K, B), h.spring(1.0), T, n)


def _random_loops(count, seed):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        T = 10 ** rng.uniform(-4, -2)               # 0.1...10 ms
        n = int(rng.integers(0, 30))
        b = 10 ** rng.uniform(-3, 1)
        B = rng.uniform(-0.5, 1.0) * b
        K = 10 ** rng.uniform(0, 4)
        yield float(rng.uniform(0.01, 2.0)), b, B, T, n, K


@pytest.mark.parametrize("m,b,B,T,n,K", [*_random_loops(25, 2026),
                                          (0.15, 0.1, 0.0, 1e-3, 2, 30.0),
                                          (0.15, 0.1, 0.05, 1e-3, 0, 150.0)])
def test_the_curve_is_colgate_schenkel_written_by_hand(m, b, B, T, n, K):
    points = 400
    res = h.sampled_passivity(_loop(m, b, B, T, n, K), curve_points=points)
    f, c = res.curve_frequency_hz, res.curve_margin
    assert f.shape == c.shape == (points,)
    assert f[-1] == pytest.approx(1 / (2 * T), rel=1e-12)       # the Nyquist frequency
    assert np.allclose(np.diff(f[1:]), f[-1] / (points - 1), rtol=1e-9)   # evenly spaced
    # the scale of the terms: rounding in the two evaluations is ~1e-15 of it; 1/(1 - cos)
    # at the first grid point (wT = pi/399) amplifies it by ~1e4: 1e-9 relative is ample
    scale = b + abs(B) + K * T * (n + 1)
    ref = colgate_schenkel(b, K, B, T, n, f[1:])
    assert np.allclose(c[1:], ref, rtol=0, atol=1e-9 * scale)
    # the first point is the w -> 0 limit: eq. (18)'s b + B - K T (1/2 + n)
    assert c[0] == pytest.approx(b + B - K * T * (0.5 + n), abs=1e-9 * scale)


@pytest.mark.parametrize("m,b,B,T,n,K", list(_random_loops(25, 15)))
def test_the_curve_minimum_is_the_margin(m, b, B, T, n, K):
    points = 2000
    res = h.sampled_passivity(_loop(m, b, B, T, n, K), curve_points=points)
    c, f = res.curve_margin, res.curve_frequency_hz
    scale = b + abs(B) + K * T * (n + 1)
    # the reported margin is the minimum refined between grid points: no grid value is
    # below it (beyond rounding, 1e-12 of the terms' scale)
    assert c.min() >= res.margin - 1e-12 * scale
    # ... and the curve touches it at the reported worst frequency: within half a grid
    # step of a smooth interior minimum the curve rises by at most f'' dw^2 / 8, and
    # f'' dw^2 is the curve's second difference there (x2 for its variation over a step)
    i = int(np.argmin(np.abs(f - res.worst_frequency_hz)))
    bend = np.abs(np.diff(c, 2)).max()
    assert c[i] - res.margin <= bend / 4 + 1e-12 * scale
    assert abs(f[i] - res.worst_frequency_hz) <= f[-1] / (points - 1) / 2 * (1 + 1e-9)


def test_peb_curve_minimum_and_nyquist():
    res = h.sampled_passivity(h.paper_peb(1e-3, 3).with_stiffness(5.0), curve_points=3000)
    assert res.curve_margin.min() >= res.margin - 1e-15    # margin ~1e-2 N*s/m: rounding
    assert res.curve_margin.min() - res.margin <= np.abs(np.diff(res.curve_margin, 2)).max()
    # n = 0, a spring: H = K at every w, the matrix [[K, -K], [-K, K]] has eigenvalues 0, 2K,
    # so the margin is b - K T at every frequency (b = 0.02, K = 3, T = 1 ms: 0.017)
    flat = h.sampled_passivity(h.paper_peb(1e-3, 0).with_stiffness(3.0), curve_points=7)
    assert np.allclose(flat.curve_margin, 0.02 - 3.0 * 1e-3, rtol=0, atol=1e-15)


def test_no_curve_unless_asked():
    res = h.sampled_passivity(h.paper_hve(1e-3, 2).with_stiffness(30.0))
    assert res.curve_margin is None and "margin_curve" not in res.to_dict()


@pytest.mark.parametrize("bad", [1, -1, 1.5, True, "400", 10 ** 6])
def test_bad_curve_points_are_refused(bad):
    with pytest.raises(AnalysisError, match="curve_points"):
        h.sampled_passivity(h.paper_hve(1e-3, 2).with_stiffness(30.0), curve_points=bad)


def test_cli_curve_is_the_library_curve():
    r = CliRunner().invoke(cli, ["passivity", "hve", "-K", "30", "-n", "2", "-B", "0.05",
                                 "--curve", "64", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    res = h.sampled_passivity(_loop(0.15, 0.1, 0.05, 1e-3, 2, 30.0), curve_points=64)
    assert d["margin_curve"]["frequency_hz"] == res.curve_frequency_hz.tolist()
    assert d["margin_curve"]["margin"] == res.curve_margin.tolist()
    assert min(d["margin_curve"]["margin"]) >= d["margin"]


def test_cli_curve_refused_for_the_circle():
    r = CliRunner().invoke(cli, ["passivity", "hve", "-K", "3", "--method", "circle",
                                 "--curve", "8"])
    assert r.exit_code == 2 and "--curve" in r.stderr
