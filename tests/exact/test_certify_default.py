"""The ball-arithmetic proof is the default (issue 26): the single call, the batched
paths and the CLI give the proved K_max unless ``certify=False`` / ``--no-certify``;
the proved K_max is the safe end of a 2^-40 window, never above the float search's.

References: the exact core (``exact_critical_stiffness``) and its ball proof
(:mod:`hapstab.analysis.exact.proved`), re-checked by ``verify_certificate``; the
passivity bound (Colgate and Schenkel 1997) as an independent floor for K_max.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.analysis.exact.core import exact_critical_stiffness
from hapstab.analysis.exact.many import critical_stiffness_many
from hapstab.cli.main import cli
from hapstab.errors import ArgumentTypeError

PROOF = "ball arithmetic (python-flint Arb)"
FLOAT = "float enclosures (not re-proved in ball arithmetic)"
# the proof's window: K_max is the lower end of an enclosure 2^-40 wide (relative)
WINDOW = 2.0 ** -40


def _hve(B, b=1.0, T=0.0078125, n=0):
    return h.HapticLoop(h.Device(1.0, b), h.SpringDamper(1.0, B), None, T, n)


def test_default_is_proved_and_below_the_float_search():
    loop = h.paper_hve(1e-3, 4)
    r, f = exact_critical_stiffness(loop), exact_critical_stiffness(loop, certify=False)
    assert r.details["proof"] == PROOF and r.certificate is not None
    assert f.details["proof"] == FLOAT and f.certificate is None
    assert r.critical_stiffness <= f.critical_stiffness
    assert f.critical_stiffness - r.critical_stiffness <= 4 * WINDOW * f.critical_stiffness
    assert h.verify_certificate(r.certificate).valid


@pytest.mark.parametrize("B", [-1.8792671916479198e-280, 1e-200, -1e-160])
def test_a_negligible_virtual_damping_does_not_set_the_base_point(B):
    # found by test_passivity: |B| = 1e-280 set K_0 = 1e-14 |B|/T, so close to K -> 0+
    # that the proof could not decide above it, and K_max came out 0 ("unstable for
    # every K > 0") though the passivity bound is 256 N/m. b + B = b to the last bit:
    # the loop is the B = 0 one
    r, r0 = exact_critical_stiffness(_hve(B)), exact_critical_stiffness(_hve(0.0))
    assert r.details["proof"] == PROOF
    assert r.details["base_point_N_per_m"] == r0.details["base_point_N_per_m"]
    assert r.critical_stiffness == pytest.approx(r0.critical_stiffness, rel=4 * WINDOW)
    assert r.critical_stiffness >= h.critical_stiffness(_hve(B), method="passivity"
                                                        ).critical_stiffness
    assert h.verify_certificate(r.certificate).valid


def test_a_negligible_teleoperation_damping_does_not_zero_kmax():
    # the PEB form of the same finding (test_passivity: B_m = 1.7e-168 beside b_m = 0.5)
    loop = h.TeleoperationLoop(h.Device(0.5, 0.5), h.Device(0.5, 0.5),
                               h.SpringDamper(1.0, 1.676359710156958e-168),
                               h.SpringDamper(1.0, 0.0), h.spring(1.0), h.spring(100.0),
                               1e-3, 1)
    r = exact_critical_stiffness(loop)
    r0 = exact_critical_stiffness(loop.replace(master_controller=h.SpringDamper(1.0, 0.0)))
    assert r.details["proof"] == PROOF
    assert r.details["base_point_N_per_m"] == r0.details["base_point_N_per_m"]
    assert r.critical_stiffness >= h.critical_stiffness(loop, method="passivity"
                                                        ).critical_stiffness > 0
    assert r.critical_stiffness <= exact_critical_stiffness(loop, certify=False
                                                            ).critical_stiffness


def test_an_undamped_loop_is_not_refused_as_heavy():
    # no damping and no termination spring: every dimensionless group is 0, which is
    # not a heavy device (its K scale is m/T^2's); the proof answers as the float does
    loop = h.HapticLoop(h.Device(0.15, 0.0), h.SpringDamper(1.0), None, 1e-3, 10)
    r, f = exact_critical_stiffness(loop), exact_critical_stiffness(loop, certify=False)
    assert r.critical_stiffness == f.critical_stiffness == 0.0


def test_the_batch_equals_the_single_call_either_way():
    loops = [h.paper_hve(T, n) for T in (5e-4, 1e-3) for n in (0, 3)] + [h.paper_peb(1e-3, 2)]
    for certify in (True, False):
        got = critical_stiffness_many(loops, certify=certify)
        for g, lp in zip(got, loops, strict=True):
            want = exact_critical_stiffness(lp, certify=certify)
            assert g.critical_stiffness == want.critical_stiffness
            assert g.details["proof"] == (PROOF if certify else FLOAT)
    with pytest.raises(ArgumentTypeError, match="certify = 'yes'"):
        critical_stiffness_many(loops, certify="yes")       # type: ignore[call-overload]


def test_boundary_is_proved_by_default():
    loop = h.paper_hve(1e-3, 2)
    T = [5e-4, 1e-3]
    got = h.boundary(loop, T, [2]).critical_stiffness[0]
    fast = h.boundary(loop, T, [2], certify=False).critical_stiffness[0]
    for t, k, kf in zip(T, got, fast, strict=True):
        at = loop.with_whole_delay(2, t)
        assert k == exact_critical_stiffness(at).critical_stiffness
        assert kf == exact_critical_stiffness(at, certify=False).critical_stiffness


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_cli_certify_is_the_default_and_no_certify_the_fast_path():
    proved, fast = _run("kmax", "hve", "--json"), _run("kmax", "hve", "--no-certify", "--json")
    assert proved.exit_code == 0 and fast.exit_code == 0, (proved.output, fast.output)
    dp, df = json.loads(proved.stdout), json.loads(fast.stdout)
    assert dp["proof"] == PROOF and df["proof"] == FLOAT
    assert dp["critical_stiffness"] <= df["critical_stiffness"]
    bad = _run("kmax", "hve", "--no-certify", "--certificate", "x.json")
    assert bad.exit_code != 0 and "--no-certify" in bad.output
    other = _run("kmax", "hve", "--method", "passivity", "--no-certify")
    assert other.exit_code != 0 and "--method exact only" in other.output
    assert _run("kmax", "hve", "--method", "passivity").exit_code == 0
