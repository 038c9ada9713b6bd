"""Benchmark (issue 5): a 200 x 200 K-B region of the delayed HVE (n = 10), exact
boundary plus Schur-Cohn cross-check grid, against what a user would do otherwise:
the spectral radius at every grid point (numpy eigenvalues, batched).

Run on one core: ``python benchmarks/bench_regions.py``.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import statistics
import time

import numpy as np

import hapstab as h
from hapstab.analysis.design.regions import stability_region, with_gains
from hapstab.engine.system import build

LOOP = h.paper_hve(delay_samples=10)
K, B, RES = (0.0, 900.0), (0.0, 20.0), 200


def brute_grid() -> np.ndarray:
    Ks, Bs = np.linspace(*K, RES), np.linspace(*B, RES)
    out = np.zeros((RES, RES), bool)
    for i, b in enumerate(Bs):
        s = build(with_gains(LOOP, 0.0, float(b)))
        A = s.A0[0][None] + Ks[:, None, None] * (s.B1 @ s.C1)[0][None]
        out[i] = np.abs(np.linalg.eigvals(A)).max(axis=1) < 1
    return out


def main() -> None:
    ts = []
    for _ in range(5):
        t0 = time.perf_counter()
        res = stability_region(LOOP, K, B, RES)
        ts.append(time.perf_counter() - t0)
    t_ours = statistics.median(ts)
    t0 = time.perf_counter()
    grid = brute_grid()
    t_brute = time.perf_counter() - t0
    Ks = res.K_grid
    margin = res.agreement["margin_N_per_m"]
    near = np.zeros_like(grid)
    for i, iv in enumerate(res.intervals):
        for e in {e for pair in iv for e in pair if np.isfinite(e)}:
            near[i] |= np.abs(Ks - e) <= margin
    diff = grid != res.stable_exact
    print(f"200 x 200 K-B region, delayed HVE (n = 10), K in {K} N/m, B in {B} N*s/m")
    print(f"  eigenvalues at every grid point (batched numpy):   {t_brute:7.3f} s")
    print(f"  hapstab (exact rows + boundary + Schur-Cohn grid), median of 5: {t_ours:7.3f} s "
          "(target: under 2 s on one core)")
    print(f"  ratio {t_brute / t_ours:.1f}x; grid check vs exact: {res.agreement['disagree']} of "
          f"{res.agreement['compared']} differ away from the boundary;\n  brute-force eigenvalue grid vs "
          f"exact: {int(diff.sum())} points differ, {int((diff & ~near).sum())} of them farther than "
          f"{margin:g} N/m from the exact boundary")


def overlays() -> None:
    """The region's passivity and circle overlays: every row at once (hapstab since
    session 16) against row by row, critical_stiffness(method=...) of each row's loop
    (what hapstab did before, and what a user of the single-loop API writes)."""
    import contextlib

    from hapstab.analysis.design.regions import _overlay
    from hapstab.analysis.methods import critical_stiffness
    loop = h.HapticLoop(h.Device(0.3, 0.5), operator=h.mass_spring_damper(0.5, 5, 500),
                        period=1e-3).with_delay_s(0.02)      # the README's region command
    Bs = np.linspace(0.0, 20.0, RES)
    print(f"overlays of the README's region (0.3 kg, 20 ms), {RES} rows of B:")
    for name in ("passivity", "circle"):
        ts = []
        for _ in range(3):
            t0 = time.perf_counter()
            got = _overlay(loop, name, Bs)
            ts.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        ref = np.full(Bs.size, np.nan)
        for i, b in enumerate(Bs):
            with contextlib.suppress(h.HapstabError):
                ref[i] = critical_stiffness(with_gains(loop, 1.0, float(b)),
                                            method=name).critical_stiffness
        t_rows = time.perf_counter() - t0
        rel = float(np.nanmax(np.abs(got - ref) / np.maximum(np.abs(ref), 1e-300)))
        print(f"  {name:9s} all rows at once (median of 3) {statistics.median(ts):7.3f} s; "
              f"row by row {t_rows:7.3f} s; ratio {t_rows / statistics.median(ts):5.1f}x; "
              f"largest relative difference {rel:.1e}")


if __name__ == "__main__":
    main()
    overlays()
