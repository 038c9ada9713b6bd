"""Bounded-impedance absolute stability (issue 13, item 1): Llewellyn's test when every
operator / environment is known to have at least some damping.

References: a closed form worked by hand at w = pi/T (below), the plain test at zero
bounds, and a seeded campaign of loops closed with terminations inside the bounds,
judged by the exact analysis.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
import lanes
from hapstab.analysis.teleoperation.twoport import critical_stiffness_llewellyn, llewellyn_test
from hapstab.cli.main import cli


def _different_channels(b=0.5):
    return h.TeleoperationLoop(h.Device(0.015, b), h.Device(0.015, b), h.SpringDamper(1.0, 0.05),
                               h.SpringDamper(1.0, 0.15), "spring:1", "spring:1", 1e-3, 0)


def test_zero_bounds_are_the_plain_test():
    lp = _different_channels()
    a = critical_stiffness_llewellyn(lp)
    b = critical_stiffness_llewellyn(lp, operator_damping_min=0.0, environment_damping_min=0)
    assert a.critical_stiffness == b.critical_stiffness


@pytest.mark.parametrize("b1, b2", [(0.5, 0.5), (1.0, 0.7), (0.2, 2.0), (0.0, 1.5)])
def test_the_bound_at_w_pi_over_T_matches_its_closed_form(b1, b2):
    """At z = -1 with n = 0 and the forward X = -T/2 (t = T/2), P is real:
    p11 = b_m + b1 - t C_m, p22 = b_s + b2 - t C_s, p12 = t C_m, p21 = t C_s with
    C = K + 2B/T. Llewellyn's p11 p22 >= p12 p21 gives, with c1 = b_m + b1, c2 = b_s + b2:
    c1 c2 >= t (c1 C_s + c2 C_m), i.e. K <= (2 c1 c2 / T - 2 (c1 B_s + c2 B_m) / T) / (c1 + c2).
    This is where these loops bind (the plain case: 300 N/m, checked by hand in
    test_twoport)."""
    T, bm, bs, Bm, Bs = 1e-3, 0.5, 0.5, 0.05, 0.15
    c1, c2 = bm + b1, bs + b2
    want = (2 * c1 * c2 / T - 2 * (c1 * Bs + c2 * Bm) / T) / (c1 + c2)
    got = critical_stiffness_llewellyn(_different_channels(), operator_damping_min=b1,
                                       environment_damping_min=b2)
    # bisection to 1e-9 relative (critical_stiffness_llewellyn), below the bound
    assert got.critical_stiffness == pytest.approx(want, rel=2e-9)
    assert got.critical_stiffness <= want
    assert got.details["operator_damping_min"] == b1


def test_more_known_damping_allows_more_stiffness():
    lp = h.paper_peb(delay_samples=3)
    ks = [critical_stiffness_llewellyn(lp, operator_damping_min=b,
                                       environment_damping_min=b).critical_stiffness
          for b in (0.0, 0.01, 0.1, 1.0)]
    assert ks == sorted(ks) and ks[-1] > ks[0]


def test_bounds_are_checked():
    lp = h.paper_peb()
    with pytest.raises(h.ModelError, match="operator_damping_min"):
        critical_stiffness_llewellyn(lp, operator_damping_min=-1.0)
    with pytest.raises(TypeError, match="environment_damping_min"):
        llewellyn_test(lp, environment_damping_min="1")
    with pytest.raises(h.HapstabError, match="operator_damping_min"):
        h.critical_stiffness(h.paper_hve(), method="circle", operator_damping_min=1.0)


def _campaign(seed, loops, pairs):
    """Random PEB loops; terminations drawn with at least the bounds' damping."""
    rng = np.random.default_rng(seed)

    def term(b_min):
        c = rng.integers(0, 4)
        extra = float(rng.choice([0.0, 10 ** rng.uniform(-2, 1)]))
        if c == 0:          # a pure damper
            return h.mass_spring_damper(0.0, b_min + extra, 0.0)
        if c == 1:          # a damped spring
            return h.mass_spring_damper(0.0, b_min + extra, float(10 ** rng.uniform(-1, 3)))
        if c == 2:
            return h.mass_spring_damper(float(10 ** rng.uniform(-2, 0)), b_min + extra,
                                        float(10 ** rng.uniform(0, 3.5)))
        return h.mass_spring_damper(0.0, b_min, 2e4)             # a stiff, damped wall

    found, checked = [], 0
    for _ in range(loops):
        T, n = float(rng.choice([5e-4, 1e-3, 2e-3])), int(rng.integers(0, 7))
        bm, bs = float(10 ** rng.uniform(-2.3, 0.7)), float(10 ** rng.uniform(-2.3, 0.7))
        Bm, Bs = (float(rng.choice([0.0, rng.uniform(0, min(bm, bs))])) for _ in range(2))
        b_op, b_env = (float(10 ** rng.uniform(-2, 0.5)) for _ in range(2))
        base = h.TeleoperationLoop(
            h.Device(float(10 ** rng.uniform(-2, 0)), bm), h.Device(float(10 ** rng.uniform(-2, 0.3)), bs),
            h.SpringDamper(1.0, Bm), h.SpringDamper(1.0, Bs), None, None, T, n)
        KL = critical_stiffness_llewellyn(base, operator_damping_min=b_op,
                                          environment_damping_min=b_env).critical_stiffness
        if not 0 < KL < np.inf:
            continue
        for _ in range(pairs):
            loop = base.replace(operator=term(b_op), environment=term(b_env))
            checked += 1
            # the exact K_max is certified; 1e-9 is the Llewellyn bisection's tolerance
            if h.critical_stiffness(loop).critical_stiffness < KL * (1 - 1e-9):
                found.append((loop, KL))
    return checked, found


def test_bounded_llewellyn_is_a_bound_for_terminations_inside_the_bounds():
    # the default lane 3 of the seed's 6 loops (tests/lanes.py), each with 4 terminations
    checked, found = _campaign(int(os.environ.get("HAPSTAB_CAMPAIGN_SEED", "31")),
                               lanes.size(3, 6), 4)
    assert checked >= lanes.size(10, 20) and not found, found[:3]


@pytest.mark.slow
def test_bounded_llewellyn_is_a_bound_in_a_campaign_of_500_pairs():
    checked, found = _campaign(int(os.environ.get("HAPSTAB_CAMPAIGN_SEED", "3131")), 125, 5)
    assert checked >= 500 and not found, found[:3]


def test_cli_bounds():
    args = ["-B", "0.05", "--slave-virtual-damping", "0.15", "--master-damping", "0.5",
            "--slave-damping", "0.5", "--operator-damping-min", "0.5",
            "--environment-damping-min", "0.5", "--json"]
    out = CliRunner().invoke(cli, ["kmax", "peb", "--method", "llewellyn", *args])
    assert out.exit_code == 0, out.output
    d = json.loads(out.stdout)
    # the closed form above with c1 = c2 = 1: (2 - 0.4) / (2 T) = 800 N/m
    assert d["critical_stiffness"] == pytest.approx(800.0, rel=2e-9)
    one = CliRunner().invoke(cli, ["twoport", "peb", "-K", "790", *args])
    assert one.exit_code == 0 and json.loads(one.stdout)["absolutely_stable"] is True
    assert json.loads(one.stdout)["operator_damping_min"] == 0.5
    bad = CliRunner().invoke(cli, ["kmax", "peb", "--operator-damping-min", "1"])
    assert bad.exit_code == 2 and "--method llewellyn" in bad.output
    hve = CliRunner().invoke(cli, ["kmax", "hve", "--operator-damping-min", "1"])
    assert hve.exit_code == 2
