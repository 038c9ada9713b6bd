"""The stability explorer: a local web page over a small HTTP JSON API (``hapstab explore``).

The API (:mod:`hapstab.explorer.api`) answers with the CLI's own ``--json`` objects: a
request ``{"kind": "hve", "options": {...}}`` to ``/api/v1/kmax`` runs ``hapstab kmax hve
... --json`` in-process, through the same click command. :mod:`hapstab.explorer.app` is the
Starlette application, :mod:`hapstab.explorer.code` writes the "copy as CLI / Python"
text. Starlette and uvicorn are imported only here (``pip install 'hapstab[explore]'``).
"""

from __future__ import annotations

from typing import Any

__all__ = ["create_app"]


def create_app(study_path: str | None = None, host: str | None = None) -> Any:
    """The explorer's Starlette application (see :func:`hapstab.explorer.app.create_app`).

    Parameters
    ----------
    study_path : str, optional
        A study file (kind hve or peb) whose [loop] table is the page's initial state.
    host : str, optional
        The interface it listens on: accepted as a Host header beside 127.0.0.1,
        localhost and ::1.

    Returns
    -------
    starlette.applications.Starlette
    """
    from hapstab.explorer.app import create_app as make

    return make(study_path, host)
