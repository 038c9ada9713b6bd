"""The lanes' machinery itself: ``--dist loadgroup`` honours the ``xdist_group`` marks.

pytest-xdist 3.8 groups a test by appending ``@group`` to its node id; under pytest 9 the
rename is silently lost and a group's module fixture is built on both workers again
(measured: the explorer's code answers and the 52 --json outputs, twice).
"""

import pytest

pytestmark = pytest.mark.xdist_group("lanes-check")


def test_a_grouped_test_knows_its_group(request):
    if not getattr(request.config.option, "loadgroup", False):     # set on an xdist worker
        pytest.skip("only under pytest -n N --dist loadgroup (make test)")
    assert request.node.nodeid.endswith("@lanes-check"), request.node.nodeid


def test_a_draws_two_parts_are_disjoint_and_cover_it_and_costly_is_a_campaign_case():
    from lanes import FULL, PARTS, costly, part

    cases = list(range(81))
    reduced, rest = part(cases, 27, False), part(cases, 27, True)
    assert len(reduced) == 27 and sorted(reduced + rest) == cases
    assert reduced[0] == 0 and reduced[-1] == 80       # the ends kept, as draw() keeps them
    marks = [[m.name for m in p.marks] for p in PARTS]
    assert [p.values for p in PARTS] == [(False,), (True,)]
    assert marks == ([[], []] if FULL else [[], ["campaign"]])
    assert [m.name for m in costly(1, 2, id="x").marks] == ([] if FULL else ["campaign"])
