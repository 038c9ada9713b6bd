"""The files a command writes: targets checked before any work, everything written
atomically and committed together (see :mod:`hapstab.outputs`).

``--csv -`` writes the CSV to standard output; the command's table then goes to
standard error, so that the CSV can be piped on unmixed.
"""

from __future__ import annotations

import os
import sys
from contextvars import ContextVar
from typing import Any

from hapstab.errors import HapstabError
from hapstab.outputs import OutputError, Outputs, check_target, figure_to

#: Set when standard output carries a file (``--csv -``): tables go to standard error.
STDOUT_TAKEN: ContextVar[bool] = ContextVar("hapstab_stdout_taken", default=False)

_STDOUT = ("-", "/dev/stdout", "/dev/fd/1", "/proc/self/fd/1")


def _on_stdout(path: str | None) -> bool:
    return path is not None and (path in _STDOUT or os.path.abspath(path) in _STDOUT[1:])


def check_files(csv_path: str | None = None, plot_path: str | None = None,
                as_json: bool = False) -> None:
    """Refuse bad ``--csv`` / ``--plot`` targets before the computation starts: a target
    that cannot be written, two options naming one file, or two outputs on standard
    output (``--csv -`` with ``--json``).

    Parameters
    ----------
    csv_path, plot_path : str or None
        The options' values (None: not asked for; ``--csv -``: standard output).
    as_json : bool
        Whether ``--json`` writes the answer to standard output.

    Raises
    ------
    OutputError
        One of the above, naming the option and its value.
    """
    from hapstab.plotting import FORMATS

    if plot_path == "-":
        raise OutputError("--plot = '-': a figure is written to a file; give --plot a path")
    if csv_path is not None and csv_path != "-":
        check_target(csv_path, "--csv")
    if plot_path is not None:
        check_target(plot_path, "--plot", FORMATS)
    on_stdout = [n for n, p in (("--csv", csv_path), ("--plot", plot_path)) if _on_stdout(p)]
    if as_json:
        on_stdout.append("--json")
    if len(on_stdout) > 1:
        raise OutputError(f"{' and '.join(on_stdout)} would both write to standard output; "
                          f"give {on_stdout[0]} a file")
    if csv_path and plot_path and not _on_stdout(csv_path) and \
            os.path.realpath(csv_path) == os.path.realpath(plot_path):
        raise OutputError(f"--plot = {plot_path!r}: the same file as --csv; give each its own")
    if _on_stdout(csv_path):
        STDOUT_TAKEN.set(True)


def write_files(res: Any, csv_path: str | None = None, plot_path: str | None = None,
                **plot_kw: Any) -> list[str]:
    """Write ``res.to_csv`` and ``res.plot()`` to the targets asked for, together: either
    every file is replaced by its complete new version, or none is.

    Parameters
    ----------
    res : result object
        With ``to_csv(file)`` and ``plot(ax=None)``.
    csv_path, plot_path : str or None
        The targets (None: not asked for; ``--csv -``: standard output, written after
        the files).
    **plot_kw
        Passed to ``savefig`` (e.g. ``dpi``).

    Returns
    -------
    list of str
        The files written (``-`` for standard output).
    """
    check_files(csv_path, plot_path)
    with Outputs() as out:
        if csv_path is not None and csv_path != "-":
            with out.open(csv_path, "--csv", newline="") as fh:
                res.to_csv(fh)
        if plot_path is not None:
            figure_to(out, res, plot_path, "--plot", **plot_kw)
    if csv_path == "-":
        try:
            res.to_csv(sys.stdout)
            sys.stdout.flush()
        except OSError as e:
            raise HapstabError(f"--csv = '-': cannot write to standard output "
                               f"({e.strerror or e})") from None
        out.written.append("-")
    return out.written
