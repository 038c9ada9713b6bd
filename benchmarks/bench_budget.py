"""Benchmark (issue 11): the cost model against the measured cost.

For each computation the budget estimates before it starts, this prints the estimated
time (``hapstab.budget``) beside the measured median of 3 runs, and their ratio. A
budget needs the estimate right within a factor of a few, and rather above than below
(ratio >= 1 means the estimate is safe). Run on one core:
``python benchmarks/bench_budget.py``.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import statistics
import time

import hapstab as h
from hapstab import budget
from hapstab.analysis.design.regions import _region_cost
from hapstab.engine.system import build
from hapstab.simulation.search import critical_stiffness_simulation, search_cost


def median_time(f, reps=3):
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def cases():
    for n in (10, 100, 400):
        loop = h.paper_hve(1e-3, n).with_stiffness(0.5)
        s = build(loop)
        yield (f"stability, HVE n = {n}", lambda lp=loop: h.stability(lp),
               budget.EIG_SECONDS_PER_N3 * s.order ** 3)
        yield (f"simulate 20 s, HVE n = {n}", lambda lp=loop: h.simulate(lp, 20.0),
               budget.simulation_cost(20000, s.order, s.n_ports).seconds)
    for n in (10, 100):
        loop = h.paper_hve(1e-3, n)
        yield (f"K_max search by simulation, HVE n = {n}",
               lambda lp=loop: critical_stiffness_simulation(lp), search_cost(loop).seconds)
        yield (f"region 100 x 100, HVE n = {n}",
               lambda lp=loop: h.stability_region(lp, (0, 900), (0, 20), 100),
               _region_cost(loop, 100).seconds)


def main():
    print(f"{'computation':45s} {'estimate':>10s} {'measured':>10s} {'ratio':>7s}")
    for name, f, est in cases():
        t = median_time(f)
        print(f"{name:45s} {est:9.3g}s {t:9.3g}s {est / t:7.2f}")


if __name__ == "__main__":
    main()
