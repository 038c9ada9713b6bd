"""``hapstab explore``: the stability explorer, a local web page (see :mod:`hapstab.explorer`)."""

from __future__ import annotations

import sys
from typing import Any

import click

from hapstab.cli.options import IntRange
from hapstab.errors import HapstabError

#: Where the explorer listens unless told otherwise (this machine only).
LOCAL = "127.0.0.1"


@click.command("explore", short_help="The stability explorer: a local web page.")
@click.option("--port", type=IntRange(0, 65535), default=8765, show_default=True,
              help="TCP port (0: any free port; the address printed says which).")
@click.option("--host", default=LOCAL, show_default=True,
              help="Interface to listen on; anything but localhost, 127.x or ::1 lets other "
                   "machines in (a warning says so).")
@click.option("--study", "study_path", metavar="FILE", default=None,
              help="A study file (kind hve or peb): its [loop] is the page's first state.")
@click.option("--open", "open_browser", is_flag=True, help="Open the page in a browser.")
def explore_cmd(port: int, host: str, study_path: str | None, open_browser: bool) -> None:
    """Start the stability explorer: a page where the loop's inputs move its verdict, K_max,
    K-B region, simulated step and passivity margin, over a small JSON API (/api/v1) that
    answers as the commands' --json do. Ctrl-C stops it."""
    try:
        import uvicorn

        from hapstab.explorer.app import create_app
    except ImportError as e:
        raise HapstabError(f"hapstab explore needs starlette and uvicorn ({e.name} is "
                           "missing): pip install 'hapstab[explore]'") from None
    _check_listen(host, port)
    app = create_app(study_path, host)
    from hapstab.explorer.app import warm_workers

    warm_workers()            # the workers' server imports hapstab now, not at the first request
    if not is_loopback(host):
        click.echo(f"hapstab: warning: --host = {host}: the explorer is reachable from other "
                   "machines on that interface; it has no authentication", err=True)
    server = uvicorn.Server(uvicorn.Config(app, host=host, port=port, log_level="warning",
                                           access_log=False, lifespan="off"))
    _serve(server, host, open_browser)


def is_loopback(host: str) -> bool:
    """Whether ``host`` is this machine only: localhost, 127.x.y.z or ::1.

    Parameters
    ----------
    host : str
        The --host given (an IPv6 literal with or without brackets).

    Returns
    -------
    bool
    """
    import ipaddress

    name = host.strip().strip("[]").lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def _check_listen(host: str, port: int) -> None:
    """Refuse, in one line, a host this machine cannot listen on or a port in use (before
    uvicorn tries and logs it)."""
    import socket

    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (OSError, UnicodeError, ValueError) as e:
        raise HapstabError(f"--host = {host!r:.80}: not a name or address of an interface "
                           f"({getattr(e, 'strerror', None) or e})") from None
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(address)
        except OSError as e:
            raise HapstabError(f"--host/--port = {host}:{port}: cannot listen there "
                               f"({e.strerror or e})") from None


def _serve(server: Any, host: str, open_browser: bool) -> None:
    """Run ``server`` until Ctrl-C; print its address (the port bound) once listening."""
    import asyncio
    import contextlib
    import threading

    def announce() -> None:
        while not server.started and not server.should_exit:
            threading.Event().wait(0.02)
        if not server.started:
            return
        sock = server.servers[0].sockets[0]
        port = sock.getsockname()[1]
        shown = f"[{host}]" if ":" in host else host
        url = f"http://{shown}:{port}/"
        click.echo(f"hapstab explorer: {url}")
        sys.stdout.flush()
        if open_browser:
            import webbrowser

            webbrowser.open(url)

    if threading.current_thread() is threading.main_thread():
        import signal

        # uvicorn stops on SIGINT / SIGTERM and then raises the signal again for the
        # handler it found: a stop asked for is a normal end (exit 0), not an interrupt
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda signum, frame: None)
    threading.Thread(target=announce, daemon=True).start()
    try:
        with contextlib.suppress(KeyboardInterrupt):    # (uvicorn handles SIGINT itself)
            asyncio.run(server.serve())
    except SystemExit:          # uvicorn could not start (it said why on stderr)
        server.started = False
    if not server.started:
        raise HapstabError(f"--host/--port: could not listen on {host} (see the message above)")
