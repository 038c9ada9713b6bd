"""Models: validation at construction, impedance decomposition, spec parsing."""

import dataclasses
import math

import numpy as np
import pytest

import hapstab as h
from hapstab.errors import HapstabError, ModelError


@pytest.mark.parametrize("mass", [0.0, -1.0, math.nan, math.inf])
def test_device_rejects_bad_mass(mass):
    with pytest.raises(ModelError, match="mass"):
        h.Device(mass, 0.1)


def test_device_rejects_negative_damping_and_names_value():
    with pytest.raises(ModelError, match=r"damping = -0.5: must be >= 0"):
        h.Device(1.0, -0.5)


def test_errors_are_value_errors():
    assert issubclass(HapstabError, ValueError)
    with pytest.raises(ValueError):
        h.Device("heavy", 1.0)


@pytest.mark.parametrize("period", [0.0, -1e-3, math.nan, math.inf])
def test_loop_rejects_bad_period(period):
    with pytest.raises(ModelError, match="period"):
        h.paper_hve(period=period)


@pytest.mark.parametrize("delay", [1.5, -1, math.nan, "2"])
def test_loop_rejects_non_integer_delay(delay):
    with pytest.raises(ModelError, match="delay_samples"):
        h.paper_hve(delay_samples=delay)


def test_integral_float_delay_is_accepted():
    assert h.paper_hve(delay_samples=3.0).delay_samples == 3


def test_loops_are_frozen():
    loop = h.paper_hve()
    with pytest.raises(dataclasses.FrozenInstanceError):
        loop.period = 2e-3  # type: ignore[misc]


@pytest.mark.parametrize("spec,mass,damping,stiffness", [
    ("none", 0, 0, 0), ("spring:1", 0, 0, 1), ("msd:0.2,3,400", 0.2, 3, 400),
    (" Spring:2.5 ", 0, 0, 2.5)])
def test_parse_impedance(spec, mass, damping, stiffness):
    z = h.parse_impedance(spec)
    assert (z.mass, z.damping, z.stiffness) == pytest.approx((mass, damping, stiffness))


@pytest.mark.parametrize("spec", ["spring", "spring:abc", "msd:1,2", "msd:1,2,3,4", "tf:1", "spring:-1",
                                  "spring:nan"])
def test_parse_impedance_rejects_malformed(spec):
    with pytest.raises(ModelError, match=r"--operator = .*allowed: none, spring:k, msd:m,b,k"):
        h.parse_impedance(spec, "--operator")


def test_general_impedance_decomposes_exactly():
    # Z(s) = 0.3 s + 2 + 50/s + 4/(s + 7): a mass, a damper, a spring and a lag
    num = np.polyadd(np.polymul([0.3, 2.0, 50.0], [1.0, 7.0]), [4.0, 0.0])
    den = np.polymul([1.0, 0.0], [1.0, 7.0])
    z = h.Impedance(tuple(num), tuple(den))
    assert (z.mass, z.damping, z.stiffness) == pytest.approx((0.3, 2.0, 50.0), rel=1e-12)
    A, B, C = z.state_space()
    for s in (0.5j, 3.0 + 1j, 40j):
        rest = (C @ np.linalg.solve(s * np.eye(A.shape[0]) - A, B))[0, 0]
        assert z.mass * s + z.damping + z.stiffness / s + rest == pytest.approx(z(s), rel=1e-12)


@pytest.mark.parametrize("num,den", [((1.0, 0, 0, 0), (1.0,)), ((1.0,), (1.0, 0, 0))])
def test_impedance_rejects_improper_or_double_integrator(num, den):
    with pytest.raises(ModelError):
        h.Impedance(num, den)


def test_python_control_transfer_function_is_accepted():
    control = pytest.importorskip("control")
    tf = control.tf([0.2, 3.0, 400.0], [1.0, 0.0])
    z = h.Impedance.from_any(tf)
    assert (z.mass, z.damping, z.stiffness) == pytest.approx((0.2, 3.0, 400.0))
    with pytest.raises(ModelError, match="continuous"):
        h.Impedance.from_any(control.tf([1.0], [1.0, 0.5], 1e-3))


def test_spring_damper_transfer_is_eq_23():
    T, K, B = 1e-3, 120.0, 0.4
    num, den = h.SpringDamper(K, B).transfer(T)
    z = 0.3 + 0.9j
    assert np.polyval(num, z) / np.polyval(den, z) == pytest.approx(K + B * (z - 1) / (T * z))


@pytest.mark.parametrize("B", [-0.5, -1e-9, -30.0])
def test_spring_damper_accepts_negative_virtual_damping(B):
    # B < 0 is used in practice (to cancel device damping or friction): accepted as given
    c = h.SpringDamper(10.0, B)
    assert c.damping == B
    num, den = c.transfer(1e-3)
    z = 0.2 - 0.7j
    assert np.polyval(num, z) / np.polyval(den, z) == pytest.approx(10.0 + B * (z - 1) / (1e-3 * z))


@pytest.mark.parametrize("B", [math.nan, math.inf, -math.inf, "soft"])
def test_spring_damper_rejects_non_finite_virtual_damping(B):
    with pytest.raises(ModelError, match="virtual damping"):
        h.SpringDamper(10.0, B)


def test_spring_damper_still_rejects_negative_stiffness():
    with pytest.raises(ModelError, match=r"stiffness = -1.0: must be >= 0"):
        h.SpringDamper(-1.0, -0.1)


def test_discrete_controller_must_be_proper():
    with pytest.raises(ModelError, match="proper"):
        h.DiscreteController((1.0, 0.0, 1.0), (1.0, 0.5))


def test_with_stiffness_keeps_ratio_for_teleoperation():
    loop = h.paper_peb().replace(slave_controller=h.SpringDamper(20.0))
    new = loop.with_stiffness(5.0)
    assert new.master_controller.stiffness == 5.0
    assert new.slave_controller.stiffness == pytest.approx(10.0)


def test_critical_stiffness_needs_no_dummy_stiffness():
    # issue #12: a loop for K_max needed SpringDamper(stiffness=...) that was then ignored
    import hapstab as h

    bare = h.HapticLoop(h.Device(0.15, 0.1), operator=h.spring(1.0), delay_samples=10)
    dummy = bare.replace(controller=h.SpringDamper(123.0))
    assert h.critical_stiffness(bare).critical_stiffness == \
        h.critical_stiffness(dummy).critical_stiffness
    peb = h.TeleoperationLoop(h.Device(0.015, 0.02), h.Device(0.015, 0.02), delay_samples=4)
    assert h.critical_stiffness(peb).critical_stiffness > 0
    assert h.SpringDamper(damping=0.5).stiffness == 0.0


def test_loops_show_in_a_notebook_and_print_cleanly():
    # issue #12: reprs like rest_num=(np.float64(0.0),) and no _repr_html_ for loops
    import hapstab as h

    for loop in (h.paper_hve(), h.paper_peb()):
        assert "np.float64" not in repr(loop) and "rest_num" not in repr(loop)
        page = loop._repr_html_()
        assert page.startswith("<table><caption>") and "period" in page and "0.001 s" in page
    assert "device mass</th><td style='text-align:left'>0.15 kg" in h.paper_hve()._repr_html_()
