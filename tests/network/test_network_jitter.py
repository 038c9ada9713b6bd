"""Time-varying delay (issue 30, item 2): the bracket [stable_up_to, unstable_from]
against an independent reference.

The reference (tests/references/jittery.py) steps the brute-force loop with the
newest-arrived rule and builds its own mode matrices, products and simulations; the
constant-delay K_max comes from the brute-force scan (tests/references/brute.py). On
seeded HVE loops (50, the default lane runs an evenly spaced few; ``-m campaign`` the
rest) and a few PEB loops:

- stable_up_to <= unstable_from <= min over constant delays d in [lo, hi] of K_max(d);
- a reported non-constant pattern grows: its product's spectral radius, rebuilt
  independently, is above 1, and a simulation of the pattern grows; a constant one is
  the constant-delay worst case and the constant loop is unstable just above it;
- at stable_up_to and 0.9 stable_up_to every enumerated pattern, rebuilt independently,
  decays, and random admissible delay sequences at 0.9 stable_up_to stay bounded.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from tests.lanes import draw
from tests.references import brute, jittery

from hapstab import Device, HapticLoop, SpringDamper, TeleoperationLoop, jitter
from hapstab.analysis.network.jitter import RATE_MARGIN
from hapstab.analysis.network.jitter_gain import hinf_norm
from hapstab.analysis.network.jitter_modes import jitter_modes, patterns
from hapstab.errors import AnalysisError, ModelError

#: K_max of the brute-force scan bisects to 1e-10 and the exact core is certified;
#: 1e-7 relative covers both with room.
KMAX_RTOL = 1e-7


def _termination(rng: np.random.Generator) -> str:
    if rng.random() < 0.5:
        return f"spring:{rng.uniform(1, 400):.6g}"
    return f"msd:{rng.uniform(0.01, 0.5):.6g},{rng.uniform(0, 2):.6g},{rng.uniform(1, 400):.6g}"


def hve_case(seed: int):
    rng = np.random.default_rng(30_200 + seed)
    m, b, T = rng.uniform(0.05, 1.0), rng.uniform(0.01, 2.0), rng.uniform(5e-4, 5e-3)
    B, op = rng.uniform(0, 3.0) if rng.random() < 0.7 else 0.0, _termination(rng)
    lo = int(rng.integers(0, 4))
    hi = lo + int(rng.integers(1, 4))
    loop = HapticLoop(Device(m, b), SpringDamper(1.0, B), op, T, lo)
    return loop, brute.hve_loop(m, b, T, lo, B, op), lo, hi


def resonant_case(seed: int):
    """A stiff hand resonating near the Nyquist rate (ω_hand T in 0.2..3): the draws on
    which a non-constant delay pattern destabilises below the constant worst case (the
    smooth draws of :func:`hve_case` never do, see docs/guide/networks.md)."""
    rng = np.random.default_rng(1000 + seed)
    m, b, T = rng.uniform(0.02, 0.5), rng.uniform(0.0, 1.0), rng.uniform(5e-4, 1e-2)
    B = rng.uniform(-0.5 * b, 2.0)
    om, w = rng.uniform(0.005, 0.3), rng.uniform(0.2, 3.0) / T
    op = f"msd:{om:.6g},{rng.uniform(0, 0.5):.6g},{om * w * w:.6g}"
    lo = int(rng.integers(0, 3))
    hi = lo + int(rng.integers(1, 3))
    loop = HapticLoop(Device(m, b), SpringDamper(1.0, B), op, T, lo)
    return loop, brute.hve_loop(m, b, T, lo, B, op), lo, hi


#: The seeds of :func:`resonant_case` (among its first 300) whose worst pattern is not
#: constant, as found by hapstab: each is then checked against the reference.
RESONANT = (8, 91, 114, 138, 139, 147, 171, 255, 284, 290)


def peb_case(seed: int):
    rng = np.random.default_rng(30_300 + seed)
    mm, bm, ms, bs = (rng.uniform(0.01, 0.5), rng.uniform(0.01, 1.0),
                      rng.uniform(0.01, 0.5), rng.uniform(0.01, 1.0))
    T = rng.uniform(5e-4, 4e-3)
    B, Bs, ratio = rng.uniform(0, 1.0), rng.uniform(0, 1.0), rng.uniform(0.5, 2.0)
    op, env = _termination(rng), _termination(rng)
    lo = int(rng.integers(0, 2))
    hi = lo + 1
    loop = TeleoperationLoop(Device(mm, bm), Device(ms, bs), SpringDamper(1.0, B),
                             SpringDamper(ratio, Bs), op, env, T, lo, lo)
    return loop, brute.peb_loop(mm, bm, ms, bs, T, lo, lo, B, Bs, ratio, op, env), lo, hi


def _constant_kmax(ref: brute.Loop, lo: int, hi: int, terms: int) -> dict[tuple, float]:
    """The brute-force K_max of every constant delay (every pair for PEB)."""
    return {d: brute.stable_intervals(jittery.with_delay(ref, d)).kmax
            for d in itertools.product(range(lo, hi + 1), repeat=terms)}


def _grows(ref: brute.Loop, pattern, K: float, hi: int) -> float:
    """log of the growth of a simulation of ``pattern`` repeated from a random state:
    three periods stepped sample by sample (checked against the period's product), then
    2^j periods by squaring the product (scaled, its log scale kept), until the state
    has grown by 1e6 or 2^60 periods have passed."""
    rng = np.random.default_rng(1)
    N = jittery.size(ref, hi)
    x0 = rng.standard_normal(N)
    x = x0.copy()
    for _ in range(3):
        for d in pattern:
            x = jittery.step(ref, x, tuple(d), K, hi)
    P = np.eye(N)
    for d in pattern:
        P = jittery.mode(ref, tuple(d), K, hi) @ P
    # the stepped simulation is the product's, to rounding (1e-9 of the state's size)
    assert np.allclose(x, np.linalg.matrix_power(P, 3) @ x0, rtol=1e-9,
                       atol=1e-9 * np.abs(x).max())
    Q, log_scale = P.copy(), 0.0
    for _ in range(60):
        grown = log_scale + math.log(np.linalg.norm(Q @ x0) / np.linalg.norm(x0))
        if grown >= math.log(1e6):
            break
        Q = Q @ Q
        s = float(np.abs(Q).max())
        Q /= s
        log_scale = 2 * log_scale + math.log(s)
    return grown


def _check_bracket(case, max_length: int = 6, res=None) -> None:
    loop, ref, lo, hi = case
    res = res or jitter(loop, (lo, hi), max_length=max_length)
    terms = len(res.terms)
    kc = _constant_kmax(ref, lo, hi, terms)
    worst = min(kc.values())
    assert 0.0 <= res.stable_up_to <= res.unstable_from, res.reason
    assert res.unstable_from <= worst * (1 + KMAX_RTOL), res.reason
    assert res.constant_worst == pytest.approx(worst, rel=KMAX_RTOL)
    if res.pattern_is_constant:
        d = res.pattern[0]
        assert len(res.pattern) == 1 and kc[d] == pytest.approx(worst, rel=KMAX_RTOL)
        # the constant loop is unstable just above its K_max (it is the boundary)
        K_above = res.unstable_from * (1 + 1e-4)
        assert brute.radius(jittery.with_delay(ref, d), K_above)[0] > 1.0
        assert _grows(ref, res.pattern, K_above, hi) >= math.log(1e6)
    else:
        r = jittery.rate(ref, res.pattern, res.unstable_from, hi)
        assert r >= 1.0 + RATE_MARGIN / 2, (r, res.pattern)
        assert r == pytest.approx(res.pattern_rate, rel=1e-11)
        assert _grows(ref, res.pattern, res.unstable_from, hi) >= math.log(1e6)
    if res.stable_up_to == 0.0:
        return                                  # nothing is claimed stable
    pats = patterns(lo, hi, terms, max_length)
    for K in (res.stable_up_to, 0.9 * res.stable_up_to):
        at = jittery.modes(ref, lo, hi, K)
        rates = [jittery.rate(ref, q, K, hi, at) for q in pats]
        assert max(rates) < 1.0, (K, pats[int(np.argmax(rates))])
    _bounded(ref, lo, hi, terms, 0.9 * res.stable_up_to)


def _bounded(ref: brute.Loop, lo: int, hi: int, terms: int, K: float) -> None:
    """Random admissible sequences at K stay bounded."""
    rng = np.random.default_rng(7)
    modes = jittery.modes(ref, lo, hi, K)
    N = jittery.size(ref, hi)
    for _ in range(10):
        x0 = rng.standard_normal(N)
        x, top = x0.copy(), 1.0
        for d in jittery.random_sequence(rng, lo, hi, terms, 3000):
            x = modes[d] @ x
            top = max(top, float(np.linalg.norm(x) / np.linalg.norm(x0)))
        # transients of a stable switched loop stay within 1e3 of the start (measured up
        # to 12 on the campaign: slow loops, rho ~ 1 - 2e-5 per sample, wander before
        # they decay); an unstable one grows without bound
        assert top < 1e3


@pytest.mark.parametrize("seed", draw(range(50), 3))
def test_hve_bracket_against_the_reference(seed):
    _check_bracket(hve_case(seed))


@pytest.mark.parametrize("seed", draw(RESONANT, 1))
def test_destabilising_patterns_against_the_reference(seed):
    loop, _ref, lo, hi = case = resonant_case(seed)
    res = jitter(loop, (lo, hi))
    assert not res.pattern_is_constant and res.unstable_from < res.constant_worst
    _check_bracket(case, res=res)


@pytest.mark.parametrize("seed", draw(range(6), 1))
def test_peb_bracket_against_the_reference(seed):
    _check_bracket(peb_case(seed), max_length=3)


def test_modes_equal_the_reference():
    loop, ref, lo, hi = hve_case(4)
    jm = jitter_modes(loop, lo, hi)
    K = 0.5 * jitter(loop, (lo, hi)).constant_worst
    at = jittery.modes(ref, lo, hi, K)
    for q in patterns(lo, hi, 1, 4)[:40]:
        P = np.eye(jm.order)
        for d in q:
            P = jm.at(K)[jm.delays.index(d)] @ P
        mine = float(np.abs(np.linalg.eigvals(P)).max() ** (1 / len(q)))
        assert mine == pytest.approx(jittery.rate(ref, q, K, hi, at), rel=1e-11)


def test_small_gain_is_the_formula_of_the_docs():
    """N ||M||_inf equals N max |e^{jw} - 1| |GC / (1 + GC e^{-jw lo})| on a fine grid,
    with G C from the reference's constant-delay-0 loop transfer (stepped)."""
    loop, ref, lo, hi = hve_case(2)
    K = 0.3 * jitter(loop, (lo, hi)).stable_up_to
    jm = jitter_modes(loop, lo, hi)
    A = jm.at(K)[jm.nominal]
    g = hinf_norm(A, jm.B0 + K * jm.B1, jm.C)
    # the reference: the loop at delay lo with an input r added to the measurement
    N = jittery.size(ref, hi)
    base = jittery.mode(ref, (lo,), K, hi)
    b = jittery.mode(ref, (lo + 1,), K, hi)[:, 2 + lo] - base[:, 2 + lo]
    c = np.zeros(N)
    c[0 if lo == 0 else 2 + lo - 1] += 1.0
    c[2 + lo] -= 1.0
    w = np.concatenate([np.geomspace(1e-6, 1e-1, 20000), np.linspace(0.1, np.pi, 20000)])
    z = np.exp(1j * w)
    X = np.linalg.solve(z[:, None, None] * np.eye(N) - base,
                        np.broadcast_to(b[:, None], (w.size, N, 1)))
    Mz = np.einsum("n,wn->w", c, X[..., 0])
    grid = float(np.abs(Mz).max())
    assert grid <= g * (1 + 1e-9)               # the answer is an upper end of the peak
    assert g == pytest.approx(grid, rel=1e-4)   # and the grid of 40000 resolves it to 1e-4


def test_no_jitter_is_the_constant_delay():
    loop, ref, lo, _ = hve_case(0)
    res = jitter(loop, (lo, lo))
    kc = brute.stable_intervals(jittery.with_delay(ref, (lo,))).kmax
    assert res.stable_up_to == res.unstable_from == pytest.approx(kc, rel=KMAX_RTOL)
    assert res.gap == 0.0 and res.pattern == ((lo,),)


def test_seconds_are_whole_samples_at_the_receiver():
    import hapstab as h

    loop = h.paper_hve(1e-3, 0)
    a, b = jitter(loop, delay_s=(4.5e-3, 6e-3)), jitter(loop, (5, 6))
    assert a.delay_samples == (5, 6) and a.range_s == (4.5e-3, 6e-3)
    assert a.stable_up_to == b.stable_up_to and a.unstable_from == b.unstable_from


def test_patterns_are_every_admissible_cycle_once():
    pats = patterns(2, 5, 1, 5)
    for p in range(1, 6):
        want = set()
        for s in itertools.product(range(2, 6), repeat=p):
            if all(s[(i + 1) % p] <= s[i] + 1 for i in range(p)):
                rots = [s[i:] + s[:i] for i in range(p)]
                if all(s < r for r in rots[1:]):
                    want.add(tuple((d,) for d in s))
        assert {q for q in pats if len(q) == p} == want
    assert len(pats) == len(set(pats))


@pytest.mark.parametrize("bad", [(3, 2), (1.5, 3), (-1, 2), "5:15", None])
def test_bad_ranges_are_refused(bad):
    loop = hve_case(0)[0]
    with pytest.raises(ModelError, match="delay"):
        jitter(loop, bad)


def test_a_range_too_long_for_the_budget_is_refused_before_any_work():
    import time

    from hapstab.budget import BudgetError

    t0 = time.perf_counter()
    with pytest.raises(BudgetError, match=r"jitter: .* modes"):
        jitter(hve_case(0)[0], (0, 400))
    assert time.perf_counter() - t0 < 1.0


def test_four_channel_is_refused():
    import hapstab as h

    four = h.FourChannelLoop(h.Device(0.015, 0.02), h.Device(0.015, 0.02),
                             h.SpringDamper(0.0, 0.5), h.SpringDamper(1.0, 0.8),
                             h.parse_impedance("msd:0.5,5,500"), h.spring(1000.0), 1e-3, 2,
                             slave_from_master=h.SpringDamper(1.0, 0.8),
                             master_from_slave=h.SpringDamper(0.0, 0.5), force_to_master=1.0)
    with pytest.raises(AnalysisError, match="jitter"):
        jitter(four, (1, 2))


def test_result_protocol():
    import json

    import matplotlib

    matplotlib.use("Agg")
    import io

    import hapstab as h

    res = jitter(h.paper_hve(1e-3, 0), (1, 3))
    d = res.to_dict()
    json.dumps(d, allow_nan=False)
    assert d["stable_up_to_N_per_m"] <= d["unstable_from_N_per_m"]
    assert res._repr_html_().startswith("<table>")
    buf = io.StringIO()
    res.to_csv(buf)
    lines = buf.getvalue().splitlines()
    assert lines[0] == "search,stiffness_N_per_m,value"
    assert len(lines) == 1 + len(res.scan_K) + len(res.gain_K)
    assert res.plot().has_data()
    assert math.isfinite(res.small_gain) and res.small_gain < 1


def test_rigid_teleoperator_is_deflated():
    """PEB with no operator and no environment: the rigid-body mode (z = 1 in every mode,
    for every K) is divided out; at stable_up_to every pattern's product, rebuilt by the
    reference, has that one eigenvalue at 1 and every other inside the circle."""
    loop = TeleoperationLoop(Device(0.015, 0.02), Device(0.015, 0.02), SpringDamper(1.0, 0.0),
                             SpringDamper(1.0, 0.0), None, None, 1e-3, 1, 1)
    ref = brute.peb_loop(0.015, 0.02, 0.015, 0.02, 1e-3, 1, 1)
    res = jitter(loop, (1, 2), max_length=3)
    assert jitter_modes(loop, 1, 2).deflated
    assert 0 < res.stable_up_to <= res.unstable_from <= res.constant_worst
    at = jittery.modes(ref, 1, 2, res.stable_up_to)
    for q in patterns(1, 2, 2, 3):
        P = np.eye(jittery.size(ref, 2))
        for d in q:
            P = at[d] @ P
        mods = np.sort(np.abs(np.linalg.eigvals(P)))[::-1]
        # the rigid mode: 1 to the rounding of a product of <= 3 matrices
        assert abs(mods[0] - 1.0) < 1e-9 and mods[1] < 1.0, (q, mods[:3])
