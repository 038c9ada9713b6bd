"""Benchmark (issue 14, item 3): robust K_max over a box of operators, certified, beside
what a user would do otherwise: the exact K_max at a dense grid of operators (no
certificate between grid points, and a grid of 20^3 = 8000 operators costs more).

Run on one core: ``python benchmarks/bench_robust.py``.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import time

import numpy as np

import hapstab as h
from hapstab.analysis.exact.crossings import analyse
from hapstab.engine.frequency import loop_response, stack_responses

CASES = [
    ("HVE, n = 20, +-10 % box",
     h.HapticLoop(h.Device(0.3, 0.5), h.SpringDamper(0.0, 0.0), period=1e-3, delay_samples=20),
     h.operator_box(mass=(0.45, 0.55), damping=(4.5, 5.5), stiffness=(450.0, 550.0))),
    ("PEB, n = 2, +-10 % box",
     h.TeleoperationLoop(h.Device(0.3, 0.5), h.Device(0.3, 0.5), h.SpringDamper(0, 0),
                         h.SpringDamper(0, 0), operator=h.spring(1.0),
                         environment=h.spring(1000.0), period=1e-3, delay_samples=2),
     h.operator_box(mass=(0.45, 0.55), damping=(4.5, 5.5), stiffness=(450.0, 550.0))),
    ("HVE, minimum inside an edge",
     h.HapticLoop(h.Device(0.01, 0.0251), h.SpringDamper(0.0, 0.0), period=4.52e-3,
                  delay_samples=6),
     h.operator_box(mass=0.0, damping=(0.15, 0.25), stiffness=(600.0, 760.0))),
]


def grid_min(loop, box, n: int) -> tuple[float, float]:
    """The smallest exact K_max over an n^d grid of the box (batched), and its time."""
    axes = [np.linspace(a, b, n if b > a else 1) for a, b in zip(box.lo, box.hi, strict=True)]
    P = np.array(np.meshgrid(*axes, indexing="ij")).reshape(3, -1).T
    t0 = time.perf_counter()
    resps = [loop_response(loop.replace(operator=h.mass_spring_damper(*p))) for p in P]
    K = min(r.kmax for r in analyse(stack_responses(resps), full=False))
    return K, time.perf_counter() - t0


def main() -> None:
    print(f"{'case':32s} {'robust (certified)':>20s} {'s':>6s} {'boxes':>6s} "
          f"{'20^d grid min':>14s} {'s':>6s} {'vertices':>12s}")
    for name, loop, box in CASES:
        t0 = time.perf_counter()
        r = h.robust_critical_stiffness(loop, box)
        t = time.perf_counter() - t0
        g, tg = grid_min(loop, box, 20)
        print(f"{name:32s} {r.critical_stiffness:20.10g} {t:6.2f} {r.boxes:6d} {g:14.10g} "
              f"{tg:6.2f} {r.vertex_minimum:12.8g}")


if __name__ == "__main__":
    main()
