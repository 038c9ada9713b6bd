"""Every reference value says where it comes from, and the brute-force ones are
reproduced by the independent brute force (not by hapstab)."""

import pytest

from reference_data import VALUES
from references import brute


def test_every_value_has_a_loop_a_tolerance_and_a_source():
    assert VALUES
    for name, e in VALUES.items():
        assert {"value", "rel", "loop", "source"} <= set(e), name
        assert 0 < e["rel"] < 1e-2 and e["source"] and e["loop"], name


@pytest.mark.parametrize("name", [k for k, e in VALUES.items() if "brute" in e])
def test_brute_force_reproduces_the_value(name):
    e = VALUES[name]
    spec = e["brute"]
    make = brute.hve_loop if spec["kind"] == "hve" else brute.peb_loop
    got = brute.stable_intervals(make(*spec["args"], **spec.get("kwargs", {}))).kmax
    assert got == pytest.approx(e["value"], rel=e["rel"])
