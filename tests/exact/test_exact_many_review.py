"""Adversarial review of ``critical_stiffness_many`` (issue 16, part B): batches that
mix loops differing in exactly one structural option (the options the structure key
must separate: filters and their N, AffineController coefficients, general impedances
with states, free ports on either side of FREE_SPRING, fractional and asymmetric
delays, scaling, slave K = 0, 4-channel force gains and dampers), each compared with
``critical_stiffness`` one loop at a time by ``to_dict()`` equality (bitwise), in
several orders so that the batches' compositions change. Seeded and small.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import hapstab as h
from hapstab.analysis.exact import many
from hapstab.analysis.exact.boxes import Cells, trim_boxes
from hapstab.analysis.exact.many import critical_stiffness_many
from hapstab.engine.frequency import build_responses, loop_response, plan_response
from hapstab.errors import HapstabError
from hapstab.models.controllers import AffineController, FilteredSpringDamper
from hapstab.models.fourchannel import FourChannelLoop
from hapstab.models.parts import Impedance
from lanes import PARTS, part_groups, reduced_indices
from references.mixed import batch_keys


def _single(loop):
    try:
        return h.critical_stiffness(loop)
    except HapstabError as e:
        return e


def _diff(got, want) -> str:
    if isinstance(want, HapstabError) or isinstance(got, HapstabError):
        same = type(got) is type(want) and str(got) == str(want)
        return "" if same else f"{want!r} vs batched {got!r}"
    a, b = got.to_dict(), want.to_dict()
    bad = [k for k in b if not (a[k] == b[k] or (isinstance(a[k], float) and math.isnan(a[k])
                                                 and math.isnan(b[k])))]
    return f"{bad}: {a} vs {b}" if bad else ""


def _check(loops) -> None:
    want = [_single(lp) for lp in loops]
    for order in (list(range(len(loops))), list(range(len(loops)))[::-1]):
        got = critical_stiffness_many([loops[i] for i in order], errors="return")
        bad = [(i, _diff(g, want[i])) for i, g in zip(order, got, strict=True)]
        bad = [b for b in bad if b[1]]
        assert not bad, f"{len(bad)} differ; first: loop {bad[0][0]}: {bad[0][1]}"


def _lane(loops, groups, rest, also=()):
    """The lane's loops: ``groups`` of the whole draw's batches (the loops sharing a
    structure), whole (lanes.part_groups: every batch of the whole call is one lane's);
    with ``rest`` the other batches and the loops alone in theirs."""
    return part_groups(loops, batch_keys(loops), groups, rest, also)


def _hve(rng, ctrl, op="spring:200", frac=0.0, n=2, dev_b=None):
    m = float(10 ** rng.uniform(-1.5, 0.5))
    b = float(10 ** rng.uniform(-3, 0)) if dev_b is None else dev_b
    return h.HapticLoop(h.Device(m, b), ctrl, op, float(1 / 10 ** rng.uniform(2.5, 3.7)), n,
                        fractional_delay=frac)


# impedances with states of their own (the termination's rest Z_r), two different orders
Z1 = Impedance((1.0, 10.0), (1.0, 50.0))                      # 1 - 40/(s + 50)
Z2 = Impedance((2.0, 3.0, 40.0), (1.0, 30.0, 200.0))          # 2 + rest of order 2


# 7 of the draw's 13 batches by default (15 loops), whole; the other 45 loops -m campaign
@pytest.mark.parametrize("rest", PARTS)
def test_hve_options_differing_in_one_structural_thing_equal_the_single_core(rest):
    rng = np.random.default_rng(16_21)
    ctrls = [h.SpringDamper(1, 0.02), h.SpringDamper(1, -0.001), h.SpringDamper(1, 0.0),
             FilteredSpringDamper(1, 0.02, "lowpass:300"), FilteredSpringDamper(1, 0.02, "lowpass:30"),
             FilteredSpringDamper(1, 0.02, "lowpass:1e7"),      # pole underflows: no filter
             FilteredSpringDamper(1, 0.02, "average:1"), FilteredSpringDamper(1, 0.02, "average:2"),
             FilteredSpringDamper(1, 0.02, "average:3"),
             AffineController(1.0, (1.0,), (1.0,), (0.02, -0.02), (1e-3, 0.0)),
             AffineController(1.0, (1.0,), (1.0,), (0.02, -0.015), (1e-3, -2e-4)),
             AffineController(1.0, (1.0, 0.0), (1.0, -0.3), (0.01, -0.01), (1e-3, 0.0))]
    loops = []
    for c in ctrls:
        for op in ("spring:200", "none", Z1, Z2):
            period_free = isinstance(c, AffineController)
            lp = _hve(rng, c, op, n=int(rng.integers(0, 4)))
            if period_free:      # an AffineController's coefficients belong to T = 1 ms
                lp = h.HapticLoop(lp.device, c, op, 1e-3, lp.delay_samples)
            loops.append(lp)
    for frac in (0.0, 0.25, 0.75):
        loops += [_hve(rng, h.SpringDamper(1, 0.01), "spring:50", frac=frac) for _ in range(2)]
    # free device on either side of FREE_SPRING (k T^2 / m = 1e-21 and 1e-19)
    for k in (1e-15, 1e-13, 0.0):
        loops += [h.HapticLoop(h.Device(1.0, 0.01), h.SpringDamper(1, 0.01), f"spring:{k:g}",
                               1e-3, n) for n in (1, 2)]
    _check(_lane(loops, 7, rest))


# 3 of the draw's 16 batches by default, whole (a batch is one kind's three plain
# spring-damper slaves, with or without the environment): equal delays with springs at both
# ends (loop 1's), a fractional forward delay (20's), position and force scaling (50's),
# ~1.3 s of the batches' 0.1-2.7 s; the other 13 batches, the loops alone in theirs (the
# filtered slaves) and the refused one -m campaign
@pytest.mark.parametrize("rest", PARTS)
def test_teleoperators_differing_in_one_structural_thing_equal_the_single_core(rest):
    rng = np.random.default_rng(16_22)

    def dev():
        return h.Device(float(10 ** rng.uniform(-1.5, 0.5)), float(rng.choice([0.0, 0.02, 1.0])))

    loops = []
    kinds = [dict(), dict(delay_backward_samples=4), dict(fractional_delay=0.3),
             dict(fractional_delay=0.3, fractional_delay_backward=0.6),
             dict(fractional_delay=0.0, fractional_delay_backward=0.6),
             dict(position_scale=2.0, force_scale=0.5), dict(position_scale=0.5),
             dict(force_scale=3.0, fractional_delay=0.4)]
    slaves = [h.SpringDamper(1, 0.01), h.SpringDamper(0.0, 0.01), h.SpringDamper(3.0, -0.002),
              FilteredSpringDamper(1, 0.01, "lowpass:200"),
              FilteredSpringDamper(1, 0.01, "average:2")]
    for kw in kinds:
        for sc in slaves:
            for env in ("spring:500", None):
                loops.append(h.TeleoperationLoop(dev(), dev(), h.SpringDamper(1, 0.01), sc,
                                                 "spring:30" if env else None, env,
                                                 float(1 / 10 ** rng.uniform(2.5, 3.5)), 2, **kw))
    # master stiffness 0 with the slave's not (refused), next to accepted neighbours
    loops.append(h.TeleoperationLoop(dev(), dev(), h.SpringDamper(0, 0.01), h.SpringDamper(1, 0.01),
                                     None, None, 1e-3, 2))
    _check(_lane(loops, 0, rest, also=[1, 20, 50]))


# the draw's one batch of two loops by default (whole) and 7 evenly spaced loops, one of
# them in that batch (every gain set, both slave dampers and the three master-from-slave
# channels among them): 8 loops; the other 22 -m campaign
@pytest.mark.parametrize("rest", PARTS)
def test_four_channel_gains_and_dampers_equal_the_single_core(rest):
    rng = np.random.default_rng(16_23)
    loops = []
    for gains in ((0.0, 0.0, 0.0, 0.0), (0.5, 0.0, 0.0, 0.0), (0.0, 0.5, 0.0, 0.0),
                  (0.5, 0.3, 0.2, 0.1), (0.5, -0.3, 0.0, 0.1)):
        for Bs in (0.0, 0.01):
            for c4 in (None, h.SpringDamper(2.0, 0.0), h.SpringDamper(0.0, 0.01)):
                f2m, f2s, sff, mff = gains
                loops.append(FourChannelLoop(
                    h.Device(float(10 ** rng.uniform(-1.5, 0)), 0.01),
                    h.Device(float(10 ** rng.uniform(-1.5, 0)), 0.02),
                    h.SpringDamper(float(rng.choice([1.0, 0.0])), 0.01), h.SpringDamper(1.5, Bs),
                    "spring:30", "msd:0.05,0.01,300", 1e-3, int(rng.integers(1, 4)),
                    int(rng.integers(1, 4)), master_from_slave=c4, force_to_master=f2m,
                    force_to_slave=f2s, slave_force_feedback=sff, master_force_feedback=mff))
    _check(_lane(loops, 1, rest, also=reduced_indices(len(loops), 7)))


def test_structure_keys_separate_what_the_core_treats_as_structure():
    def key(lp):
        return plan_response(lp).key()

    base = dict(device=h.Device(0.1, 0.01), operator="spring:100", period=1e-3, delay_samples=2)
    hv = lambda c, **kw: h.HapticLoop(**{**base, **kw, "controller": c})   # noqa: E731
    distinct = [hv(h.SpringDamper(1, 0.1)), hv(FilteredSpringDamper(1, 0.1, "average:2")),
                hv(FilteredSpringDamper(1, 0.1, "average:3")),
                hv(FilteredSpringDamper(1, 0.1, "lowpass:100")),
                hv(AffineController(1.0, (1.0,), (1.0,), (0.1, -0.1), (1e-3, 0.0))),
                hv(AffineController(1.0, (1.0,), (1.0,), (0.2, -0.1), (1e-3, 0.0))),
                hv(h.SpringDamper(1, 0.1), operator=Z1), hv(h.SpringDamper(1, 0.1), operator=Z2),
                hv(h.SpringDamper(1, 0.1), fractional_delay=0.5),
                hv(h.SpringDamper(1, 0.1), delay_samples=3),
                hv(h.SpringDamper(1, 0.1), operator="spring:1e-17")]        # free
    keys = [key(lp) for lp in distinct]
    assert len(set(keys)) == len(keys)
    # and what is only numbers shares a key (B, masses, K ratio, period, low-pass pole)
    same = [hv(h.SpringDamper(1, 0.3)), hv(h.SpringDamper(2, -0.01), device=h.Device(3.0, 0.0)),
            hv(h.SpringDamper(1, 0.1), period=2e-4, operator="msd:0.1,0.2,300")]
    assert len({key(lp) for lp in same}) == 1


# ---------------------------------------------------------- findings (reproducers)
def test_trim_of_one_box_does_not_depend_on_other_items_boxes():
    # a box of the PEB below whose feasible u-set is two pieces (captured from its own
    # search); put after a box of another loop of the batch reaching u = 1e10
    peb = h.TeleoperationLoop(h.Device(0.1, 0.01), h.Device(0.2, 0.0), h.SpringDamper(1, 0.001),
                              h.SpringDamper(1, 0.001), "spring:50", "spring:100", 1e-3, 3)
    other = h.paper_peb(1e-3, 3)
    resp = build_responses([plan_response(other), plan_response(peb)])
    c = Cells()
    th, rho = 0.9817477042468103, 0.04908738521234052
    cells = c.add(resp, np.array([0, 1]), np.array([0.0, th]), np.array([rho, rho]),
                  np.array([1, 0]))
    lo, hi = np.full(2, 1e-14), np.full(2, 1e10)
    alone = trim_boxes(c, cells[1:], lo[1:], hi[1:])
    together = trim_boxes(c, cells, lo, hi)
    assert alone[1].size == 2                    # two pieces when trimmed alone
    mine = together[0] == cells[1]
    assert together[1][mine].tolist() == alone[1].tolist()
    assert together[2][mine].tolist() == alone[2].tolist()


def test_batch_size_accounts_for_the_filter_order():
    loop = h.HapticLoop(h.Device(0.1, 0.01), FilteredSpringDamper(1, 0.05, "average:500"), None,
                        1e-3, 2)
    rate = loop_response(loop).phase_rate                  # 505
    budget = max(8, int(many.BATCH_BYTES // (many.PER_RATE * rate)))
    assert many.batch_size(plan_response(loop)) <= budget
