"""Reading and checking a recorded run for :func:`hapstab.identify`: time, commanded
force and measured position at a fixed rate, every value a finite number."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from hapstab.errors import ModelError, check_reals

__all__ = ["read_log", "COLUMN_NAMES", "MIN_SAMPLES", "JITTER"]

#: Header names recognised for each column (case-insensitive), time, force, position.
COLUMN_NAMES = (("time_s", "time", "t", "t_s"),
                ("force_n", "force", "f", "u", "command_n", "commanded_force_n"),
                ("position_m", "position", "x", "y", "x_m", "measured_position_m"))
#: Fewest samples of a log: five parameters and their intervals from the residuals'
#: spread need many more samples than parameters (the t quantile with N - 5 degrees of
#: freedom, and a spread estimated to ~1/sqrt(2N) = 7 % at N = 100).
MIN_SAMPLES = 100
#: Largest relative deviation of a period from the log's mean period: the exact model
#: has one period T; 1e-3 T also allows times written with 4 significant digits of T
#: (a CSV of milliseconds rounded to microseconds).
JITTER = 1e-3


def read_log(log: Any, columns: tuple[str, str, str] | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, str]:
    """The time, force and position of a log, checked, and its period.

    Parameters
    ----------
    log : str, os.PathLike, dict or (N, 3) array
        A CSV file with a header naming time (s), force (N) and position (m) (see
        :data:`COLUMN_NAMES`; other columns are ignored), a dict of three arrays or an
        (N, 3) array.
    columns : tuple of str, optional
        The CSV's (or dict's) time, force and position names, when not recognised.

    Returns
    -------
    t, F, y : (N,) arrays
    period_s : float
        The mean period.
    source : str
        What was read (the file's name, ``dict`` or ``array``).

    Raises
    ------
    ModelError
        Unreadable or missing columns, a value that is not a finite number, a time that is
        not increasing at a fixed rate, or fewer than :data:`MIN_SAMPLES` samples.
    """
    if isinstance(log, (str, os.PathLike)):
        t, F, y = _from_csv(os.fspath(log), columns)
        source = os.path.basename(os.fspath(log))
    elif isinstance(log, Mapping):
        names = _pick(list(log), columns, "log")
        t, F, y = (check_reals(f"log[{n!r}]", log[n]) for n in names)
        source = "dict"
    else:
        a = np.asarray(check_reals("log", log)).reshape(np.shape(log))
        if a.ndim != 2 or a.shape[1] != 3:
            raise ModelError(f"log: an array of shape {a.shape}; need (N, 3): time, force, "
                             "position")
        t, F, y = a[:, 0], a[:, 1], a[:, 2]
        source = "array"
    for name, v in (("time", t), ("force", F), ("position", y)):
        _finite(name, v)
    if not t.size == F.size == y.size:
        raise ModelError(f"log: columns of {t.size}, {F.size} and {y.size} values; need equal")
    T = _period(t)
    from hapstab.errors import PERIOD_RANGE
    if not PERIOD_RANGE[0] <= T <= PERIOD_RANGE[1]:
        raise ModelError(f"log: period {T:g} s: must be between {PERIOD_RANGE[0]:g} s and "
                         f"{PERIOD_RANGE[1]:g} s (the models' range)")
    for name, v, unit in (("force", F, "N"), ("position", y, "m")):
        top = float(np.abs(v).max())
        if top and not SCALE[0] <= top <= SCALE[1]:
            raise ModelError(f"log: {name} up to {top:g} {unit}: the largest must be between "
                             f"{SCALE[0]:g} and {SCALE[1]:g} {unit} (the fit's products and "
                             "squares must stay inside double precision); give it in SI units")
    return t, F, y, T, source


#: The largest |force| (N) and |position| (m) a log may have (when not all 0): the fit
#: squares and multiplies them with the period's powers; 1e-300 or 1e300 overflowed it
#: (scipy's least_squares refused its scale, LAPACK's SVD failed: a helper's fuzz).
SCALE = (1e-100, 1e100)


#: Largest log file read (bytes): ~1 million rows of ~60 bytes (time, force, position),
#: far more than any identification needs; a larger file is refused.
MAX_LOG_BYTES = 64 * 1024 ** 2


def _from_csv(path: str, columns: tuple[str, str, str] | None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import csv
    import io

    from hapstab.reading import read_bounded
    raw = read_bounded(str(path), "log", MAX_LOG_BYTES, "a log is a CSV file", ModelError)
    try:
        # utf-8-sig: a byte-order mark (a spreadsheet's "CSV UTF-8") is not the first
        # column's name
        rows = list(csv.reader(io.StringIO(raw.decode("utf-8-sig"), newline="")))
    except UnicodeDecodeError as e:
        raise ModelError(f"log = {path!r}: not UTF-8 text ({e})") from None
    rows = [r for r in rows if r and not r[0].lstrip().startswith("#")]
    if len(rows) < 2:
        raise ModelError(f"log = {path!r}: needs a header line and data rows")
    header = [h.strip() for h in rows[0]]
    names = _pick(header, columns, f"log = {path!r}")
    cols = [header.index(n) for n in names]
    out = np.empty((3, len(rows) - 1))
    for i, r in enumerate(rows[1:]):
        for j, c in enumerate(cols):
            try:
                out[j, i] = float(r[c])
            except (ValueError, IndexError):
                raise ModelError(f"log = {path!r}: row {i + 2}, column {names[j]!r}: "
                                 f"{r[c] if c < len(r) else ''!r} is not a number") from None
    return out[0], out[1], out[2]


def _pick(names: list[str], columns: tuple[str, str, str] | None, what: str) -> list[str]:
    """The time, force and position column names among ``names``."""
    if columns is not None:
        if len(columns) != 3:
            raise ModelError(f"columns = {columns!r}: need three names: time, force, position")
        missing = [c for c in columns if c not in names]
        if missing:
            raise ModelError(f"{what}: no column {missing[0]!r}; it has {', '.join(names)}")
        return list(columns)
    low = {n.lower(): n for n in names}
    found = []
    for kind, options in zip(("time", "force", "position"), COLUMN_NAMES, strict=True):
        hit = next((low[o] for o in options if o in low), None)
        if hit is None:
            raise ModelError(f"{what}: no {kind} column (looked for {', '.join(options)}; it "
                             f"has {', '.join(names)}); name them with columns=/--columns")
        found.append(hit)
    return found


def _finite(name: str, v: np.ndarray) -> None:
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise ModelError(f"log: {name} at sample {int(bad[0])} is {v[bad[0]]}: every value "
                         f"must be a finite number ({bad.size} are not)")


def _period(t: np.ndarray) -> float:
    """The log's period, refusing too few samples or a time not at a fixed rate."""
    if t.size < MIN_SAMPLES:
        raise ModelError(f"log: {t.size} samples: too short; need >= {MIN_SAMPLES}")
    d = np.diff(t)
    if not np.all(d > 0):
        k = int(np.flatnonzero(d <= 0)[0])
        raise ModelError(f"log: time does not increase at sample {k + 1} ({t[k]:.9g} s then "
                         f"{t[k + 1]:.9g} s)")
    T = float((t[-1] - t[0]) / (t.size - 1))
    dev = np.abs(d - T) / T
    if dev.max() > JITTER:
        k = int(dev.argmax())
        raise ModelError(f"log: non-uniform time: the period at sample {k + 1} is {d[k]:.6g} s, "
                         f"{100 * dev[k]:.3g} % from the mean {T:.6g} s (allowed {JITTER:.0e} "
                         "relative); the model needs a fixed sampling rate")
    if not math.isfinite(T) or T <= 0:
        raise ModelError(f"log: period {T} s")
    return T
