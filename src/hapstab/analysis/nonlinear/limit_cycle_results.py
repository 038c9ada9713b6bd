"""The results of :func:`hapstab.analysis.nonlinear.limit_cycles.limit_cycles`: each predicted cycle,
and the prediction with its existence conditions, describing-function plot and table."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.results import Result, jsonable, write_csv

__all__ = ["PredictedCycle", "LimitCycleResult", "VERDICTS"]

#: What a prediction can say.
VERDICTS = ("limit cycle", "chatter", "threshold", "undecided", "no limit cycle predicted")

_COLUMNS = ("amplitude_m", "frequency_hz", "period_s", "offset_m", "stable", "first_harmonic_m",
            "describing_function_amplitude_m", "describing_function_frequency_hz",
            "samples_per_period", "refined", "trusted", "notes")


@dataclass(frozen=True)
class PredictedCycle(Result):
    """One periodic solution of the harmonic balance.

    Parameters
    ----------
    amplitude_m : float
        Half the peak-to-peak position of the (refined) waveform, m: what the simulator's
        verdict calls the amplitude.
    frequency_hz : float
        Its frequency (refined), Hz.
    offset_m : float
        Its mean position, m (about Δ/2 for a floor encoder).
    stable : bool
        Loeb's criterion: an attractor (True) or a threshold between decay and growth.
    first_harmonic_m : float
        Amplitude of its fundamental, m.
    describing_function_amplitude_m, describing_function_frequency_hz : float
        The first-harmonic (describing function) root it was refined from.
    samples_per_period : float
        2 pi / (w T) of the describing function's root.
    refined : bool
        Whether the harmonic balance converged (else the describing function's values).
    trusted : bool
        Inside the method's range: enough samples per period, refined, no sticking.
    notes : str
        Why not trusted, if not.
    """

    amplitude_m: float
    frequency_hz: float
    offset_m: float
    stable: bool
    first_harmonic_m: float
    describing_function_amplitude_m: float
    describing_function_frequency_hz: float
    samples_per_period: float
    refined: bool
    trusted: bool
    notes: str

    @property
    def period_s(self) -> float:
        """1 / frequency, s."""
        return 1.0 / self.frequency_hz

    def to_dict(self) -> dict[str, Any]:
        return jsonable({c: getattr(self, c) for c in _COLUMNS})


@dataclass(frozen=True)
class LimitCycleResult(Result):
    """Limit cycles predicted for a haptic loop with quantisation and / or friction.

    Parameters
    ----------
    stiffness : float
        K in N/m.
    period_s : float
        T in s.
    delay_samples : int
        n.
    virtual_damping : float
        B in N*s/m.
    resolution_m : float
        Δ in m (0: none).
    quantizer : str
        ``"floor"`` or ``"nearest"``.
    coulomb_friction_N : float
        f_c in N (0: none).
    harmonics : int
        Harmonics of the refining balance.
    cycles : tuple of PredictedCycle
        Every root found, by amplitude.
    linear_verdict : str
        The exact verdict of the loop without quantisation and friction.
    crossovers : tuple of (float, float)
        The phase crossovers of the loop the quantiser sees: (Hz, gain margin).
    max_gain : float
        The largest describing-function gain of the quantiser over the amplitudes searched
        (4/pi for a centred one; 1 without quantiser).
    searched_m : (float, float)
        The amplitudes searched, m.
    rests : str
        Where the device can rest (spring, controller and friction in balance):
        ``"inside a step"``, only ``"on a line"`` (then only if it arrives there without
        overshooting), ``"nowhere"`` (it chatters across a line) or ``"free in a step"``
        (no spring, friction below K Δ/2: it may bounce across a step's lines).
    rest_position_m : float
        Where the operator's spring is relaxed, m.
    curves : dict
        The describing-function plot's data (not in :meth:`to_dict`).
    """

    stiffness: float
    period_s: float
    delay_samples: int
    virtual_damping: float
    resolution_m: float
    quantizer: str
    coulomb_friction_N: float
    harmonics: int
    cycles: tuple[PredictedCycle, ...]
    linear_verdict: str
    crossovers: tuple[tuple[float, float], ...]
    max_gain: float
    searched_m: tuple[float, float]
    rests: str
    rest_position_m: float
    curves: dict[str, np.ndarray] = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def build(cls, loop: Any, *args: Any) -> LimitCycleResult:
        """From the loop and the other fields in order (see the class).

        Parameters
        ----------
        loop : HapticLoop
            The loop analysed.
        *args
            resolution_m, quantizer, coulomb_friction_N, harmonics, cycles,
            linear_verdict, crossovers, max_gain, searched_m, rests, rest_position_m,
            curves.

        Returns
        -------
        LimitCycleResult
        """
        c = loop.controller
        return cls(float(c.stiffness), float(loop.period), int(loop.delay_samples),
                   float(c.damping), *args)

    @property
    def verdict(self) -> str:
        """``limit cycle`` (a trusted stable one), ``chatter`` (the device can rest nowhere:
        it chatters across an encoder line, which the describing function does not
        describe), ``threshold`` (only unstable ones), ``undecided`` (only cycles outside
        the method's range, or a rest only on a line) or ``no limit cycle predicted``."""
        trusted = [c for c in self.cycles if c.trusted]
        if any(c.stable for c in trusted):
            return "limit cycle"
        if self.rests == "nowhere":
            return "chatter"
        if self.rests in ("on a line", "free in a step"):
            return "undecided"
        if trusted:
            return "threshold"
        return "undecided" if self.cycles else "no limit cycle predicted"

    @property
    def conditions(self) -> str:
        """The existence conditions, with this loop's numbers."""
        out = []
        if self.resolution_m:
            gm = min((g for _, g in self.crossovers), default=math.inf)
            f = next((f for f, g in self.crossovers if g == gm), math.nan)
            verdict = ("below it, so quantisation can sustain a cycle there"
                       if gm < self.max_gain else
                       "not below it, so quantisation alone cannot sustain one")
            if gm < self.max_gain and self.coulomb_friction_N:
                verdict = ("below it, so quantisation alone could sustain a cycle there; with "
                           "the friction's equivalent damper 4 f_c/(pi A w) in the same "
                           "first-harmonic balance " + (
                               "it has no root (the figure's curves Re F = 0 and Im F = 0 do "
                               "not cross)" if not self.cycles else
                               "the cycles listed solve it"))
            out.append(f"quantisation: a cycle needs the quantiser's gain N(A) = 1/|C| at a phase "
                       f"crossover of the loop it sees; N is at most {self.max_gain:.4g} (4/pi = "
                       f"1.273 for a centred quantiser), so a cycle is possible only where the "
                       f"loop's gain margin (1/|C| there) is below {self.max_gain:.4g}: "
                       + (f"here it is {gm:.4g} at {f:.4g} Hz, {verdict}" if math.isfinite(gm)
                          else "this loop has no phase crossover, so none is possible"))
        if self.rests == "free in a step":
            out.append("rest: no operator's spring and friction below K Delta/2 (Abbott-Okamura's "
                       "quantisation condition): the device coasts within an encoder step and may "
                       "bounce across its lines, a motion the describing function does not "
                       "describe (not predicted)")
        elif self.resolution_m and self.rests != "inside a step":
            out.append(f"rest: with the operator's spring relaxed at {self.rest_position_m:g} m "
                       "no position strictly inside an encoder step balances the spring and the "
                       "controller (within friction): "
                       + ("the device chatters across a line" if self.rests == "nowhere" else
                          "it rests only on a line, if it arrives there without overshooting; "
                          "otherwise it chatters across it (not predicted)"))
        if self.coulomb_friction_N:
            out.append(f"Coulomb friction only dissipates: with a stable linear loop it adds no "
                       f"cycle; with an unstable one its cycle is unstable (Loeb), a threshold: "
                       f"smaller motions stop or decay, larger ones grow (the linear loop here: "
                       f"{self.linear_verdict})")
        return "; ".join(out)

    @property
    def reason(self) -> str:
        """The verdict in words."""
        v = self.verdict
        head = {"limit cycle": "limit cycle predicted", "threshold": "no stable limit cycle; "
                "a threshold (unstable cycle) between decay and growth",
                "undecided": "undecided: what the describing function cannot tell (see the "
                             "conditions and the cycles' notes)",
                "chatter": "no rest inside an encoder step: the device chatters across a line",
                "no limit cycle predicted": "no limit cycle predicted"}[v]
        parts = [f"{'stable' if c.stable else 'unstable'} cycle of amplitude {c.amplitude_m:.4g} "
                 f"m at {c.frequency_hz:.5g} Hz" + ("" if c.trusted else f" (untrusted: {c.notes})")
                 for c in self.cycles]
        lo, hi = self.searched_m
        tail = f"amplitudes searched from {lo:.3g} to {hi:.3g} m"
        if v == "no limit cycle predicted" and self.linear_verdict == "unstable":
            tail += "; the linear loop is unstable: motions grow"
        return f"{head}: " + "; ".join([*parts, tail, self.conditions])

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"verdict": self.verdict, "stiffness": self.stiffness,
                         "period_s": self.period_s, "delay_samples": float(self.delay_samples),
                         "virtual_damping": self.virtual_damping,
                         "nonlinear": {"resolution_m": self.resolution_m,
                                       "quantizer": self.quantizer,
                                       "coulomb_friction_N": self.coulomb_friction_N},
                         "harmonics": self.harmonics,
                         "cycles": [c.to_dict() for c in self.cycles],
                         "linear_verdict": self.linear_verdict,
                         "crossovers": [{"frequency_hz": f, "gain_margin": g}
                                        for f, g in self.crossovers],
                         "max_gain": self.max_gain, "searched_m": list(self.searched_m),
                         "rests": self.rests, "rest_position_m": self.rest_position_m,
                         "conditions": self.conditions, "reason": self.reason})

    def to_csv(self, path: Any) -> None:
        """One row per predicted cycle (the columns of :class:`PredictedCycle`).

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        write_csv(path, list(_COLUMNS),
                  ([repr(float(v)) if isinstance(v, (float, np.floating)) else v for v in
                    (getattr(c, k) for k in _COLUMNS)] for c in self.cycles))

    def plot(self, ax: Any = None) -> Any:
        """The figure of what the verdict solves: with one nonlinearity the
        describing-function plot (the loop the nonlinearity sees against -1/N(A) on the
        negative real axis), with quantisation and friction the first-harmonic balance's
        curves Re F = 0 and Im F = 0 over amplitude and frequency (friction's equivalent
        damper depends on A, so C against -1/N(A) alone is not the balance); the predicted
        cycles marked (filled: stable). See :mod:`hapstab.plotting.limit_cycles`.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw; a new figure when omitted.

        Returns
        -------
        matplotlib Axes
        """
        from hapstab.plotting.limit_cycles import plot_limit_cycles

        return plot_limit_cycles(self, ax)
