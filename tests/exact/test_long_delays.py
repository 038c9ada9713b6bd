"""Long delays (issue 26 item 4): the exact core's K_max up to 10^5 samples, checked
against a reference built here from the Nyquist condition alone; everything whose cost
grows with the delay is refused up front, by name, when over the budget."""

import math

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.signal import cont2discrete

import hapstab as h
from hapstab.budget import BudgetError
from hapstab.cli.main import cli


def _nyquist_kmax(m, b, k, T, n):
    """K_max of u[k] = -K x[k-n] on the ZOH-sampled 1/(m s^2 + b s + k), from the
    Nyquist condition: the open loop is stable, so the closed loop stays stable until
    K z^-n G(z) first reaches -1, i.e. K_max = min 1/|G(e^{j theta})| over the angles
    where n theta - arg G(e^{j theta}) is an odd multiple of pi. The crossing cells are
    found in doubles (a grid of 64 points per oscillation and 20,000 log-spaced low
    angles); the three lowest are solved in 40-digit mpmath (G from the matrix
    exponential, Newton on the two real equations in theta and K): in doubles, G near z = 1 loses ~eps/theta^2
    (1e-9 relative at theta ~ 4e-4)."""
    import mpmath as mp
    num, den, _ = cont2discrete(([1.0], [m, b, k]), T, method="zoh")
    num = np.atleast_1d(np.squeeze(num))

    def G(th):
        z = np.exp(1j * th)
        return np.polyval(num, z) / np.polyval(den, z)

    # the operator spring's resonance (theta ~ 2.6e-3 at T = 1 ms, damping ratio 0.13)
    # turns arg G by pi over a few 1e-4 rad: log-spaced low angles resolve it
    th = np.union1d(np.linspace(1e-9, math.pi, 64 * (n + 3)), np.geomspace(1e-9, 1.0, 20_000))
    ph = n * th - np.unwrap(np.angle(G(th)))
    f = (ph - math.pi) / (2 * math.pi)
    cells = np.flatnonzero(np.floor(f[1:]) != np.floor(f[:-1]))
    cells = cells[np.argsort(1.0 / np.abs(G(th[cells])))[:3]]
    with mp.workdps(40):
        A = mp.matrix([[0, 1, 0], [-mp.mpf(k) / m, -mp.mpf(b) / m, 1 / mp.mpf(m)], [0, 0, 0]])
        E = mp.expm(A * mp.mpf(T))
        Ad = mp.matrix([[E[0, 0], E[0, 1]], [E[1, 0], E[1, 1]]])
        Bd = mp.matrix([E[0, 2], E[1, 2]])

        def F(t, K):        # 1 + K z^-n G(z) on the circle, as two real equations
            t = mp.re(t)
            z = mp.exp(1j * t)
            v = 1 + mp.re(K) * mp.exp(-1j * n * t) * mp.lu_solve(z * mp.eye(2) - Ad, Bd)[0]
            return [mp.re(v), mp.im(v)]

        best = mp.inf
        for i in cells:
            # Newton (mpmath's findroot) from the cell's start, where the float G holds
            t, K = mp.findroot(F, (mp.mpf(th[i]), mp.mpf(1.0 / abs(G(th[i])))), tol=1e-35)
            assert th[i] - 1e-3 <= t <= th[i + 1] + 1e-3        # the same crossing
            best = min(best, mp.re(K))
        return float(best)


@pytest.mark.parametrize("n", [2400, 20_000, pytest.param(100_000, marks=pytest.mark.campaign)])
def test_kmax_at_a_long_delay_is_the_nyquist_value_and_never_above_it(n):
    loop = h.paper_hve(delay_samples=n)
    res = h.critical_stiffness(loop, certify=True)
    ref = _nyquist_kmax(0.15, 0.1, 1.0, 1e-3, n)
    k = res.critical_stiffness
    # the reference is good to ~1e-30; the proof's safe end lies within its 2^-40
    # window (~1e-12) below the truth: never above it, and 1e-9 is far more than that
    assert k <= ref
    assert k >= ref * (1 - 1e-9)
    assert res.details["proof"].startswith("ball arithmetic")


def test_the_issues_long_haul_command_is_answered():
    # 300 ms at 8 kHz: 2400 samples, refused before (at most 2000)
    r = CliRunner().invoke(cli, ["kmax", "hve", "--rate", "8kHz", "--delay-s", "300ms", "--certify",
                                 "--json"])
    assert r.exit_code == 0, r.output
    import json
    k = json.loads(r.output)["critical_stiffness"]
    ref = _nyquist_kmax(0.15, 0.1, 1.0, 1.25e-4, 2400)
    assert ref * (1 - 1e-9) <= k <= ref      # the safe end (see above)


@pytest.mark.parametrize("args,cost", [
    (["kmax", "peb", "--delay", "100000"], "exact K_max: a delay power of"),
    (["kmax", "peb", "--delay", "30000", "--method", "llewellyn"], "Llewellyn's K_max"),
    (["kmax", "peb", "--delay", "100000", "--method", "passivity"], "a frequency grid of"),
    (["kmax", "hve", "--delay-range", "9000:10000"], "delay range: K_max at"),
    (["limit-cycle", "hve", "-n", "100000", "-K", "0.2", "--resolution", "1e-4"], "build:"),
    (["simulate", "hve", "-n", "100000", "-K", "0.2", "--duration", "1"], "build:"),
])
def test_what_grows_with_the_delay_is_refused_up_front_naming_its_cost(args, cost):
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 2, r.output
    assert cost in r.output and "--yes" in r.output


def test_the_api_refuses_with_a_budget_error_and_answers_with_a_larger_budget():
    loop = h.paper_peb(delay_samples=100_000)
    with pytest.raises(BudgetError, match="exact K_max: a delay power of 200006 samples"):
        h.critical_stiffness(loop)
    # within a budget the refusal is the estimate's, not a limit of the model
    with h.budget.limits(memory_bytes=2e9, seconds=1e-3), \
            pytest.raises(BudgetError, match="budget"):
        h.critical_stiffness(h.paper_hve(delay_samples=20_000))


def test_delays_beyond_the_model_are_refused_by_name():
    with pytest.raises(h.ModelError, match="at most 100000 samples"):
        h.paper_hve(delay_samples=100_001)
