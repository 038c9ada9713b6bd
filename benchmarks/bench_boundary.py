"""Benchmark (issue 2): the 40 boundary points of Fig. 5 and Fig. 6, hapstab against
what a user would do with python-control, plus 10,000 boundary points.

Baseline per point: continuous plant -> control.sample_system(..., 'zoh'),
discrete controller with z^-n, control.feedback, control.poles, bisection on K
to 1e-6 relative. Run on one core: ``python benchmarks/bench_boundary.py``.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")          # one core, as the target says
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import statistics
import time

import numpy as np

import hapstab as h

try:
    import control
except ImportError:  # pragma: no cover
    raise SystemExit("python-control is the baseline: pip install control (make bench does)") from None

PERIODS = np.arange(1, 11) * 1e-3


def plant_tf(m: float, b: float, k: float) -> "control.TransferFunction":
    """Force to position of a device held by a spring k (the paper's operator 1/s)."""
    return control.tf([1.0], [m, b, k])


def controller(K: float, B: float, T: float, n: int) -> "control.TransferFunction":
    z = control.tf([1, 0], [1], T)
    return (K + B * (z - 1) / (T * z)) * control.tf([1], [1] + [0] * n, T)


def stable_hve(K: float, T: float, n: int) -> bool:
    Pd = control.sample_system(plant_tf(0.15, 0.1, 1.0), T, method="zoh")
    cl = control.feedback(Pd, controller(K, 0.0, T, n))
    return bool(np.max(np.abs(control.poles(cl))) < 1)


def stable_peb(K: float, T: float, n: int) -> bool:
    P = control.ss(plant_tf(0.015, 0.02, 1.0))
    Pd = control.sample_system(control.append(P, P), T, method="zoh")
    # u_m = C x_m - C z^-n x_s, u_s = -C z^-n x_m + C x_s (eq. 20), from SISO blocks
    # (a MIMO transfer matrix would need slycot to become state space)
    C, Cd = control.ss(controller(K, 0.0, T, 0)), control.ss(controller(K, 0.0, T, n))
    blocks = control.append(C, Cd, Cd, C)
    gain = lambda D: control.ss(np.zeros((0, 0)), np.zeros((0, D.shape[1])),  # noqa: E731
                                np.zeros((D.shape[0], 0)), D, T)
    inp = gain(np.array([[1.0, 0], [0, 1], [1, 0], [0, 1]]))
    out = gain(np.array([[1.0, -1, 0, 0], [0, 0, -1, 1]]))
    cl = control.feedback(Pd, out * blocks * inp)
    return bool(np.max(np.abs(control.poles(cl))) < 1)


def bisect(stable, T: float, n: int) -> float:
    lo, hi = 0.0, 1.0
    while stable(hi, T, n):
        lo, hi = hi, 2 * hi
    while hi - lo > 1e-6 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid, T, n) else (lo, mid)
    return 0.5 * (lo + hi)


def hapstab_40() -> np.ndarray:
    a = h.boundary(h.paper_hve(), PERIODS, [0, 10]).critical_stiffness
    b = h.boundary(h.paper_peb(), PERIODS, [0, 4]).critical_stiffness
    return np.vstack([a, b])


def main() -> None:
    times = []
    for _ in range(7):
        t0 = time.perf_counter()
        ours = hapstab_40()
        times.append(time.perf_counter() - t0)
    t_ours = statistics.median(times)

    t0 = time.perf_counter()
    base = np.array([[bisect(stable_hve, T, n) for T in PERIODS] for n in (0, 10)]
                    + [[bisect(stable_peb, T, n) for T in PERIODS] for n in (0, 4)])
    t_base = time.perf_counter() - t0
    err = np.max(np.abs(ours / base - 1))

    print("40 boundary points of Fig. 5 and Fig. 6 (T = 1..10 ms; HVE n = 0, 10; PEB n = 0, 4)")
    print(f"  python-control (ZOH, feedback, poles, bisection to 1e-6): {t_base:9.3f} s "
          f"= {1e3 * t_base / 40:8.2f} ms/point")
    print(f"  hapstab exact (median of {len(times)} runs):                 {t_ours:9.4f} s "
          f"= {1e3 * t_ours / 40:8.3f} ms/point")
    print(f"  ratio: {t_base / t_ours:,.0f}x faster; max relative difference {err:.2e} "
          "(the baseline's bisection tolerance is 1e-6)")

    for name, loop, n in (("HVE n = 10", h.paper_hve(), 10), ("PEB n = 4", h.paper_peb(), 4)):
        T = np.linspace(1e-3, 1e-2, 10_000)
        ts = []
        for _ in range(3):
            t0 = time.perf_counter()
            h.boundary(loop, T, [n])
            ts.append(time.perf_counter() - t0)
        print(f"10,000 boundary points, {name}: median {statistics.median(ts):.2f} s "
              "(target: under 2 s on one core)")


if __name__ == "__main__":
    main()
