"""The crossing analysis: the fast K_max path equals the full one, and the safety
net finds a crossing that the candidate step did not propose."""

import numpy as np
import pytest

import hapstab as h
from hapstab.crossings import _repair, exact_kmax_batch
from hapstab.engine import build


@pytest.mark.parametrize("loop", [h.paper_hve(delay_samples=10), h.paper_peb(delay_samples=4),
                                  h.paper_hve(damping=0.05, delay_samples=2)])
def test_kmax_only_path_equals_full_path(loop):
    s = build(loop, np.geomspace(1e-4, 2e-2, 9))
    fast = [r["kmax"] for r in exact_kmax_batch(s, intervals=False)]
    full = [r["kmax"] for r in exact_kmax_batch(s, intervals=True)]
    np.testing.assert_allclose(fast, full, rtol=1e-12)


def test_repair_finds_a_withheld_crossing():
    s = build(h.paper_peb(delay_samples=4))
    A0, B1, C1 = s.A0[0], s.B1[0], s.C1[0]
    A1 = B1 @ C1
    Ks = np.linalg.norm(A0) / np.linalg.norm(A1)
    cr, u, _ = _repair(A0, A1, B1, C1, 0, [], Ks, 0)      # as if no candidate had been found
    assert cr and cr[0][0] == pytest.approx(4.0074008645888, rel=1e-9)   # polished, not bisected
    assert u[0] == 0 and u[1] == 0 and u[2] == 2
