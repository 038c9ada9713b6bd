"""Small frozen result objects: every analysis returns one. ``to_dict()`` gives a
JSON-ready dict; ``.plot()`` hands off to :mod:`hapstab.plotting`."""

from __future__ import annotations

import html
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Result", "StabilityResult", "CriticalStiffnessResult", "BoundaryResult", "jsonable",
           "html_table", "write_csv",
           "dumps", "INFINITE"]


#: The key under which :func:`jsonable` lists the values it wrote as ``null`` because
#: they were infinite: ``{"path": 1}`` for +inf, ``-1`` for -inf (paths join keys and
#: list indices with "/", e.g. ``"stable_intervals/0/1"``).
INFINITE = "infinite"


def jsonable(x: Any) -> Any:
    """Convert numpy scalars/arrays, tuples and non-finite floats for strict JSON.

    NaN becomes ``null``; an infinity becomes ``null`` and, when ``x`` is a dict, its
    path is flagged under :data:`INFINITE` with its sign (so ``K_max = inf`` reads
    ``{"critical_stiffness": null, "infinite": {"critical_stiffness": 1}}``). Complex
    numbers become ``{"re": ..., "im": ...}``.

    Parameters
    ----------
    x : object
        A dict (a result's fields), list, scalar or array.

    Returns
    -------
    object
        Made of dict, list, str, int, float (finite), bool and None only.
    """
    found: dict[str, int] = {}
    out = _convert(x, "", found)
    if found and isinstance(out, dict):
        out[INFINITE] = {**out.get(INFINITE, {}), **found}
    return out


def _convert(x: Any, path: str, found: dict[str, int]) -> Any:
    at = (lambda k: f"{path}/{k}" if path else str(k))  # noqa: E731
    if isinstance(x, dict):
        return {k: _convert(v, at(k), found) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_convert(v, at(i), found) for i, v in enumerate(x)]
    if isinstance(x, np.ndarray):
        return _convert(x.tolist(), path, found)
    if isinstance(x, (np.floating, float)):
        v = float(x)
        if math.isinf(v):
            found[path] = 1 if v > 0 else -1
        return v if math.isfinite(v) else None
    if isinstance(x, (np.integer, np.bool_)):
        return x.item()
    if isinstance(x, (complex, np.complexfloating)):
        return {"re": _convert(x.real, at("re"), found), "im": _convert(x.imag, at("im"), found)}
    return x


def dumps(data: Any) -> str:
    """Strict JSON text (never NaN or Infinity) of ``data`` after :func:`jsonable`.

    Parameters
    ----------
    data : object
        A result's ``to_dict()`` or any dict of plain values.

    Returns
    -------
    str
    """
    return json.dumps(jsonable(data), allow_nan=False)


class Result:
    """What every result object gives: :meth:`to_dict` (JSON-ready, units in the
    key names) and a table of its scalar values in a notebook (``_repr_html_``)."""

    def to_dict(self) -> dict[str, Any]:
        """The result as a JSON-ready dict."""
        raise NotImplementedError

    def _repr_html_(self) -> str:
        return html_table(type(self).__name__, display_rows(self.to_dict()))


#: Units of to_dict keys, by suffix (``period_s``) or by name (``critical_stiffness``).
UNIT_SUFFIXES = (("_N_s_per_m", "N*s/m"), ("_N_per_m", "N/m"), ("_hz", "Hz"),
                 ("_samples", "samples"), ("_kg", "kg"), ("_N", "N"), ("_J", "J"),
                 ("_s", "s"), ("_m", "m"))
UNIT_NAMES = {"critical_stiffness": "N/m", "stiffness": "N/m", "damping": "N*s/m",
              "delay_samples": "samples", "stable_intervals": "N/m", "uncertain_intervals": "N/m"}


def display_value(key: str, v: Any) -> str:
    """One value of a result for a notebook: with its unit (from the key), rounded to 6
    significant digits (K_max's certified enclosure is far narrower; a reader compares a
    few digits), a complex number as one (``0.998+0.029j``), not as ``{re, im}``.

    Parameters
    ----------
    key : str
        The to_dict key.
    v : object
        Its value.

    Returns
    -------
    str
    """
    unit = UNIT_NAMES.get(key, "")
    for suffix, u in UNIT_SUFFIXES:
        if not unit and key.endswith(suffix):
            unit = u
    if isinstance(v, dict) and set(v) == {"re", "im"} and None not in v.values():
        v = complex(v["re"], v["im"])
    if isinstance(v, complex):
        return f"{v.real:.6g}{v.imag:+.6g}j"
    if isinstance(v, bool) or v is None:
        return "n/a" if v is None else str(v)
    if isinstance(v, (int, float)):
        # |z| near 1 is what a spectral radius says: its distance to 1 needs 10 digits
        return f"{v:.{10 if key == 'spectral_radius' else 6}g} {unit}".strip()
    if isinstance(v, list) and v and all(isinstance(p, list) and len(p) == 2 for p in v):
        return ", ".join(f"({_num(a)}, {_num(b)}]" for a, b in v) + f" {unit}".rstrip()
    return _cell(v)


