"""Issue #11: the Python API names a wrong argument itself -- a TypeError (that is also a
HapstabError) for a wrong type, never a bare TypeError/ValueError from numpy or float() --
and shows no numpy warnings for unusual numeric types."""

import warnings
from fractions import Fraction

import numpy as np
import pytest

import hapstab as h
from hapstab.errors import ArgumentTypeError, HapstabError, ModelError

LOOP = h.paper_hve().with_stiffness(10.0)


@pytest.mark.parametrize("call,needle", [
    (lambda: h.simulate(LOOP, 0.1, initial_position=1 + 2j), "initial_position = (1+2j)"),
    (lambda: h.simulate(LOOP, 0.1, initial_position="a"), "initial_position = 'a'"),
    (lambda: h.simulate(LOOP, 0.1, initial_velocity=[[1], [2, 3]]), "initial_velocity = "),
    (lambda: h.simulate(LOOP, 0.1, initial_state="abc"), "initial_state = 'abc'"),
    (lambda: h.simulate(LOOP, "1"), "duration = '1'"),
    (lambda: h.critical_stiffness_simulation(LOOP, rtol="0.1"), "rtol = '0.1'"),
    (lambda: h.critical_stiffness_simulation(LOOP, ratio=[2]), "ratio = [2]"),
    (lambda: h.best_damping(LOOP, max_seconds=[0.1]), "max_seconds = [0.1]"),
    (lambda: h.Device(mass="0.1", damping=1), "mass = '0.1'"),
    (lambda: LOOP.with_stiffness(1 + 2j), "stiffness = (1+2j)"),
    (lambda: h.positive_real(h.RationalMatrix.scalar([1], [1]), rtol="x"), "rtol = 'x'"),
])
def test_a_wrong_type_is_a_type_error_naming_the_argument(call, needle):
    with pytest.raises(ArgumentTypeError) as e:
        call()
    assert isinstance(e.value, TypeError) and isinstance(e.value, HapstabError)
    assert str(e.value).startswith(needle), str(e.value)


def test_model_type_errors_are_still_model_errors():
    with pytest.raises(ModelError):
        h.Device(mass="0.1", damping=1)


@pytest.mark.parametrize("method,option", [("exact", "rtol"), ("circle", "approx"),
                                           ("colgate", "sector")])
def test_an_option_a_method_does_not_take_is_named_with_the_ones_it_does(method, option):
    with pytest.raises(ArgumentTypeError, match=f"{option} = 1: not an option of method "
                                                f"'{method}'; it takes: "):
        h.critical_stiffness(h.paper_hve(), method, **{option: 1})
    with pytest.raises(ArgumentTypeError, match=f"{option} = 1: not an option"):
        h.boundary(h.paper_hve(), [1e-3], method=method, **{option: 1})


@pytest.mark.parametrize("value", [np.uint8(200), np.int64(2**40), np.float32(1e3),
                                   np.longdouble("1e3"), np.array(5.0)])
def test_numpy_scalars_are_accepted_without_warnings(value):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert LOOP.with_stiffness(value).controller.stiffness == float(value)


def test_an_overflowing_longdouble_is_a_model_error_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ModelError, match=r"stiffness = .*must be finite"):
            LOOP.with_stiffness(np.longdouble("1e4000"))


@pytest.mark.parametrize("call,needle", [
    (lambda: h.critical_stiffness(LOOP, method=["exact"]), "method = ['exact']: must be a string"),
    (lambda: h.boundary(LOOP, "0.001"), "periods = '0.001'"),
    (lambda: h.boundary(LOOP, b"1"), "periods = b'1'"),
    (lambda: h.boundary(LOOP, [1e-3 + 1j]), "periods = "),
    (lambda: h.boundary(LOOP, True), "periods = True"),
    (lambda: h.stability_region(LOOP, (0, 20), (0, 1), 8, overlays=3), "overlays = 3"),
    (lambda: h.simulate(LOOP, 0.1, rest_position="abc"), "rest_position = 'abc'"),
    (lambda: h.simulate(LOOP, 0.1, rest_position=1 + 2j), "rest_position = (1+2j)"),
    (lambda: h.critical_stiffness_simulation(LOOP, seed="abc"), "seed = 'abc'"),
    (lambda: h.critical_stiffness_simulation(LOOP, seed=-1), "seed = -1"),
])
def test_more_wrong_types_are_type_errors_naming_the_argument(call, needle):
    with pytest.raises(ArgumentTypeError) as e:
        call()
    assert str(e.value).startswith(needle), str(e.value)


