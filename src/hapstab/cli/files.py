"""The files a command writes: targets checked before any work, everything written
atomically and committed together (see :mod:`hapstab.outputs`)."""

from __future__ import annotations

from typing import Any

from hapstab.outputs import Outputs, check_target, figure_to


def check_files(csv_path: str | None = None, plot_path: str | None = None) -> None:
    """Refuse bad ``--csv`` / ``--plot`` targets before the computation starts.

    Parameters
    ----------
    csv_path, plot_path : str or None
        The options' values (None: not asked for).
    """
    from hapstab.plotting import FORMATS

    if csv_path is not None:
        check_target(csv_path, "--csv")
    if plot_path is not None:
        check_target(plot_path, "--plot", FORMATS)


def write_files(res: Any, csv_path: str | None = None, plot_path: str | None = None,
                **plot_kw: Any) -> list[str]:
    """Write ``res.to_csv`` and ``res.plot()`` to the targets asked for, together: either
    every file is replaced by its complete new version, or none is.

    Parameters
    ----------
    res : result object
        With ``to_csv(file)`` and ``plot(ax=None)``.
    csv_path, plot_path : str or None
        The targets (None: not asked for).
    **plot_kw
        Passed to ``savefig`` (e.g. ``dpi``).

    Returns
    -------
    list of str
        The files written.
    """
    check_files(csv_path, plot_path)
    with Outputs() as out:
        if csv_path is not None:
            with out.open(csv_path, "--csv", newline="") as fh:
                res.to_csv(fh)
        if plot_path is not None:
            figure_to(out, res, plot_path, "--plot", **plot_kw)
    return out.written
