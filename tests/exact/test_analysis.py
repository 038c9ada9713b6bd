"""Method dispatch and the vectorised boundary."""

import re

import numpy as np
import pytest

import hapstab as h
from hapstab.errors import AnalysisError, ModelError


def test_boundary_equals_pointwise_exact():
    T = np.array([1e-3, 2.5e-3, 7e-3])
    res = h.boundary(h.paper_hve(), T, [0, 10])
    assert res.critical_stiffness.shape == (2, 3)
    for i, n in enumerate((0, 10)):
        for j, t in enumerate(T):
            one = h.critical_stiffness(h.paper_hve(period=t, delay_samples=n)).critical_stiffness
            # the boundary's K_max-only path polishes the same crossing: same value
            assert res.critical_stiffness[i, j] == pytest.approx(one, rel=1e-12)


def test_boundary_of_peb_and_closed_form_method():
    res = h.boundary(h.paper_peb(), [1e-3, 2e-3], [4], method="eq34")
    np.testing.assert_allclose(res.critical_stiffness, [[0.02 / 5e-3, 0.02 / 10e-3]])
    rows = res.rows()
    assert rows[0] == {"period_s": 1e-3, "delay_samples": 4, "critical_stiffness": pytest.approx(4.0)}


def test_boundary_csv(tmp_path):
    res = h.boundary(h.paper_hve(), [1e-3, 2e-3], [0])
    path = tmp_path / "b.csv"
    res.to_csv(str(path))
    lines = path.read_text().splitlines()
    assert lines[0] == "period_s,delay_samples,critical_stiffness" and len(lines) == 3


@pytest.mark.parametrize("periods,delays,err", [([], [0], AnalysisError), ([1e-3], [], AnalysisError),
                                                ([-1e-3], [0], ModelError), ([1e-3], [1.5], ModelError)])
def test_boundary_rejects_bad_grids(periods, delays, err):
    with pytest.raises(err):
        h.boundary(h.paper_hve(), periods, delays)


@pytest.mark.parametrize("periods,bad", [([1e-3, 1e-9], "1e-09"), ([1e-3, 1e9], "1e+09"),
                                         ([1e-3, 2e-3, 5e3], "5000"), ([1e-3, float("nan")], "nan"),
                                         ([1e-3, 0.0], "0.0")])
def test_boundary_checks_every_period_like_the_model(periods, bad):
    # every period, not only the first: 1e-9 used to give K_max = 0 and 1e9 inf
    with pytest.raises(ModelError, match="^" + re.escape(f"period = {bad}: must ")) as e:
        h.boundary(h.paper_hve(), periods, [0])
    assert "\n" not in str(e.value)
    with pytest.raises(ModelError) as m:   # the same rule as the model's own period check
        h.paper_hve(period=periods[-1])
    assert str(m.value) == str(e.value)


def test_unknown_method_names_the_allowed_ones():
    with pytest.raises(AnalysisError, match=r"method = 'nope': unknown; allowed: exact"):
        h.critical_stiffness(h.paper_hve(), method="nope")


def test_methods_for_kind():
    assert "eq34" in h.methods_for("peb") and "eq34" not in h.methods_for("hve")
    assert "colgate" in h.methods_for("hve") and "colgate" not in h.methods_for("peb")


def test_result_to_dict_is_json_ready():
    import json

    d = json.loads(json.dumps(h.critical_stiffness(h.paper_hve()).to_dict()))
    assert d["method"] == "exact" and d["stable_intervals"] == [[0.0, d["critical_stiffness"]]]
    # a loop stable for every K reports inf, which JSON cannot hold as a number
    free = h.HapticLoop(h.Device(0.1, 0.1), h.SpringDamper(1.0), None, 1e-3, 0)
    d = json.loads(json.dumps(h.colgate(free).to_dict()))
    assert d["critical_stiffness"] == pytest.approx(200.0)


def test_boundary_replaces_the_templates_delays():
    tmpl = h.paper_peb().replace(delay_backward_samples=6, fractional_delay=0.3)
    a = h.boundary(tmpl, [1e-3], [0, 4]).critical_stiffness
    b = h.boundary(h.paper_peb(), [1e-3], [0, 4]).critical_stiffness
    np.testing.assert_array_equal(a, b)
