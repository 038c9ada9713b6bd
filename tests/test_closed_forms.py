"""Closed forms: the paper's equations evaluated by hand, and where they apply."""

import pytest

import hapstab as h
from hapstab.errors import AnalysisError


def test_hve_conditions_at_paper_parameters():
    T = 1e-3
    assert h.colgate(h.paper_hve()).critical_stiffness == pytest.approx(2 * 0.1 / T)   # (13)
    loop = h.paper_hve(delay_samples=10)
    assert h.eq18(loop).critical_stiffness == pytest.approx(0.1 / (T / 2 + 10 * T))      # 9.5238
    assert h.gil(loop).critical_stiffness == h.eq18(loop).critical_stiffness              # (2) = (18)
    assert "not valid" in h.colgate(loop).reason                                           # no delay in (13)


def test_virtual_damping_enters_as_the_paper_says():
    loop = h.paper_hve(damping=0.02, delay_samples=2)
    assert h.colgate(loop).critical_stiffness == pytest.approx(2 * (0.1 - 0.02) / 1e-3)
    assert h.eq18(loop).critical_stiffness == pytest.approx((0.1 + 0.02) / (0.5e-3 + 2e-3))


def test_peb_conditions_at_paper_parameters():
    assert h.eq29(h.paper_peb()).critical_stiffness == pytest.approx(0.02 / 1e-3)           # (29)
    assert h.eq34(h.paper_peb(delay_samples=4)).critical_stiffness == pytest.approx(0.02 / 5e-3)
    # b = min(b_m, b_s)
    loop = h.paper_peb().replace(slave=h.Device(0.015, 0.005))
    assert h.eq29(loop).critical_stiffness == pytest.approx(0.005 / 1e-3)


def test_eq34_does_not_reduce_to_eq29_with_damping():
    loop = h.paper_peb(damping=0.004)
    assert h.eq34(loop).critical_stiffness > h.eq29(loop).critical_stiffness


def test_conditions_refuse_the_wrong_loop():
    with pytest.raises(AnalysisError, match="HapticLoop"):
        h.colgate(h.paper_peb())
    with pytest.raises(AnalysisError, match="TeleoperationLoop"):
        h.eq34(h.paper_hve())
    with pytest.raises(AnalysisError, match="C_m = C_s"):
        h.eq29(h.paper_peb().replace(slave_controller=h.SpringDamper(1.0, 0.5)))
    with pytest.raises(AnalysisError, match="no operator"):
        h.gil2004(h.paper_hve())


def test_negative_bound_is_reported_as_zero():
    res = h.colgate(h.paper_hve(damping=0.2))            # b < B: no stiffness passes (13)
    assert res.critical_stiffness == 0.0 and res.stable_intervals == ()
