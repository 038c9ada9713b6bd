"""Passivity with Coulomb friction and encoder quantisation (Abbott & Okamura 2005),
checked against energies measured on trajectories, not against its own formula: the hand
moves the device through a closed, sample-aligned path (constant velocity within each
sample, the adversary's best: it dissipates least for a given displacement), and the
energy it puts in is summed term by term,

    E = sum_k [ b d_k^2 / T + f_c |d_k| + K q(x_k) d_k ],   d_k = x_{k+1} - x_k,

with q the simulator's own encoder (:func:`hapstab.simulation.run.quantize`). The device
side is passive iff no closed path has E < 0 (else repeating it extracts energy without
bound). Above the limit a construction must find E < 0; below it, no path may."""

import math

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.analysis.conditions.passivity import critical_stiffness_passivity
from hapstab.analysis.nonlinear.nonlinear_passivity import abbott_okamura, nonlinear_passivity
from hapstab.cli.main import cli
from hapstab.errors import AnalysisError, ModelError
from hapstab.simulation.run import quantize


def energy_in(path, K, b, fc, T, delta, quantizer):
    """Energy the hand puts into device + sampled quantised spring over a closed path."""
    x = np.asarray(path, float)
    d = np.diff(x)
    q = quantize(x[:-1], delta, quantizer) if delta else x[:-1]
    return float(np.sum(b * d * d / T + fc * np.abs(d) + K * q * d))


def loop_of(b, T, m=0.2, B=0.0, n=0, op=None):
    return h.HapticLoop(h.Device(m, b), h.SpringDamper(1.0, B), operator=op, period=T,
                        delay_samples=n)


def test_hand_worked_values():
    # m = 0.15 kg, b = 0.1 N*s/m, T = 1 ms: 2b/T = 200 N/m
    lp = h.paper_hve()
    assert abbott_okamura(lp, coulomb_friction_N=0.005, resolution_m=1e-4).critical_stiffness == 100.0
    assert abbott_okamura(lp, coulomb_friction_N=0.005, resolution_m=1e-5).critical_stiffness == 200.0
    r = abbott_okamura(lp, coulomb_friction_N=0.0, resolution_m=1e-4)
    assert r.critical_stiffness == 0.0 and "no K > 0 is passive" in r.reason
    r = abbott_okamura(lp.replace(device=h.Device(0.15, 0.1, coulomb_friction=0.02)),
                       resolution_m=1e-4)    # the device's own friction: 2 * 0.02 / 1e-4 = 400
    assert r.critical_stiffness == 200.0 and r.details["binding"] == "sampling"
    assert r.details["quantization_limit"] == 400.0


@pytest.mark.parametrize("seed", range(6))
def test_friction_and_quantisation_free_limit_is_todays_exactly(seed):
    rng = np.random.default_rng(seed)
    op = [None, h.spring(3.0), h.mass_spring_damper(0.1, 1.0, 50.0)][seed % 3]
    lp = loop_of(10 ** rng.uniform(-2, 0), 10 ** rng.uniform(-4, -2.5), B=rng.uniform(-0.005, 0.3),
                 n=int(rng.integers(0, 12)), op=op)
    today = critical_stiffness_passivity(lp).critical_stiffness
    assert abbott_okamura(lp).critical_stiffness == today
    assert abbott_okamura(lp, coulomb_friction_N=0.0, resolution_m=0.0).critical_stiffness == today
    # friction alone does not move it (Delta = 0): linear energy ~ l^2 outgrows f_c ~ l
    assert abbott_okamura(lp, coulomb_friction_N=1.0).critical_stiffness == today


def _line_chatter(K, b, fc, T, delta, quantizer):
    """Back and forth across one encoder line, one sample each way, starting just below it:
    each crossing is sensed late and gives K*Delta*d; friction takes 2 f_c d."""
    line = delta if quantizer == "floor" else delta / 2
    d = min(0.01 * delta, 0.005 * fc * T / b if b else delta)   # viscous: 1/4 of the 2 % margin
    x0 = line - 1e-3 * d                   # just below the line (a thousandth of the stroke)
    return [x0, x0 + d] * 20 + [x0]


def _fast_swing(a):
    """A two-sample oscillation of amplitude a (the Nyquist rate), where sampling binds."""
    return [a, -a] * 20 + [a]


@pytest.mark.parametrize("seed", range(12))
def test_energy_is_extracted_just_above_the_limit_and_never_below(seed):
    rng = np.random.default_rng(100 + seed)
    b, T = 10 ** rng.uniform(-2, 0.5), 10 ** rng.uniform(-4, -2.5)
    fc, delta = 10 ** rng.uniform(-3, -0.5), 10 ** rng.uniform(-6, -3)
    quantizer = ["floor", "nearest"][seed % 2]
    res = abbott_okamura(loop_of(b, T), coulomb_friction_N=fc, resolution_m=delta)
    K = res.critical_stiffness
    # above: the binding mode's construction extracts energy
    Ku = 1.02 * K
    big = 1e4 * delta + 10 * fc / (Ku - 2 * b / T)      # where f_c is outgrown
    path = (_line_chatter(Ku, b, fc, T, delta, quantizer) if res.details["binding"] == "quantization"
            else _fast_swing(big))
    assert energy_in(path, Ku, b, fc, T, delta, quantizer) < 0
    # below: no path extracts energy (both constructions, and random closed paths at every
    # scale from 1e-3 to 1e3 steps; rounding allowance 1e-12 of the path's dissipation)
    Kl = 0.98 * K
    paths = [_line_chatter(Kl, b, fc, T, delta, quantizer), _fast_swing(big)]
    for scale in 10.0 ** np.arange(-3, 4):
        for _ in range(20):
            p = rng.uniform(-1, 1, int(rng.integers(2, 30))) * scale * delta
            paths.append([*p, p[0]])
    for p in paths:
        E = energy_in(p, Kl, b, fc, T, delta, quantizer)
        diss = energy_in(p, 0.0, b, fc, T, delta, quantizer)
        assert E >= -1e-12 * diss, (p[:4], E)    # rounding of the sum only


