"""The command-line interface (the library never imports it).

``hapstab --version`` answers without importing the commands (numpy, scipy, the
analyses): the entry point :func:`main` loads :mod:`hapstab.cli.main` only for a real
command; ``cli`` (the click group) loads on first use.
"""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["cli", "main"]


def main(argv: list[str] | None = None) -> None:
    """Console entry point: ``hapstab --version`` at once, anything else by the click group.

    Parameters
    ----------
    argv : list of str, optional
        The command line after ``hapstab`` (default ``sys.argv[1:]``).
    """
    args = sys.argv[1:] if argv is None else list(argv)
    if args == ["--version"]:
        from hapstab import __version__

        # click's version_option prints "%(prog)s, version %(version)s" (tests compare)
        print(f"hapstab, version {__version__}")
        sys.exit(0)
    try:
        from hapstab.cli.main import main as run
    except BaseException as e:         # a Ctrl-C while the commands load (numpy, scipy)
        if not _caused_by_interrupt(e):
            raise
        import os

        print("hapstab: interrupted", file=sys.stderr, flush=True)
        # os._exit, not sys.exit: nothing is started or written yet, and a Ctrl-C that
        # unwound through an exec() of a string (scipy's imports do that) makes
        # ``python -m hapstab`` end by SIGINT (-2) whatever sys.exit says
        os._exit(130)
    run(argv)


def _caused_by_interrupt(e: BaseException | None) -> bool:
    """Whether ``e`` is a Ctrl-C or was raised because of one.

    An extension module whose initialisation a Ctrl-C interrupts re-raises it as
    ``ImportError: initialization failed`` from the KeyboardInterrupt (pybind11 does, in
    scipy.optimize's HiGHS); the interrupt is then the exception's cause or context.
    """
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def __getattr__(name: str) -> Any:
    """``hapstab.cli.cli``: the click group, imported on first use (PEP 562)."""
    if name == "cli":
        from hapstab.cli.main import cli

        return cli
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
