"""The explorer's Starlette application: the page, its static files and the JSON API.

Routes (see docs/guide/explorer.md for the requests and answers)::

    GET  /                    the page (static/index.html)
    GET  /static/{path}       its files
    GET  /api/v1              version, endpoints, kinds, commands
    GET  /api/v1/schema       every command's options, and the --study file's loop
    POST /api/v1/code         the command line and a Python script for a request
    POST /api/v1/{command}    the JSON answer of ``hapstab COMMAND KIND ... --json``

Every error is JSON ``{"error", "parameter", "status"}``; an unexpected exception is a
500 ``internal error (<Type>)`` with its traceback on the server's stderr only.
Computations run in worker threads, at most :data:`WORKERS` at a time; a request that
carries ``X-Hapstab-Channel`` / ``X-Hapstab-Seq`` is answered 409 without computing when
a later one of its channel arrived before its turn came.
"""

from __future__ import annotations

import json
import os
import re
import sys
import traceback
from collections.abc import Awaitable, Callable
from typing import Any

from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Route

from hapstab.explorer.api import (
    COMMANDS,
    KINDS,
    MAX_BODY_BYTES,
    ApiError,
    check_request,
    command_kinds,
    loop_command,
    option_args,
    parse_body,
    run_command,
    schema,
)

__all__ = ["create_app", "STATIC", "WORKERS", "LOCAL_HOSTS"]

#: The page's files.
STATIC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "static")
#: Computations at once (the machine has 2 cores).
WORKERS = 2
#: Channels remembered for superseded requests (the oldest are forgotten beyond).
MAX_CHANNELS = 1000
ENDPOINTS = ["GET /", "GET /static/{path}", "GET /api/v1", "GET /api/v1/schema",
             "POST /api/v1/code", "POST /api/v1/{command}"]

#: The Host headers always accepted (with the --host given): a page reached through another
#: name (DNS rebinding) gets a 400.
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")
#: ``X-Hapstab-Seq``: an optional minus, then at most 18 ASCII digits.
SEQ_PATTERN = re.compile(r"-?[0-9]{1,18}")

Handler = Callable[[Request], Awaitable[Response]]


class _Json(JSONResponse):
    """JSON in ASCII (a request's lone surrogate, echoed in a message, stays encodable)."""

    def render(self, content: Any) -> bytes:
        return json.dumps(content, allow_nan=False, separators=(",", ":")).encode("ascii")


def _error(e: ApiError, headers: dict[str, str] | None = None) -> JSONResponse:
    return _Json(e.to_dict(), status_code=e.status, headers=headers)


def _guarded(handler: Handler) -> Handler:
    """Answer an ApiError as its JSON, anything unexpected as a 500 (logged to stderr)."""
    async def wrapped(request: Request) -> Response:
        try:
            return await handler(request)
        except ApiError as e:
            return _error(e)
        except Exception as e:           # a bug of hapstab's: never a traceback to the client
            print(f"hapstab explorer: internal error on {request.method} {request.url.path}:",
                  file=sys.stderr)
            traceback.print_exc(file=sys.stderr)
            return _error(ApiError(500, f"internal error ({type(e).__name__})"))
    return wrapped


async def _http_error(request: Request, exc: Exception) -> Response:
    """Starlette's own 404 / 405 as the API's JSON."""
    assert isinstance(exc, HTTPException)
    what = {404: f"not found: {request.url.path[:120]}",
            405: f"method {request.method} not allowed on {request.url.path[:120]}"}
    return _error(ApiError(exc.status_code, what.get(exc.status_code, str(exc.detail))),
                  headers=dict(exc.headers or {}))


def _same_origin(request: Request) -> None:
    """A POST from another site's page (its ``Origin`` is not this server's) is a 403."""
    origin = request.headers.get("origin")
    if origin is None:
        return
    own = f"{request.url.scheme}://{request.headers.get('host', '')}".lower()
    if origin.strip().lower().rstrip("/") != own:
        raise ApiError(403, f"Origin {origin[:100]!r}: this API answers its own page only "
                            f"({own[:100]})")


async def _read_body(request: Request) -> dict[str, Any]:
    """The JSON object of a POST from the server's own origin (403 otherwise; 413 beyond
    :data:`MAX_BODY_BYTES`, read no further)."""
    _same_origin(request)
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype != "application/json":
        raise ApiError(415, f"content type {ctype[:60]!r}: send application/json")
    length = request.headers.get("content-length", "")
    if length.isdigit() and int(length) > MAX_BODY_BYTES:
        raise ApiError(413, f"request body of {int(length)} bytes: at most {MAX_BODY_BYTES}")
    from starlette.requests import ClientDisconnect

    raw = bytearray()
    try:
        async for chunk in request.stream():
            raw += chunk
            if len(raw) > MAX_BODY_BYTES:
                raise ApiError(413, f"request body over {MAX_BODY_BYTES} bytes: at most "
                                    f"{MAX_BODY_BYTES}")
    except ClientDisconnect:      # the client hung up mid-body: nobody to answer, no bug
        raise ApiError(400, f"the client hung up after {len(raw)} bytes of the body") from None
    return parse_body(bytes(raw))


