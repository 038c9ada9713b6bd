"""Circle-criterion K_max (forward difference, the paper's method) for the 40
boundary points of Fig. 5 (HVE, n = 0 and 10) and Fig. 6 (PEB, n = 0 and 4),
T = 1..10 ms, on the paper's parameters. Target: under 1 s in total at 1e-6
relative accuracy; accuracy is checked against the closed forms (13), (18),
(29), (34), which are exact consequences of the forward test at B = 0.

Run: ``python benchmarks/bench_circle.py``
"""

from __future__ import annotations

import time

import numpy as np

import hapstab as h
from hapstab.analysis.conditions.circle import critical_stiffness_circle

PERIODS = np.arange(1, 11) * 1e-3
CASES = [("Fig. 5 HVE", h.paper_hve, 0, h.colgate, "(13)"), ("Fig. 5 HVE", h.paper_hve, 10, h.eq18, "(18)"),
         ("Fig. 6 PEB", h.paper_peb, 0, h.eq29, "(29)"), ("Fig. 6 PEB", h.paper_peb, 4, h.eq34, "(34)")]


def main() -> None:
    critical_stiffness_circle(h.paper_hve())  # import / first-call costs out of the timing
    loops = [(fig, n, eq, line, make(period=float(T), delay_samples=n))
             for fig, make, n, line, eq in CASES for T in PERIODS]
    t0 = time.perf_counter()
    ks = [critical_stiffness_circle(lp).critical_stiffness for *_, lp in loops]
    total = time.perf_counter() - t0
    worst = 0.0
    print(f"{'figure':<11} {'n':>3} {'T (ms)':>7} {'K_max circle':>14} {'closed form':>14} "
          f"{'eq.':>5} {'rel. err':>9}")
    for (fig, n, eq, line, lp), K in zip(loops, ks, strict=True):
        ref = line(lp).critical_stiffness
        err = abs(K - ref) / ref
        worst = max(worst, err)
        print(f"{fig:<11} {n:>3} {lp.period * 1e3:>7.0f} {K:>14.8f} {ref:>14.8f} {eq:>5} {err:>9.1e}")
    print(f"\n40 points in {total * 1e3:.1f} ms ({total / 40 * 1e3:.2f} ms per point); "
          f"worst relative error {worst:.1e} (target 1e-6); "
          f"{'PASS' if total < 1.0 and worst < 1e-6 else 'FAIL'}: under 1 s at 1e-6")


if __name__ == "__main__":
    main()
