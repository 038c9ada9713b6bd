"""The result of :func:`hapstab.identify`: the device's estimated parameters with their
confidence intervals, the fit, and the command line that analyses the device."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.models.parts import Device
from hapstab.results import Result, html_table, write_csv

__all__ = ["IdentificationResult", "NOISE_MODEL"]

#: The noise model under which the intervals hold (said in every result).
NOISE_MODEL = ("reading = encoder(position + white noise); force applied as commanded; the "
               "reading's error (noise plus quantisation) independent, one variance")
_NAMES = ("mass_kg", "damping_N_s_per_m", "coulomb_friction_N", "initial_position_m",
          "initial_velocity_m_per_s")


@dataclass(frozen=True, eq=False)
class IdentificationResult(Result):
    """A device identified from a log (see :mod:`hapstab.analysis.identification.identify`).

    Attributes
    ----------
    time_s, force_N, position_m : arrays
        The log (the encoder's readings as recorded).
    fitted_m : array
        The fitted model's exact position at each sample.
    period_s : float
        The log's period T.
    estimate, low, high, std_error : tuple of 5 floats
        m (kg), b (N*s/m), f_c (N), x_0 (m), v_0 (m/s): the estimate, the ends of its
        ``confidence`` interval (b's and f_c's lower ends cut at 0) and its standard error.
        f_c is 0 with a standard error of 0 when friction was not fitted.
    residual_std_m : float
        s, the spread of the readings about the fit (noise and quantisation).
    confidence : float
        The intervals' level.
    resolution_m : float or None
        The encoder step used; ``quantizer`` how it reads.
    friction : str
        What was asked (auto, yes, no); ``friction_fitted`` whether f_c is in the model;
        ``friction_upper_N`` with auto and no friction detected: the upper end of f_c's
        interval in the fit that had it.
    whiteness : float
        Lag-1 autocorrelation of the residuals (the intervals assume about 0).
    check : float
        Share of samples whose reading the fit, through the encoder, reproduces within
        one step (NaN without a resolution).
    quantizer : str
        How the encoder rounds (the readings were fitted under it).
    friction_upper_N : float
        Upper end of the Coulomb friction's interval, N.
    friction_fitted : bool
        Whether friction was part of the fit.
    source : str
        Where the log came from (its file name), for displays.
    """

    time_s: np.ndarray
    force_N: np.ndarray
    position_m: np.ndarray
    fitted_m: np.ndarray
    period_s: float
    estimate: tuple[float, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    std_error: tuple[float, ...]
    residual_std_m: float
    confidence: float
    resolution_m: float | None
    quantizer: str
    friction: str
    friction_upper_N: float | None
    friction_fitted: bool
    source: str
    whiteness: float
    check: float

    @property
    def reading_offset_m(self) -> float:
        """What is added to a reading to centre its quantisation error: Delta / 2 for a
        floor encoder, else 0."""
        return self.resolution_m / 2 if self.resolution_m and self.quantizer == "floor" else 0.0

    @property
    def residuals_m(self) -> np.ndarray:
        """reading + offset - fitted position: the errors the intervals' model describes."""
        return self.position_m + self.reading_offset_m - self.fitted_m

    @property
    def mass(self) -> float:
        """m in kg."""
        return self.estimate[0]

    @property
    def damping(self) -> float:
        """b in N*s/m."""
        return self.estimate[1]

    @property
    def coulomb_friction(self) -> float:
        """f_c in N (0 when friction is not in the model)."""
        return self.estimate[2]

    def device(self) -> Device:
        """The identified :class:`~hapstab.Device` (the estimates)."""
        return Device(self.mass, max(self.damping, 0.0), max(self.coulomb_friction, 0.0))

    def commands(self) -> dict[str, str]:
        """``hapstab kmax hve`` command lines for the identified device at the log's rate:
        ``estimate`` (m, b, f_c as estimated) and ``low_damping`` (b at the lower end of
        its interval: a device's damping is what lets a sampled wall be stiff, Colgate
        and Schenkel's ``K < 2 b / T``, so the cautious line for a first K_max). Add the
        loop's own ``--delay`` / ``--delay-s`` and operator."""
        fc = f" --friction {self.coulomb_friction:.4g}" if self.friction_fitted else ""
        base = f"hapstab kmax hve --period {self.period_s:.6g} --mass {self.mass:.4g}"
        return {"estimate": f"{base} --damping {max(self.damping, 0):.4g}{fc}",
                "low_damping": f"{base} --damping {_down(self.low[1])}{fc}"}

    def rows(self) -> list[tuple[str, float, float, float, float]]:
        """(name with unit, estimate, low, high, standard error) of each fitted parameter."""
        keep = [0, 1, 2, 3, 4] if self.friction_fitted else [0, 1, 3, 4]
        return [(_NAMES[i], self.estimate[i], self.low[i], self.high[i], self.std_error[i])
                for i in keep]

    def to_dict(self) -> dict[str, Any]:
        """The estimates, intervals (``*_interval``: [low, high]), fit quality and
        command lines, units in the keys."""
        d: dict[str, Any] = {}
        for name, est, lo, hi, se in self.rows():
            d[name] = est
            d[f"{name}_interval"] = [lo, hi]
            d[f"{name}_std_error"] = se
        d.update({
            "coulomb_friction_fitted": self.friction_fitted,
            "coulomb_friction_upper_N": self.friction_upper_N,
            "confidence_level": self.confidence, "period_s": self.period_s,
            "samples": int(self.time_s.size), "resolution_m": self.resolution_m,
            "quantizer": self.quantizer, "residual_std_m": self.residual_std_m,
            "residual_lag1_autocorrelation": self.whiteness,
            "readings_reproduced": None if np.isnan(self.check) else self.check,
            "method": "output-error least squares on the exact ZOH model (stick-slip exact); "
                      "Wald intervals s^2 (J^T J)^-1 with Student's t (N - p)",
            "noise_model": NOISE_MODEL, "source": self.source,
            "commands": self.commands()})
        return d

    def to_csv(self, path: Any) -> None:
        """Write the log and the fit: time, force, reading, fitted position, residual."""
        r = self.residuals_m
        write_csv(path, ["time_s", "force_N", "position_m", "fitted_position_m", "residual_m"],
                  ([repr(float(v)) for v in row] for row in zip(
                      self.time_s, self.force_N, self.position_m, self.fitted_m, r,
                      strict=True)))

    def plot(self, ax: Any = None) -> Any:
        """The readings and the fitted exact model (and, on a new figure, the residuals);
        see :func:`hapstab.plotting.identify.plot_identification`."""
        from hapstab.plotting.identify import plot_identification

        return plot_identification(self, ax)

    def summary(self) -> str:
        """One line: each parameter with its interval."""
        iv = [interval_text(self.estimate[i], self.low[i], self.high[i]) for i in range(3)]
        parts = [f"m = {iv[0]} kg", f"b = {iv[1]} N*s/m"]
        if self.friction_fitted:
            parts.append(f"f_c = {iv[2]} N")
        elif self.friction_upper_N is not None:
            parts.append(f"no Coulomb friction detected (f_c <= {self.friction_upper_N:.3g} N)")
        return f"{', '.join(parts)} ({100 * self.confidence:g} % intervals)"

    def _repr_html_(self) -> str:
        items = [(f"{n} ({100 * self.confidence:g} % interval)",
                  interval_text(e, lo, hi)) for n, e, lo, hi, _ in self.rows()]
        items += [("residual_std_m", f"{self.residual_std_m:.3g}"),
                  ("samples", str(self.time_s.size)), ("period_s", f"{self.period_s:.6g}"),
                  ("noise model", NOISE_MODEL), ("kmax", self.commands()["estimate"])]
        return html_table("IdentificationResult", items)


def _down(x: float, digits: int = 4) -> str:
    """``x`` to ``digits`` significant digits, rounded towards 0 (a lower end stays one)."""
    if x <= 0:
        return "0"
    e = math.floor(math.log10(x)) - digits + 1
    return f"{math.floor(x / 10.0 ** e) * 10.0 ** e:.{digits}g}"


def interval_text(est: float, lo: float, hi: float) -> str:
    """``est [lo, hi]`` with the digits the interval's width supports (two beyond its
    first significant digit), so that a narrow interval does not read ``0.25 [0.25, 0.25]``."""
    width = hi - lo
    scale = max(abs(est), abs(lo), abs(hi))
    if not (width > 0 and scale > 0 and math.isfinite(width)):
        return f"{est:.4g} [{lo:.4g}, {hi:.4g}]"
    digits = min(12, max(3, math.ceil(math.log10(scale / width)) + 2))
    return f"{est:.{digits}g} [{lo:.{digits}g}, {hi:.{digits}g}]"