class _Sequencer:
    """The latest ``X-Hapstab-Seq`` seen on each ``X-Hapstab-Channel``."""

    def __init__(self) -> None:
        self.latest: dict[str, int] = {}

    def arrive(self, request: Request) -> tuple[str, int] | None:
        channel = request.headers.get("x-hapstab-channel")
        seq = request.headers.get("x-hapstab-seq")
        if channel is None and seq is None:
            return None
        if channel is None or seq is None or not SEQ_PATTERN.fullmatch(seq.strip()) \
                or len(channel) > 100:
            raise ApiError(400, "X-Hapstab-Channel and X-Hapstab-Seq: give both, the channel a "
                                "name (<= 100 characters), the seq an integer", None)
        n = int(seq)
        if channel not in self.latest and len(self.latest) >= MAX_CHANNELS:
            self.latest.pop(next(iter(self.latest)))
        self.latest[channel] = max(n, self.latest.get(channel, n))
        return channel, n

    def superseded(self, mark: tuple[str, int] | None) -> bool:
        return mark is not None and mark[1] < self.latest.get(mark[0], mark[1])


class _Answers:
    """The answers already given, by command line (least recently used dropped first).

    A command's JSON is a function of its command line (the CLI is deterministic: the
    same options give the same bytes), so the same question asked again -- a page
    reloaded, a field changed and changed back, K moved while the K_max-against-T plot
    and the best damping, which do not depend on it, are asked again -- is answered at
    once instead of computed again. Only answers are kept, never a refusal (a budget
    refusal depends on the machine's load). Bounded by :data:`ANSWERS` entries and
    :data:`ANSWER_BYTES` in all; one per application.
    """

    def __init__(self) -> None:
        from collections import OrderedDict
        self.kept: OrderedDict[str, str] = OrderedDict()
        self.size = 0

    @staticmethod
    def key(arg: Any) -> str:
        return json.dumps(arg)

    def get(self, arg: Any) -> str | None:
        k = self.key(arg)
        text = self.kept.get(k)
        if text is not None:
            self.kept.move_to_end(k)
        return text

    def put(self, arg: Any, text: str) -> None:
        k = self.key(arg)
        if k in self.kept or len(text) > ANSWER_BYTES:
            return
        self.kept[k] = text
        self.size += len(text)
        while len(self.kept) > ANSWERS or self.size > ANSWER_BYTES:
            self.size -= len(self.kept.popitem(last=False)[1])


#: Answers kept per application (:class:`_Answers`): a page asks ~8 per change.
ANSWERS = 512
#: Their size in all (characters of JSON): a page's answers are ~0.1-0.3 MB.
ANSWER_BYTES = 32 * 2 ** 20


#: Computations run in worker processes that are ended when superseded or abandoned
#: (:mod:`hapstab.explorer.workers`); False: in threads, which run to their end.
IN_PROCESSES = True
#: Seconds between two looks at whether a running computation is superseded or its
#: client has gone; its answer is taken as soon as it is there (the request waits on
#: the worker's pipe: a fixed look every 20 ms kept a 10 ms verdict waiting up to 20).
POLL_S = 0.02


def warm_workers() -> None:
    """Start the worker processes' server now (:func:`hapstab.explorer.workers.warm`)."""
    if IN_PROCESSES:
        from hapstab.explorer.workers import warm

        warm()


async def _in_process(request: Request, kind: str, arg: Any, superseded: Callable[[], bool],
                      limiter: Any) -> str | None:
    """``arg`` computed in a worker process; None (and the process ended) as soon as the
    request is superseded or its client has gone."""
    import anyio

    from hapstab.explorer.workers import Job

    async with limiter:
        if superseded():
            return None
        job = Job(kind, arg)
        try:
            while not job.ready():
                if superseded() or await request.is_disconnected():
                    return None
                with anyio.move_on_after(POLL_S):
                    await anyio.wait_readable(job.fileno())
            return job.result()
        finally:
            job.stop()


async def _compute(request: Request, kind: str, arg: Any, seq: _Sequencer,
                   limiter: Any, answers: _Answers) -> Response:
    """One computation of a request (at most :data:`WORKERS` at once): 409 if superseded
    before it starts or, in a worker process, while it runs."""
    import anyio

    mark = seq.arrive(request)
    if kind == "code":
        # A translation of the options, no computation: answered at once in a thread,
        # not queued behind the page's plots in the worker processes (it waited for
        # them: the "Copy as CLI" box stayed empty > 15 s on a loaded 2-core machine).
        from hapstab.explorer.code import code_for

        answer = await anyio.to_thread.run_sync(lambda: json.dumps(code_for(arg)))
        return Response(answer.encode("utf-8", "replace"), media_type="application/json")
    text = None if seq.superseded(mark) else answers.get(arg)
    if text is not None:        # asked before: the same bytes (see _Answers)
        return Response(text.encode("utf-8", "replace"), media_type="application/json")
    if not IN_PROCESSES:
        from hapstab.explorer.code import code_for

        work = (lambda: json.dumps(code_for(arg))) if kind == "code" else \
            (lambda: run_command(arg))

        def job() -> str | None:
            return None if seq.superseded(mark) else work()

        text = await anyio.to_thread.run_sync(job, limiter=limiter)
    else:
        text = await _in_process(request, kind, arg, lambda: seq.superseded(mark), limiter)
    if text is None:
        raise ApiError(409, "superseded: a later request of this channel arrived first")
    answers.put(arg, text)
    return Response(text.encode("utf-8", "replace"), media_type="application/json")


