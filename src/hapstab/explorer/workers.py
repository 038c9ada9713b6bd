"""The explorer's computations in worker processes that can be ended.

A thread cannot be stopped; a process can. Each computation runs in a worker process
forked from a server process that has imported hapstab already (``forkserver``,
preloaded: the fork is from a process with one thread), and the request that started it
ends the worker (``terminate``) as soon as it is superseded by a later request of its
channel or its client has gone: one user's slider never waits behind their own stale
requests.

Workers are forked *before* requests come and serve one request after another
(:data:`SPARES` wait, each on its pipe): a fresh process is not ready at once
(multiprocessing prepares it, and its first computation fills the caches a loop's
analysis keeps: measured on this 2-core machine, a PEB n = 4 verdict took 45 ms in a
fresh worker against 9 ms in-process, its K_max 82 against 45 ms). A worker that
answered goes back to the spares; one that was ended, that met a bug, or that served
:data:`MAX_REQUESTS` is replaced by a fresh one. What a worker keeps between requests
is caches keyed by the numbers they hold, never a request's options or answers.
"""

from __future__ import annotations

import json
import multiprocessing
import threading
import traceback
from typing import Any

from hapstab.explorer.api import ApiError

__all__ = ["Job", "warm", "SPARES", "MAX_IDLE", "MAX_REQUESTS"]

#: The modules the server process imports once, before it forks any worker: the API and
#: the CLI, and what a check or kmax imports lazily (the ball proof, python-flint): each
#: worker is a fresh fork, so a module not preloaded is imported again by every request
#: (measured: a PEB n = 4 check 537 ms in a worker against 27 ms in-process before these).
PRELOAD = ["hapstab.explorer.api", "hapstab.explorer.code", "hapstab.cli.main",
           "hapstab.cli.notes", "hapstab.plotting", "flint",
           "hapstab.analysis.exact.candidates", "hapstab.analysis.exact.certificate",
           "hapstab.analysis.exact.polish",
           "hapstab.analysis.exact.proof", "hapstab.analysis.exact.proved",
           "hapstab.analysis.exact.top", "hapstab.analysis.exact.winding",
           # the page's other commands: the margins of a check, the audit's nonlinear
           # rows, best-damping's design and robust modules and its bounded scalar
           # minimiser (measured: best-damping hve 1.8 s in a worker without them, 0.67 s
           # with them; scipy.optimize alone is most of the difference)
           "hapstab.engine.arb_krawczyk", "hapstab.engine.arb_fraction",
           "hapstab.analysis.margins", "hapstab.analysis.nonlinear", "hapstab.analysis.design",
           "hapstab.analysis.robust", "hapstab.engine.balls", "hapstab.engine.operator_family",
           "scipy.optimize"]
_CONTEXT: list[Any] = []
#: Workers forked at the start (the explorer computes :data:`WORKERS
#: <hapstab.explorer.app.WORKERS>` = 2 at once: the page's verdict and K_max of one
#: change, sent together, both find one ready); when a request takes the last one
#: waiting, the next is forked while it computes.
SPARES = 2
#: Workers kept waiting at most (a worker that answered beyond them ends): one more than
#: the computations at once, so that a steady page forks none.
MAX_IDLE = 3
#: Requests a worker serves before it is replaced (bounds what caches and figures a
#: long session could accumulate in one process).
MAX_REQUESTS = 200
#: The spares waiting: ``[process, parent's end of the pipe, requests served]``.
_SPARE: list[list[Any]] = []
#: Spares are taken and given back by the event loop's thread; a lock all the same
#: (several applications, each with its loop, may run in one process, as in the tests).
_LOCK = threading.Lock()


def _context() -> Any:
    if not _CONTEXT:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        _CONTEXT.append(ctx)
    return _CONTEXT[0]


def warm() -> None:
    """Start the server process the workers are forked from (it imports :data:`PRELOAD`,
    seconds on a busy machine) and the spares now rather than at the first request."""
    from multiprocessing import forkserver

    _context()
    forkserver.ensure_running()
    _refill()


def _fork() -> list[Any]:
    """A worker process, started and waiting for requests on its pipe."""
    ctx = _context()
    mine, theirs = ctx.Pipe(duplex=True)
    process = ctx.Process(target=_worker, args=(theirs,), daemon=True)
    process.start()
    theirs.close()
    return [process, mine, 0]


