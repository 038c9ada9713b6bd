"""python-control in and out (issue 29, item 3): a continuous TransferFunction Z(s) as an
impedance, a discrete one (dt = T) as a controller, and ``to_control(loop)``: the exact
sampled closed loop as a StateSpace with dt = T, checked against an independent
simulation of the same loop (hapstab.simulate) and the spectral radius of stability()."""

import numpy as np
import pytest

import hapstab
from hapstab import (
    Device,
    DiscreteController,
    HapticLoop,
    ModelError,
    SpringDamper,
    TeleoperationLoop,
    mass_spring_damper,
    spring,
)

control = pytest.importorskip("control")


def test_issue_acceptance_operator_transfer_function():
    z = control.tf([0.5, 5, 500], [1, 0])
    a = HapticLoop(Device(0.3, 0.5), operator=z, period=1e-3, delay_samples=20)
    b = HapticLoop(Device(0.3, 0.5), operator=mass_spring_damper(0.5, 5, 500), period=1e-3,
                   delay_samples=20)
    ka, kb = hapstab.critical_stiffness(a), hapstab.critical_stiffness(b)
    assert ka.critical_stiffness == kb.critical_stiffness      # the same model, bit for bit
    lp = a.with_stiffness(0.8 * ka.critical_stiffness)
    ss = hapstab.to_control(lp)
    assert ss.dt == 1e-3
    rho = np.max(np.abs(np.linalg.eigvals(ss.A)))
    # the dominant pole polished by stability() against numpy's eigvals: 1e-12
    assert abs(rho - hapstab.stability(lp).spectral_radius) < 1e-12
    assert ss.ninputs == 1 and ss.noutputs == 2


def test_environment_and_state_space_impedances():
    env = control.ss(control.tf([200.0], [1, 0]))       # a spring as a StateSpace
    lp = TeleoperationLoop(Device(0.1, 0.2), Device(0.1, 0.2), SpringDamper(50, 0.1),
                           SpringDamper(50, 0.1), operator=control.tf([1.0], [1, 0]),
                           environment=env, period=1e-3, delay_samples=3)
    ref = lp.replace(operator=spring(1.0), environment=spring(200.0))
    assert hapstab.stability(lp).spectral_radius == pytest.approx(
        hapstab.stability(ref).spectral_radius, rel=1e-12)
    ss = hapstab.to_control(lp)
    assert ss.ninputs == 2 and ss.noutputs == 4 and ss.dt == 1e-3


def test_discrete_controller_and_the_impulse_response():
    T = 1e-3
    K, B = 300.0, 0.5
    H = control.tf([K + B / T, -B / T], [1, 0], T)     # K + B (z - 1)/(T z)
    lp = HapticLoop(Device(0.3, 0.5), controller=H, operator=spring(1.0), period=T,
                    delay_samples=2)
    assert isinstance(lp.controller, DiscreteController)
    ref = lp.replace(controller=SpringDamper(K, B))
    assert hapstab.stability(lp).spectral_radius == pytest.approx(
        hapstab.stability(ref).spectral_radius, rel=1e-9)
    # python-control's own simulation of to_control against hapstab's simulator: a force
    # step on the device, positions at the samples (1e-9 m of 1e-3 m: two exact ZOH
    # models summed in different orders over 200 steps)
    ss = hapstab.to_control(ref)
    t = np.arange(200) * T
    y = control.forced_response(ss, t, np.ones_like(t)).outputs[0]
    sim = hapstab.simulate(ref, duration=t[-1], force=1.0)
    assert np.allclose(y, sim.position[: t.size, 0], atol=1e-9)


def test_refusals():
    with pytest.raises(ModelError, match="continuous-time"):
        HapticLoop(Device(0.3), operator=control.tf([1.0], [1, 0], 1e-3))
    with pytest.raises(ModelError, match="differs from the loop's period"):
        HapticLoop(Device(0.3), controller=control.tf([1.0], [1], 2e-3), period=1e-3)
    with pytest.raises(ModelError, match="continuous"):
        HapticLoop(Device(0.3), controller=control.tf([1.0], [1]), period=1e-3)
    mimo = control.ss(np.eye(2) * -1, np.eye(2), np.eye(2), np.zeros((2, 2)))
    with pytest.raises(ModelError, match="single-input single-output"):
        HapticLoop(Device(0.3), operator=mimo)
