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


@pytest.fixture(scope="module")
def reports():
    """The whole paper grid (40 simulation stars) of both figures, once: a few seconds
    (the CSV test and the stars' 1e-4 test read the same reproductions)."""
    return {name: reproduce_figure(name) for name in FIGURES}


@pytest.fixture(scope="module")
def full(reports, tmp_path_factory):
    """The whole paper grid, written."""
    out = tmp_path_factory.mktemp("out")
    return {name: write_figure(rep, str(out)) for name, rep in reports.items()}


def test_paper_grid_is_section_5():
    np.testing.assert_allclose(PAPER_PERIODS, np.arange(1, 11) * 1e-3, rtol=1e-12)


@pytest.mark.xdist_group("reproduce-full")     # `reports` once, not once per xdist worker
@pytest.mark.parametrize("fig", ["fig5", "fig6"])
def test_csv_columns_match_library(full, fig):
    csv_path, png, svg, manifest = full[fig]
    assert manifest.endswith("manifest.json")
    rows = read_csv(csv_path)
    cols = ["period_s", "delay_samples", "theory", "exact", "simulation"]
    if "circle" in METHODS:
        cols.append("circle")
    assert list(rows[0]) == cols
    assert len(rows) == 20
    assert {int(r["delay_samples"]) for r in rows} == set(FIGURES[fig].delays)
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
    for fig in ("fig5", "fig6"):
        rep = reports[fig]           # reproduce_figure(fig), the whole grid
        assert len(rep.rows) == 20
        for r in rep.rows:
            assert 0 <= 1 - r["simulation"] / r["exact"] < 1e-4, r
