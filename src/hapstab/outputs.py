"""Files a user asks for, written so that they are never half-written.

Every file goes to a temporary file in the target's own folder (``.name.XXXX.part``)
and is renamed over the target only once it is complete and flushed to disk
(``os.replace`` is atomic on one file system). An error or an interrupt removes the
temporary files and leaves the previous target untouched; concurrent writers each
leave one complete file. Several files of one run (a CSV and its plot, the folder of
a reproduction) are committed together, after every one of them was written.

A target that exists and is not a regular file (``/dev/stdout``, ``/dev/null``, a
pipe) cannot be replaced: it is written directly, and a failed write is still an
error.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import stat
import tempfile
from collections.abc import Iterator
from typing import IO, Any

from hapstab.errors import ArgumentTypeError, HapstabError

__all__ = ["OutputError", "check_target", "Outputs", "atomic_file", "writing", "figure_to",
           "write_folder", "signals_held"]


class OutputError(HapstabError):
    """A file the user asked for cannot be written (the message names the option and path)."""


def check_target(path: Any, name: str, formats: tuple[str, ...] | None = None) -> str:
    """Refuse a target before any work is done: empty, a folder, a missing folder, or an
    extension that is not one of ``formats``.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    name : str
        The option or argument that gave it (``"--csv"``), named in errors.
    formats : tuple of str, optional
        Allowed extensions (lower case, no dot); ``None``: any.

    Returns
    -------
    str
        The path as a string.

    Raises
    ------
    OutputError
        If the target cannot be written.
    """
    if not isinstance(path, (str, os.PathLike)) or not isinstance(os.fspath(path), str):
        raise ArgumentTypeError(f"{name} = {path!r:.60}: must be a file path (str or "
                                f"os.PathLike) or a file object (got {type(path).__name__})")
    p = os.fspath(path)
    if not p.strip():
        raise OutputError(f"{name} = {path!r}: must be a file path (it is empty)")
    if "\0" in p:
        raise OutputError(f"{name} = {p!r:.80}: a file path cannot contain a NUL character")
    if os.path.isdir(p):
        raise OutputError(f"{name} = {p!r}: is a folder; give a file path")
    folder = os.path.dirname(os.path.abspath(p))
    if not os.path.isdir(folder):
        raise OutputError(f"{name} = {p!r}: the folder {folder!r} does not exist")
    if not (_is_special(p) or _folder_writable(p) or _file_writable(p)):
        raise OutputError(f"{name} = {p!r}: the folder {folder!r} is not writable")
    if formats is not None:
        base = os.path.basename(p)
        ext = base.rsplit(".", 1)[-1].lower() if "." in base else ""
        if ext not in formats:
            raise OutputError(f"{name} = {p!r}: the extension {ext or '(none)'!r} is not a format "
                              f"hapstab writes; allowed: {', '.join(formats)}")
    return p


def _folder_writable(path: str) -> bool:
    """Whether a new file can be created beside ``path`` (its real location)."""
    return os.access(os.path.dirname(os.path.realpath(path)), os.W_OK | os.X_OK)


def _file_writable(path: str) -> bool:
    """Whether ``path`` exists and can be written (in place, when its folder is not writable)."""
    return os.path.isfile(path) and os.access(path, os.W_OK)


def _is_special(path: str) -> bool:
    """A target that must be written in place: a device, a pipe, or anything under /dev
    or /proc (``/dev/stdout`` is a link to whatever fd 1 is: renaming over it would replace
    the link, and resolving it would replace the file behind the shell's redirection)."""
    if os.path.abspath(path).startswith(("/dev/", "/proc/")):
        return True
    try:
        return not stat.S_ISREG(os.stat(path).st_mode)
    except OSError:          # missing, or a name the system refuses (too long): not special
        return False


class Outputs:
    """Files written together: each to a temporary file, all renamed into place by
    :meth:`commit` (the ``with`` block commits when it ends without an exception and
    removes every temporary file otherwise).

    Examples
    --------
    >>> with Outputs() as out:                                   # doctest: +SKIP
    ...     with out.open("run.csv", "--csv") as fh:
    ...         fh.write("t,x\\n0,1\\n")
    """

    def __init__(self) -> None:
        # (temporary, target, option, copied into the target in place)
        self._pending: list[tuple[str, str, str, bool]] = []
        self.written: list[str] = []

    @contextlib.contextmanager
    def open(self, path: Any, name: str, mode: str = "w", **kw: Any) -> Iterator[IO[Any]]:
        """A file object for ``path``, written to a temporary file until :meth:`commit`.

        Parameters
        ----------
        path : str or os.PathLike
            The target.
        name : str
            The option or argument that gave it, named in errors.
        mode : {"w", "wb"}
            Text or binary.
        **kw
            Passed to :func:`open` (e.g. ``newline=""``).

        Yields
        ------
        file object

        Raises
        ------
        OutputError
            The file cannot be created or written (the path and the reason named).
        """
        target = check_target(path, name)
        if _is_special(target):
            with self._failing(target, name), open(target, mode, **kw) as fh:  # device or pipe
                yield fh
                fh.flush()
            self.written.append(target)
            return
        # a symbolic link is written through (its target replaced, the link kept)
        folder, base = os.path.split(os.path.realpath(target))
        real = os.path.join(folder, base)
        if os.path.exists(real) and not (os.access(real, os.W_OK)
                                         and os.stat(real).st_mode & 0o222):
            raise OutputError(f"{name} = {target!r}: the file is read-only; hapstab does not "
                              "replace it (make it writable or choose another name)")
        in_place = not _folder_writable(real)    # a writable file in a read-only folder
        with self._failing(target, name):
            fd, tmp = _temporary(base, None if in_place else folder)
        try:
            with self._failing(target, name), os.fdopen(fd, mode, **kw) as fh:
                yield fh
                fh.flush()
                os.fsync(fh.fileno())
        except BaseException:
            _remove(tmp)
            raise
        self._pending.append((tmp, real, name, in_place))

    @contextlib.contextmanager
    def _failing(self, target: str, name: str) -> Iterator[None]:
        try:
            yield
        except OSError as e:
            raise OutputError(f"{name} = {target!r}: cannot write ({e.strerror or e})") from None

    def commit(self) -> list[str]:
        """Rename every temporary file over its target; if one rename fails, the targets
        already replaced get their previous versions back (or are removed if new).

        Returns
        -------
        list of str
            Every target written, in order.

        Raises
        ------
        OutputError
            A rename failed (the remaining temporary files are removed).
        """
        keep = len(self._pending) > 1        # one file: os.replace is all-or-nothing
        done: list[tuple[str, str | None, bool]] = []   # (target, _previous_version, in place)
        # a signal is held until the files are all replaced or all put back (a Ctrl-C
        # between two renames would leave a mix); it is delivered right after
        with signals_held():
            try:
                for tmp, target, name, in_place in self._pending:
                    with self._failing(target, name):
                        old = _previous_version(target, keep or in_place, in_place)
                        done.append((target, old, in_place))   # a failed put is undone too
                        _put(tmp, target, in_place)
            except BaseException:
                _roll_back(done)
                raise
            finally:
                self.abort()
                for _, old, _ in done:
                    if old:
                        _remove(old)
        self.written += [target for target, _, _ in done]
        return self.written

    def abort(self) -> None:
        """Remove the temporary files not yet committed."""
        for tmp, *_ in self._pending:
            _remove(tmp)
        self._pending.clear()

    def __enter__(self) -> Outputs:
        return self

    def __exit__(self, kind: Any, value: Any, tb: Any) -> None:
        if kind is None:
            self.commit()
        else:
            self.abort()


@contextlib.contextmanager
def atomic_file(path: Any, name: str, mode: str = "w", **kw: Any) -> Iterator[IO[Any]]:
    """One file written atomically (see :class:`Outputs`).

    Parameters
    ----------
    path : str or os.PathLike
        The target.
    name : str
        The option or argument that gave it, named in errors.
    mode : {"w", "wb"}
        Text or binary.
    **kw
        Passed to :func:`open`.

    Yields
    ------
    file object
    """
    with Outputs() as out, out.open(path, name, mode, **kw) as fh:
        yield fh


@contextlib.contextmanager
def writing(target: Any, name: str, mode: str = "w", **kw: Any) -> Iterator[IO[Any]]:
    """A file object to write to: ``target`` itself if it is one (anything with
    ``write``), else an atomic file at that path (see :class:`Outputs`).

    Parameters
    ----------
    target : str, os.PathLike or file object
        Where to write.
    name : str
        The argument that gave it, named in errors.
    mode : {"w", "wb"}
        Text or binary, for a path.
    **kw
        Passed to :func:`open` for a path.

    Yields
    ------
    file object
    """
    if hasattr(target, "write"):
        yield target
        return
    with atomic_file(target, name, mode, **kw) as fh:
        yield fh


def figure_to(out: Outputs, res: Any, path: str, name: str, **kw: Any) -> None:
    """Draw ``res.plot()`` on a new figure and add it to ``out`` at ``path`` (its
    extension names the format).

    Parameters
    ----------
    out : Outputs
        The files being written together.
    res : result object
        Anything with ``plot(ax=None)`` returning its axes.
    path : str
        The target.
    name : str
        The option or argument that gave it, named in errors.
    **kw
        Passed to ``savefig``.
    """
    import matplotlib.pyplot as plt
    import numpy as np

    fig = np.ravel(np.asarray(res.plot(), dtype=object))[0].figure
    kw.setdefault("dpi", 150)      # a figure to read on screen and in a report
    kw.setdefault("bbox_inches", "tight")   # titles of two or three lines stay inside
    try:
        with out.open(path, name, "wb") as fh:
            fig.savefig(fh, format=path.rsplit(".", 1)[-1].lower(), **kw)
    finally:
        plt.close(fig)


def write_folder(out_dir: str, results: list[tuple[str, Any]], manifest: dict[str, Any],
                 name: str = "out_dir") -> list[str]:
    """A folder of results: ``<name>.csv``, ``<name>.png`` and ``<name>.svg`` per result,
    then ``manifest.json`` naming the run, its inputs and every file, written last.

    Parameters
    ----------
    out_dir : str
        The folder (created if missing).
    results : list of (str, result)
        Each result's file name stem and the result.
    manifest : dict
        The run's inputs (command, arguments, hapstab version).
    name : str
        The option or argument that gave ``out_dir``, named in errors.

    Returns
    -------
    list of str
        The files written, the manifest last.
    """
    if not str(out_dir).strip():
        raise OutputError(f"{name} = {out_dir!r}: must be a folder path (it is empty)")
    try:
        os.makedirs(out_dir, exist_ok=True)
    except OSError as e:
        raise OutputError(f"{name} = {out_dir!r}: cannot create the folder ({e.strerror})") from None
    with Outputs() as out:
        names = []
        for stem, res in results:
            base = os.path.join(out_dir, stem)
            with out.open(base + ".csv", name, newline="") as fh:
                res.to_csv(fh)
            for ext in ("png", "svg"):
                figure_to(out, res, f"{base}.{ext}", name)
            names += [f"{stem}.csv", f"{stem}.png", f"{stem}.svg"]
        with out.open(os.path.join(out_dir, "manifest.json"), name) as fh:
            json.dump({**manifest, "files": names}, fh, indent=2)
            fh.write("\n")
    return out.written


def _temporary(base: str, folder: str | None) -> tuple[int, str]:
    """A new temporary file ``.base.XXXXXXXX.part`` in ``folder`` (None: the system's
    temporary folder); the name is cut so that it stays within the 255 bytes a file name
    may have."""
    stem = base.encode()[:200].decode(errors="ignore")   # + 8 random + 7 marks < 255
    return tempfile.mkstemp(prefix=f".{stem}.", suffix=".part", dir=folder)


def _previous_version(target: str, keep: bool, in_place: bool = False) -> str | None:
    """What a failed commit puts back at ``target``: None if there is no file there (the
    new one is removed), ``""`` if it is not kept (left as written), else the path of a
    second name for it (a hard link, or a copy where the file system has no links; a
    copy in the system's temporary folder for a file written in place, whose folder is
    read-only)."""
    if not os.path.lexists(target):
        return None
    if not keep:
        return ""
    folder = None if in_place else os.path.dirname(target)
    fd, old = _temporary(os.path.basename(target) + ".old", folder)
    os.close(fd)
    if in_place:
        shutil.copyfile(target, old)
        return old
    os.remove(old)                    # a fresh random name, now free for the link
    try:
        os.link(target, old)
    except OSError:
        shutil.copy2(target, old)
    return old


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP inside the block; they are delivered when it ends
    (so that files are all replaced or all put back, and a staging folder is removed).

    The signals are blocked in this thread; a signal sent to the process can still
    arrive through another thread that does not block them (pyarrow's and OpenBLAS's
    thread pools), and Python then runs its handler in the main thread. So in the main
    thread the handlers are also replaced, for the block, by ones that note the signal,
    and a noted signal is raised again once the block has ended.

    Yields
    ------
    None
    """
    import signal
    import threading

    sigs = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}
    try:
        before = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    except (AttributeError, OSError, ValueError):      # no POSIX signal masks here
        yield
        return
    noted: list[int] = []
    handlers: dict[int, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for sig in sigs:
            old = signal.getsignal(sig)
            if callable(old):                  # (SIG_DFL / SIG_IGN / a C handler: kept)
                handlers[sig] = old
                signal.signal(sig, lambda signum, frame: noted.append(signum))
    try:
        yield
    finally:
        for held, handler in handlers.items():
            signal.signal(held, handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
        for signum in noted:
            signal.raise_signal(signum)


def _put(tmp: str, target: str, in_place: bool) -> None:
    """Replace ``target`` by the complete temporary file."""
    if in_place:
        _copy_into(tmp, target)
        _remove(tmp)
    else:
        os.chmod(tmp, _mode(target))
        os.replace(tmp, target)


def _roll_back(done: list[tuple[str, str | None, bool]]) -> None:
    """Put back the previous version of every target already replaced (remove a new one)."""
    for target, old, in_place in reversed(done):
        with contextlib.suppress(OSError):
            if old is None:
                os.remove(target)
            elif old and in_place:
                _copy_into(old, target)
            elif old:
                os.replace(old, target)


def _copy_into(tmp: str, target: str) -> None:
    """Write the complete temporary file into ``target`` in place (its folder is read-only,
    so it cannot be renamed over; the computation is done and the copy is short)."""
    with open(tmp, "rb") as src, open(target, "r+b") as dst:
        shutil.copyfileobj(src, dst)
        dst.truncate()
        dst.flush()
        os.fsync(dst.fileno())


def _remove(path: str) -> None:
    with contextlib.suppress(OSError):
        os.remove(path)


def _mode(target: str) -> int:
    """The permissions of the file being replaced, or those a new file gets under the
    current umask (mkstemp makes 0600)."""
    try:
        return stat.S_IMODE(os.stat(target).st_mode)
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask
