"""Every result object follows one protocol (issue #10, step 3): it is a Result,
gives a strict-JSON dict (infinities as null plus a flag) and shows as a table in a
notebook; a result with a picture draws it with plot(ax=None) and returns the axes;
a result with a table writes it with to_csv."""

import csv
import functools
import json
import math

import numpy as np
import pytest

import hapstab as h
from hapstab.results import CriticalStiffnessResult, Result, merged


def _loops():
    return h.paper_hve(1e-3, 2), h.paper_peb(1e-3, 2)


#: (the result's class name, how to compute it): computed when a test asks for it, once
#: per worker (not at collection, where every pytest worker would compute all of them)
FACTORIES = {
    "StabilityResult": lambda hve, peb: h.stability(hve.with_stiffness(50.0)),
    "MarginResult": lambda hve, peb: h.margins(hve.with_stiffness(20.0), max_extra_samples=4.0),
    "FrequencyView": lambda hve, peb: h.frequency_view(peb.with_stiffness(3.0)),
    "CriticalStiffnessResult": lambda hve, peb: h.critical_stiffness(hve),
    "CriticalStiffnessResult-simulation":
        lambda hve, peb: h.critical_stiffness(hve, method="simulation"),
    "BoundaryResult": lambda hve, peb: h.boundary(hve, [1e-3, 2e-3], [0, 2]),
    "PassivityResult": lambda hve, peb: h.sampled_passivity(peb.with_stiffness(3.0)),
    "PositiveRealResult": lambda hve, peb: h.circle_test(hve.with_stiffness(10.0)),
    "AuditResult": lambda hve, peb: h.audit(hve),
    "RegionResult": lambda hve, peb: h.stability_region(hve, (0, 300), (0, 1), 8),
    "BestDampingResult": lambda hve, peb: h.best_damping(hve, resolution=8),
    "SimulationResult": lambda hve, peb: h.simulate(hve.with_stiffness(50.0), 0.2),
    "BoundednessVerdict": lambda hve, peb: h.simulate(hve.with_stiffness(50.0), 0.2).verdict,
    "TransparencyResult": lambda hve, peb: h.transparency(peb.with_stiffness(3.0)),
    "NonlinearPassivityResult": lambda hve, peb: h.nonlinear_passivity(
        hve.replace(delay_samples=0).with_stiffness(150.0), coulomb_friction_N=0.005,
        resolution_m=1e-4),
    "LimitCycleResult": lambda hve, peb: h.limit_cycles(
        h.paper_hve(1e-3, 10).with_stiffness(8.0), resolution_m=1e-4, quantizer="nearest"),
    "JitterResult": lambda hve, peb: h.jitter(hve, (1, 2), max_length=3),
}

#: the ones that draw themselves (test_the_plot_list_is_every_result_with_a_plot keeps it so)
PLOTS = ["StabilityResult", "MarginResult", "FrequencyView", "BoundaryResult",
         "PositiveRealResult", "AuditResult", "RegionResult", "BestDampingResult",
         "SimulationResult", "TransparencyResult", "LimitCycleResult", "JitterResult"]


@functools.cache
def _result(name):
    res = FACTORIES[name](*_loops())
    assert type(res).__name__ == name.split("-")[0], (name, type(res).__name__)
    return res


def _results():
    return [_result(name) for name in FACTORIES]


def test_the_plot_list_is_every_result_with_a_plot():
    assert PLOTS == [n for n in FACTORIES if hasattr(_result(n), "plot")]


@pytest.mark.parametrize("name", FACTORIES)
def test_every_result_is_a_result_with_json_and_html(name):
    res = _result(name)
    assert isinstance(res, Result)
    d = res.to_dict()
    text = json.dumps(d, allow_nan=False)   # JSON-ready: no NaN, no Infinity, no numpy types
    assert '"inf"' not in text               # an infinity is null plus a flag, never a string
    page = res._repr_html_()
    assert page.startswith("<table>") and type(res).__name__ in page
    # one row per key; the index of infinities is shown as "inf" in the rows it names
    assert page.count("<tr>") == len(d) - ("infinite" in d)
    assert "{re, im}" not in page          # a complex number shows as one (issue 29)


