""""Copy as CLI" and "copy as Python": the command line and a script for a request."""

from __future__ import annotations

import shlex
from typing import Any

from hapstab.explorer.api import ApiError, check_request

__all__ = ["code_for", "cli_line"]


def cli_line(argv: list[str]) -> str:
    """``hapstab ARGV``, each word shell-quoted.

    Parameters
    ----------
    argv : list of str
        A :func:`~hapstab.explorer.api.check_request` line.

    Returns
    -------
    str
    """
    return shlex.join(["hapstab", *argv])


def code_for(body: dict[str, Any]) -> dict[str, str]:
    """The command line (and, later, the Python script) of ``{"kind", "command", "options"}``.

    Parameters
    ----------
    body : dict
        The request.

    Returns
    -------
    dict
        ``{"cli": ..., "python": ...}``.

    Raises
    ------
    ApiError
        As for the command's own request; 400 without a command.
    """
    command = body.get("command")
    if not isinstance(command, str):
        raise ApiError(400, "command: missing or not a string; e.g. \"kmax\"", "command")
    argv = check_request(command, {k: v for k, v in body.items() if k != "command"})
    return {"cli": cli_line(argv), "python": ""}
