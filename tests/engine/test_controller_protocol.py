"""Every controller class answers the protocol the engine and the analyses ask
(models/protocol.py), and its answers agree with its own transfer function."""

import numpy as np
import pytest

from hapstab.errors import ModelError
from hapstab.models import (
    AffineController,
    DiscreteController,
    FilteredSpringDamper,
    SpringDamper,
)
from hapstab.models.controllers import has_stiffness
from hapstab.models.protocol import ANALYSES, ControllerProtocol

T = 1e-3                                   # s: the paper's 1 kHz loop
THETA = np.array([0.01, 0.3, 1.0, 2.5, np.pi])
#: relative agreement of two evaluations of one rational function in double precision
#: (a few hundred ulps: the realisation's (zI - A)^-1 against Horner's rule)
AGREE = 1e-9

CONTROLLERS = {
    "spring-damper": SpringDamper(40.0, 0.5),
    "spring": SpringDamper(40.0, 0.0),
    "lowpass": FilteredSpringDamper(40.0, 0.5, "lowpass:200"),
    "average": FilteredSpringDamper(40.0, 0.5, "average:4"),
    "filter-no-damper": FilteredSpringDamper(40.0, 0.0, "lowpass:200"),
    "affine": AffineController(40.0, (1.0, 0.2), (1.0, -0.5), (0.3, -0.3), (1.0, 0.1)),
    "discrete": DiscreteController((2.0, -1.0), (1.0, -0.4)),
}
#: which analyses each admits: eq. (23) itself admits all; K P + Q only the K search
ADMITS = {
    "spring-damper": set(ANALYSES), "spring": set(ANALYSES),
    "lowpass": {"stiffness"}, "average": {"stiffness"},
    "filter-no-damper": {"stiffness", "packet-loss"},
    "affine": {"stiffness"}, "discrete": set(),
}


def _tf(c, theta):
    z = np.exp(1j * theta)
    num, den = c.transfer(T)
    return np.polyval(num, z) / np.polyval(den, z)


@pytest.mark.parametrize("name", CONTROLLERS)
def test_each_controller_answers_the_protocol(name):
    c = CONTROLLERS[name]
    assert isinstance(c, ControllerProtocol)
    assert {a for a in ANALYSES if c.admits(a)} == ADMITS[name]
    assert has_stiffness(c) == c.admits("stiffness")
    with pytest.raises(ModelError, match="allowed: stiffness"):
        c.admits("stifness")


@pytest.mark.parametrize("name", CONTROLLERS)
def test_the_response_is_the_transfer_function_and_splits_into_its_parts(name):
    c = CONTROLLERS[name]
    h = c.response(THETA, T)
    assert np.allclose(h, _tf(c, THETA), rtol=AGREE, atol=0)
    if c.admits("stiffness"):
        K = c.stiffness
        parts = K * c.response(THETA, T, "K", 1.0) + c.response(THETA, T, "B", 1.0)
        assert np.allclose(parts, h, rtol=AGREE, atol=0)


@pytest.mark.parametrize("name", CONTROLLERS)
def test_the_realisation_has_the_transfer_function(name):
    c = CONTROLLERS[name]
    periods = np.array([T, 2 * T])
    Ah, Bh, Ch, D, DK, ChK = c.realisation(periods)
    K = c.stiffness if c.admits("stiffness") else 0.0
    for p, Tp in enumerate(periods):
        z = np.exp(1j * THETA)
        num, den = c.transfer(float(Tp))
        want = np.polyval(num, z) / np.polyval(den, z)
        n = Ah.shape[1]
        got = np.array([(Ch[p] + K * ChK[p]) @ np.linalg.solve(zz * np.eye(n) - Ah[p], Bh[p])
                        if n else np.zeros((1, 1)) for zz in z]).ravel() + D[p] + K * DK[p]
        assert np.allclose(got, want, rtol=AGREE, atol=0)


@pytest.mark.parametrize("name", CONTROLLERS)
def test_gains_and_affine_parts_say_what_the_controller_is(name):
    c = CONTROLLERS[name]
    gains, parts = c.gains(), c.affine_parts()
    if isinstance(c, (SpringDamper, FilteredSpringDamper)):
        assert gains == (c.stiffness, c.damping) and parts is None
    elif isinstance(c, AffineController):
        assert gains is None and all(np.array_equal(a, b) for a, b in zip(parts, c.parts(), strict=True))
    else:
        assert gains is None and parts is None
