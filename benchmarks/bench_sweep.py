"""Benchmark (issue 16): points per second of ``hapstab sweep`` on a realistic design
space, with 1 worker (in this process, no Dask) and 2 local workers (a Dask
LocalCluster of 2 processes, as ``--workers 2`` starts it; the rate is on the running
cluster, its start printed beside it), against the named baseline: calling
``critical_stiffness`` in a Python loop, timed on an evenly spaced sample of the same
points and scaled to all of them (said in the output).

The space (the CLI's own study file and loop builder, K_max per point): an HVE device
with an operator (mass 0.05...2 kg, damping 0.01...2 N*s/m, rate 250 Hz...4 kHz, delay
0...45 samples, virtual damping 0...2 N*s/m; 10 values each: 10^5 points), and a PEB
teleoperator (master and slave 0.01...1 kg, rate, delay 0...18 samples, B) at a tenth
of the points.

Run: ``python benchmarks/bench_sweep.py [points]`` (default 100000; the PEB space is a
tenth of it). One BLAS thread per process.
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import statistics
import sys
import tempfile
import time

import click

import hapstab as h
from hapstab.cli.main import cli
from hapstab.cli.study import load_study
from hapstab.cli.sweep import plan
from hapstab.sweep.run import sweep

HVE = '''kind = "hve"
[loop]
operator = "msd:0.5,5,500"
[sweep]
quantities = ["kmax"]
[sweep.axes]
mass = "0.05:2:{n}:log"
damping = "0.01:2:{n}:log"
rate = "250Hz:4kHz:{n}:log"
delay = "0:{d}:{n}"
virtual-damping = "0:2:{n}"
'''
PEB = '''kind = "peb"
[loop]
operator = "msd:0.5,5,500"
environment = "spring:1000"
[sweep]
quantities = ["kmax"]
[sweep.axes]
master-mass = "0.01:1:{n}:log"
slave-mass = "0.01:1:{n}:log"
rate = "250Hz:4kHz:{n}:log"
delay = "0:{d}:{n}"
virtual-damping = "0:2:{n}"
'''
#: Points of the baseline's sample (evenly spaced over the point ids).
SAMPLE = 300


def _args(text: str, folder: str) -> tuple[dict, str]:
    path = os.path.join(folder, "study.toml")
    with open(path, "w") as fh:
        fh.write(text)
    study = load_study(path)
    assert isinstance(cli, click.Group)
    return plan(study, cli, yes=True), study.text


def _timed_sweep(args: dict, text: str, workers: int) -> tuple[float, float]:
    """Seconds of the sweep, and of starting its Dask cluster (2 workers: a LocalCluster
    started as ``hapstab sweep --workers 2`` starts it, then the sweep on it)."""
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "out")
        if workers == 1:
            t0 = time.perf_counter()
            res = sweep(out=out, workers=1, study=text, **args)
            return time.perf_counter() - t0, 0.0
        from dask.distributed import LocalCluster

        from hapstab.sweep.cluster import _fast_malloc

        t0 = time.perf_counter()
        with _fast_malloc():
            cluster = LocalCluster(n_workers=workers, processes=True, threads_per_worker=1,
                                   dashboard_address=None, silence_logs=50)
        start = time.perf_counter() - t0
        with cluster:
            t0 = time.perf_counter()
            res = sweep(out=out, scheduler=cluster.scheduler_address, study=text, **args)
            dt = time.perf_counter() - t0
        assert res.summary["points"] == res.manifest["points"]
    return dt, start


def _baseline(args: dict, count: int) -> float:
    """Median seconds per point of critical_stiffness in a Python loop, on SAMPLE points."""
    from hapstab.sweep.axes import Points

    points = Points(tuple(args["axes"]))
    per = []
    for k in range(SAMPLE):
        i = k * count // SAMPLE
        v = points.values(i, i + 1)
        loop = args["build"]({**args["fixed"], **{n: a.tolist()[0] for n, a in v.items()}})
        t0 = time.perf_counter()
        h.critical_stiffness(loop)
        per.append(time.perf_counter() - t0)
    return statistics.median(per), statistics.mean(per)


def main() -> None:
    total = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    print(f"hapstab sweep, K_max per point; {os.cpu_count()} cores (shared machine: noisy)")
    print(f"{'space':6s} {'points':>8s} {'1 worker pt/s':>14s} {'2 workers pt/s':>15s} "
          f"{'efficiency':>10s} {'loop pt/s':>10s} {'x loop (1w)':>11s} {'x loop (2w)':>11s}")
    for name, text, share, d in (("HVE", HVE, 1.0, 45), ("PEB", PEB, 0.1, 18)):
        n = max(2, round((total * share) ** 0.2))
        with tempfile.TemporaryDirectory() as folder:
            args, study = _args(text.format(n=n, d=d), folder)
            count = n ** 5
            t1, _ = _timed_sweep(args, study, 1)
            t2, start = _timed_sweep(args, study, 2)
            med, mean = _baseline(args, count)
        loop_t = mean * count            # the Python loop over every point, scaled
        r1, r2 = count / t1, count / t2
        print(f"{name:6s} {count:8d} {r1:14.0f} {r2:15.0f} {r2 / (2 * r1):10.2f} "
              f"{1 / mean:10.0f} {loop_t / t1:11.1f} {loop_t / t2:11.1f}")
        print(f"       1 worker {t1:.1f} s, 2 workers {t2:.1f} s (+ {start:.1f} s to start the "
              f"cluster; with it {count / (t2 + start):.0f} pt/s); the "
              f"loop timed on {SAMPLE} of the points: median {med * 1e3:.2f} ms, mean "
              f"{mean * 1e3:.2f} ms a point, scaled to {count}: {loop_t:.0f} s")


if __name__ == "__main__":
    main()