def test_details_cannot_replace_a_key_of_the_result():
    r = CriticalStiffnessResult(1.0, "exact", ((0.0, 1.0),), "why", 1e-3, 0,
                                details={"method": "other"})
    with pytest.raises(ValueError, match="method"):
        r.to_dict()
    assert merged({"a": 1}, {"b": np.float64(2.0)}, "x") == {"a": 1, "b": 2.0}


@pytest.mark.parametrize("name", PLOTS)
def test_plot_returns_the_axes_and_draws_on_given_ones(name):
    res = _result(name)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axes = np.ravel(np.asarray(res.plot(), dtype=object))
    assert all(a.has_data() for a in axes)
    n = axes.size
    _fig, given = plt.subplots(n, 1, squeeze=False)
    again = np.ravel(np.asarray(res.plot(given[:, 0] if n > 1 else given[0, 0]), dtype=object))
    assert list(again) == list(given[:, 0]) and all(a.has_data() for a in again)
    plt.close("all")


def test_every_result_with_a_table_writes_csv(tmp_path):
    with_csv = [r for r in _results() if hasattr(r, "to_csv")]
    names = {type(r).__name__ for r in with_csv}
    assert {"BoundaryResult", "RegionResult", "SimulationResult", "AuditResult",
            "BestDampingResult"} <= names
    for i, r in enumerate(with_csv):
        p = tmp_path / f"{i}.csv"
        r.to_csv(str(p))
        rows = list(csv.reader(p.read_text().splitlines()))
        assert len(rows) >= 2 and all(len(x) == len(rows[0]) for x in rows)


def test_audit_csv_has_one_row_per_condition_with_the_exact_last(tmp_path):
    res = h.audit(h.paper_hve(1e-3, 2))
    res.to_csv(str(tmp_path / "a.csv"))
    rows = list(csv.DictReader((tmp_path / "a.csv").read_text().splitlines()))
    assert [r["key"] for r in rows] == [r.key for r in res.rows]
    assert math.isclose(float(rows[-1]["critical_stiffness"]), res.exact_kmax, rel_tol=1e-15)


def test_reproduction_plots_and_writes_its_points(tmp_path):
    from hapstab.paper.reproduce import reproduce_figure

    rep = reproduce_figure("fig5", [1e-3, 2e-3])
    top, bottom = rep.plot()
    assert top.get_title().startswith("Fig. 5") and top.has_data() and bottom.has_data()
    # the lower panel shows the differences in % (the paper's own line is not in it)
    assert bottom.get_ylabel() == "K_max / paper - 1 (%)"
    from matplotlib.legend import Legend

    legends = [a for a in top.artists if isinstance(a, Legend)] + [top.get_legend()]
    labels = [t.get_text() for leg in legends for t in leg.get_texts()]
    assert "exact" in labels and "n = 0" in labels and len(labels) == len(set(labels))
    rep.to_csv(str(tmp_path / "f.csv"))
    rows = list(csv.DictReader((tmp_path / "f.csv").read_text().splitlines()))
    assert len(rows) == len(rep.rows) and float(rows[0]["exact"]) == rep.rows[0]["exact"]


def test_simulation_plot_shows_the_wall_and_the_saturation():
    # issue #12: the simulation plot lacked the wall line and the saturation level, and its
    # title printed n = 3.0
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = h.simulate(h.paper_hve(1e-3, 3).with_stiffness(100.0), 0.3, wall=0.001, saturation=5,
                   force="step:1")
    ax1, ax2, _ = r.plot()
    assert "n = 3:" in ax1.get_title()
    assert any("wall at 0.001 m" in t.get_text() for t in ax1.get_legend().get_texts())
    assert any("saturation +-5 N" in t.get_text() for t in ax2.get_legend().get_texts())
    plt.close("all")
