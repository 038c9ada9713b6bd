"""The folder of a sweep: ``chunks/chunk-000123.parquet`` (one row per point) and
``manifest.json`` (what the sweep is and which chunks are finished).

A chunk is written to a temporary file in ``chunks/`` and renamed into place once it is
complete and on disk (:func:`hapstab.outputs.atomic_file`); the manifest likewise, after
the chunks it names (half a second apart at least, longer for a long manifest, and at
the end). On a rerun a chunk counts
as finished when its file is there and matches the manifest's row count and SHA-256; a
complete chunk file the manifest does not name yet (a kill between the two renames) is
checked (its rows and columns) and adopted; temporary files a kill left are removed. A
folder holding another sweep (another study's SHA-256) is refused unless ``force``.
"""

from __future__ import annotations

import glob
import hashlib
import io
import json
import os
import time
from typing import Any

from hapstab.outputs import OutputError, atomic_file
from hapstab.sweep.axes import SweepError, chunks_of, ids_of

__all__ = ["Store", "MANIFEST", "CHUNKS", "chunk_name", "arrow_schema", "read_chunk"]

MANIFEST = "manifest.json"
CHUNKS = "chunks"
#: The files a sweep writes in its folder, besides its chunks.
OWN_FILES = ("summary.json", "kmax.png", MANIFEST)
#: Seconds between two writes of the manifest at least (a sweep of 10^5 chunks must not
#: rewrite a manifest of 10^5 entries after each of them; a long one waits 20 times as long
#: as it took to write).
MANIFEST_EVERY_S = 0.5


def chunk_name(index: int) -> str:
    """``chunk-000123.parquet``: the file of chunk ``index``.

    Parameters
    ----------
    index : int

    Returns
    -------
    str
    """
    return f"chunk-{index:06d}.parquet"


def read_chunk(path: str, columns: list[str] | None = None) -> Any:
    """A chunk file's rows (opened as a file: a folder named like a URI, ``s3:x``, is
    still a folder).

    Parameters
    ----------
    path : str
    columns : list of str, optional
        Only these columns.

    Returns
    -------
    pyarrow.Table
    """
    import pyarrow.parquet as pq

    # one chunk is small: read it on this thread. pyarrow's thread pools, once started,
    # can abort the interpreter at exit ("terminate called without an active
    # exception", SIGABRT after the work is done: apache/arrow#34314), seen once in CI
    with open(path, "rb") as fh:
        return pq.read_table(fh, columns=columns, use_threads=False, pre_buffer=False)


def arrow_schema(columns: list[tuple[str, str]]) -> Any:
    """The Parquet schema of a sweep's rows.

    Parameters
    ----------
    columns : list of (str, str)
        (name, type) as :func:`hapstab.sweep.evaluate.columns` gives them.

    Returns
    -------
    pyarrow.Schema
    """
    import pyarrow as pa

    types = {"int64": pa.int64(), "float64": pa.float64(), "string": pa.string(),
             "bool": pa.bool_()}
    return pa.schema([(name, types[t]) for name, t in columns])


