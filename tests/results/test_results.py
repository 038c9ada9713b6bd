"""Result objects are JSON-ready."""

import json
import math

import numpy as np

import hapstab as h
from hapstab.results import CriticalStiffnessResult, dumps, jsonable


def test_jsonable_handles_numpy_and_non_finite():
    d = jsonable({"a": np.float64(1.5), "b": np.arange(3), "c": math.inf, "d": math.nan,
                  "e": (1, np.int64(2)), "f": 1 + 2j})
    assert json.loads(json.dumps(d)) == {"a": 1.5, "b": [0, 1, 2], "c": None, "d": None,
                                         "e": [1, 2], "f": {"re": 1.0, "im": 2.0},
                                         "infinite": {"c": 1}}


def test_infinities_are_null_with_their_path_and_sign_flagged():
    d = jsonable({"K": -math.inf, "rows": [{"x": 1.0}, {"x": math.inf}], "iv": ((0.0, math.inf),),
                  "z": complex(math.inf, 0.0)})
    assert d["K"] is None and d["rows"][1]["x"] is None and d["iv"] == [[0.0, None]]
    assert d["infinite"] == {"K": -1, "rows/1/x": 1, "iv/0/1": 1, "z/re": 1}
    # strict JSON: Python's json would otherwise write the non-standard Infinity / NaN
    assert "Infinity" not in dumps({"a": math.inf, "b": math.nan})
    assert jsonable({"a": 1.0}) == {"a": 1.0}   # no flag when nothing is infinite


def test_results_round_trip_through_json():
    r = CriticalStiffnessResult(math.inf, "exact", ((0.0, math.inf),), "stable for every K", 1e-3, 0)
    d = json.loads(json.dumps(r.to_dict()))
    assert d["critical_stiffness"] is None and d["infinite"]["critical_stiffness"] == 1
    assert d["stable_intervals"] == [[0.0, None]] and d["infinite"]["stable_intervals/0/1"] == 1
    s = h.stability(h.paper_hve(stiffness=50.0)).to_dict()
    assert json.loads(json.dumps(s))["verdict"] == "stable"
    b = h.boundary(h.paper_hve(), [1e-3], [0]).to_dict()
    assert json.loads(json.dumps(b))["critical_stiffness"][0][0] > 200
