"""Boundedness verdict and growth-rate estimate on synthetic trajectories whose
rates are known analytically (not from hapstab)."""

import math

import numpy as np
import pytest

from hapstab.simulation.growth import assess, dmd_rate

T = 1e-3


def modal(lams, k, rng, offset=None):
    """Real trajectory sum_i Re(c_i lam_i^k v_i) in R^6, plus a constant offset."""
    N = 6
    S = np.zeros((k.size, N))
    for lam in lams:
        v = rng.standard_normal(N) + 1j * rng.standard_normal(N)
        S += np.real(np.outer(lam ** k, v))
    if offset is not None:
        S += offset
    return S


@pytest.mark.parametrize("rates,freqs", [((-0.3, -5.0), (6.0, 90.0)), ((0.02, -40.0), (2.0, 300.0)),
                                         ((-0.001, -0.5), (35.0, 1.0))])
def test_rate_of_known_modes(rates, freqs):
    rng = np.random.default_rng(1)
    lams = [np.exp((r + 2j * np.pi * f) * T) for r, f in zip(rates, freqs, strict=True)]
    S = modal(lams, np.arange(3000), rng, offset=rng.standard_normal(6))
    v = assess(S, None, T)
    # noise-free data: the fitted eigenvalue is the true one to rounding, so the rate
    # (ln|lam|/T, ~1e-3 of |lam|-1 per unit of 1/s) agrees to 1e-6 of the largest rate
    assert v.growth_rate == pytest.approx(max(rates), rel=1e-6, abs=1e-8)
    assert v.verdict == ("unbounded" if max(rates) > 0 else "bounded")
    assert v.confidence == "high" and v.fit_residual < 1e-8


def test_forced_linear_recurrence():
    rng = np.random.default_rng(2)
    Q = np.linalg.qr(rng.standard_normal((5, 5)))[0]
    A = Q @ np.diag([0.999, 0.99, 0.5, -0.3, 0.9]) @ Q.T
    B = rng.standard_normal((5, 1))
    k = np.arange(2000)
    F = np.sin(0.05 * k)[:, None] + (k >= 500)[:, None]     # sine plus a step
    S = np.zeros((k.size + 1, 5))
    for i in k:
        S[i + 1] = A @ S[i] + B @ F[i]
    v = assess(S, F, T)
    assert v.bounded and v.growth_rate == pytest.approx(math.log(0.999) / T, rel=1e-6)


def test_observed_explosion_and_overflow():
    S = np.outer(1.3 ** np.arange(200), np.ones(3))
    v = assess(S, None, T)
    assert v.verdict == "unbounded" and v.basis == "observed" and v.confidence == "high"
    S[-5:] = np.inf
    assert assess(S, None, T).basis == "observed"


def test_constant_and_marginal():
    S = np.ones((100, 4))
    v = assess(S, None, T)
    assert v.bounded and v.growth_rate == -math.inf
    k = np.arange(2000)
    S = np.column_stack([np.cos(0.1 * k), np.sin(0.1 * k)])   # on the unit circle
    assert assess(S, None, T).verdict == "marginal"


def test_switching_data_is_not_high_confidence():
    # an unstable rotation held in a limit cycle by a relay: the sample map is not
    # linear, and the fit says so
    th = 0.05
    A = 1.002 * np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
    S = np.zeros((3000, 2))
    S[0] = [0.1, 0.0]
    for i in range(2999):
        S[i + 1] = A @ S[i] - np.array([0.02, 0.0]) * np.sign(S[i, 0] + 1e-12)
    v = assess(S, None, T)
    assert v.fit_residual > 1e-2 and v.confidence == "low"


def test_dmd_rate_exact_and_errors():
    lam = 0.97
    D = np.outer(lam ** np.arange(50), [1.0, -2.0])
    rho, res = dmd_rate(D)
    assert rho == pytest.approx(lam, rel=1e-12) and res < 1e-12
    assert dmd_rate(np.zeros((10, 3))) == (0.0, 0.0)
    with pytest.raises(ValueError, match="at least 8"):
        assess(np.zeros((5, 2)), None, T)
