"""Every result object follows one protocol (issue #10, step 3): it is a Result,
gives a JSON-ready dict and shows as a table in a notebook."""

import json

import numpy as np
import pytest

import hapstab as h
from hapstab.results import CriticalStiffnessResult, Result, merged


def _results():
    loop = h.paper_hve(1e-3, 2)
    peb = h.paper_peb(1e-3, 2)
    return [
        h.stability(loop.with_stiffness(50.0)),
        h.critical_stiffness(loop),
        h.critical_stiffness(loop, method="simulation"),
        h.boundary(loop, [1e-3, 2e-3], [0, 2]),
        h.sampled_passivity(peb.with_stiffness(3.0)),
        h.circle_test(loop.with_stiffness(10.0)),
        h.audit(loop),
        h.stability_region(loop, (0, 300), (0, 1), 8),
        h.best_damping(loop, resolution=8),
        h.simulate(loop.with_stiffness(50.0), 0.2),
        h.simulate(loop.with_stiffness(50.0), 0.2).verdict,
    ]


@pytest.mark.parametrize("res", _results(), ids=lambda r: type(r).__name__)
def test_every_result_is_a_result_with_json_and_html(res):
    assert isinstance(res, Result)
    d = res.to_dict()
    json.dumps(d, allow_nan=False)          # JSON-ready: no NaN, no numpy types
    page = res._repr_html_()
    assert page.startswith("<table>") and type(res).__name__ in page
    assert page.count("<tr>") == len(d)


def test_details_cannot_replace_a_key_of_the_result():
    r = CriticalStiffnessResult(1.0, "exact", ((0.0, 1.0),), "why", 1e-3, 0,
                                details={"method": "other"})
    with pytest.raises(ValueError, match="method"):
        r.to_dict()
    assert merged({"a": 1}, {"b": np.float64(2.0)}, "x") == {"a": 1, "b": 2.0}