def _num(x: Any) -> str:
    return "inf" if x is None else f"{x:.6g}"


def _label(key: str) -> str:
    """A to_dict key as a row's name: its unit suffix dropped (the value carries it)."""
    for suffix, _ in UNIT_SUFFIXES:
        if key.endswith(suffix) and key != suffix[1:]:
            return key[: -len(suffix)].replace("_", " ")
    return key.replace("_", " ")


def display_rows(d: dict[str, Any]) -> list[tuple[str, str]]:
    """A result's to_dict as (name, value with unit) rows for :func:`html_table`
    (:func:`display_value`); the infinities' index (``infinite``) as "inf" values."""
    inf = d.get(INFINITE, {})
    return [(_label(k), "inf" if inf.get(k) == 1 else display_value(k, v))
            for k, v in d.items() if k != INFINITE]


def html_table(caption: str, items: Any) -> str:
    """A small HTML table of (name, value) pairs, for notebooks.

    Parameters
    ----------
    caption : str
        Its caption (the object's class).
    items : iterable of (str, object)
        The rows; long lists and dicts are summed up.

    Returns
    -------
    str
    """
    rows = "".join(
        f"<tr><th style='text-align:left'>{html.escape(str(k))}</th>"
        f"<td style='text-align:left'>{html.escape(_cell(v))}</td></tr>"
        for k, v in items)
    return f"<table><caption>{html.escape(caption)}</caption>{rows}</table>"


def _cell(v: Any) -> str:
    """A value for one table cell: scalars as they are, long lists and tables summed up."""
    if isinstance(v, dict) and set(v) == {"re", "im"} and None not in v.values():
        return f"{v['re']:.6g}{v['im']:+.6g}j"             # a complex number, as one
    if isinstance(v, dict):
        return "{" + ", ".join(map(str, v)) + "}" if len(v) <= 6 else f"{{{len(v)} entries}}"
    if isinstance(v, list):
        return str(v) if len(str(v)) <= 120 else f"[{len(v)} values]"
    return str(v)


