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
