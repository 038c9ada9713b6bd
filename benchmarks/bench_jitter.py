"""Benchmark (issue 30, item 2): the jitter bracket against the obvious alternative,
Monte-Carlo simulation of random delay sequences (what Jitterbug/TrueTime-style
simulation does).

hapstab: ``hapstab.jitter`` (small-gain end + every periodic pattern of length <= 6).

Alternative, "Monte-Carlo": classify one K by simulating 200 random admissible delay
sequences (each delay grows by one half the time, else falls to any value at or below
it) for 5000 samples on hapstab's own mode matrices, from random states: "grows" if any
path's state grows by 1e6 (a stiff hand's transients reach 100 and more on a stable
loop: the state mixes positions and velocities of very different scales). Run at
0.9 x stable_up_to (stable for every sequence: a correct verdict is "bounded") and at
1.05 x unstable_from (where the reported pattern grows: a correct verdict is "grows"),
to see what random sequences find and what it
costs.

Loops: the paper's HVE (m = 0.15 kg, b = 0.1 N s/m, operator 1/s, B = 0) at T = 1 ms,
ranges 0:2, 0:10, 5:15; one resonant-hand draw of tests/network/test_network_jitter.py where a
non-constant pattern destabilises. One core: ``python benchmarks/bench_jitter.py``.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import time

import numpy as np

import hapstab as h
from hapstab.analysis.network.jitter_modes import jitter_modes, pattern_rates


def monte_carlo(loop, lo: int, hi: int, K: float, paths: int = 200, samples: int = 5000,
                seed: int = 0) -> tuple[bool, float]:
    """(some path grew by 1e6, seconds)."""
    t0 = time.perf_counter()
    jm = jitter_modes(loop, lo, hi)
    A = jm.at(K)
    index = {d[0]: i for i, d in enumerate(jm.delays)}
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((paths, jm.order))
    start = np.linalg.norm(X, axis=1)
    d = rng.integers(lo, hi + 1, paths)
    grew = False
    for _ in range(samples):
        X = np.einsum("pij,pj->pi", A[[index[int(v)] for v in d]], X)
        up = rng.random(paths) < 0.5
        d = np.where(up & (d < hi), d + 1, [int(rng.integers(lo, v + 1)) for v in d])
        if np.any(np.linalg.norm(X, axis=1) > 1e6 * start):
            grew = True
            break
    return grew, time.perf_counter() - t0


def main() -> None:
    import sys

    sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
    from tests.test_network_jitter import resonant_case

    cases = [("paper HVE 0:2", h.paper_hve(1e-3, 0), 0, 2),
             ("paper HVE 0:10", h.paper_hve(1e-3, 0), 0, 10),
             ("paper HVE 5:15", h.paper_hve(1e-3, 0), 5, 15)]
    loop, _, lo, hi = resonant_case(255)
    cases.append(("resonant draw 1255", loop, lo, hi))
    print("| loop | hapstab bracket (N/m) | time | MC at 0.9 x stable_up_to | "
          "MC at 1.05 x unstable_from | the pattern's growth per 5000 samples there |")
    print("|---|---|---|---|---|---|")
    for name, loop, lo, hi in cases:
        t0 = time.perf_counter()
        r = h.jitter(loop, (lo, hi))
        t = time.perf_counter() - t0
        below = monte_carlo(loop, lo, hi, 0.9 * r.stable_up_to) if r.stable_up_to > 0 else None
        above = monte_carlo(loop, lo, hi, 1.05 * r.unstable_from)
        b = (f"{'grows' if below[0] else 'bounded'} ({below[1]:.1f} s)" if below else "n/a")
        a = f"{'grows' if above[0] else 'bounded'} ({above[1]:.1f} s)"
        jm = jitter_modes(loop, lo, hi)
        rate = pattern_rates(jm.at(1.05 * r.unstable_from),
                             {d: i for i, d in enumerate(jm.delays)}, [r.pattern])[0]
        print(f"| {name} | [{r.stable_up_to:.6g}, {r.unstable_from:.6g}] "
              f"({r.pattern_text()}) | {t:.2f} s | {b} | {a} | {rate ** 5000:.4g} |",
              flush=True)


if __name__ == "__main__":
    main()
