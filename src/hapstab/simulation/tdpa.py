"""The time-domain passivity approach (TDPA) in simulation: a passivity observer (PO)
and an impedance-type passivity controller (PC) at each device port.

Every port here has *impedance causality*: the controller reads the device's position
(velocity in) and commands a force (force out). With ``f`` the force the controller
applies (it acts on the device as ``-f``, so ``f v`` is the power flowing from the
device into the controller), ``v`` the velocity estimate at the sample and ``T`` the
period, the PC is a variable damper in series with the controller's force,
``f2[k] = f1[k] + alpha[k] v[k]`` with ``alpha[k] = -W[k] / (T v[k]^2)`` when the
observed energy ``W[k]`` would be negative, else 0 (Hannaford & Ryu 2002): it
dissipates exactly the observed deficit, so ``W`` after the PC is 0 up to rounding.

The PC *cuts the port's output, it never reverses the force*: it acts only while the
sample's power flows out of the controller (``f1 v < 0``) and ``alpha <= -f1 / v``,
so ``f2`` lies between 0 and ``f1`` (and within a saturation ``f1`` met). With the
papers' observer and no cap this is their PC exactly: ``W`` was >= 0 after the last
sample, so a deficit is always this sample's output and their ``alpha`` never exceeds
``-f1 / v`` (only a ``W`` a few rounding errors below 0 is left alone). With
``v = 0`` no power flows and nothing can be dissipated: ``alpha = 0``; a deficit
waits for the next sample that outputs. Without
the rule, the ``"held"`` observer's small prediction deficits at a velocity reversal
asked for ``alpha`` of 10^3 N*s/m on a 15 g device (a sampled damper is unstable
beyond about ``2 m / T`` = 30 N*s/m there) and the run chattered apart.
``max_damping`` caps ``alpha`` further (hapstab's option, not the papers'); a capped
PC can leave ``W < 0``, and the record shows it.

What each port's observer observes
----------------------------------
* **HVE (one port): Hannaford & Ryu 2002.** The delayed virtual environment is the
  one-port seen from the device: delay line plus controller. Its PO is the energy that
  has flowed into it, ``W[k] = T sum_{i<=k} f2[i] v[i]`` (one running sum); the PC's
  own dissipation is part of it (their PO adds ``alpha[k-1] v[k-1]^2 T`` at the next
  sample; here the sample's power is taken after the PC, which is the same sum).
* **PEB with delay (two ports): the time-domain passivity network of Ryu, Artigas &
  Preusche 2010.** Each port's power is split into input and output energy,
  ``E_in_j = sum max(P_j, 0)`` and ``E_out_j = sum max(-P_j, 0)`` with ``P_j = f2_j v_j
  T``. Port j's PO compares what it has sent out with what the *other* port has put
  in, as that port reports it across the channel with its positions, ``lag`` samples
  late: ``W_j[k] = E_in_other[k - lag] - E_out_j[k]``, and its PC keeps ``W_j >= 0``.
  Then ``E_in_m + E_in_s - E_out_m - E_out_s >= E_in_m[k] - E_in_m[k - lag] +
  E_in_s[k] - E_in_s[k - lag] >= 0`` (input energies never decrease): the whole
  teleoperator (controllers and delayed channel) is passive as observed. ``lag`` is the
  delay of the channel that brings the other port's position, in whole samples
  (rounded up; with no delay, one sample: both PCs decide at the same instant).
  Ryu, Kwon & Hannaford 2004's two-port PO sums both ports' powers at one place and
  time; behind a delay no site has both, and summing one's own with the other's
  delayed *net* energy lets both sides spend the same stored energy: not passive.
  Hence the network's split. Its argument uses only the port powers, so it holds for a
  4-channel loop too (the force channels are inside the two-port).

Observers
---------
* ``"paper"``: ``P[k] = f2[k] v[k] T``, the papers' PO. It pairs the force of sample
  k with the velocity over the sample *before* it, while the hold applies ``f2[k]``
  over the sample *after* it: it does not see the energy a zero-order hold leaks
  (for a spring, ``K/2 sum (x[k+1] - x[k])^2``); against the hold's energy it counts
  about ``K T`` of damping too much, so the device's own damping must cover it: TDPA
  with this PO bounds a loop only below about ``K = b / T``. Above that the
  simulation shows the run growing while ``W`` stays >= 0.
* ``"held"`` (hapstab's variant, not the papers'): the energy each held force
  actually delivered, ``f2[k-1] (x[k] - x[k-1])``, known at sample k (the same sum as
  :class:`SimulationResult.port_energy`, exact with an exact encoder), plus the
  coming sample predicted as ``f2[k] v[k] T``. It sees the hold's leak; the
  prediction's error is only corrected at the port's next output, so its ``W`` can
  dip below 0 by that error (reported). Very stiff walls (``K T^2 / m`` of 0.4 and
  more) defeat the prediction.

References
----------
B. Hannaford and J.-H. Ryu, "Time-domain passivity control of haptic interfaces",
IEEE Trans. Robotics and Automation 18(1):1-10, 2002 (doi:10.1109/70.988969): the
passivity observer and the series (impedance-causality) passivity controller.
J.-H. Ryu, D.-S. Kwon and B. Hannaford, "Stable teleoperation with time-domain
passivity control", IEEE Trans. Robotics and Automation 20(2), 2004: the two-port PO
and a PC at each port (no delay).
J.-H. Ryu, J. Artigas and C. Preusche, "A passive bilateral control scheme for a
teleoperator with time-varying communication delay", Mechatronics 20(7):812-823, 2010:
input and output energies per port, exchanged across the delayed channel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.errors import ModelError, check_real

__all__ = ["TDPA", "TdpaRecord", "PassivityController", "tdpa_options", "passivity_controller",
           "channel_lags", "OBSERVERS", "VELOCITIES"]

#: The passivity observers (see the module docstring).
OBSERVERS = ("paper", "held")
#: The velocity estimates: the encoder's backward difference, or a velocity sensor
#: (the device's true velocity at the sample).
VELOCITIES = ("backward", "sensor")


@dataclass(frozen=True)
class TDPA:
    """Options of the time-domain passivity approach.

    Parameters
    ----------
    observer : {"paper", "held"}
        ``"paper"``: Hannaford & Ryu's ``P[k] = f[k] v[k] T``; ``"held"``: the energy
        each held force delivered plus the coming sample predicted (module docstring).
    velocity : {"backward", "sensor"}
        ``"backward"``: ``(x[k] - x[k-1]) / T`` of the (quantised) encoder reading;
        ``"sensor"``: the device's velocity at the sample.
    max_damping : float or None
        Cap on the PC's damping ``alpha`` in N*s/m; None (default): none, as in the
        papers.
    """

    observer: str = "paper"
    velocity: str = "backward"
    max_damping: float | None = None

    def __post_init__(self) -> None:
        for name, val, allowed in (("observer", self.observer, OBSERVERS),
                                   ("velocity", self.velocity, VELOCITIES)):
            if not isinstance(val, str) or val not in allowed:
                raise ModelError(f"tdpa {name} = {val!r}: allowed: {', '.join(allowed)}")
        if self.max_damping is not None:
            object.__setattr__(self, "max_damping",
                               check_real("tdpa max_damping", self.max_damping, positive=True))

    def to_dict(self) -> dict[str, Any]:
        """The options, with units in the keys."""
        return {"observer": self.observer, "velocity": self.velocity,
                "max_damping_N_s_per_m": self.max_damping}


def tdpa_options(tdpa: Any) -> TDPA | None:
    """The TDPA options asked for: None / False (off), True (the papers' defaults), a
    :class:`TDPA`, or a dict of its fields.

    Parameters
    ----------
    tdpa : None, bool, TDPA or dict
        What ``simulate(..., tdpa=...)`` received.

    Returns
    -------
    TDPA or None

    Raises
    ------
    ModelError
        Anything else, or a dict with unknown keys or bad values.
    """
    if tdpa is None or tdpa is False:
        return None
    if tdpa is True:
        return TDPA()
    if isinstance(tdpa, TDPA):
        return tdpa
    if isinstance(tdpa, dict):
        unknown = set(tdpa) - {"observer", "velocity", "max_damping"}
        if unknown:
            raise ModelError(f"tdpa: unknown option(s) {', '.join(sorted(map(str, unknown)))}; "
                             "allowed: observer, velocity, max_damping")
        return TDPA(**tdpa)
    raise ModelError(f"tdpa = {tdpa!r:.60}: must be True, False, None, a TDPA or a dict of "
                     "its options")


@dataclass(frozen=True)
class TdpaRecord:
    """What the passivity observers and controllers did, sample by sample.

    Parameters
    ----------
    options : TDPA
        The options of the run.
    lags : tuple of int
        Per port, the samples after which the other port's input energy arrives (the
        channel's delay, rounded up, at least 1); empty for a one-port (HVE).
    commanded : (M+1, p) array, N
        The force the controller commanded (after a wall and a saturation), before the
        PC; the force applied is ``SimulationResult.controller_force``.
    energy_in, energy_out : (M+1, p) arrays, J
        Input and output energy of each port as its observer counts it, after the
        sample's PC (``"held"``: the samples completed by t_k).
    observed : (M+1, p) array, J
        The observed energy ``W`` each PC keeps >= 0, after the PC (module docstring);
        ``"held"`` includes the predicted coming sample.
    damping : (M+1, p) array, N*s/m
        The PC's damping ``alpha[k]`` (0 where it is idle).
    dissipated : (M+1, p) array, J
        The PC's cumulative dissipation as its observer counts it, ``sum alpha v^2 T``.
    """

    options: TDPA
    lags: tuple[int, ...]
    commanded: np.ndarray
    energy_in: np.ndarray
    energy_out: np.ndarray
    observed: np.ndarray
    damping: np.ndarray
    dissipated: np.ndarray

    def summary(self, labels: tuple[str, ...]) -> dict[str, Any]:
        """Per port: the lowest and final observed energy, the energy dissipated, the
        largest damping and the fraction of samples the PC acted.

        Parameters
        ----------
        labels : tuple of str
            The ports' names.

        Returns
        -------
        dict
        """
        out: dict[str, Any] = {}
        with np.errstate(invalid="ignore"):
            for j, lab in enumerate(labels):
                W, a = self.observed[:, j], self.damping[:, j]
                out[f"tdpa_min_observed_energy_J_{lab}"] = float(np.min(W))
                out[f"tdpa_final_observed_energy_J_{lab}"] = float(W[-1])
                out[f"tdpa_dissipated_J_{lab}"] = float(self.dissipated[-1, j])
                out[f"tdpa_peak_damping_N_s_per_m_{lab}"] = float(np.max(a))
                out[f"tdpa_active_fraction_{lab}"] = float(np.mean(a > 0))
        return out

    def columns(self, labels: tuple[str, ...]) -> dict[str, np.ndarray]:
        """The CSV columns, per port.

        Parameters
        ----------
        labels : tuple of str
            The ports' names.

        Returns
        -------
        dict of str to array
        """
        cols = {}
        for j, lab in enumerate(labels):
            cols[f"tdpa_observed_energy_{lab}_J"] = self.observed[:, j]
            cols[f"tdpa_damping_{lab}_N_s_per_m"] = self.damping[:, j]
            cols[f"tdpa_dissipated_{lab}_J"] = self.dissipated[:, j]
        return cols


class PassivityController:
    """The PO and PC of every port, called by the stepper at each sample with the force
    the controller commands (after the wall and saturation) and returning the force
    to apply (between 0 and the commanded one: module docstring).

    Parameters
    ----------
    options : TDPA
        The run's options.
    period : float
        T in s.
    n_samples : int
        M (the record has M+1 rows).
    pos_idx : (p,) int array
        Each port's position entry in the state (its velocity follows it).
    lags : sequence of int
        Per port, the other port's energy lag in samples (ignored for one port).
    rows : (p, M+1) int array, optional
        Through a network with a varying delay: per port and sample, the sample of the
        other port's input energy its PO has (it travels with the newest position that
        has arrived, Ryu, Artigas & Preusche 2010); replaces ``lags``.
    """

    def __init__(self, options: TDPA, period: float, n_samples: int, pos_idx: np.ndarray,
                 lags: Any, rows: np.ndarray | None = None) -> None:
        self.o, self.T = options, float(period)
        self.rows = rows
        self.pos = np.asarray(pos_idx, dtype=int)
        p = self.pos.size
        self.lags = tuple(int(n) for n in lags) if p > 1 else ()
        shape = (n_samples + 1, p)
        self.f1, self.e_in, self.e_out, self.W, self.alpha, self.diss = (
            np.full(shape, np.nan) for _ in range(6))
        self._in, self._out, self._d = [0.0] * p, [0.0] * p, [0.0] * p
        self._net = [0.0] * p                  # one port: its PO, one running sum
        self._x_prev: np.ndarray | None = None
        self._f_prev = [0.0] * p

    def _commit(self, j: int, power: float) -> None:
        self._net[j] += power
        if power > 0:
            self._in[j] += power
        else:
            self._out[j] -= power

    def _available(self, k: int, j: int) -> float:
        """Energy port j may still send out before its PC (without this sample's)."""
        if not self.lags:                       # one port: its own net energy
            return self._net[j]
        other = 1 - j
        row = k - self.lags[j] if self.rows is None else int(self.rows[j, k])
        got = float(self.e_in[row, other]) if row >= 0 else 0.0
        return got - self._out[j]

    def __call__(self, k: int, u: np.ndarray, s: np.ndarray, sm: np.ndarray) -> np.ndarray:
        x = np.asarray(sm, float)[self.pos]
        if self._x_prev is None:
            self._x_prev = x.copy()             # the history is at rest: v[0] = 0
        dx = x - self._x_prev
        v = dx / self.T if self.o.velocity == "backward" else np.asarray(s, float)[self.pos + 1]
        held = self.o.observer == "held"
        out = np.array(u, dtype=float)
        for j in range(out.size):
            if held:                            # the sample that just ended, exactly
                self._commit(j, self._f_prev[j] * float(dx[j]))
            out[j] = self._port(k, j, float(out[j]), float(v[j]), held)
        self._x_prev = x
        return out

    def _port(self, k: int, j: int, f: float, v: float, held: bool) -> float:
        """One port's PO and PC at sample k; returns the force to apply."""
        T = self.T
        self.f1[k, j] = f
        q = f * v * T
        base = self._available(k, j)
        W = base + (q if not self.lags else min(q, 0.0))
        a = cut = 0.0
        if W < 0 and f * v < 0 and T * abs(v) > 0:     # (T |v| can underflow to 0)
            # |alpha v| = -W / (T |v|), the force taken off; never more than |f|
            cut = min(-W / (T * abs(v)), abs(f))
            a = cut / abs(v)
            if self.o.max_damping is not None and a > self.o.max_damping:
                a = self.o.max_damping
                cut = a * abs(v)
            f -= math.copysign(cut, f)               # alpha v has the sign of v, not f's
            q = f * v * T
        self._d[j] += cut * abs(v) * T
        if held:
            self._f_prev[j] = f
        else:
            self._commit(j, q)
        W = self._available(k, j) + ((q if not self.lags else min(q, 0.0)) if held else 0.0)
        self.e_in[k, j], self.e_out[k, j] = self._in[j], self._out[j]
        self.W[k, j], self.alpha[k, j], self.diss[k, j] = W, a, self._d[j]
        return f

    def record(self) -> TdpaRecord:
        """The record of the run (rows after an overflow are NaN).

        Returns
        -------
        TdpaRecord
        """
        arrays = (self.f1, self.e_in, self.e_out, self.W, self.alpha, self.diss)
        for a in arrays:
            a.setflags(write=False)
        return TdpaRecord(self.o, self.lags, *arrays)


def channel_lags(channels: Any, n_ports: int) -> tuple[int, ...]:
    """Per port, after how many samples the other port's input energy arrives: the
    smallest delay among the terms of the port's channels that read the other port,
    rounded up to whole samples, at least 1 (with no delay both PCs decide at the same
    instant, so the other's energy is used one sample late). A port no channel
    informs of the other never receives its energy (a lag beyond any run).

    Parameters
    ----------
    channels : sequence of Channel
        The loop's channels (:func:`hapstab.engine.structure.structure_of`).
    n_ports : int
        p.

    Returns
    -------
    tuple of int
        Empty for one port.
    """
    if n_ports < 2:
        return ()
    lags = []
    for i in range(n_ports):
        ds = [d for ch in channels if ch.port == i for (j, _sgn, d) in ch.terms if j != i]
        lags.append(max(1, math.ceil(min(ds))) if ds else 2 ** 62)
    return tuple(lags)


def passivity_controller(tdpa: Any, loop: Any, n_samples: int, pos_idx: np.ndarray,
                         rows: np.ndarray | None = None) -> PassivityController | None:
    """The PO/PC of a run, or None when ``tdpa`` asks for none.

    Parameters
    ----------
    tdpa : None, bool, TDPA or dict
        What ``simulate(..., tdpa=...)`` received (:func:`tdpa_options`).
    loop : HapticLoop, TeleoperationLoop or FourChannelLoop
        The loop simulated.
    n_samples : int
        M.
    pos_idx : (p,) int array
        Each port's position entry in the closed-loop state.
    rows : (p, M+1) int array, optional
        Through a network: which sample of the other port's energy each PO has
        (:func:`hapstab.simulation.network.tdpa_rows`).

    Returns
    -------
    PassivityController or None

    Raises
    ------
    ModelError
        Bad options, a scaled teleoperator, or a loop with more than two ports.
    """
    from hapstab.engine.structure import structure_of

    opts = tdpa_options(tdpa)
    if opts is None:
        return None
    scales = (getattr(loop, "position_scale", 1.0), getattr(loop, "force_scale", 1.0))
    if scales != (1.0, 1.0):
        raise ModelError(f"tdpa: position_scale = {scales[0]:g}, force_scale = {scales[1]:g}: a "
                         "scaled teleoperator is meant not to be passive in its raw port powers; "
                         "TDPA is simulated for unscaled loops only (allowed: scales 1)")
    st = structure_of(loop)
    if len(st.ports) > 2:
        raise ModelError(f"tdpa: a loop with {len(st.ports)} ports; allowed: one port (HVE) "
                         "or two (a teleoperator)")
    return PassivityController(opts, loop.period, n_samples, pos_idx,
                               channel_lags(st.channels, len(st.ports)), rows)