@pytest.mark.parametrize("call", [
    lambda: h.circle_test(LOOP, scaling=np.array(["auto"])),
    lambda: h.simulate(LOOP, 0.1, quantizer=np.array(["floor"])),
    lambda: h.boundary(LOOP, [1e-3], axis=np.array(["rate"])),
    lambda: h.methods_for(np.array(["hve", "peb"])),
    lambda: h.critical_stiffness_simulation(LOOP, rtol=1e-17),    # hung: neighbouring doubles
])
def test_array_choices_and_a_tolerance_below_rounding_are_refused_not_crashed(call):
    with pytest.raises(HapstabError):
        call()


def test_a_budget_beyond_double_precision_means_no_limit():
    assert h.stability(LOOP, max_memory=10**400, max_seconds=10**400).verdict == "stable"


HVE2 = h.paper_hve(delay_samples=2)


G1 = h.RationalMatrix([[[1.0, 0.2]]], [[[1.0, -0.5]]])
HLK = h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(100.0, 0.05), period=1e-3,
                   delay_samples=2)


# the helper's fuzz, second round: each was silently misread (a complex value's imaginary
# part dropped, a switch read by truthiness, -10**400 s meaning no limit) or a bare exception
MISREAD = [
    (lambda: h.stability(HVE2, max_seconds=-10 ** 400), "max_seconds = -1000"),
    (lambda: h.critical_stiffness(HVE2, certify=None), "certify = None"),
    (lambda: h.critical_stiffness(HVE2, certify="False"), "certify = 'False'"),
    (lambda: h.stability(HVE2, certify=2), "certify = 2"),
    (lambda: h.stability_region(HVE2, K=(0, 20), B=(0, 1), resolution=4, certify=None),
     "certify = None"),
    (lambda: h.margins(HVE2, max_seconds=-1.0), "max_seconds = -1.0"),
    (lambda: h.margins(HVE2, view=None), "view = None"),
    (lambda: h.simulate(HLK, 0.05, force=np.full(50, 1 + 5j)), "force = array("),
    (lambda: h.circle_criterion(G1, sector=np.complex128(50 + 7j)), "sector = "),
    (lambda: h.circle_criterion(G1, sector=Fraction(10 ** 400, 3)), "sector = Fraction"),
    (lambda: h.simulate(HVE2, 0.1, network=dict(jitter=(1, 3), loss=complex(0.1, 0), seed=3)),
     "network loss = (0.1+0j)"),
    (lambda: h.simulate(HVE2, 0.1, network=dict(jitter=(1, 3), loss=10 ** 400, seed=3)),
     "network loss = 1000"),
    (lambda: h.gil2004(h.HapticLoop(h.Device(0.15, 1e308), h.SpringDamper(9.0, 0.0),
                                    period=1e-3)), "method = 'gil2004': b T / m"),
    (lambda: h.stability_region(HVE2, K={20.0, 0.0}, B=(0, 1), resolution=4), "K = {"),
    (lambda: h.circle_criterion(G1, sector=2.0, period=5e-324), "period = 4.94066e-324"),
    (lambda: h.critical_stiffness(h.HapticLoop(h.Device(0.3, 0.5), h.SpringDamper(9.0, 0.0),
                                               operator=h.mass_spring_damper(1e308, 5.0, 500.0),
                                               period=1e-3, delay_samples=20)), "device mass"),
    (lambda: h.jitter(h.paper_hve(stiffness=50.0), delay_samples={2, 4}), "delay_samples = {"),
    (lambda: h.operator_box("arm-grasp", stiffness={67.5, 100.0}), "operator stiffness = {"),
    (lambda: h.identify({"time_s": [0.0, 1e-3], "force_N": [1 + 3j, 1.0],
                         "position_m": [0.0, 0.0]}), "log['force_N'] = "),
]


