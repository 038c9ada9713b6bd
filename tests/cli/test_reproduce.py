"""reproduce: Fig. 5 / Fig. 6 points against the library (theory, exact) and the
simulation stars against the exact K_max; files written."""

import csv
import math
from pathlib import Path

import numpy as np
import pytest

import hapstab as h
from hapstab.analysis.exact.core import exact_critical_stiffness
from hapstab.analysis.methods import METHODS, critical_stiffness
from hapstab.errors import AnalysisError
from hapstab.paper.reproduce import FIGURES, PAPER_PERIODS, reproduce_figure, write_figure
from lanes import PARTS, part


def read_csv(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def theory(fig, T, n):
    # the paper's lines, from the closed forms directly
    if fig == "fig5":
        lp = h.paper_hve(T, n)
        return (h.colgate(lp) if n == 0 else h.eq18(lp)).critical_stiffness
    lp = h.paper_peb(T, n)
    return (h.eq29(lp) if n == 0 else h.eq34(lp)).critical_stiffness


#: the paper's periods the default lane reproduces: 1, 4, 7 and 10 ms (16 of the 40 stars,
#: both ends of the grid and both delays of each figure); the other 6 periods (24 stars) run
#: in `make test-campaign`, which reproduces the whole default grid (and checks that it is
#: the paper's 20 rows a figure) and checks its rows at those periods: every star once
REDUCED_PERIODS = 4


@pytest.fixture(scope="module", params=PARTS)
def reports(request):
    """The paper grid's part of both figures (see `REDUCED_PERIODS`), once: a few seconds
    (the CSV test and the stars' 1e-4 test read the same reproductions). Returns the
    reproductions, the periods whose rows the lane checks and whether the reproductions
    are the default call's whole grid."""
    whole = request.param        # the rest: the default call, the whole grid
    periods = part(PAPER_PERIODS, REDUCED_PERIODS, whole)
    return ({name: reproduce_figure(name, None if whole else periods) for name in FIGURES},
            periods, whole)


@pytest.fixture(scope="module")
def full(reports, tmp_path_factory):
    """The part's reproductions, written."""
    out = tmp_path_factory.mktemp("out")
    reps, periods, whole = reports
    return {name: write_figure(rep, str(out)) for name, rep in reps.items()}, periods, whole


def checked(rows, periods):
    """The rows at the lane's periods (each lane checks its own stars)."""
    return [r for r in rows if any(math.isclose(float(r["period_s"]), T, rel_tol=1e-12)
                                   for T in periods)]


def test_paper_grid_is_section_5():
    np.testing.assert_allclose(PAPER_PERIODS, np.arange(1, 11) * 1e-3, rtol=1e-12)


@pytest.mark.xdist_group("reproduce-full")     # `reports` once, not once per xdist worker
@pytest.mark.parametrize("fig", ["fig5", "fig6"])
def test_csv_columns_match_library(full, fig):
    files, periods, whole = full
    csv_path, png, svg, manifest = files[fig]
    assert manifest.endswith("manifest.json")
    rows = read_csv(csv_path)
    cols = ["period_s", "delay_samples", "theory", "exact", "simulation"]
    if "circle" in METHODS:
        cols.append("circle")
    assert list(rows[0]) == cols
    # the rest's reproduction is the default call: the paper's grid, 20 rows
    assert len(rows) == (20 if whole else 2 * len(periods))
    assert {int(r["delay_samples"]) for r in rows} == set(FIGURES[fig].delays)
    rows = checked(rows, periods)
    assert len(rows) == 2 * len(periods)
    make = h.paper_hve if fig == "fig5" else h.paper_peb
    for r in rows:
        T, n = float(r["period_s"]), int(r["delay_samples"])
        ex = exact_critical_stiffness(make(T, n)).critical_stiffness
        # the CSV stores repr() of the floats: equal to 1e-9 as the issue demands
        assert float(r["exact"]) == pytest.approx(ex, rel=1e-9)
        assert float(r["theory"]) == pytest.approx(theory(fig, T, n), rel=1e-9)
        # the acceptance for the stars: within 1 % of exact
        assert abs(float(r["simulation"]) / ex - 1) < 0.01
        if "circle" in cols:
            c = critical_stiffness(make(T, n), method="circle").critical_stiffness
            assert float(r["circle"]) == pytest.approx(c, rel=1e-9)
    for p in (png, svg):
        with open(p, "rb") as fh:
            head = fh.read(200)
        assert len(head) == 200
    assert Path(png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in Path(svg).read_bytes()


def test_reduced_grid_and_progress(tmp_path):
    ticks = []
    rep = reproduce_figure("fig6", [2e-3, 7e-3], progress=ticks.append)
    assert len(rep.rows) == 4 and sum(ticks) == 4
    assert rep.worst_simulation_error() < 0.01
    paths = write_figure(rep, str(tmp_path / "sub" / "dir"))
    assert all((tmp_path / "sub" / "dir" / f"fig6.{e}").stat().st_size > 0 for e in ("csv", "png", "svg"))
    assert len(paths) == 4 and paths[-1].endswith("manifest.json")


def test_bad_inputs():
    with pytest.raises(AnalysisError, match="figure"):
        reproduce_figure("fig7")
    with pytest.raises(AnalysisError, match="periods"):
        reproduce_figure("fig5", [-1.0])
    assert math.isfinite(reproduce_figure("fig5", [5e-3]).rows[0]["exact"])


@pytest.mark.xdist_group("reproduce-full")     # `reports` once, beside the CSV test
def test_simulation_stars_within_1e_4_of_exact_on_the_papers_40_points(reports):
    # issue #9's acceptance: the verdict's rework must keep the paper's procedure
    # exact. The bisection brackets K_max to relative width rtol = 1e-4 and every
    # verdict in it is resolved (noise-free linear runs), so the star is below the
    # exact K_max by less than 1e-4
    reps, periods, whole = reports
    for fig in ("fig5", "fig6"):
        rep = reps[fig]              # the lane's part of the paper's grid (`reports`)
        assert len(rep.rows) == (20 if whole else 2 * len(periods))
        rows = checked(rep.rows, periods)
        assert len(rows) == 2 * len(periods)
        for r in rows:
            assert 0 <= 1 - r["simulation"] / r["exact"] < 1e-4, r