def _refill(least: int = SPARES) -> None:
    """Fork spares up to ``least`` waiting (dead ones, e.g. ended by a signal, dropped)."""
    with _LOCK:
        for w in [w for w in _SPARE if not w[0].is_alive()]:
            _SPARE.remove(w)
            _end(w)
        while len(_SPARE) < least:
            _SPARE.append(_fork())


def _end(w: list[Any], computing: bool = False) -> None:
    """End a worker and reap it: one ``computing`` (a superseded request, a bug) at once
    (SIGTERM, then SIGKILL); a waiting one by closing its pipe (its wait for a request
    sees the end)."""
    process, conn = w[0], w[1]
    if computing and process.is_alive():
        process.terminate()
    conn.close()
    process.join(2.0)
    if process.is_alive():       # pragma: no cover - SIGTERM ignored, or a hung wait
        process.kill()
        process.join()
    process.close()


def _take() -> list[Any]:
    """A spare worker that is alive, else a new one."""
    with _LOCK:
        while _SPARE:
            w = _SPARE.pop(0)
            if w[0].is_alive():
                return w
            _end(w)
        return _fork()


def _give_back(w: list[Any]) -> None:
    """A worker that answered: a spare again, or ended (:data:`MAX_IDLE` wait already,
    or it served its :data:`MAX_REQUESTS`)."""
    with _LOCK:
        if len(_SPARE) < MAX_IDLE and w[2] < MAX_REQUESTS and w[0].is_alive():
            _SPARE.append(w)
            return
    _end(w)


def _worker(conn: Any) -> None:
    """A worker: computes each request ``(kind, arg)`` that comes (:func:`_child`),
    until the explorer closes the pipe. A Ctrl-C at the terminal reaches the workers
    too (one process group): they leave it to the explorer, which ends them."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            kind, arg = conn.recv()
        except (EOFError, OSError):
            return
        _child(conn, kind, arg)


def _child(conn: Any, kind: str, arg: Any) -> None:
    """One request: ``("ok", text)``, ``("api", status, error, parameter)`` or
    ``("bug", type name, traceback)`` down the pipe."""
    try:
        if kind == "code":
            from hapstab.explorer.code import code_for

            out: tuple[Any, ...] = ("ok", json.dumps(code_for(arg)))
        else:
            from hapstab.explorer.api import run_command

            out = ("ok", run_command(arg))
    except ApiError as e:
        out = ("api", e.status, e.error, e.parameter)
    except BaseException as e:          # a bug: reported as the 500 it is, with its traceback
        out = ("bug", type(e).__name__, traceback.format_exc())
    try:
        conn.send(out)
    except OSError:         # the explorer has gone (it ends its workers as it goes)
        return


class Job:
    """One computation in a worker process.

    Parameters
    ----------
    kind : {"command", "code"}
        :func:`~hapstab.explorer.api.run_command` of an argv, or
        :func:`~hapstab.explorer.code.code_for` of a request body.
    arg : list of str or dict
        Its argument.
    """

    def __init__(self, kind: str, arg: Any) -> None:
        self._worker = _take()
        self.process, self._recv = self._worker[0], self._worker[1]
        self._worker[2] += 1
        self._recv.send((kind, arg))
        self._answered = False       # its answer read, and not a bug's
        _refill(1)      # one waiting for the next request, forked while this one computes

    def fileno(self) -> int:
        """The pipe the answer comes down (to wait on it: readable when :meth:`ready`)."""
        return int(self._recv.fileno())

    def ready(self) -> bool:
        """The answer is there (or the worker died)."""
        return bool(self._recv.poll())

    def result(self) -> str:
        """The answer's text.

        Raises
        ------
        ApiError
            The command's refusal, as it gave it.
        RuntimeError
            A bug in the worker, or the worker died (its message says which).
        """
        try:
            msg = self._recv.recv()
        except EOFError:
            raise RuntimeError(f"the worker process died (exit code "
                               f"{self.process.exitcode})") from None
        self._answered = msg[0] != "bug"
        if msg[0] == "ok":
            return str(msg[1])
        if msg[0] == "api":
            raise ApiError(msg[1], msg[2], msg[3])
        raise RuntimeError(f"{msg[1]} in the worker process:\n{msg[2]}")

    def stop(self) -> None:
        """Done with the worker: a spare again if it answered, else ended at once (it
        still computes a superseded request, or it met a bug)."""
        if self._answered:
            _give_back(self._worker)
        else:
            _end(self._worker, computing=True)
