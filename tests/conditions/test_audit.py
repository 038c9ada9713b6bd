"""The audit flags exactly the promises the exact analysis (or the PR test) breaks:
checked against stability() at the promised stiffness, written out here."""

import math

import pytest

import hapstab as h
from hapstab.analysis.conditions.audit import audit
from hapstab.errors import AnalysisError
from hapstab.models.controllers import DiscreteController, SpringDamper
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.models.parts import Device


def rows(a):
    return {r.key: r for r in a.rows}


def test_paper_case_nothing_wrong_with_forward_and_eq18():
    a = audit(h.paper_hve(delay_samples=10))
    r = rows(a)
    assert "colgate" not in r  # derived without delay: not listed for n = 10
    assert r["eq18"].flag is None and r["circle-forward"].flag is None and r["passivity"].flag is None
    # backward and Tustin promise more than the exact limit (9.536): flagged
    assert {"circle-backward", "circle-tustin"} <= set(a.flagged)
    assert r["eq18"].critical_stiffness == pytest.approx(9.5238095, rel=1e-7)
    assert a.exact_kmax > r["eq18"].critical_stiffness


@pytest.mark.parametrize("loop,keys", [
    (h.paper_hve(delay_samples=4, damping=-0.03), ("gil", "eq18")),
    (h.paper_peb(damping=-0.004), ("eq29", "eq34")),
])
def test_negative_b_closed_forms_keep_their_promise(loop, keys):
    # for B < 0 the paper's lines are the exact passivity limit: nothing to flag, and
    # the exact loop is stable just below each promised K (checked here independently)
    a = audit(loop)
    r = rows(a)
    assert a.virtual_damping < 0
    for k in (*keys, "circle-forward", "passivity"):
        assert r[k].flag is None
        assert r[k].critical_stiffness == pytest.approx(a.passivity_kmax, rel=1e-9)
        assert h.stability(loop.with_stiffness(r[k].critical_stiffness * (1 - 1e-6))).stable
    assert a.exact_kmax > a.passivity_kmax


def test_negative_b_beyond_device_damping_lists_zero_everywhere():
    a = audit(h.paper_hve(damping=-0.2))
    assert a.exact_kmax == 0.0 and all(r.critical_stiffness == 0.0 for r in a.rows)
    assert not a.flagged


def test_eq34_without_delay_over_promises_with_virtual_damping():
    # (34) at n = 0, B > 0 allows (b + 2B)/T, where (29) allows (b - 2B)/T
    loop = h.paper_peb(damping=0.005)
    a = audit(loop)
    r = rows(a)
    assert r["eq29"].flag is None
    assert r["eq34"].critical_stiffness == pytest.approx(30.0, rel=1e-12)
    assert "eq34" in a.flagged and "over-promises" in r["eq34"].flag
    # independent of the audit's bookkeeping: the exact loop is unstable just below 30 N/m
    assert not h.stability(loop.with_stiffness(30.0 * (1 - 1e-6))).stable


def test_eq18_with_large_virtual_damping_over_promises():
    loop = h.paper_hve(delay_samples=4, damping=0.08)
    a = audit(loop)
    r = rows(a)
    assert "eq18" in a.flagged and "gil" in a.flagged
    assert "not passive" in r["eq18"].flag
    assert not h.stability(loop.with_stiffness(r["eq18"].critical_stiffness * (1 - 1e-6))).stable
    # the forward circle and passivity limits are honoured by the exact analysis
    assert h.stability(loop.with_stiffness(r["circle-forward"].critical_stiffness * 0.999)).stable


def test_flags_agree_with_stability_checks():
    broken = kept = 0
    for loop in (h.paper_hve(period=5e-3, delay_samples=2, damping=0.03),
                 h.paper_peb(delay_samples=4, damping=0.01),
                 h.paper_hve(period=1e-3, delay_samples=4, damping=0.08)):
        a = audit(loop)
        for r in a.rows:
            K = r.critical_stiffness
            if r.key == "exact" or not math.isfinite(K) or K <= 0:
                continue
            unstable_below = not h.stability(loop.with_stiffness(K * (1 - 1e-6))).stable
            over = bool(r.flag) and "over-promises" in r.flag
            # a broken promise is flagged, and a kept one is not
            assert over == unstable_below, (r.key, K, r.flag)
            broken += unstable_below
            kept += not unstable_below
    # both kinds occur, so both directions were checked (n = 4, B = 0.08: eq. (18)
    # promises 40 N/m, the exact limit is 39.976)
    assert broken >= 1 and kept >= 1


def test_unequal_controllers_skip_peb_closed_forms():
    loop = TeleoperationLoop(Device(0.015, 0.02), Device(0.015, 0.02), SpringDamper(1.0),
                             SpringDamper(2.0), "spring:1", "spring:1", 1e-3, 0)
    keys = set(rows(audit(loop)))
    assert "eq29" not in keys and "eq34" not in keys and "passivity" in keys


def test_to_dict_and_errors():
    d = audit(h.paper_hve()).to_dict()
    assert d["loop"] == "hve" and isinstance(d["rows"], list) and "flagged" in d
    with pytest.raises(AnalysisError):
        audit(HapticLoop(Device(0.1, 0.1), DiscreteController((1.0,), (1.0,)), None, 1e-3, 0))
    with pytest.raises(TypeError, match="loop = 'not a loop': must be a HapticLoop"):
        audit("not a loop")        # a TypeError, and a HapstabError (one line on the CLI)


def test_the_verdict_column_agrees_with_the_closed_loop_eigenvalues():
    """The audit reads each row's verdict from the certified stable set; an independent
    eigenvalue check of the closed loop at K (1 - 1e-4) must agree, on seeded loops. (Within
    ~1e-6 of a crossing the certified count of poles outside may be undecidable once the
    enclosures carry the matrix exponential's normwise error, and stability() then says
    marginal, as it should.)"""
    import numpy as np

    rng = np.random.default_rng(20261124)
    for i in range(12):
        n = int(rng.integers(0, 6))
        T = float(rng.choice([5e-4, 1e-3, 2e-3]))
        if i % 2:
            loop = h.paper_peb(T, n).replace(
                master=h.Device(float(rng.uniform(0.01, 1)), float(rng.uniform(0.01, 3))),
                environment=h.spring(float(rng.choice([1.0, 500.0, 2e4]))))
        else:
            loop = h.paper_hve(T, n).replace(
                device=h.Device(float(rng.uniform(0.05, 1)), float(rng.uniform(0.01, 3))))
        for r in h.audit(loop).rows:
            if r.exact_verdict == "-":
                continue
            v = h.stability(loop.with_stiffness(r.critical_stiffness * (1 - 1e-4))).verdict
            assert v == r.exact_verdict, (i, r.key, r.critical_stiffness, v, r.exact_verdict)
