"""Network trace files for simulation: the format of
:mod:`hapstab.simulation.network`, read and checked row by row.

A trace is CSV with one header line and columns by name: ``sample`` (0, 1, 2, ... in
order) or ``time_s`` (k T), ``delay_samples`` (the transport delay of the packet sent at
that sample, a whole number >= 0), ``arrived`` (1 / 0, true / false); for PEB optionally
``delay_backward_samples`` and ``arrived_backward`` (the slave -> master direction).
Lines starting with ``#`` are comments. Every refusal names the row (the file's line,
the header being row 1) and the column.

References
----------
See :mod:`hapstab.simulation.network`.
"""

from __future__ import annotations

import csv
import math

import numpy as np

from hapstab.errors import MAX_DELAY_SAMPLES, ModelError
from hapstab.simulation.network import Network

__all__ = ["NetworkTraceError", "read_trace", "TRACE_COLUMNS", "TIME_TOL"]


class NetworkTraceError(ModelError):
    """A network trace file that cannot be read: names its row and column."""



#: Largest trace file read (bytes): ~3 million rows of ~20 bytes, more samples than the
#: simulation's budget steps in a minute (25 us a sample); a larger file is refused.
MAX_TRACE_BYTES = 64 * 1024 ** 2


def read_trace(path: str, period_s: float | None = None) -> Network:
    """Read a network trace file (format: the module docstring).

    Parameters
    ----------
    path : str
        The CSV file.
    period_s : float, optional
        T in s; needed when the file gives times (``time_s``) instead of samples.

    Returns
    -------
    Network

    Raises
    ------
    NetworkTraceError
        A row or column that breaks the format, named (rows counted from 1, the header
        being row 1).
    """
    from hapstab.reading import read_bounded
    raw = read_bounded(str(path), "delay trace", MAX_TRACE_BYTES,
                       "a delay trace is a CSV file", NetworkTraceError)
    try:
        text = raw.decode("utf-8-sig")      # a byte-order mark is not the header's
    except UnicodeDecodeError as e:
        raise NetworkTraceError(f"delay trace {path!r}: cannot be read ({e})") from None
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines(keepends=True))
             if not ln.lstrip().startswith("#") and ln.strip()]
    if not lines:
        raise NetworkTraceError(f"delay trace {path!r}: empty; need a header line "
                                "sample,delay_samples,arrived and one row per sample")
    rows = list(csv.reader([ln for _, ln in lines]))
    head = [h.strip() for h in rows[0]]
    back = _header(head, f"delay trace {path!r}, row {lines[0][0]} (header)")
    cols = ["delay_samples", "arrived"] + (["delay_backward_samples", "arrived_backward"]
                                          if back else [])
    idx = {h: i for i, h in enumerate(head)}
    n = len(rows) - 1
    D, A = np.zeros((len(cols) // 2, n), int), np.zeros((len(cols) // 2, n), bool)
    times = np.zeros(n)
    for r, (line_no, _), row in zip(range(n), lines[1:], rows[1:], strict=True):
        at = f"delay trace {path!r}, row {line_no}"
        if len(row) != len(head):
            raise NetworkTraceError(f"{at}: {len(row)} fields; the header has {len(head)}")
        cell = {h: row[i].strip() for h, i in idx.items()}
        if "sample" in cell:
            if not (cell["sample"].isdigit() and int(cell["sample"]) == r):
                raise NetworkTraceError(f"{at}, column 'sample': {cell['sample']!r}; the rows "
                                        f"must be the samples 0, 1, 2, ... in order (expected {r})")
        else:
            times[r] = _number(cell["time_s"], at, "time_s")
        for t in range(len(cols) // 2):
            dname, aname = cols[2 * t], cols[2 * t + 1]
            v = _number(cell[dname], at, dname)
            if not (v == math.floor(v) and 0 <= v <= MAX_DELAY_SAMPLES):
                raise NetworkTraceError(f"{at}, column {dname!r}: {cell[dname]!r}; must be a "
                                        f"whole number of samples in [0, {MAX_DELAY_SAMPLES}]")
            D[t, r] = int(v)
            flag = cell[aname].lower()
            if flag not in ("1", "0", "true", "false"):
                raise NetworkTraceError(f"{at}, column {aname!r}: {cell[aname]!r}; must be 1 "
                                        "or 0 (true / false)")
            A[t, r] = flag in ("1", "true")
    if n == 0:
        raise NetworkTraceError(f"delay trace {path!r}: a header and no rows")
    if "time_s" in head:
        _check_times(times, period_s, path, [ln for ln, _ in lines[1:]])
    return Network(delay_samples=D, arrived=A, source=str(path))


#: A time stamp is sample k when within this fraction of T of k T: written with a few
#: significant digits a time is off by far less than this, and a neighbour is a whole T away.
TIME_TOL = 1e-6


def _check_times(times: np.ndarray, period_s: float | None, path: str, line_nos: list) -> None:
    if period_s is None:
        raise NetworkTraceError(f"delay trace {path!r}: a time_s column needs the sampling "
                                "period (read_trace(path, period_s=T)); or give 'sample'")
    k = np.arange(times.size)
    bad = np.flatnonzero(np.abs(times - k * period_s) > TIME_TOL * period_s)
    if bad.size:
        r = int(bad[0])
        raise NetworkTraceError(f"delay trace {path!r}, row {line_nos[r]}, column 'time_s': "
                                f"{times[r]!r}; the rows must be the samples k T = "
                                f"{r * period_s:g} s in order (T = {period_s:g} s, within "
                                f"{TIME_TOL:g} T)")


#: The columns a trace file may have.
TRACE_COLUMNS = ("sample", "time_s", "delay_samples", "arrived", "delay_backward_samples",
                 "arrived_backward")


def _header(head: list[str], where: str) -> bool:
    """Check a trace file's header; True when it has the backward direction."""
    allowed = set(TRACE_COLUMNS)
    for h in head:
        if h not in allowed:
            raise NetworkTraceError(f"{where}: column {h!r} is unknown; allowed: "
                                    f"{', '.join(sorted(allowed))}")
    if len(set(head)) != len(head):
        raise NetworkTraceError(f"{where}: a column is named twice ({', '.join(head)})")
    if ("sample" in head) == ("time_s" in head):
        raise NetworkTraceError(f"{where}: give one of the columns 'sample' or 'time_s'")
    for need in ("delay_samples", "arrived"):
        if need not in head:
            raise NetworkTraceError(f"{where}: column {need!r} is missing")
    back = [h in head for h in ("delay_backward_samples", "arrived_backward")]
    if any(back) and not all(back):
        raise NetworkTraceError(f"{where}: give both delay_backward_samples and "
                                "arrived_backward, or neither")
    return all(back)


def _number(text: str, at: str, col: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise NetworkTraceError(f"{at}, column {col!r}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise NetworkTraceError(f"{at}, column {col!r}: {text!r} is not finite")
    return v