# a helper's fuzz of the API with unusual numeric types (seed 20261207): each was a bare
# exception (TypeError, ValueError, OverflowError) or a numpy warning
@pytest.mark.parametrize("call,needle", [
    (lambda: h.jitter(h.paper_hve(stiffness=50.0), delay_samples=(2, 4), max_length=4,
                      budget=float("inf")), "budget = inf"),
    (lambda: h.jitter(h.paper_hve(stiffness=50.0), delay_samples=(2, 4), max_length=4,
                      budget=300 + 0j), "budget = (300+0j)"),
    (lambda: h.jitter(h.paper_hve(stiffness=50.0), delay_s=[0.002, 0.004, 0.006]),
     "delay_s = [0.002, 0.004, 0.006]"),
    (lambda: h.margins(HVE2, step_samples=np.array([0.5])), "step_samples = [0.5]"),
    (lambda: h.frequency_view(HVE2, frequencies_hz={0.5, 5.0}), "frequencies_hz = {"),
    (lambda: h.frequency_view(HVE2, frequencies_hz=[0.5, np.nan]), "frequencies_hz = [0.5, nan]"),
    (lambda: h.Impedance(np.array([5.0, 500.0], dtype=complex), (1.0, 0.0)),
     "impedance numerator = array("),
    (lambda: h.critical_stiffness(h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(9.0, 1e308),
                                               period=1e-3)), "device virtual damping = 1e+308"),
    *MISREAD,
])
def test_unusual_values_are_refused_naming_the_argument(call, needle):
    """A bare exception or numpy warning before, or silently misread (MISREAD): a
    complex value's imaginary part dropped, a switch read by truthiness, -10**400 s as
    no limit."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(HapstabError) as e:
            call()
    assert str(e.value).startswith(needle), str(e.value)


def test_numpy_widths_do_not_reach_the_arithmetic():
    """An int8 window overflowed (2 * 100), a float32 ratio made the search's bracket in
    single precision (K_max 39.99168743 against 39.99168479 with 4.0), a uint64 dense
    overflowed the budget's sums: each now gives the Python number's answer."""
    ref = h.critical_stiffness_simulation(HVE2, n_samples=400, window=100, rtol=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for kw in ({"window": np.int8(100)}, {"ratio": np.float32(4.0)},
                   {"n_samples": np.int16(400)}):
            got = h.critical_stiffness_simulation(HVE2, **{"n_samples": 400, "window": 100,
                                                           "rtol": 1e-3, **kw})
            assert got.critical_stiffness == ref.critical_stiffness, kw
        with pytest.raises(HapstabError):       # refused by the budget, not an overflow
            h.simulate(LOOP, 0.02, force=1.0, dense=np.uint64(2 ** 64 - 1))


def test_numpy_flags_and_widths_are_their_python_values():
    assert h.critical_stiffness(HVE2, certify=np.bool_(False)).critical_stiffness == \
        h.critical_stiffness(HVE2, certify=False).critical_stiffness
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert h.positive_real(G1, grid=np.int8(100)).positive_real == \
            h.positive_real(G1, grid=100).positive_real
        box = h.operator_box("arm-grasp", stiffness=np.array([67.5, 100.0]))
    assert box.stiffness == (67.5, 100.0) and "(modified)" in box.label
    with warnings.catch_warnings():     # a Fraction force is the number it stands for
        warnings.simplefilter("error")
        a = h.simulate(HLK, 0.05, force=Fraction(1)).to_dict()
        light = h.HapticLoop(h.Device(1e-300, 0.1), h.SpringDamper(100.0, 0.05), period=1e-3)
        h.simulate(light, 0.05, force=1.0)          # a 1e-300 kg device: no warning
        big = h.simulate(HLK, 0.05, initial_velocity=-1e308)      # nor a 1e308 state
        assert big.verdict.verdict == h.simulate(HLK, 0.05, initial_velocity=-1.0).verdict.verdict
    assert a == h.simulate(HLK, 0.05, force=1.0).to_dict()
