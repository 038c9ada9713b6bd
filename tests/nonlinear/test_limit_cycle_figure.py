"""The limit-cycle figure agrees with the verdict (issue 29 item 7): on a device with both
a 2 µm encoder and 0.05 N of Coulomb friction the describing-function plot drew C against
-1/N(A), which cross (gain margin 1.25 < 4/pi), beside the verdict "no limit cycle
predicted". The verdict is the right one: friction enters the same first-harmonic balance
as the equivalent damper 4 f_c/(pi A w), which at the encoder's amplitudes is ~10^3 N·s/m
(K Δ = 1e-4 N against 0.05 N of friction: the device cannot be moved by a step), so the
balance has no root. With both nonlinearities the figure now draws that balance's curves
Re F = 0 and Im F = 0, which cross exactly where a cycle is predicted."""

import math

import numpy as np
import pytest

import hapstab as h
from hapstab.plotting.limit_cycles import balance_grid, from_root
from lanes import costly

DELTA = 2e-6          # m: the engineer's encoder


def _loop(fc, ratio=0.8, n=20):
    """The engineer's device (0.25 kg, 0.8 N·s/m) at 2 kHz, 10 ms of delay."""
    base = h.HapticLoop(h.Device(0.25, 0.8, coulomb_friction=fc), h.SpringDamper(1.0, 0.0),
                        h.spring(1.0), 1 / 2000, n)
    K = h.critical_stiffness(base).critical_stiffness
    return base.with_stiffness(ratio * K)


def _crossing_cells(res, grid=None):
    """Cells of the figure's grid (``balance_grid(res)``, or ``grid`` when the caller has
    it) where both Re F and Im F change sign: where the two zero curves can meet (a
    contour passes through a cell only where its corners' signs differ, so without such a
    cell they cannot cross)."""
    _, _, F = grid if grid is not None else balance_grid(res)
    out = []
    for part in (F.real, F.imag):
        s = np.sign(part)
        corners = np.stack([s[:-1, :-1], s[1:, :-1], s[:-1, 1:], s[1:, 1:]])
        out.append(corners.min(axis=0) < corners.max(axis=0))
    return np.argwhere(out[0] & out[1])


@pytest.fixture(scope="module")
def plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    yield plt
    plt.close("all")


def test_friction_that_leaves_no_cycle_draws_curves_that_do_not_cross(plt):
    res = h.limit_cycles(_loop(0.05), resolution_m=DELTA)
    assert res.verdict == "no limit cycle predicted" and not res.cycles
    assert res.crossovers[0][1] < res.max_gain     # the old figure's crossing: C meets -1/N
    assert _crossing_cells(res).size == 0           # the balance's curves do not meet
    ax = res.plot()
    assert ax.get_xlabel() == "frequency (Hz)" and ax.get_yscale() == "log"
    assert ax.get_title().endswith("no limit cycle predicted")
    assert "quantisation alone could sustain a cycle there" in res.conditions
    assert "it has no root (the figure's curves Re F = 0 and Im F = 0 do not cross)" \
        in res.conditions


def test_friction_small_enough_for_a_cycle_draws_curves_crossing_at_it(plt):
    res = h.limit_cycles(_loop(1e-8), resolution_m=DELTA)
    assert res.verdict == "limit cycle" and all(from_root(c) for c in res.cycles)
    grid = balance_grid(res)
    f, A, _ = grid
    cells = _crossing_cells(res, grid)          # the same grid, computed once
    assert cells.size
    for c in res.cycles:          # each cycle from a root sits in a crossing cell (or its
        i = np.searchsorted(A, c.describing_function_amplitude_m) - 1   # neighbour)
        j = np.searchsorted(f, c.describing_function_frequency_hz) - 1
        assert np.any((np.abs(cells[:, 0] - i) <= 1) & (np.abs(cells[:, 1] - j) <= 1))
    assert "the cycles listed solve it" in res.conditions
    ax = res.plot()
    assert len(ax.lines) == len(res.cycles)         # the cycles marked
    assert ax.get_title().endswith("limit cycle")
    assert "cycles where they meet (filled: stable)" in [
        t.get_text() for t in ax.get_legend().get_texts()]


def test_a_cycle_only_the_harmonics_close_is_marked_as_such(plt):
    """f_c = 1e-6 N: the first harmonic comes close but has no root (the curves do not
    meet); harmonic balance closes the gap (a cycle). The figure must not show it as a
    crossing: a square, and the legend says so."""
    res = h.limit_cycles(_loop(1e-6), resolution_m=DELTA)
    assert res.verdict == "limit cycle" and _crossing_cells(res).size == 0
    assert res.cycles and not any(from_root(c) for c in res.cycles)
    ax = res.plot()
    assert [ln.get_marker() for ln in ax.lines] == ["s"] * len(res.cycles)
    assert "a cycle the harmonics close where they only come near" in [
        t.get_text() for t in ax.get_legend().get_texts()]


#: 0.95 K_max in `make test-campaign`: 0.8 K_max asks the same (a crossing, and cycles
#: predicted), 0.5 K_max the other side (neither)
@pytest.mark.parametrize("ratio", [0.5, 0.8, costly(0.95, id="0.95")])
def test_quantisation_alone_the_curves_cross_where_cycles_are_predicted(plt, ratio):
    """One nonlinearity: C against -1/N(A) is the balance; a crossing (the phase crossover
    -1/gain margin inside -1/N's range) goes with predicted cycles, none without."""
    res = h.limit_cycles(_loop(0.0, ratio), resolution_m=DELTA)
    inv = res.curves["minus_inverse"]
    inv = inv[np.isfinite(inv)].real
    at = [-1 / g for _, g in res.crossovers]
    crosses = any(inv.min() <= x <= inv.max() for x in at)
    assert crosses == bool(res.cycles)
    assert crosses == (res.verdict == "limit cycle")
    ax = res.plot()
    assert ax.get_xlabel() == "real"
    assert math.isclose(ratio, res.stiffness / h.critical_stiffness(
        _loop(0.0, 1.0)).critical_stiffness, rel_tol=1e-12)    # (rounding of K = ratio K_max)