def test_both_modes_are_needed_independently():
    # plenty of viscous damping does not cover quantisation, plenty of friction not sampling
    b, T, delta = 5.0, 1e-3, 1e-4
    fc = 0.001                                   # 2 fc / delta = 20 N/m << 2 b / T = 1e4 N/m
    K = 1.05 * 2 * fc / delta
    assert energy_in(_line_chatter(K, b, fc, T, delta, "floor"), K, b, fc, T, delta, "floor") < 0
    b, fc = 0.01, 10.0                           # 2 b / T = 20 N/m << 2 fc / delta = 2e5 N/m
    K = 1.05 * 2 * b / T
    assert energy_in(_fast_swing(10 * fc / (K - 2 * b / T)), K, b, fc, T, delta, "floor") < 0


def test_verdict_at_a_stiffness():
    lp = h.paper_hve().with_stiffness(150.0)
    r = nonlinear_passivity(lp, coulomb_friction_N=0.005, resolution_m=1e-4)
    assert not r.passive and r.failed_condition == "abbott-okamura"
    assert math.isclose(r.quantization_margin_N, 0.005 - 150 * 1e-4 / 2, rel_tol=1e-12)
    r = nonlinear_passivity(lp.with_stiffness(99.0), coulomb_friction_N=0.005, resolution_m=1e-4)
    assert r.passive and r.failed_condition is None
    r = nonlinear_passivity(lp.with_stiffness(250.0), coulomb_friction_N=0.005, resolution_m=1e-4)
    assert r.failed_condition == "colgate-schenkel+abbott-okamura"
    lin = h.sampled_passivity(lp.replace(delay_samples=3).with_stiffness(5.0))
    r = nonlinear_passivity(lp.replace(delay_samples=3).with_stiffness(5.0))
    assert (r.passive, r.margin) == (lin.passive, lin.margin)


def test_refusals_name_the_parameter():
    with pytest.raises(AnalysisError, match="B = 0 and no delay"):
        abbott_okamura(h.paper_hve(1e-3, 2), resolution_m=1e-4)
    with pytest.raises(AnalysisError, match="B = 0"):
        abbott_okamura(h.paper_hve().with_controllers(h.SpringDamper(0, 0.05)), resolution_m=1e-4)
    with pytest.raises(AnalysisError, match="hve"):
        abbott_okamura(h.paper_peb(), resolution_m=1e-4)
    with pytest.raises(AnalysisError, match="SpringDamper"):
        abbott_okamura(h.paper_hve().with_controllers(h.DiscreteController([1.0], [1.0])))
    with pytest.raises(ModelError, match="resolution_m"):
        abbott_okamura(h.paper_hve(), resolution_m=-1e-4)
    with pytest.raises(ModelError, match="coulomb_friction_N"):
        abbott_okamura(h.paper_hve(), coulomb_friction_N=float("nan"))
    with pytest.raises(AnalysisError, match="hve"):
        h.audit(h.paper_peb(), resolution_m=1e-4)


def test_audit_row_only_when_asked():
    plain = h.audit(h.paper_hve())
    assert "abbott-okamura" not in [r.key for r in plain.rows]
    a = h.audit(h.paper_hve(), coulomb_friction_N=0.005, resolution_m=1e-4)
    keys = [r.key for r in a.rows]
    assert keys[:-1] == [*[r.key for r in plain.rows][:-1], "abbott-okamura"]
    row = a.rows[keys.index("abbott-okamura")]
    assert row.critical_stiffness == 100.0 and row.claims == "passivity" and row.flag is None
    assert [r.critical_stiffness for r in a.rows if r.key != "abbott-okamura"] == \
        [r.critical_stiffness for r in plain.rows]


def test_cli_passivity_and_audit():
    import json

    r = CliRunner().invoke(cli, ["passivity", "hve", "-K", "150", "--friction", "0.005",
                                 "--resolution", "1e-4", "--json"])
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["verdict"] == "not passive" and d["failed_condition"] == "abbott-okamura"
    assert d["nonlinear"]["critical_stiffness"] == 100.0 and "friction_note" not in d
    r = CliRunner().invoke(cli, ["passivity", "hve", "-K", "150", "--json"])
    assert json.loads(r.stdout)["verdict"] == "passive" and "nonlinear" not in json.loads(r.stdout)
    r = CliRunner().invoke(cli, ["audit", "hve", "--friction", "0.005", "--resolution", "1e-4",
                                 "--json"])
    rows = {x["key"]: x for x in json.loads(r.stdout)["rows"]}
    assert rows["abbott-okamura"]["critical_stiffness"] == 100.0
    r = CliRunner().invoke(cli, ["passivity", "hve", "-K", "5", "-n", "2", "--resolution", "1e-4"])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and "no delay" in r.stderr
