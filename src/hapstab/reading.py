"""Reading a user's input file safely: only a regular file, of a bounded size.

A path given as a study, a delay trace or a recorded log may name a device
(``/dev/zero``, ``/dev/urandom``), a FIFO, a socket or a folder, or a file far larger
than any such input; reading it naively hangs or fills the memory (issue 27). Every
reader of a user's file goes through :func:`read_bounded`.
"""

from __future__ import annotations

import os
import stat

__all__ = ["read_bounded"]


def read_bounded(path: str, name: str, max_bytes: int, what: str,
                 error: type[Exception]) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes`` of them.

    Opened without blocking (a FIFO would wait for a writer) and checked on the open
    descriptor (no race with a rename): a device, FIFO, socket or folder is refused, and
    so is a file larger than the bound (read bounded as well: a file that grows while it
    is read is refused too).

    Parameters
    ----------
    path : str
        The file.
    name : str
        How the user gave it (an option or parameter name), for the message.
    max_bytes : int
        The largest file accepted.
    what : str
        What the file is, in words (``"a study is a TOML file"``).
    error : type
        The exception raised (a :class:`~hapstab.errors.HapstabError`).

    Returns
    -------
    bytes
    """
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise error(f"{name} = {path!r}: cannot read it ({e.strerror or e})") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise error(f"{name} = {path!r}: not a regular file (a device, FIFO, socket or "
                    f"folder); {what}")
    with os.fdopen(fd, "rb") as fh:
        if st.st_size > max_bytes:
            raise error(f"{name} = {path!r}: {st.st_size} bytes; at most {max_bytes} bytes "
                        f"are read ({what})")
        try:
            raw = fh.read(max_bytes + 1)
        except OSError as e:
            raise error(f"{name} = {path!r}: cannot read it ({e.strerror or e})") from None
    if len(raw) > max_bytes:
        raise error(f"{name} = {path!r}: more than {max_bytes} bytes; at most {max_bytes} "
                    f"bytes are read ({what})")
    return raw
