"""The certified crossing analysis: the K_max-only path equals the full one, the
three reproducers of the missed crossings (issue #8) give their true values, and
the counts from crossing directions agree with the argument principle."""

import numpy as np
import pytest

import hapstab as h
from hapstab.analysis.exact.crossings import U_LO, analyse, winding
from hapstab.engine.frequency import loop_response
from hapstab.engine.system import build
from reference_data import ref


@pytest.mark.parametrize("loop", [h.paper_hve(delay_samples=10), h.paper_peb(delay_samples=4),
                                  h.paper_hve(damping=0.05, delay_samples=2)])
def test_kmax_only_path_equals_full_path(loop):
    r = loop_response(loop, np.geomspace(1e-4, 2e-2, 9))
    fast = [x.kmax for x in analyse(r, full=False)]
    full = [x.kmax for x in analyse(r, full=True)]
    np.testing.assert_allclose(fast, full, rtol=1e-12)


def _eig_count(loop, K):
    """Poles strictly outside the circle from the closed-loop matrix (rigid mode
    at z = 1 dropped), for comparison with the argument principle."""
    s = build(loop)
    ev = np.linalg.eigvals(s.closed_loop(K)[0])
    if loop_response(loop).rigid:
        ev = ev[np.argsort(np.abs(ev - 1))[1:]]
    return int(np.sum(np.abs(ev) > 1))


@pytest.mark.parametrize("loop", [h.paper_hve(delay_samples=7), h.paper_peb(delay_samples=3),
                                  h.paper_peb(delay_samples=3).replace(operator=None, environment=None),
                                  h.paper_hve(delay_samples=2).replace(fractional_delay=0.4)])
def test_winding_counts_match_eigenvalues(loop):
    r = loop_response(loop)
    Ks = np.geomspace(1e-3, 1e6, 23) * 1.0001
    got = winding(r, np.zeros(Ks.size, int), Ks / r.scale[0])
    want = [_eig_count(loop, K) for K in Ks]
    np.testing.assert_array_equal(got, want)


# issue #8's reproducers; true values from an independent brute force (tests/brute.py)
ISSUE1 = h.TeleoperationLoop(h.Device(0.45, 2.2), h.Device(0.56, 0.0048), h.SpringDamper(1, 0.002),
                             h.SpringDamper(1, 0.002), h.spring(0.82), h.spring(3200), 0.00072, 30)
ISSUE1B = h.TeleoperationLoop(h.Device(0.2136, 0.001524), h.Device(2.4919, 0.78027),
                              h.SpringDamper(1, 0.0022915), h.SpringDamper(0.48475, 0.0), None,
                              h.spring(808.67), 0.0032137, 24)
FREE = h.TeleoperationLoop(h.Device(0.113, 0.0027), h.Device(0.28, 0.0032), h.SpringDamper(1, 0.0004),
                           h.SpringDamper(1, 0.0004), None, None, 0.000376, 11)


def test_missed_window_of_a_lightly_damped_resonance():
    res = h.critical_stiffness(ISSUE1)
    ivs, rel = ref("issue8_peb30_intervals")
    assert res.critical_stiffness == pytest.approx(ivs[0][1], rel=rel)
    (a, b), (c, d) = res.stable_intervals
    assert a == 0 and b == res.critical_stiffness
    assert c == pytest.approx(ivs[1][0], rel=rel) and d == pytest.approx(ivs[1][1], rel=rel)
    # inside the window the loop is unstable, on both sides stable
    for K, want in ((0.999 * b, True), (1.001 * b, False), (165.0, False), (1.001 * c, True)):
        assert h.stability(ISSUE1.with_stiffness(K)).stable is want, K


def test_unequal_controllers_three_intervals():
    res = h.critical_stiffness(ISSUE1B)
    k, rel = ref("issue8_unequal_kmax")
    assert res.critical_stiffness == pytest.approx(k, rel=rel)
    ivs = res.stable_intervals
    assert len(ivs) == 3
    assert ivs[1][0] == pytest.approx(15.6, rel=2e-3) and ivs[1][1] == pytest.approx(45.69, rel=1e-4)
    assert ivs[2][0] == pytest.approx(127.3, rel=2e-3) and ivs[2][1] == pytest.approx(191.45, rel=1e-4)


def test_free_peb_is_not_biased_low_and_names_the_complex_pair():
    res = h.critical_stiffness(FREE)
    assert res.critical_stiffness == pytest.approx(1.0810478, rel=1e-7)
    assert "complex pole pair" in res.reason and "rigid-body" in res.reason
    assert np.isfinite(res.crossing_frequency_hz) and res.crossing_frequency_hz > 0


def test_anchor_count_at_small_K_is_zero_for_a_damped_loop():
    r = loop_response(h.paper_hve(delay_samples=5))
    assert winding(r, np.zeros(1, int), np.array([U_LO]))[0] == 0


def test_a_crossing_inside_an_unresolved_zone_is_not_counted_twice():
    # (from the independent review) an unresolved box of one theta-cell can span a
    # crossing proved in another cell: the stable set must end at the zone, safely,
    # and the intervals above must survive
    from hapstab.analysis.exact.boxes import Cells, initial_cells
    from hapstab.analysis.exact.counts import dedupe_crossings, item_stable_set, winding_on_cells
    from hapstab.analysis.exact.crossings import branch_and_prune
    resp = loop_response(ISSUE1B)
    c = Cells()
    first = c.add(resp, *initial_cells(resp, np.arange(1)))
    anchor = int(winding_on_cells(resp, c, first, np.full(1, U_LO))[0])
    found = branch_and_prune(resp, np.arange(1), np.full(1, np.inf), start=(c, first))
    cross = dedupe_crossings(found.cross[0])
    s = resp.scale[0]
    u1 = next(u for u, *_ in cross if abs(u * s - 45.69) < 0.1)
    res = item_stable_set(resp, 0, anchor, cross, [(0.99 * u1, 1.01 * u1)], True)
    ivs = res.intervals
    assert len(ivs) == 3 and ivs[1][1] == pytest.approx(0.99 * u1 * s, rel=1e-12)
    assert ivs[2][0] == pytest.approx(127.345, rel=1e-5) and res.uncertain
