"""Benchmark (issue 30): each network analysis against its obvious alternative in one
run, the median of ``REPEATS`` timings of each and their ratio.

- Delay range: ``delay_range_critical_stiffness`` over 5:15 samples (the paper's HVE,
  T = 1 ms) against a grid of the exact core's K_max at each delay of the range, one
  ``critical_stiffness`` call per delay (their minimum is the same number: checked).
- Packet loss: ``loss_critical_stiffness`` (HVE, n = 5, 5 % loss: the whole mean-square
  K_max) against Monte-Carlo simulation of the second moment (bench_network.monte_carlo:
  2000 random-loss paths x 2000 samples) for ONE verdict at 0.9 x K_max (a bisection
  needs ~30 of them, each statistical).
- Jitter: ``h.jitter`` over 0:2 samples (the paper's HVE) against random delay sequences
  (bench_jitter.monte_carlo: 200 paths x 5000 samples) at 0.9 x stable_up_to, ONE verdict.

One core: ``python benchmarks/bench_network_all.py``.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import hapstab as h
from bench_jitter import monte_carlo as jitter_mc
from bench_network import monte_carlo as loss_mc
from hapstab.analysis.network import delay_range_critical_stiffness, loss_critical_stiffness

REPEATS = 3


def median_time(f, *a):
    """(the last result, the median wall time of REPEATS calls in s)."""
    times, out = [], None
    for _ in range(REPEATS):
        t = time.perf_counter()
        out = f(*a)
        times.append(time.perf_counter() - t)
    return out, statistics.median(times)


def grid(lo: int, hi: int) -> float:
    """The exact core's K_max of the paper's HVE at every whole delay lo..hi, minimised."""
    return min(h.critical_stiffness(h.paper_hve(1e-3, n)).critical_stiffness
               for n in range(lo, hi + 1))


def main() -> None:
    hve = h.paper_hve(1e-3, 0)
    print("| analysis | hapstab | s (median) | alternative | s (median) | ratio |")
    print("|---|---|---|---|---|---|")
    res, t1 = median_time(lambda: delay_range_critical_stiffness(hve, 5, 15, seconds=False))
    ref, t2 = median_time(grid, 5, 15)
    assert abs(res.critical_stiffness - ref) <= 1e-9 * ref, (res.critical_stiffness, ref)
    print(f"| delay range 5:15 | K_max {res.critical_stiffness:.8g} N/m | {t1:.3f} | "
          f"grid of 11 exact K_max, min {ref:.8g} | {t2:.3f} | {t2 / t1:.2f} |", flush=True)
    loop = h.paper_hve(delay_samples=5).with_controllers(h.SpringDamper(1.0, 0.5))
    res, t1 = median_time(loss_critical_stiffness, loop, 0.05)
    verdict, t2 = median_time(loss_mc, loop, 0.05, 0.9 * res.critical_stiffness)
    print(f"| loss 5 %, n = 5 | K_max {res.critical_stiffness:.8g} N/m | {t1:.3f} | "
          f"Monte-Carlo, one verdict at 0.9 K_max: {'decays' if verdict else 'grows'} | "
          f"{t2:.3f} | {t2 / t1:.2f} |", flush=True)
    r, t1 = median_time(h.jitter, hve, (0, 2))
    (grew, _), t2 = median_time(jitter_mc, hve, 0, 2, 0.9 * r.stable_up_to)
    print(f"| jitter 0:2 | [{r.stable_up_to:.6g}, {r.unstable_from:.6g}] N/m | {t1:.3f} | "
          f"random sequences, one verdict at 0.9 stable_up_to: "
          f"{'grows' if grew else 'bounded'} | {t2:.3f} | {t2 / t1:.2f} |", flush=True)


if __name__ == "__main__":
    main()
