"""Progress of the computations that take long (a grid of K_max, a region, the best
damping, an audit), reported to whoever listens: the command line draws a bar on a
terminal; a Python user may pass any callback. Nothing is reported unless a listener
is set, and a listener never changes a result.

Examples
--------
>>> import hapstab as h
>>> from hapstab import progress
>>> seen = []
>>> def listener(what, total):
...     return lambda k: seen.append(k)
>>> with progress.listening(listener):
...     _ = h.boundary(h.paper_hve(), [1e-3, 2e-3], [0, 1, 2])
>>> sum(seen)
6
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from typing import Any

__all__ = ["steps", "listening", "Listener"]

#: ``listener(what, total)`` returns ``advance(k)`` (or a context manager yielding it).
Listener = Callable[[str, int], Any]

_LISTENER: ContextVar[Listener | None] = ContextVar("hapstab_progress", default=None)


def _noop(k: int = 1) -> None:
    """Advance nothing (no listener)."""


@contextlib.contextmanager
def steps(total: int, what: str) -> Iterator[Callable[[int], None]]:
    """A computation of ``total`` steps: yields ``advance(k)`` to call as steps finish.

    Parameters
    ----------
    total : int
        Number of steps.
    what : str
        What is being computed, for the listener.

    Yields
    ------
    callable
        ``advance(k=1)``.
    """
    listener = _LISTENER.get()
    if listener is None or total < 2:
        yield _noop
        return
    made = listener(what, int(total))
    if hasattr(made, "__enter__"):
        with made as advance:
            yield advance or _noop
    else:
        yield made


@contextlib.contextmanager
def listening(listener: Listener | None) -> Iterator[None]:
    """Report the progress of the computations inside the block to ``listener``.

    Parameters
    ----------
    listener : callable or None
        ``listener(what, total)`` returning ``advance(k)`` or a context manager
        yielding it; None: nothing reported.

    Yields
    ------
    None
    """
    token = _LISTENER.set(listener)
    try:
        yield
    finally:
        _LISTENER.reset(token)