def create_app(study_path: str | None = None, host: str | None = None) -> Starlette:
    """The explorer's application.

    Parameters
    ----------
    study_path : str, optional
        A study file of kind hve or peb: its [loop] table is the page's initial state
        (``GET /api/v1/schema``'s ``study``).
    host : str, optional
        The interface it listens on (``--host``): a Host header naming it is accepted
        beside :data:`LOCAL_HOSTS` (any other is a 400: DNS rebinding).

    Returns
    -------
    starlette.applications.Starlette

    Raises
    ------
    hapstab.errors.HapstabError
        The study cannot be read, or its kind or [loop] table is not the explorer's.
    """
    import anyio

    from hapstab import __version__

    study = _study(study_path) if study_path is not None else None
    seq = _Sequencer()
    answers = _Answers()
    limiter: list[anyio.CapacityLimiter] = []

    async def compute(request: Request, kind: str, arg: Any) -> Response:
        if not limiter:
            limiter.append(anyio.CapacityLimiter(WORKERS))
        return await _compute(request, kind, arg, seq, limiter[0], answers)

    async def index(request: Request) -> Response:
        page = os.path.join(STATIC, "index.html")
        if not os.path.isfile(page):
            raise ApiError(404, "the page is not installed (static/index.html); the API "
                                "answers under /api/v1")
        return FileResponse(page, media_type="text/html")

    async def static(request: Request) -> Response:
        return _static_file(request.path_params["path"])

    async def info(request: Request) -> Response:
        return _Json({"version": __version__, "endpoints": ENDPOINTS,
                             "kinds": list(KINDS), "commands": list(COMMANDS)})

    async def get_schema(request: Request) -> Response:
        return _Json({"kinds": schema(), "study": study})

    async def code(request: Request) -> Response:

        body = await _read_body(request)
        return await compute(request, "code", body)

    async def command(request: Request) -> Response:
        name = request.path_params["command"]
        if name == "schema":
            raise ApiError(405, "method POST not allowed on /api/v1/schema (GET it)")
        command_kinds(name)     # 404 / 422 for a command it does not run, before the body
        argv = check_request(name, await _read_body(request))
        return await compute(request, "command", argv)

    routes = [Route("/", _guarded(index), methods=["GET"]),
              Route("/static/{path:path}", _guarded(static), methods=["GET"]),
              Route("/api/v1", _guarded(info), methods=["GET"]),
              Route("/api/v1/schema", _guarded(get_schema), methods=["GET"]),
              Route("/api/v1/code", _guarded(code), methods=["POST"]),
              Route("/api/v1/{command}", _guarded(command), methods=["POST"])]
    names = [h.strip("[]") for h in (*LOCAL_HOSTS, *([host] if host else []))]
    hosts = [f"[{h}]" if ":" in h else h for h in names]     # (IPv6 literals in brackets)
    return Starlette(routes=routes, exception_handlers={HTTPException: _http_error},
                     middleware=[Middleware(TrustedHostMiddleware, allowed_hosts=hosts)])


def _static_file(path: str) -> Response:
    """A file under :data:`STATIC` (404 for anything outside it or missing)."""
    if "\0" in path:
        raise ApiError(404, "not found: a path with a NUL byte")
    root = os.path.realpath(STATIC)
    full = os.path.realpath(os.path.join(root, path))
    if os.path.commonpath([root, full]) != root or not os.path.isfile(full):
        raise ApiError(404, f"not found: /static/{path[:100]}")
    return FileResponse(full)


def _study(path: str) -> dict[str, Any]:
    """The --study file's kind and [loop] table, checked as kmax's options."""
    from hapstab.cli.study import StudyError, load_study

    study = load_study(path)
    if study.kind not in KINDS:
        raise StudyError(f"--study = {path!r}: its kind is {study.kind!r}; the explorer "
                         f"builds {' or '.join(KINDS)} loops")
    try:
        option_args(loop_command("kmax", study.kind), "kmax", study.kind, study.loop)
    except ApiError as e:
        raise StudyError(f"{study.path}: [loop]: {e.error}") from None
    return {"kind": study.kind, "options": {k.replace("_", "-"): v for k, v in study.loop.items()}}
