"""Benchmark (issue 16): points per second of ``critical_stiffness_many`` over chunks of
1, 10, 100, 1000 and 10,000 loops, against the named baseline
``[critical_stiffness(l) for l in loops]`` on the same loops, side by side.

Two populations, as a design sweep draws them: the paper's HVE (n = 10 samples) and
PEB (n = 4 each way) with the device mass and damping, the operator's stiffness, the
sampling period and the virtual damping B drawn over decades (one structure each:
the case the batching is for), and a mixed population of every structure
(:func:`mixed`: HVE / PEB / 4-channel, filtered velocity, delays 0-10), where each
structure is its own batch. Medians over repeats (7, 5, 3 for chunks of 1, 10, 100;
one run above). The baseline is timed on every loop of chunks up to 100 and on the
first 200 loops of larger chunks (its cost per loop does not depend on the chunk).
Times are the process's CPU time (one BLAS thread), so that other work on a shared
machine does not count. Run: ``python benchmarks/bench_many.py`` (``--quick``: chunks
up to 1000).
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")          # one core
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import statistics
import sys
import time

import numpy as np

import hapstab as h
from hapstab.models.controllers import FilteredSpringDamper

CHUNKS = (1, 10, 100, 1000, 10_000)
REPEATS = {1: 7, 10: 5, 100: 3}
BASELINE_SAMPLE = 200


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(10 ** rng.uniform(np.log10(lo), np.log10(hi)))


def hve(rng: np.random.Generator):
    return h.HapticLoop(h.Device(_u(rng, 0.05, 0.5), _u(rng, 0.01, 1.0)),
                        h.SpringDamper(0.0, float(rng.uniform(0.0, 0.5))),
                        h.spring(_u(rng, 0.1, 100.0)), 1.0 / _u(rng, 500.0, 1e4), 10)


def peb(rng: np.random.Generator):
    c = h.SpringDamper(0.0, float(rng.uniform(0.0, 0.05)))
    return h.TeleoperationLoop(h.Device(_u(rng, 0.01, 0.1), _u(rng, 0.005, 0.1)),
                               h.Device(_u(rng, 0.01, 0.1), _u(rng, 0.005, 0.1)), c, c,
                               h.spring(_u(rng, 0.1, 100.0)), h.spring(_u(rng, 1.0, 1e4)),
                               1.0 / _u(rng, 500.0, 1e4), 4)


def mixed(rng: np.random.Generator):
    """Any structure: kind, delay 0-10, operator/environment type, filter."""
    k = rng.integers(4)
    n = int(rng.integers(0, 11))
    op = str(rng.choice(["none", "spring:1", "msd:0.2,1,30"]))
    T = 1.0 / _u(rng, 500.0, 1e4)
    if k == 0:
        return h.HapticLoop(h.Device(_u(rng, 0.05, 0.5), _u(rng, 0.01, 1.0)),
                            h.SpringDamper(0.0, float(rng.uniform(0, 0.5))), op, T, n)
    if k == 1:
        return h.HapticLoop(h.Device(_u(rng, 0.05, 0.5), _u(rng, 0.01, 1.0)),
                            FilteredSpringDamper(0.0, float(rng.uniform(0.01, 0.5)), "lowpass:200"),
                            op, T, n)
    c = h.SpringDamper(0.0, float(rng.uniform(0.0, 0.05)))
    dev = lambda: h.Device(_u(rng, 0.01, 0.1), _u(rng, 0.005, 0.1))  # noqa: E731
    cls = h.TeleoperationLoop if k == 2 else h.FourChannelLoop
    return cls(dev(), dev(), c, c, op, str(rng.choice(["spring:1000", "none"])), T, n % 5)


def _time(f, reps: int) -> float:
    out = []
    for _ in range(reps):
        t = time.process_time()      # CPU time: the machine is shared, wall time is not ours
        f()
        out.append(time.process_time() - t)
    return statistics.median(out)


def run(name: str, make, chunks) -> None:
    print(f"\n{name}")
    print(f"{'chunk':>7} {'batched pts/s':>14} {'per point':>10} {'baseline pts/s':>15} "
          f"{'per point':>10} {'ratio':>6}")
    for n in chunks:
        rng = np.random.default_rng(16 + n)
        loops = [make(rng) for _ in range(n)]
        reps = REPEATS.get(n, 1)
        tb = _time(lambda: h.critical_stiffness_many(loops), reps) / n   # noqa: B023
        base = loops if n <= 100 else loops[:BASELINE_SAMPLE]
        t0 = _time(lambda: [h.critical_stiffness(lp) for lp in base], reps) / len(base)  # noqa: B023
        print(f"{n:>7} {1 / tb:>14.0f} {tb * 1e3:>8.2f}ms {1 / t0:>15.0f} {t0 * 1e3:>8.2f}ms "
              f"{t0 / tb:>6.1f}")


def main() -> None:
    chunks = CHUNKS[:4] if "--quick" in sys.argv else CHUNKS
    print("critical_stiffness_many against [critical_stiffness(l) for l in loops], medians")
    run("HVE, paper's structure (n = 10), numbers over decades", hve, chunks)
    run("PEB (n = 4 each way), numbers over decades", peb, chunks)
    run("mixed structures (HVE / filtered HVE / PEB / 4-channel, delays 0-10)", mixed, chunks)


if __name__ == "__main__":
    main()
