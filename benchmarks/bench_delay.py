"""Benchmark (issue 8): the cost of an exact K_max as the delay grows, against a naive
eigenvalue bisection of the same loop, and 10,000 boundary points.

Baseline ("naive eigenvalue bisection", what the issue timed): the closed-loop matrix
of the loop (hapstab's own state-space engine, N = n + a few states),
``numpy.linalg.eigvals`` at each trial K, a geometric scan of 400 K from 1e-3 to
1e7 N/m up to the first unstable one, then bisection to 1e-6 relative. Where one
solve takes longer than 50 ms, the baseline is the number of solves it would make
times the median of 3 timed solves, and is marked "extrapolated".

hapstab: ``exact_kmax_batch(loop, intervals=False)`` (K_max only) and
``critical_stiffness(loop)`` (every stable interval), medians of repeated runs; peak
memory of one K_max call by ``tracemalloc`` (numpy reports its buffers to it).

Loops: HVE m = 0.3 kg, b = 2 N s/m, operator msd:0.5,5,500, T = 1 ms; the paper's
PEB (Fig. 6 parameters), T = 1 ms. Run on one core: ``python benchmarks/bench_delay.py``.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import statistics
import time
import tracemalloc
from functools import partial

import numpy as np

import hapstab as h
from hapstab.analysis.exact.core import exact_kmax_batch
from hapstab.engine.system import build

DELAYS = (10, 100, 300, 1000)
SCAN = 400          # geometric scan points of the naive method over 1e-3 ... 1e7 N/m


def loops(n: int):
    hve = h.HapticLoop(h.Device(0.3, 2.0), h.SpringDamper(1.0), h.mass_spring_damper(0.5, 5, 500),
                       1e-3, n)
    return {"hve": hve, "peb": h.paper_peb(delay_samples=n)}


def median_time(f, repeat: int) -> float:
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def naive(loop, kmax: float) -> tuple[float, float, str]:
    """(seconds, K found, note) of the naive method: eigenvalues of the closed-loop
    matrix on a geometric scan of K (SCAN points over 1e-3 ... 1e7 N/m, stopping at
    the first unstable one) and bisection of that bracket to 1e-6 relative. Where one
    solve takes longer than 50 ms the time is the number of solves it would make
    times the median of 3 timed solves ("extrapolated")."""
    s = build(loop)
    A0, A1 = s.A0[0], (s.B1 @ s.C1)[0]
    grid = np.geomspace(1e-3, 1e7, SCAN)
    first = int(np.searchsorted(grid, kmax))          # scan points up to the bracket
    solves = first + 1 + int(np.ceil(np.log2((grid[1] / grid[0] - 1) / 1e-6)))
    t1 = time.perf_counter()
    np.linalg.eigvals(A0 + kmax * A1)
    if time.perf_counter() - t1 > 0.05:
        ts = [median_time(lambda: np.linalg.eigvals(A0 + kmax * A1), 1) for _ in range(3)]
        return solves * statistics.median(ts), float("nan"), "extrapolated"
    rho = lambda K: np.abs(np.linalg.eigvals(A0 + K * A1)).max()  # noqa: E731
    t = time.perf_counter()
    lo = 0.0
    for K in grid:
        if rho(K) >= 1:
            hi = K
            break
        lo = K
    while hi - lo > 1e-6 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if rho(mid) < 1 else (lo, mid)
    return time.perf_counter() - t, lo, "measured"


def main() -> None:
    print(f"{'loop':4} {'n':>5} {'N':>5} | {'naive bisection':>17} | {'hapstab K_max':>13} "
          f"{'ratio':>7} {'peak MB':>8} | {'all intervals':>13} | agree")
    for n in DELAYS:
        for name, loop in loops(n).items():
            N = build(loop).order
            rep = 5 if n <= 300 else 3
            k = exact_kmax_batch(loop, intervals=False)[0].kmax
            t_fast = median_time(partial(exact_kmax_batch, loop, intervals=False), rep)
            t_full = median_time(partial(h.critical_stiffness, loop), max(1, rep // 2))
            tracemalloc.start()
            exact_kmax_batch(loop, intervals=False)
            peak = tracemalloc.get_traced_memory()[1] / 2**20
            tracemalloc.stop()
            t_naive, k_naive, note = naive(loop, k)
            agree = "n/a" if np.isnan(k_naive) else f"{abs(k_naive / k - 1):.1e}"
            print(f"{name:4} {n:5d} {N:5d} | {t_naive * 1e3:10.0f} ms {note[:5]:>5} | "
                  f"{t_fast * 1e3:10.1f} ms {t_naive / t_fast:6.0f}x {peak:8.1f} | "
                  f"{t_full * 1e3:10.0f} ms | {agree}", flush=True)
    T = np.linspace(1e-4, 2e-2, 10_000)
    for name, loop, n in (("hve", h.paper_hve(), 10), ("peb", h.paper_peb(), 4)):
        t = median_time(partial(h.boundary, loop, T, [n]), 3)
        print(f"10,000 boundary points, paper {name} (n = {n}): {t:.2f} s "
              f"({t / T.size * 1e6:.0f} us per point)", flush=True)
    long_verdicts()


def long_verdicts() -> None:
    """stability() at K = K_max / 2 as the delay grows: past 1,000 states the certified
    count and Newton's dominant pole (analysis/exact/long_poles.py) against the dense
    eigenvalues of the closed-loop matrix a user would take (numpy.linalg.eigvals; one
    timed solve, skipped past 4,000 states), with the spectral radii's difference."""
    print(f"{'loop':4} {'n':>6} {'N':>6} | {'numpy eigvals':>13} | {'hapstab stability':>17} "
          f"{'ratio':>7} | rho difference", flush=True)
    for n in (1000, 2000, 10_000):
        for name, loop in loops(n).items():
            k = exact_kmax_batch(loop, intervals=False)[0].kmax
            at = loop.with_stiffness(0.5 * k)
            t_h = median_time(partial(h.stability, at), 3)
            rho = h.stability(at).spectral_radius
            N = 2 * n + 8 if name == "peb" else n + 4           # about (build refuses 10^4)
            if N <= 4000:
                A = build(at).closed_loop()[0]
                t0 = time.perf_counter()
                ev = np.linalg.eigvals(A)
                t_e = time.perf_counter() - t0
                diff = f"{abs(np.abs(ev).max() / rho - 1):.1e}"
                te, ratio = f"{t_e * 1e3:10.0f} ms", f"{t_e / t_h:6.0f}x"
            else:
                te, ratio, diff = "   (skipped)", "     -", "-"
            print(f"{name:4} {n:6d} {N:6d} | {te:>13} | {t_h * 1e3:14.0f} ms {ratio:>7} | {diff}",
                  flush=True)


if __name__ == "__main__":
    main()
