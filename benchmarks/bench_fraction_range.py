"""Benchmark (issue 30, item 1): the proved minimum of K_max over a continuum of delays
acting between the samples, against the grids one would otherwise compute.

- hapstab: ``fractional_range_critical_stiffness(loop, lo_s, hi_s)`` (a proved enclosure over
  the continuum, the worst delay);
- grid 1: the tests' independent brute force (tests/references/brute_fractional.py, and
  brute_fractional_peb.py for the PEB: closed-loop matrix eigenvalues and bisection,
  batched) at 1000 delays of the range: nothing proved between its points, its minimum
  at or above the continuum's;
- grid 2: the exact core's ``critical_stiffness`` at 100 delays of the range (one call
  per delay; the time of 1000 is ten times it).

Loops: the paper's HVE at 1 kHz over 5-15 ms (K_max falls with the delay: the worst is
the end), a device behind a hand (0.3 kg, 0.5 N*s/m, msd:0.5,5,500, B = 0.7 N*s/m,
1 kHz) over 2.3-5.6 ms, and the paper's PEB at 1 kHz over 5-15 ms one way (the same
delay both ways). Medians of ``REPEATS`` runs; one BLAS thread:
``python benchmarks/bench_fraction_range.py``.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np
from tests.references import brute_fractional as bf
from tests.references import brute_fractional_peb as bp

import hapstab as h
from hapstab.analysis.network import fractional_range_critical_stiffness

REPEATS = 3


def median_time(f, *a):
    """(the last result, the median wall time of REPEATS calls in s)."""
    times, out = [], None
    for _ in range(REPEATS):
        t = time.perf_counter()
        out = f(*a)
        times.append(time.perf_counter() - t)
    return out, statistics.median(times)


def cases():
    """(name, loop, the brute-force grid at delays in samples, lo_s, hi_s) of each loop."""
    hand = h.HapticLoop(h.Device(0.3, 0.5), h.SpringDamper(1.0, 0.7), "msd:0.5,5,500", 1e-3, 0)
    peb = ((0.015, 0.02, 1.0), (0.015, 0.02, 1.0))          # paper_peb: device + spring 1 N/m
    return [("paper HVE, 5-15 ms", h.paper_hve(1e-3),
             lambda ds: bf.kmax_many(0.15, 0.1, 1.0, 1e-3, ds, 0.0), 5e-3, 15e-3),
            ("hand-held device, 2.3-5.6 ms", hand,
             lambda ds: bf.kmax_many(0.8, 5.5, 500.0, 1e-3, ds, 0.7), 2.3e-3, 5.6e-3),
            ("paper PEB, 5-15 ms one way", h.paper_peb(1e-3),
             lambda ds: bp.kmax_many(peb, 1e-3, ds, (0.0, 0.0), 1.0), 5e-3, 15e-3)]


def main() -> None:
    print("| loop | hapstab [lower, upper] N/m | s | brute grid (1000) min | s | ratio | "
          "core grid (100) min | s | ratio (x10 for 1000) |")
    print("|---|---|---|---|---|---|---|---|---|")
    only = sys.argv[1:]                     # names containing any of these words, if given
    for name, loop, grid, lo, hi in cases():
        if only and not any(w in name for w in only):
            continue
        T = loop.period
        res, t1 = median_time(fractional_range_critical_stiffness, loop, lo, hi)
        ds = np.linspace(lo / T, hi / T, 1000)
        ref, t2 = median_time(grid, ds)
        assert res.critical_stiffness <= ref.min() * (1 + 1e-10)
        t = time.perf_counter()
        core = min(h.critical_stiffness(loop.with_delay_s(float(d) * T)).critical_stiffness
                   for d in np.linspace(lo / T, hi / T, 100))
        t3 = time.perf_counter() - t
        print(f"| {name} | [{res.critical_stiffness:.10g}, {res.upper_bound:.10g}] | {t1:.2f} | "
              f"{ref.min():.10g} | {t2:.2f} | {t2 / t1:.1f} | {core:.10g} | {t3:.2f} | "
              f"{10 * t3 / t1:.1f} |", flush=True)


if __name__ == "__main__":
    main()
