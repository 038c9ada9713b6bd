"""Benchmark of hapstab.simulate (issue 4; not a timed test).

1. 10 s of the delayed HVE of Fig. 5 (T = 1 ms, n = 10: 10,000 samples) with
   hapstab.simulate against, in the same run, the loop a user would write with
   scipy: solve_ivp between samples with the controller force held constant.
   Target: >= 100x faster, same trajectory to 1e-6 relative.
2. All 40 simulation stars of Fig. 5 and Fig. 6 (K_max by simulation). Target: < 10 s
   on one core.
3. The same 10 s with Coulomb friction on the device (f_c = 0.05 N: it slides, stops,
   sticks): hapstab's exact stick-slip stepping against the scipy loop a user would
   write (solve_ivp per sample with a terminal event where v = 0 and the stick rule).
   Target: < 2 s, same trajectory to 1e-6 relative.

Run: .venv/bin/python benchmarks/bench_simulate.py
"""

import os

# "one core": set before numpy is imported
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import sys
import time
from collections import deque

import numpy as np
from scipy.integrate import solve_ivp

import hapstab as h
from hapstab.paper.reproduce import FIGURES, PAPER_PERIODS
from hapstab.simulation import critical_stiffness_simulation, simulate

M_DEV, B_DEV, K_OP = 0.15, 0.1, 1.0       # Fig. 5 device and 1/s operator
T, N_DELAY, K, B_VIRT, F_OP, DURATION = 1e-3, 10, 8.0, 0.0, 1.0, 10.0


def scipy_user_loop(n_samples: int) -> np.ndarray:
    """What one writes by hand: sample, delay line, H(z) = K + B(z-1)/(Tz), then
    solve_ivp over one period with the force held."""
    y = np.array([0.0, 0.0])
    line = deque([0.0] * (N_DELAY + 1), maxlen=N_DELAY + 1)
    e_prev = 0.0
    xs = [y[0]]
    for k in range(n_samples):
        line.append(y[0])
        e = line[0]
        u = K * e + B_VIRT * (e - e_prev) / T
        e_prev = e
        f = F_OP - u
        sol = solve_ivp(lambda t, z, f: [z[1], (f - B_DEV * z[1] - K_OP * z[0]) / M_DEV],
                        (k * T, (k + 1) * T), y, args=(f,), rtol=1e-10, atol=1e-13)
        y = sol.y[:, -1]
        xs.append(y[0])
    return np.array(xs)


F_C = 0.05                                 # part 3: the device's Coulomb friction, N


def scipy_user_loop_friction(n_samples: int) -> np.ndarray:
    """Part 3 by hand: as :func:`scipy_user_loop`, with friction -F_C sign(v) while the
    device slides, a terminal event where v crosses 0, and there the stick rule (stuck
    while |net force| <= F_C)."""
    y = np.array([0.0, 0.0])
    line = deque([0.0] * (N_DELAY + 1), maxlen=N_DELAY + 1)
    xs = [y[0]]

    def rhs(t, z, f, s):
        return [z[1], (f - B_DEV * z[1] - K_OP * z[0] - s * F_C) / M_DEV] if s else [0.0, 0.0]

    def stop(t, z, f, s):
        return z[1]
    stop.terminal = True
    for k in range(n_samples):
        line.append(y[0])
        f = F_OP - K * line[0]
        t, t1 = k * T, (k + 1) * T
        while t < t1:
            net = f - K_OP * y[0]
            s = np.sign(y[1]) if y[1] != 0 else (0.0 if abs(net) <= F_C else np.sign(net))
            if s == 0:
                break
            stop.direction = -s
            sol = solve_ivp(rhs, (t, t1), y, args=(f, s), events=stop, rtol=1e-10, atol=1e-13)
            y, t = sol.y[:, -1].copy(), sol.t[-1]
            if sol.status == 1:
                y[1] = 0.0
        xs.append(y[0])
    return np.array(xs)


def best_of(fn, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> int:
    ok = True
    loop = h.paper_hve(T, N_DELAY, K, B_VIRT)
    t_h, res = best_of(lambda: simulate(loop, DURATION, force=F_OP), 5)
    n = res.time.size - 1
    print(f"delayed HVE, T = {T * 1e3:g} ms, n = {N_DELAY}, K = {K} N/m, {n} samples")
    t0 = time.perf_counter()
    x_ref = scipy_user_loop(n)
    t_s = time.perf_counter() - t0
    err = np.max(np.abs(res.position[:, 0] - x_ref)) / np.max(np.abs(x_ref))
    ratio = t_s / t_h
    print(f"  hapstab.simulate       : {t_h * 1e3:9.2f} ms (best of 5)")
    print(f"  scipy solve_ivp loop   : {t_s * 1e3:9.2f} ms")
    print(f"  speed-up               : {ratio:9.0f} x   (target >= 100 x)")
    print(f"  max relative difference: {err:9.2e}     (target <= 1e-6)")
    ok &= ratio >= 100 and err <= 1e-6

    loops = [FIGURES[f].make(t, d, 1.0) for f in ("fig5", "fig6") for d in FIGURES[f].delays
             for t in PAPER_PERIODS]
    t0 = time.perf_counter()
    stars = [critical_stiffness_simulation(lp).critical_stiffness for lp in loops]
    t_stars = time.perf_counter() - t0
    worst = max(abs(s / h.critical_stiffness(lp).critical_stiffness - 1)
                for s, lp in zip(stars, loops, strict=True))
    print(f"Fig. 5 + Fig. 6 simulation stars: {len(stars)} in {t_stars:.2f} s (target < 10 s); "
          f"worst |sim/exact - 1| = {worst:.1e}")
    ok &= t_stars < 10 and len(stars) == 40

    floop = h.HapticLoop(h.Device(M_DEV, B_DEV, F_C), loop.controller, loop.operator, T, N_DELAY)
    t_f, fres = best_of(lambda: simulate(floop, DURATION, force=F_OP), 3)
    t0 = time.perf_counter()
    xf = scipy_user_loop_friction(n)
    t_fs = time.perf_counter() - t0
    ferr = np.max(np.abs(fres.position[:, 0] - xf)) / np.max(np.abs(xf))
    stuck = int((fres.velocity[:, 0] == 0).sum())
    print(f"with Coulomb friction f_c = {F_C} N ({stuck} samples stuck)")
    print(f"  hapstab.simulate       : {t_f * 1e3:9.2f} ms (best of 3; target < 2 s)")
    print(f"  scipy solve_ivp + events: {t_fs * 1e3:9.2f} ms")
    print(f"  max relative difference: {ferr:9.2e}     (target <= 1e-6)")
    ok &= t_f < 2 and ferr <= 1e-6 and stuck > 0
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
