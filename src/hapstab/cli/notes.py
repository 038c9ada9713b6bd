"""Notes the command line says once on stderr beside an answer (not errors): a delay of
a second or more given as a bare number, most often milliseconds meant."""

from __future__ import annotations

import re
from typing import Any

import click

__all__ = ["remember_plain_seconds", "note_plain_seconds"]

#: A number written without a unit (digits, a point, an exponent).
_PLAIN = re.compile(r"\s*[\d.eE+-]+\s*")


def remember_plain_seconds(value: Any, param: Any, ctx: Any) -> None:
    """Remember a delay option given in seconds without a unit (``--delay-s 10``)."""
    if ctx is not None and param is not None and "delay" in (param.name or "") \
            and _PLAIN.fullmatch(str(value)):
        ctx.meta.setdefault("hapstab_plain_seconds", {})[param.opts[0]] = str(value).strip()


def note_plain_seconds(delay_s: float) -> None:
    """Once the loop is built: if its delay (s) is a second or more and was given as a
    bare number, say that it reads as seconds."""
    ctx = click.get_current_context(silent=True)
    plain = ctx.meta.get("hapstab_plain_seconds", {}) if ctx is not None else {}
    if delay_s >= 1.0:
        for opt, raw in plain.items():
            click.echo(f"hapstab: note: {opt} {raw} reads as {float(raw):g} s; for "
                       f"milliseconds write {raw}ms", err=True)
