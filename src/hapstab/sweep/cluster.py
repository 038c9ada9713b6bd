"""The chunks of a sweep on Dask: a :class:`dask.distributed.LocalCluster` of processes
(one thread each), or a client of an existing cluster. Tasks are chunks; at most a few
per worker are in flight, more are submitted as results arrive (so that a sweep of 10^5
chunks does not hold 10^5 futures), and the results are handed back in the order they
finish."""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterator
from typing import Any

from hapstab.sweep.axes import SweepError
from hapstab.sweep.evaluate import Spec, evaluate_chunk

__all__ = ["on_dask", "check_address", "CONNECT_TIMEOUT_S"]

#: Seconds to reach a scheduler before giving up (one line, exit 2).
CONNECT_TIMEOUT_S = 10
#: Tasks in flight per worker thread.
IN_FLIGHT = 4
_ADDRESS = re.compile(r"^(?:(?:tcp|tls|ucx|ws|wss)://)?"
                      r"(?:[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?|\[[0-9A-Fa-f:.]+\]):\d{1,5}$")


def check_address(address: Any) -> str:
    """A scheduler's address, ``[tcp://]host:port``.

    Parameters
    ----------
    address : str

    Returns
    -------
    str

    Raises
    ------
    SweepError
        Not of that form.
    """
    if not isinstance(address, str) or not _ADDRESS.match(address.strip()):
        raise SweepError(f"--scheduler = {address!r:.80}: a Dask scheduler's address is "
                         "[tcp://]host:port (e.g. tcp://10.0.0.5:8786)")
    return address.strip()


def on_dask(spec: Spec, todo: list[int], workers: int, scheduler: str | None
            ) -> Iterator[tuple[int, dict[str, list[Any]]]]:
    """Evaluate the chunks ``todo`` on Dask; yield (chunk, columns) as they finish.

    Parameters
    ----------
    spec : Spec
    todo : list of int
        The chunks to evaluate.
    workers : int
        Local worker processes (ignored with ``scheduler``).
    scheduler : str or None
        An existing scheduler's address.

    Yields
    ------
    (int, dict)
    """
    from dask.distributed import Client, LocalCluster

    cluster = client = None
    try:
        try:
            if scheduler is None:
                with _fast_malloc(), _ctrl_c_after_start():
                    cluster = LocalCluster(n_workers=workers, processes=True,
                                           threads_per_worker=1, **NO_DASHBOARD,
                                           silence_logs=50)
                client = Client(cluster)
            else:
                client = _connect(check_address(scheduler))
        except (SweepError, KeyboardInterrupt):
            raise
        except Exception as e:         # (dask's own errors: one line, the address named)
            raise SweepError(f"{'--scheduler = ' + repr(scheduler) if scheduler else '--workers'}"
                             f": cannot start Dask ({type(e).__name__}: "
                             f"{' '.join(str(e).split())[:200]})") from None
        yield from _stream(client, spec, todo)
    except BaseException:              # a Ctrl-C or SIGTERM mid-start or mid-run
        with _quiet_asyncio():
            _close(client, cluster)
        raise
    _close(client, cluster)


def _close(client: Any, cluster: Any) -> None:
    """Close the client, then the local cluster (every process and socket)."""
    if client is not None:
        client.close()
    if cluster is not None:
        cluster.close()


@contextlib.contextmanager
def _quiet_asyncio() -> Iterator[None]:
    """Closing a cluster interrupted mid-request (a Ctrl-C during the spec's scatter) left
    the scheduler's task to fail against a worker already gone, and asyncio logged it
    ("Task exception was never retrieved", a traceback) when it was collected: the run
    was stopped by the user, its tasks' failures are not news. Held until collected."""
    import gc
    import logging

    log = logging.getLogger("asyncio")
    level = log.level
    log.setLevel(logging.CRITICAL + 1)
    try:
        yield
        gc.collect()
    finally:
        log.setLevel(level)


