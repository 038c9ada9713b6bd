"""The CLI's human output: a console, two-column tables, numbers, progress bars."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["console", "rich_table", "fmt", "progress"]


def console() -> Any:
    """A rich console as wide as the terminal, and 160 columns when piped or redirected
    (rich's 80 would cut numbers in tables); on standard error when standard output
    carries a file (``--csv -``)."""
    import shutil

    from rich.console import Console

    from hapstab.cli.files import STDOUT_TAKEN

    class _Console(Console):
        def on_broken_pipe(self) -> None:   # rich exits 1 silently; hapstab says so (exit 2)
            self.quiet = True
            raise BrokenPipeError(32, "Broken pipe")

    return _Console(width=max(shutil.get_terminal_size((160, 24)).columns, 100),
                    stderr=STDOUT_TAKEN.get())


def rich_table(title: str, rows: list[tuple[str, str]], loop: Any = None) -> None:
    """Two columns, no header; with ``loop``, a last row saying which loop it is for."""
    from rich.markup import escape
    from rich.table import Table

    from hapstab.models.loops import headline

    t = Table(title=escape(title), show_header=False)
    t.add_column(style="bold")
    t.add_column()
    for k, v in [*rows, *([("loop", headline(loop))] if loop is not None else [])]:
        t.add_row(escape(k), escape(v))
    console().print(t)


def fmt(x: float) -> str:
    return "inf" if math.isinf(x) else f"{x:.10g}"


@contextmanager
def progress(total: int, description: str, quiet: bool = False
             ) -> Iterator[Callable[[int], None] | None]:
    """A progress bar on stderr when it is a terminal (nothing with --json, when piped,
    or when ``quiet``); yields ``advance(k)`` or None.

    Parameters
    ----------
    total : int
        Steps in all.
    description : str
        What is being done.
    quiet : bool
        No bar (e.g. ``--json``).
    """
    if quiet or not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), transient=True, console=Console(stderr=True)) as prog:
        task = prog.add_task(description, total=total)
        yield lambda k: prog.advance(task, k)


#: Piped progress (stderr not a terminal): nothing for the first PIPED_QUIET_S seconds (a
#: quick command prints no progress, so scripts reading stderr see only its answer), then
#: a line at most every PIPED_EVERY_S seconds: a log file of a 5-minute robust search gets
#: about 30 lines, not a bar's thousands of redraws.
PIPED_QUIET_S = 10.0
PIPED_EVERY_S = 10.0


def progress_lines(what: str, total: int) -> Callable[[int], None]:
    """A progress listener (:mod:`hapstab.progress`) writing ``hapstab: progress: WHAT:
    DONE of TOTAL, S s`` lines to stderr, for when it is not a terminal.

    Parameters
    ----------
    what : str
        What is being computed.
    total : int
        Steps in all (an open-ended search: its step budget; it may stop sooner).

    Returns
    -------
    callable
        ``advance(k)``.
    """
    import time

    t0 = time.monotonic()
    done = [0]
    due = [t0 + PIPED_QUIET_S]

    def advance(k: int = 1) -> None:
        import click

        done[0] += int(k)
        now = time.monotonic()
        if now >= due[0]:
            due[0] = now + PIPED_EVERY_S
            click.echo(f"hapstab: progress: {what}: {done[0]} of {total}, "
                       f"{now - t0:.0f} s", err=True)

    return advance
