"""The explorer's computations in worker processes that can be ended.

A thread cannot be stopped; a process can. Each computation runs in a process forked
from a server process that has imported hapstab already (``forkserver``, preloaded: a
computation starts in tens of milliseconds, and the fork is from a process with one
thread), and the request that started it ends it (``terminate``) as soon as it is
superseded by a later request of its channel or its client has gone: one user's
slider never waits behind their own stale requests.
"""

from __future__ import annotations

import json
import multiprocessing
import traceback
from typing import Any

from hapstab.explorer.api import ApiError

__all__ = ["Job", "warm"]

#: The modules the server process imports once, before it forks any worker: the API and
#: the CLI, and what a check or kmax imports lazily (the ball proof, python-flint): each
#: worker is a fresh fork, so a module not preloaded is imported again by every request
#: (measured: a PEB n = 4 check 537 ms in a worker against 27 ms in-process before these).
PRELOAD = ["hapstab.explorer.api", "hapstab.explorer.code", "hapstab.cli.main",
           "hapstab.cli.notes", "hapstab.plotting", "flint",
           "hapstab.analysis.exact.candidates", "hapstab.analysis.exact.certificate",
           "hapstab.analysis.exact.polish",
           "hapstab.analysis.exact.proof", "hapstab.analysis.exact.proved",
           "hapstab.analysis.exact.top", "hapstab.analysis.exact.winding"]
_CONTEXT: list[Any] = []


def _context() -> Any:
    if not _CONTEXT:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        _CONTEXT.append(ctx)
    return _CONTEXT[0]


def warm() -> None:
    """Start the server process the workers are forked from (it imports :data:`PRELOAD`,
    seconds on a busy machine) now rather than at the first request."""
    from multiprocessing import forkserver

    _context()
    forkserver.ensure_running()


def _child(conn: Any, kind: str, arg: Any) -> None:
    """The worker: ``("ok", text)``, ``("api", status, error, parameter)`` or
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
    conn.send(out)
    conn.close()


class Job:
    """One computation in its own process.

    Parameters
    ----------
    kind : {"command", "code"}
        :func:`~hapstab.explorer.api.run_command` of an argv, or
        :func:`~hapstab.explorer.code.code_for` of a request body.
    arg : list of str or dict
        Its argument.
    """

    def __init__(self, kind: str, arg: Any) -> None:
        ctx = _context()
        self._recv, send = ctx.Pipe(duplex=False)
        self.process = ctx.Process(target=_child, args=(send, kind, arg), daemon=True)
        self.process.start()
        send.close()

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
        if msg[0] == "ok":
            return str(msg[1])
        if msg[0] == "api":
            raise ApiError(msg[1], msg[2], msg[3])
        raise RuntimeError(f"{msg[1]} in the worker process:\n{msg[2]}")

    def stop(self) -> None:
        """End the process (at once if it still computes) and close the pipe."""
        if self.process.is_alive():
            self.process.terminate()
        self.process.join(2.0)
        if self.process.is_alive():       # pragma: no cover - SIGTERM ignored
            self.process.kill()
            self.process.join()
        self._recv.close()
        self.process.close()
