"""Result objects are JSON-ready."""

import json
import math

import numpy as np

import hapstab as h
from hapstab.results import CriticalStiffnessResult, jsonable


def test_jsonable_handles_numpy_and_non_finite():
    d = jsonable({"a": np.float64(1.5), "b": np.arange(3), "c": math.inf, "d": math.nan,
                  "e": (1, np.int64(2)), "f": 1 + 2j})
    assert json.loads(json.dumps(d)) == {"a": 1.5, "b": [0, 1, 2], "c": "inf", "d": None,
                                         "e": [1, 2], "f": {"re": 1.0, "im": 2.0}}


def test_results_round_trip_through_json():
    r = CriticalStiffnessResult(math.inf, "exact", ((0.0, math.inf),), "stable for every K", 1e-3, 0)
    assert json.loads(json.dumps(r.to_dict()))["critical_stiffness"] == "inf"
    s = h.stability(h.paper_hve(stiffness=50.0)).to_dict()
    assert json.loads(json.dumps(s))["verdict"] == "stable"
    b = h.boundary(h.paper_hve(), [1e-3], [0]).to_dict()
    assert json.loads(json.dumps(b))["critical_stiffness"][0][0] > 200