def write_csv(path: Any, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> None:
    """The one CSV writer of every result's ``to_csv``: a header line, then the rows,
    to a file object or, atomically, to a path (:func:`hapstab.outputs.writing`).

    Parameters
    ----------
    path : str, os.PathLike or file object
        Where to write.
    header : sequence of str
        The column names.
    rows : iterable of sequences
        The values, already formatted or as numbers.
    """
    import csv

    from hapstab.outputs import writing

    with writing(path, "path", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)


def merged(base: dict[str, Any], details: dict[str, Any], what: str) -> dict[str, Any]:
    """``base`` with a method's ``details`` added; a detail may not replace a key.

    Raises
    ------
    ValueError
        A detail has the name of a key of ``base`` (a bug of the method, not a user error).
    """
    clash = set(base) & set(details)
    if clash:
        raise ValueError(f"{what}: details {sorted(clash)} would replace keys of the result")
    return {**base, **details}


@dataclass(frozen=True)
class StabilityResult(Result):
    """Stability of a loop at its own parameters.

    Attributes
    ----------
    verdict : {"stable", "unstable", "marginal"}
    spectral_radius : float
        Largest |z| over the closed-loop poles (rigid-body modes excluded, see
        ``reason``).
    dominant_pole : complex
        The pole of largest modulus.
    frequency_hz : float
        |arg(dominant_pole)| / (2 pi T).
    reason : str
        Why, in words.
    period : float
        Sampling period T in s.
    poles : tuple of complex
        All closed-loop poles at the sampling instants; for a loop of more than
        :data:`~hapstab.analysis.exact.core.LONG_STATES` states (a long delay), the
        poles near the circle Newton's method found, with their conjugates (the reason
        says so).
    rigid_body_modes : int
        Poles at z = 1 that no stiffness can move (nothing ties a mass to ground).
    note : str
        What applies to the whole analysis, said once (a device's Coulomb friction: the
        linear loop is friction-free, :func:`~hapstab.models.parts.friction_note`); JSON
        ``friction_note``, absent when empty.
    """

    verdict: str
    spectral_radius: float
    dominant_pole: complex
    frequency_hz: float
    reason: str
    period: float
    poles: tuple[complex, ...] = field(repr=False, default=())
    rigid_body_modes: int = 0
    note: str = field(default="", compare=False)

    @property
    def stable(self) -> bool:
        return self.verdict == "stable"

    def to_dict(self) -> dict[str, Any]:
        return jsonable({
            "verdict": self.verdict, "spectral_radius": self.spectral_radius,
            "dominant_pole": {"re": self.dominant_pole.real, "im": self.dominant_pole.imag},
            "frequency_hz": self.frequency_hz, "reason": self.reason, "period_s": self.period,
            "rigid_body_modes": self.rigid_body_modes,
            **({"friction_note": self.note} if self.note else {}),
        })

    def plot(self, ax: Any = None) -> Any:
        from hapstab.plotting import plot_poles
        return plot_poles(self, ax=ax)


@dataclass(frozen=True)
class CriticalStiffnessResult(Result):
    """The largest K such that the loop is stable for every K in (0, K_max].

    Attributes
    ----------
    critical_stiffness : float
        K_max in N/m (``inf`` if stable for every K > 0, 0 if for none).
    method : str
        ``exact``, a closed form (``colgate``, ``gil``, ``eq18``, ...), ``circle``,
        ``passivity`` or ``simulation``.
    stable_intervals : tuple of (float, float)
        The stable set in K (``exact`` only lists more than one when it is not
        one interval).
    reason : str
        Which condition says so.
    period : float
        Sampling period T in s.
    delay_samples : int or float
        The delay in samples (t_d / T).
    crossing_frequency_hz : float
        Frequency of the closed-loop pole that reaches |z| = 1 at K_max (nan if
        not applicable).
    details : dict
        Method-specific extras (e.g. the simulation's bracket), added to
        :meth:`to_dict`.
    note : str
        What applies to the whole analysis, said once, not in ``reason`` (the
        friction-free model); JSON ``friction_note``, absent when empty.
    certificate : dict or None
        The exact core's ball-arithmetic proof as a JSON-ready certificate of the
        range [K_0, K_max] it proved (K_0 the base point standing for K -> 0+; (0, K_0)
        is not proved); ``hapstab.verify_certificate`` re-checks it. None when not
        proved in ball arithmetic or when the proof has nothing to certify.
    """

    critical_stiffness: float
    method: str
    stable_intervals: tuple[tuple[float, float], ...]
    reason: str
    period: float
    delay_samples: int | float
    crossing_frequency_hz: float = float("nan")
    details: dict[str, Any] = field(default_factory=dict, compare=False)
    note: str = field(default="", compare=False)
    #: the exact core's proof as a checkable certificate (JSON-ready dict; None when
    #: not proved in ball arithmetic): ``hapstab.verify_certificate`` re-checks it
    certificate: dict[str, Any] | None = field(default=None, compare=False, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return jsonable(merged({
            "critical_stiffness": self.critical_stiffness, "method": self.method,
            "stable_intervals": [list(iv) for iv in self.stable_intervals],
            "reason": self.reason, "period_s": self.period,
            "delay_samples": float(self.delay_samples),
            "crossing_frequency_hz": self.crossing_frequency_hz,
            **({"friction_note": self.note} if self.note else {})}, self.details, self.method))


@dataclass(frozen=True)
class BoundaryResult(Result):
    """K_max over a grid of sampling periods and delays (Fig. 5 / Fig. 6), or over
    sampling rates at fixed delays in seconds.

    Attributes
    ----------
    periods : (nT,) array, seconds
    delays : (nd,) array
        Whole samples (``delay_unit == "samples"``) or seconds (``"s"``: each delay held
        fixed in time while T varies).
    critical_stiffness : (nd, nT) array, N/m
    method : str
        The method that computed it.
    loop_kind : {"hve", "peb"}
        The loop kind.
    delay_unit : {"samples", "s"}
        The unit of ``delays``.
    axis : {"period", "rate"}
        The plot's horizontal axis: T in ms or the sampling rate 1/T in Hz.
    """

    periods: np.ndarray
    delays: np.ndarray
    critical_stiffness: np.ndarray
    method: str
    loop_kind: str = "hve"
    delay_unit: str = "samples"
    axis: str = "period"

    @property
    def _delay_key(self) -> str:
        return "delay_s" if self.delay_unit == "s" else "delay_samples"

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"method": self.method, "loop": self.loop_kind,
                         "period_s": self.periods, self._delay_key: self.delays.astype(float),
                         "critical_stiffness": self.critical_stiffness})

    def rows(self) -> list[dict[str, Any]]:
        seconds = self.delay_unit == "s"
        return [{"period_s": float(T), **({"delay_s": float(d)} if seconds else {}),
                 "delay_samples": float(d) / float(T) if seconds else float(d),
                 "critical_stiffness": float(self.critical_stiffness[i, j])}
                for i, d in enumerate(self.delays) for j, T in enumerate(self.periods)]

    def to_csv(self, path: Any) -> None:
        """Write one row per (delay, period): period_s, [delay_s,] delay_samples,
        critical_stiffness (N/m; ``inf`` as Python writes it).

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        cols = ["period_s", *(["delay_s"] if self.delay_unit == "s" else []), "delay_samples",
                "critical_stiffness"]
        write_csv(path, cols, ([r[c] for c in cols] for r in self.rows()))

    def plot(self, ax: Any = None) -> Any:
        from hapstab.plotting import plot_boundary
        return plot_boundary(self, ax=ax)
