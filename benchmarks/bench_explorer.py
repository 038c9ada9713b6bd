"""Benchmark (issue 15): the explorer's API against its named baseline, the CLI run as a
process (``hapstab kmax hve ... --json``: what a script or another tool would do per
input change without the server).

Measures, for the HVE and the PEB (n = 4, B = 0.5, the page's other defaults), medians
of N rounds over HTTP to a running ``hapstab explore`` (a separate process, keep-alive):

(a) one input change: the requests the page sends for it, at once, as the page does:
    verdict + K_max (``check`` and ``kmax``: what the 100 ms target is about), then the
    whole set (+ ``passivity`` with a 400-point margin curve and ``audit``);
(b) the K-B region at the page's default resolution (60 x 60, no overlay; target < 1 s)
    and at 200 x 200.

Run: ``python benchmarks/bench_explorer.py`` (PYTHONPATH=src for a source tree).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import httpx

N = 15
MODELS = {"hve": {"delay": 4, "virtual-damping": 0.5},
          "peb": {"delay": 4, "virtual-damping": 0.5}}


def start_server() -> tuple[subprocess.Popen, str]:
    p = subprocess.Popen([sys.executable, "-m", "hapstab", "explore", "--port", "0"],
                         stdout=subprocess.PIPE, text=True, env=os.environ.copy())
    assert p.stdout is not None
    line = p.stdout.readline()
    if not line.startswith("hapstab explorer: "):
        p.kill()
        raise SystemExit(f"the explorer did not start: {line!r}")
    return p, line.split(": ", 1)[1].strip()


def cli_baseline(kind: str, options: dict) -> float:
    argv = [sys.executable, "-m", "hapstab", "kmax", kind,
            *[f"--{k}={v}" for k, v in options.items()], "--json"]
    ts = []
    for _ in range(5):
        t0 = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def timed_batch(client: httpx.Client, pool: ThreadPoolExecutor, url: str,
                batch: list[tuple[str, dict]], kind: str) -> float:
    """Seconds until every request of ``batch`` (sent at once) has its answer."""
    def one(item: tuple[str, dict]) -> None:
        command, options = item
        r = client.post(f"{url}api/v1/{command}", json={"kind": kind, "options": options},
                        timeout=60)
        if r.status_code != 200:
            raise SystemExit(f"{command}: {r.status_code} {r.text}")

    t0 = time.perf_counter()
    list(pool.map(one, batch))
    return time.perf_counter() - t0


def median_of(client: httpx.Client, pool: ThreadPoolExecutor, url: str,
              batch: list[tuple[str, dict]], kind: str, n: int = N) -> float:
    """Median seconds of ``n`` rounds of ``batch`` (after one to warm up)."""
    timed_batch(client, pool, url, batch, kind)
    return statistics.median(timed_batch(client, pool, url, batch, kind) for _ in range(n))


def main() -> None:
    server, url = start_server()
    try:
        with httpx.Client() as client, ThreadPoolExecutor(8) as pool:
            for kind, model in MODELS.items():
                headline = [("check", {**model, "stiffness": 5.0}), ("kmax", model)]
                change = [*headline, ("passivity", {**model, "stiffness": 5.0, "curve": 400}),
                          ("audit", model)]
                plain = {k: v for k, v in model.items() if k != "virtual-damping"}  # it varies B
                region = [("region", {**plain, "K": "0:40", "B": "0:2", "resolution": 60,
                                      "overlay": "none"})]
                region200 = [("region", {**plain, "K": "0:40", "B": "0:2", "resolution": 200,
                                         "overlay": "none"})]
                t_cli = cli_baseline(kind, model)
                t_kmax = median_of(client, pool, url, [headline[1]], kind)
                t_head = median_of(client, pool, url, headline, kind)
                t_change = median_of(client, pool, url, change, kind)
                t_region = median_of(client, pool, url, region, kind, 5)
                t_r200 = median_of(client, pool, url, region200, kind, 3)
                print(f"{kind}: baseline CLI process `hapstab kmax {kind} --json`: "
                      f"{t_cli * 1e3:.0f} ms; API kmax {t_kmax * 1e3:.1f} ms "
                      f"({t_cli / t_kmax:.0f}x faster)")
                print(f"{kind}: one input change, verdict + K_max: {t_head * 1e3:.1f} ms "
                      f"(target < 100 ms); + passivity curve + audit: {t_change * 1e3:.1f} ms")
                print(f"{kind}: K-B region 60 x 60: {t_region * 1e3:.0f} ms (target < 1 s); "
                      f"200 x 200: {t_r200 * 1e3:.0f} ms")
    finally:
        server.terminate()
        server.wait(20)


if __name__ == "__main__":
    main()