class Store:
    """A sweep's folder.

    Parameters
    ----------
    folder : str
        The folder (created if missing).
    head : dict
        What the sweep is (study SHA-256, points, chunk size, axes, columns, version):
        the manifest's fixed part.
    columns : list of (str, str)
        The rows' columns.
    force : bool
        Start over in a folder that holds another sweep.
    """

    def __init__(self, folder: str, head: dict[str, Any], columns: list[tuple[str, str]],
                 force: bool = False) -> None:
        self.folder, self.head, self.columns = folder, dict(head), columns
        self.schema = arrow_schema(columns)
        self.chunks_dir = os.path.join(folder, CHUNKS)
        self.path = os.path.join(folder, MANIFEST)
        self.done: dict[int, dict[str, Any]] = {}
        self._written, self._every = 0.0, MANIFEST_EVERY_S
        self._open(force)

    # ------------------------------------------------------------------ opening
    def _open(self, force: bool) -> None:
        self._refuse_link(self.chunks_dir)
        try:
            os.makedirs(self.chunks_dir, exist_ok=True)
        except OSError as e:
            raise OutputError(f"--out = {self.folder!r:.80}: cannot create the folder "
                              f"({e.strerror or e})") from None
        for path in (*self._chunk_files(), *self._parts(),
                     *(os.path.join(self.folder, f) for f in OWN_FILES)):
            self._refuse_link(path)
        old = None if force else self._read_manifest()
        if old is not None and old.get("study_sha256") != self.head["study_sha256"]:
            raise SweepError(f"--out = {self.folder!r:.80}: holds another sweep (study "
                             f"SHA-256 {str(old.get('study_sha256'))[:12]}..., this one "
                             f"{self.head['study_sha256'][:12]}...); choose another folder, "
                             "or --force to start over there")
        if force:
            self._clear()
        for tmp in self._parts():      # a kill's leftovers: never complete
            os.remove(tmp)
        if old is None and not force and self._chunk_files():
            raise SweepError(f"--out = {self.folder!r:.80}: has chunk files but no manifest "
                             "(not a sweep's folder, or its manifest was removed); choose "
                             "another folder, or --force to start over there")
        if old is not None:
            self.head["chunk"] = int(old.get("chunk", self.head["chunk"]))
            for entry in old.get("finished", []):
                if self._matches(entry):
                    self.done[int(entry["chunk"])] = entry
        self._adopt()
        self.write_manifest(now=True)

    def _refuse_link(self, path: str) -> None:
        """Refuse a symbolic link where the sweep writes or deletes: the sweep never makes
        one, so it is someone else's, and writing or deleting through it would reach
        files outside the folder (``--force`` deleted ``chunk-*.parquet`` in a linked
        ``chunks/``'s target)."""
        if os.path.islink(path):
            raise SweepError(f"--out = {self.folder!r:.80}: {os.path.relpath(path, self.folder)} "
                             "is a symbolic link (a sweep never makes one, and never writes "
                             "or deletes through one); remove it, or choose another folder")

    def _parts(self) -> list[str]:
        return [t for d in (self.chunks_dir, self.folder)
                for t in glob.glob(os.path.join(glob.escape(d), ".*.part"))]

    def _read_manifest(self) -> dict[str, Any] | None:
        if not os.path.exists(self.path):
            return None
        try:
            with open(self.path) as fh:
                data = json.load(fh)
        except (OSError, ValueError) as e:
            raise SweepError(f"--out = {self.folder!r:.80}: its {MANIFEST} cannot be read "
                             f"({e}); --force starts over") from None
        if not isinstance(data, dict):
            raise SweepError(f"--out = {self.folder!r:.80}: its {MANIFEST} is not a sweep's "
                             "manifest; --force starts over")
        return data

    def _clear(self) -> None:
        for f in self._chunk_files():
            os.remove(f)
        for f in OWN_FILES:
            if os.path.exists(os.path.join(self.folder, f)):
                os.remove(os.path.join(self.folder, f))

    def _chunk_files(self) -> list[str]:
        return sorted(glob.glob(os.path.join(glob.escape(self.chunks_dir), "chunk-*.parquet")))

    def _matches(self, entry: Any) -> bool:
        """A manifest entry whose file is there with its rows and SHA-256."""
        try:
            index, rows, sha = int(entry["chunk"]), int(entry["rows"]), str(entry["sha256"])
        except (KeyError, TypeError, ValueError):
            return False
        path = os.path.join(self.chunks_dir, chunk_name(index))
        return (0 <= index < self.n_chunks and rows == self.rows_of(index)
                and os.path.exists(path) and _sha256(path) == sha)

    def _adopt(self) -> None:
        """Complete chunk files the manifest does not name: checked, then counted."""
        import pyarrow.parquet as pq

        for path in self._chunk_files():
            try:
                index = int(os.path.basename(path)[6:12])
            except ValueError:
                continue
            if index in self.done or not 0 <= index < self.n_chunks:
                continue
            try:
                with open(path, "rb") as fh:
                    meta = pq.ParquetFile(fh)
                    schema, rows = meta.schema_arrow, meta.metadata.num_rows
            except Exception:       # not a Parquet file we wrote: computed again
                continue
            if rows == self.rows_of(index) and schema.equals(self.schema):
                self.done[index] = {"chunk": index, "rows": rows, "sha256": _sha256(path)}

    # ------------------------------------------------------------------ the work
    @property
    def n_chunks(self) -> int:
        """Chunks in all."""
        return chunks_of(int(self.head["points"]), int(self.head["chunk"]))

    def rows_of(self, index: int) -> int:
        """Points in chunk ``index``.

        Parameters
        ----------
        index : int

        Returns
        -------
        int
        """
        start, stop = ids_of(index, int(self.head["chunk"]), int(self.head["points"]))
        return stop - start

    def missing(self) -> list[int]:
        """The chunks not finished, in order.

        Returns
        -------
        list of int
        """
        return [c for c in range(self.n_chunks) if c not in self.done]

    def write_chunk(self, index: int, cols: dict[str, list[Any]]) -> None:
        """Write one chunk's rows (then, at most every half second, the manifest).

        Parameters
        ----------
        index : int
        cols : dict
            Column -> values, every column of the schema.
        """
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table({name: pa.array(cols[name], type=self.schema.field(name).type)
                          for name in self.schema.names}, schema=self.schema)
        buf = io.BytesIO()
        pq.write_table(table, buf, compression="zstd")
        data = buf.getvalue()
        with atomic_file(os.path.join(self.chunks_dir, chunk_name(index)), "--out", "wb") as fh:
            fh.write(data)
        self.done[index] = {"chunk": index, "rows": table.num_rows,
                            "sha256": hashlib.sha256(data).hexdigest()}
        self.write_manifest()

    def write_manifest(self, now: bool = False, **extra: Any) -> dict[str, Any]:
        """Write the manifest (atomically); unless ``now``, only when the last write is
        half a second old.

        Parameters
        ----------
        now : bool
            Write it whatever the time.
        **extra
            More keys (the summary's files, at the end).

        Returns
        -------
        dict
            The manifest written (empty if it was not written now).
        """
        if not (now or time.monotonic() - self._written >= self._every):
            return {}
        t0 = time.monotonic()
        m = self.manifest(**extra)
        with atomic_file(self.path, "--out") as fh:
            json.dump(m, fh, indent=1)
            fh.write("\n")
        self._written = time.monotonic()
        # a long manifest (10^5 chunks) is written less often: at most 5 % of the time
        self._every = max(MANIFEST_EVERY_S, 20 * (self._written - t0))
        return m

    def manifest(self, **extra: Any) -> dict[str, Any]:
        """The manifest as it stands.

        Parameters
        ----------
        **extra
            More keys.

        Returns
        -------
        dict
        """
        finished = [self.done[c] for c in sorted(self.done)]
        return {**self.head, "chunks": self.n_chunks, "finished_chunks": len(finished),
                "finished_points": sum(int(e["rows"]) for e in finished), **extra,
                "finished": finished}

    def chunk_paths(self) -> list[str]:
        """The finished chunks' files, in order.

        Returns
        -------
        list of str
        """
        return [os.path.join(self.chunks_dir, chunk_name(c)) for c in sorted(self.done)]


def _sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
