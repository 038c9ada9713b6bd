"""The velocity estimate a virtual damper acts on: a backward difference, filtered.

References
----------
F. Janabi-Sharifi, V. Hayward and C.-S. J. Chen, "Discrete-time adaptive windowing for
velocity estimation", IEEE Trans. Control Systems Technology 8(6), 2000.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.errors import ModelError, ascii_float

__all__ = ["VelocityFilter", "MIN_FILTER_GAIN"]


#: The smallest gain 1 - a of a low-pass velocity filter: 1000 ulps of 1, so that the
#: pole a = exp(-2 pi f_c T), rounded to a double, still gives 1 - a to 1e-3 (below it
#: the pole is not representable apart from 1, and at a = 1 the loop degenerates).
MIN_FILTER_GAIN = 1000 * float(np.finfo(float).eps)


@dataclass(frozen=True)
class VelocityFilter:
    """The velocity estimate a virtual damper acts on: the backward difference
    ``(x[k] - x[k-1]) / T`` passed through F(z).

    * ``"lowpass"``: a first-order low-pass with cutoff f_c, its pole placed by the
      exponential map, ``F(z) = (1 - a) / (1 - a z^-1)``, ``a = exp(-2 pi f_c T)``:
      ``v[k] = a v[k-1] + (1 - a) (x[k] - x[k-1]) / T``, unit gain at DC; as
      f_c -> infinity, a -> 0 and F -> 1 (the plain backward difference of eq. 23).
    * ``"average"``: the mean of the last N backward differences,
      ``v[k] = (x[k] - x[k-N]) / (N T)``, ``F(z) = (1 - z^-N) / (N (1 - z^-1))``;
      N = 1 is the plain backward difference.

    Parameters
    ----------
    kind : str
        ``"lowpass"`` or ``"average"``.
    cutoff_hz : float
        f_c in Hz, > 0 (``"lowpass"`` only; ``inf`` is the plain difference).
    samples : int
        N >= 1 (``"average"`` only).

    Raises
    ------
    ModelError
        An unknown kind, f_c <= 0 or not a number, N < 1 or not whole.

    References
    ----------
    F. Janabi-Sharifi, V. Hayward and C.-S. J. Chen, "Discrete-time adaptive
    windowing for velocity estimation", IEEE Trans. Control Systems Technology
    8(6), 2000 (backward differences, their averages and low-pass filters as the
    velocity estimators of haptic devices); J. E. Colgate and J. M. Brown, "Factors
    affecting the Z-width of a haptic display", IEEE ICRA 1994 (the filtered
    velocity limits the damping a wall can display).
    """

    kind: str = "lowpass"
    cutoff_hz: float = float("inf")
    samples: int = 1

    def __post_init__(self) -> None:
        if self.kind not in ("lowpass", "average"):
            raise ModelError(f"velocity filter kind = {self.kind!r}: must be 'lowpass' or 'average'")
        if self.kind == "lowpass":
            c = self.cutoff_hz
            if not isinstance(c, (int, float)) or isinstance(c, bool) or not c > 0:
                raise ModelError(f"velocity filter cutoff = {c!r} Hz: must be a number > 0 "
                                 "(inf: no filter)")
            object.__setattr__(self, "cutoff_hz", float(c))
        n = self.samples
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1 or n > 100000:
            raise ModelError(f"velocity filter samples = {n!r}: must be a whole number from 1 "
                             "to 100000")
        object.__setattr__(self, "samples", int(n))

    @classmethod
    def parse(cls, spec: str) -> VelocityFilter:
        """``"lowpass:F"`` (f_c in Hz) or ``"average:N"`` (N samples).

        Raises
        ------
        ModelError
            Anything else, naming the spec and what is allowed.
        """
        kind, _, val = str(spec).partition(":")
        try:
            if kind == "lowpass":
                return cls("lowpass", cutoff_hz=ascii_float(val))
            if kind == "average" and re.fullmatch("[0-9]+", val.strip()):
                return cls("average", samples=int(val))
        except ValueError:
            pass
        raise ModelError(f"velocity filter = {spec!r}: must be lowpass:F (cutoff F Hz > 0) or "
                         "average:N (N >= 1 samples)")

    def pole(self, period: np.ndarray | float) -> np.ndarray:
        """The low-pass pole a = exp(-2 pi f_c T) per period (0 for ``"average"``).

        Raises
        ------
        ModelError
            The cutoff is too low for the period: 1 - a, the filter's gain, is below
            :data:`MIN_FILTER_GAIN` (``lowpass:1e-320`` makes a = 1 exactly: a filter
            that passes nothing, with a pole on the unit circle).
        """
        T = np.asarray(period, float)
        if self.kind != "lowpass":
            return np.zeros(T.shape)
        x = 2.0 * np.pi * self.cutoff_hz * T
        bad = -np.expm1(-x) < MIN_FILTER_GAIN
        if np.any(bad):
            t = float(np.max(np.atleast_1d(T)[np.atleast_1d(bad)]))
            raise ModelError(f"velocity filter cutoff = {self.cutoff_hz:g} Hz: too low for the "
                             f"period {t:g} s (the pole exp(-2 pi f_c T) is 1 to within "
                             f"{MIN_FILTER_GAIN:g}: not representable apart from 1); allowed: "
                             f"f_c >= {MIN_FILTER_GAIN / (2 * np.pi * t):.3g} Hz at this period")
        return np.exp(-x)

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        """(num, den) of F(z) in z, highest power first."""
        if self.kind == "average":
            N = self.samples
            return np.ones(N) / N, np.concatenate([[1.0], np.zeros(N - 1)])
        a = float(self.pole(period))
        return np.array([1.0 - a, 0.0]), np.array([1.0, -a])

    def to_dict(self) -> dict[str, Any]:
        """The filter as JSON-ready values, units in the keys."""
        if self.kind == "average":
            return {"kind": "average", "samples": self.samples}
        return {"kind": "lowpass", "cutoff_Hz": self.cutoff_hz}

    def __str__(self) -> str:
        return f"average:{self.samples}" if self.kind == "average" else f"lowpass:{self.cutoff_hz:g}"
