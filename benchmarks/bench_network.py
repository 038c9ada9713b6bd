"""Benchmark (issue 30): mean-square K_max with packet loss against the obvious
alternatives, and how its cost grows with the delay.

hapstab: ``loss_critical_stiffness`` (the first real root of det(I - T(K)) = 0 of the
second-moment operator, QZ on the symmetric-reduced companion pencil; ARPACK scan above
``MAX_PENCIL``).

Alternative 1, "Kronecker scan": the dense Kronecker operator sum_i pi_i A_i (x) A_i
(hapstab's own mode matrices), ``numpy.linalg.eigvals`` at each trial K of a 128-point
scan up to 4 x the loss-free K_max, then bisection to 1e-9 relative.

Alternative 2, "Monte-Carlo": classify one K (0.9 x the answer) as decaying by
simulating 2000 random-loss paths for 2000 samples (what Jitterbug/TrueTime-style
simulation does): the time of that one verdict, and whether the sample second moment
says "decays" (a bisection needs ~30 such verdicts; each is statistical).

Loops: the paper's HVE (m = 0.15 kg, b = 0.1 N s/m, operator 1/s, B = 0.5 N s/m) at
T = 1 ms, loss 5 %, delays n = 0 ... 40; the paper's PEB at n = 2, loss 5 %, with and
without bursts. One core: ``python benchmarks/bench_network.py``.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import time

import numpy as np

import hapstab as h
from hapstab.analysis.network import loss_critical_stiffness
from hapstab.analysis.network.jump import lossy_system


def kron_scan(loop, P: float) -> float:
    js = lossy_system(loop, P)
    k0 = h.critical_stiffness(loop).critical_stiffness

    def rho(K: float) -> float:
        A = js.at(K)
        op = sum(js.stationary[i] * np.kron(A[i], A[i]) for i in range(js.modes))
        return float(np.abs(np.linalg.eigvals(op)).max())

    lo = 0.0
    for K in np.linspace(4 * k0 / 128, 4 * k0, 128):
        if rho(K) >= 1:
            hi = K
            break
        lo = K
    else:
        return float("inf")
    while hi - lo > 1e-9 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if rho(mid) < 1 else (lo, mid)
    return lo


def monte_carlo(loop, P: float, K: float, paths: int = 2000, steps: int = 2000) -> bool:
    rng = np.random.default_rng(1)
    js = lossy_system(loop, P)
    A = js.at(K)
    S = rng.standard_normal((paths, js.order))
    m0 = np.mean(np.sum(S * S, axis=1))
    bits = int(np.log2(js.modes))
    for _ in range(steps):
        idx = (rng.random((paths, bits)) < P).astype(int) @ (2 ** np.arange(bits))
        S = np.einsum("pij,pj->pi", A[idx], S)
    return bool(np.mean(np.sum(S * S, axis=1)) < m0)


def timed(f, *a):
    t = time.perf_counter()
    out = f(*a)
    return out, time.perf_counter() - t


def main() -> None:
    print("HVE, loss 5 %: hapstab (roots) against the Kronecker scan")
    print(f"{'n':>4} {'N':>4} {'hapstab K_max':>16} {'s':>8} {'scan K_max':>16} {'s':>8}")
    for n in (0, 5, 10, 20, 30, 40):
        loop = h.paper_hve(delay_samples=n).with_controllers(h.SpringDamper(1.0, 0.5))
        res, t1 = timed(loss_critical_stiffness, loop, 0.05)
        if n <= 20:
            ref, t2 = timed(kron_scan, loop, 0.05)
            alt = f"{ref:16.10g} {t2:8.2f}"
        else:
            alt = f"{'(not run)':>16} {'':>8}"
        print(f"{n:4d} {res.order:4d} {res.critical_stiffness:16.10g} {t1:8.2f} {alt}")
    loop = h.paper_hve(delay_samples=5).with_controllers(h.SpringDamper(1.0, 0.5))
    res = loss_critical_stiffness(loop, 0.05)
    verdict, t = timed(monte_carlo, loop, 0.05, 0.9 * res.critical_stiffness)
    print(f"Monte-Carlo verdict at 0.9 K_max (n = 5): decays = {verdict}, {t:.2f} s for one K "
          f"(hapstab's whole K_max: {res.seconds:.2f} s)")
    print("PEB (paper), n = 2, loss 5 %")
    for L in (None, 3.0):
        res, t = timed(loss_critical_stiffness, h.paper_peb(delay_samples=2), 0.05, L)
        print(f"  burst {L}: K_max {res.critical_stiffness:.10g} N/m in {t:.2f} s "
              f"({res.search}, N = {res.order}, {res.modes} modes)")


if __name__ == "__main__":
    main()