@contextlib.contextmanager
def _ctrl_c_after_start() -> Iterator[None]:
    """SIGINT blocked in this thread while the local cluster starts, delivered after it.

    A Ctrl-C on a terminal goes to the whole process group: to the worker processes too,
    which then died mid-import with their tracebacks, and Dask's half-started cluster
    printed "Nanny failed to start" and its own at exit (issue 27, 11). The cluster's
    event-loop thread is made inside ``LocalCluster()`` and inherits this thread's signal
    mask, and the workers it spawns inherit it across ``exec``: they never take the
    terminal's Ctrl-C (the cluster ends them). Here a Ctrl-C during the start is held
    (pending) until the cluster is whole, then raised, so the caller closes a whole
    cluster and the CLI says one line (exit 130).

    The first process spawned starts multiprocessing's resource tracker, which blocks
    SIGINT around its own spawn and then *unblocks* it (not restores it) in the spawning
    thread: Dask's event-loop thread, whose Ctrl-C mask every worker then lost, so a
    Ctrl-C to the process group (a terminal's) printed each worker's KeyboardInterrupt
    traceback (issue 27). The tracker is started here, before the mask.
    """
    import signal
    import threading

    block = getattr(signal, "pthread_sigmask", None)
    if block is None or threading.current_thread() is not threading.main_thread():
        yield                          # (no POSIX masks; or SIGINT is not ours to handle)
        return
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()  # (running already: nothing; it touches no mask then)
    old = block(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        block(signal.SIG_SETMASK, old)     # a pending Ctrl-C is raised here


#: A local cluster without a dashboard and without a fixed port: Dask's scheduler starts
#: its HTTP server even with ``dashboard_address=None`` (at 8787, and with 8787 taken by
#: another cluster it warns and leaves a socket behind); here it listens on a free port
#: of the loopback interface only, with the dashboard off.
NO_DASHBOARD: dict[str, Any] = {"dashboard_address": "127.0.0.1:0",
                                "scheduler_kwargs": {"dashboard": False}}


def _fast_malloc() -> Any:
    """Dask's config without its ``MALLOC_TRIM_THRESHOLD_`` for the workers it spawns:
    glibc then keeps its mmap threshold fixed at 128 KiB, every array of the exact core
    above it is mapped and unmapped, and a chunk took 3-4 times as long (2.8-5.6 s
    against 1.0-1.3 s for 500 HVE points, measured on the project's machine)."""
    import dask

    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    env.pop("MALLOC_TRIM_THRESHOLD_", None)
    return dask.config.set({"distributed.nanny.pre-spawn-environ": env})


def _connect(address: str) -> Any:
    from dask.distributed import Client

    try:
        return Client(address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as e:
        raise SweepError(f"--scheduler = {address!r}: cannot reach it within "
                         f"{CONNECT_TIMEOUT_S} s ({' '.join(str(e).split())[:160]})") from None


def _stream(client: Any, spec: Spec, todo: list[int]
            ) -> Iterator[tuple[int, dict[str, list[Any]]]]:
    import uuid

    from dask.distributed import as_completed

    run = uuid.uuid4().hex[:12]          # keys of this run only (a shared scheduler)
    threads = max(1, sum(client.nthreads().values()))
    shared = client.scatter(spec, broadcast=True)
    pending = list(todo)[::-1]
    queue = as_completed()
    for _ in range(min(len(pending), IN_FLIGHT * threads)):
        c = pending.pop()
        queue.add(client.submit(evaluate_chunk, shared, c, key=f"hapstab-chunk-{run}-{c}",
                                pure=False))
    for fut in queue:
        c = int(fut.key.rsplit("-", 1)[1])
        cols = fut.result()
        fut.release()
        if pending:
            n = pending.pop()
            queue.add(client.submit(evaluate_chunk, shared, n, key=f"hapstab-chunk-{run}-{n}",
                                    pure=False))
        yield c, cols
