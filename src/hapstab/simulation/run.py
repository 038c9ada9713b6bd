"""Time-domain simulation of the sampled-data loops, exact between samples.

The continuous part (device, operator / environment impedance) is discretised
exactly for the zero-order hold (matrix exponential, :mod:`hapstab.engine`); then
come the sampler, the delay line and the discrete controller, as in the paper's
Simulink models of Fig. 2a and Fig. 3. The linear loop is propagated by the exact
recurrence ``s[k+1] = A_cl s[k] + B_ext f[k]``, many samples per matrix product
(block recurrence); with nonlinear elements the loop is stepped sample by sample.

Optional nonlinear elements act at the sampling instants, where a real
controller sees and commands them:

* ``resolution``: the controller sees positions quantised to the encoder step Δ:
  by default ``Δ floor(x / Δ)``, the count of encoder lines passed (an
  incremental encoder's reading), or with ``quantizer="nearest"`` the nearest
  step (ties away from zero);
* ``wall``: the virtual environment (HVE) acts only while the (delayed,
  measured) position it sees penetrates ``x > wall``, and then only pushes: a
  virtual damper that would pull the device into the wall (``u < 0`` while the
  device leaves it fast) gives no force, unless ``wall_pulls=True``;
* ``saturation``: each actuator force is clipped to +-saturation.

A device's Coulomb friction (``Device(..., coulomb_friction=f_c)``) acts between the
samples: each port's stick-slip motion under the held force is integrated exactly, its
events (the velocity reaching 0, the net force leaving the stick band) located to
machine precision (:mod:`hapstab.simulation.friction`). It makes the run nonlinear.

The operator's (and the environment's) spring is relaxed at the port's initial
position, where a hand holding the device at rest puts it; ``rest_position``
moves it.

The verdict separates the loop from its input. A linear run is judged on its
free responses (:func:`~hapstab.simulation.growth.combine`): from the initial state, and
from an impulse where each force enters — a bounded force gives a bounded
response exactly when these decay. A nonlinear run is judged on its envelope
(:func:`~hapstab.simulation.behaviour.assess_nonlinear`): it settles, oscillates in a limit
cycle, grows, drifts, or the run is too short to tell.

References
----------
The paper, Fig. 2a (HVE), Fig. 3 / eq. (19)-(21) (PEB), eq. (23) (H(z)) and
Section 5 (simulation study).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from hapstab import budget
from hapstab.engine.structure import structure_of
from hapstab.engine.system import build
from hapstab.engine.zoh import port_matrices
from hapstab.errors import ModelError, check_real, check_reals
from hapstab.models.loops import HapticLoop, TeleoperationLoop, headline, require_loop
from hapstab.models.parts import quantize
from hapstab.simulation.behaviour import assess_nonlinear
from hapstab.simulation.friction import LoopFriction
from hapstab.simulation.growth import BoundednessVerdict, assess, combine
from hapstab.simulation.inputs import ForceSpec, force_grows, force_samples
from hapstab.simulation.network import network_loop, network_options, tdpa_rows, wire
from hapstab.simulation.propagate import propagate_linear
from hapstab.simulation.result import SimulationResult
from hapstab.simulation.stepper import dense_output, roles_of, step_nonlinear
from hapstab.simulation.stepper import initial_state as make_initial_state
from hapstab.simulation.tdpa import passivity_controller

__all__ = ["simulate", "quantize", "QUANTIZERS"]


# ------------------------------------------------------------------ inputs


# ------------------------------------------------------------ linear engine


# --------------------------------------------------------------- simulate
def simulate(loop: HapticLoop | TeleoperationLoop, duration: float, *,
             force: ForceSpec = None, environment_force: ForceSpec = None,
             initial_position: float | Sequence[float] = 0.0,
             initial_velocity: float | Sequence[float] = 0.0,
             initial_state: Sequence[float] | None = None,
             rest_position: float | Sequence[float] | None = None,
             wall: float | None = None, wall_pulls: bool = False,
             saturation: float | None = None,
             resolution: float | None = None, quantizer: str = "floor",
             dense: int = 0, max_memory: float | None = None,
             max_seconds: float | None = None, tdpa: Any = None,
             network: Any = None) -> SimulationResult:
    """Simulate the sampled-data loop for ``duration`` seconds.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop; a device's ``coulomb_friction`` is simulated exactly (stick-slip between
        the samples, :mod:`hapstab.simulation.friction`) and makes the run nonlinear.
    duration : float
        Seconds; ``round(duration / T)`` samples are taken.
    force : force spec, optional
        Exogenous operator force on the device (HVE) / master (a teleoperator: PEB or
        the 4-channel loop); see :func:`force_samples`. Held over each sample; a
        4-channel loop's force channels measure it as part of the operator's force.
    environment_force : force spec, optional
        Exogenous environment force on the slave (teleoperators only).
    initial_position, initial_velocity : float or sequence
        Per port (a scalar applies to every port). The loop's history is at rest
        at the initial position (delay registers and controller states consistent).
    initial_state : sequence, optional
        The full closed-loop state instead (engine layout), for experts.
    rest_position : float or sequence, optional
        Where each port's operator / environment spring is relaxed (m); default
        the port's initial position (a hand holding the device at rest there).
    wall : float, optional
        HVE only: the virtual environment acts only while the position it sees
        (delayed, quantised) penetrates ``x > wall``; it then acts on ``x - wall``.
    wall_pulls : bool
        Let the wall's damper pull the device in (``u < 0`` in contact). Default
        False: a wall only pushes.
    saturation : float, optional
        Actuator force limit |u| <= saturation (N), each port.
    resolution : float, optional
        Encoder resolution Δ (m). Not with a measured force (a 4-channel loop's force
        gains) yet.
    quantizer : {"floor", "nearest"}
        ``floor``: the controller sees ``Δ floor(x / Δ)`` (an encoder's count);
        ``nearest``: the nearest multiple of Δ, ties away from zero.
    dense : int
        If >= 2, also return the exact trajectory at ``dense`` points per sample.
    max_memory, max_seconds : float, optional
        Budget for this run in bytes and seconds (default :mod:`hapstab.budget`'s):
        the run's cost is estimated first and a run above it is refused.
    tdpa : bool, TDPA or dict, optional
        The time-domain passivity approach at every device port
        (:mod:`hapstab.simulation.tdpa`): True for the papers' observer and controller,
        or a :class:`~hapstab.simulation.tdpa.TDPA` (``observer``, ``velocity``,
        ``max_damping``). It makes the run nonlinear; ``result.tdpa`` records it.
        Through a ``network`` its PEB form is the time-varying one (each PO uses the
        other port's input energy of the newest sample that has arrived, Ryu, Artigas
        & Preusche 2010).
    network : Network or dict, optional
        A network in the position channels (:mod:`hapstab.simulation.network`): a trace
        (``hapstab.simulation.read_trace(path)``, or ``dict(delay_samples=...,
        arrived=...)``) or random delays and losses (``dict(jitter=(lo, hi), loss=P,
        seed=S)``). The controller uses the newest sample that has arrived and holds the
        last value it used while nothing newer arrives; PEB: each direction on its own.
        It replaces the loop's own delay and makes the run stepped (time-varying);
        ``result.nonlinear["network"]`` records it. HVE and PEB only.

    Returns
    -------
    SimulationResult
        ``verdict``: for a linear run, judged on its free responses (from the
        initial state, and from an impulse where each force enters); for a
        nonlinear one, on its envelope (settles, limit cycle, grows, drifts,
        undecided).

    Raises
    ------
    ModelError
        Invalid duration, forces, initial state or nonlinear parameters.
    BudgetError
        The run would need more memory or time than the budget.

    References
    ----------
    The paper, Fig. 2a, Fig. 3, eq. (19)-(23), Section 5.
    """
    require_loop(loop)
    T = loop.period
    M, dense = _samples(duration, T, dense)
    haptic = len(loop.port_names) == 1           # one device, one delay
    nl = _nonlinear_options(haptic, environment_force, wall, wall_pulls, saturation, resolution,
                            quantizer)
    if (net := network_options(network)) is not None:
        loop = network_loop(net, loop)
        nl["network"] = net.to_dict()
    sysm = build(loop)
    p = sysm.n_ports
    ports = structure_of(loop).ports
    _admit(sysm, ports, nl, M, dense, max_memory, max_seconds)
    roles, line, rows = _network(net, loop, sysm, roles_of(loop, sysm), M, nl)
    t = np.arange(M + 1) * T
    F = _forces(force, environment_force, t, p)
    pos_idx = np.argmax(sysm.pos, axis=1)
    if (pc := passivity_controller(tdpa, loop, M, pos_idx, rows)) is not None:
        nl["tdpa"] = pc.o.to_dict()
    measure = _measurement(roles, p, nl)
    s0 = make_initial_state(sysm, roles, initial_position, initial_velocity, initial_state, measure)
    springs = np.array([pt.termination.stiffness for pt in ports])
    rest = _rest(rest_position, s0[pos_idx], p)
    if roles.held_f.size and initial_state is None:
        # a force measured at the first sample sees the hand at rest: the spring's offset
        s0 = make_initial_state(sysm, roles, initial_position, initial_velocity, None, measure,
                                held_force=springs * rest)
    Fd = F + springs * rest              # a spring relaxed at r: -k (x - r) = -k x + k r
    contact, fr = None, None
    if not nl:
        S = propagate_linear(roles.A, roles.G, s0, Fd, M)
        with np.errstate(over="ignore", invalid="ignore"):
            U = S @ roles.Fu.T
    else:
        fr = LoopFriction(ports, sysm, M, budget.seconds_allowed(max_seconds)) \
            if "coulomb_friction_N" in nl else None
        S, U, contact = step_nonlinear(roles, s0, Fd, M, measure, wall is not None,
                                       nl.get("saturation"), wall_pulls, pc, between=fr,
                                       network=line)
    X, V = S[:, pos_idx], S[:, pos_idx + 1]
    pe, ee, Fx = _energies(X, U, F, p)
    growing = force_grows(F)
    if not nl or set(nl) == {"network"}:
        verdict = _linear_verdict(roles, s0, Fd, S, T, sysm.labels, _free(roles, measure, line, T, pos_idx))
    else:
        verdict = _nonlinear_verdict(loop, roles, S, X, T, nl, growing)
    if growing:
        verdict = _input_caveat(verdict)
    dt = dx = dv = None
    if dense >= 2 and np.all(np.isfinite(S)):
        dt, dx, dv = dense_output(sysm, S, Fd - U[:-1], T, dense)
        if fr is not None:               # the friction ports' stick-slip, exact
            fr.dense(dx, dv, S, Fd - U[:-1], dense)
    fe = None if fr is None else fr.dissipated
    arrays = [t, X, V, U, Fx, pe, ee, S] + ([] if fe is None else [fe])
    for a in arrays:
        a.setflags(write=False)
    K = float(sysm.stiffness[0])
    return SimulationResult(t, X, V, U, Fx, pe, ee, S, verdict, tuple(sysm.labels), T,
                            loop.delay_in_samples, K, nl, contact, dt, dx, dv,
                            rest=tuple(float(r) for r in rest), model=headline(loop),
                            tdpa=None if pc is None else pc.record(), friction_energy=fe)


def _network(net: Any, loop: Any, sysm: Any, roles: Any, M: int, nl: dict[str, Any]
             ) -> tuple[Any, Any, np.ndarray | None]:
    """The roles, the network line and the TDPA's energy rows of a run through ``net``
    (the roles alone, None, None without one)."""
    if net is None:
        return roles, None, None
    roles, line, terms = wire(net, loop, sysm, roles, M)
    nl["network"].update(line.summary())
    return roles, line, tdpa_rows(line, terms, sysm.n_ports)


def _energies(X: np.ndarray, U: np.ndarray, F: np.ndarray, p: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Port energy (controller force times displacement), exogenous energy, and the
    exogenous force with a last row (M+1, p) each."""
    with np.errstate(over="ignore", invalid="ignore"):
        dX = np.diff(X, axis=0)
        pe = np.vstack([np.zeros(p), np.cumsum(U[:-1] * dX, axis=0)])
        ee = np.vstack([np.zeros(p), np.cumsum(F * dX, axis=0)])
    return pe, ee, np.vstack([F, F[-1:]])


def _forces(force: ForceSpec, environment_force: ForceSpec, t: np.ndarray, p: int) -> np.ndarray:
    """The exogenous forces held over each sample, (M, p): operator, environment."""
    F = np.zeros((t.size - 1, p))
    F[:, 0] = force_samples(force, t[:-1], "force")
    if p > 1:
        F[:, 1] = force_samples(environment_force, t[:-1], "environment_force")
    return F


def _admit(sysm: Any, ports: Sequence[Any], nl: dict[str, Any], M: int, dense: int,
           max_memory: float | None, max_seconds: float | None) -> None:
    """Add the devices' Coulomb friction to ``nl``, refuse what is not simulated yet and
    check the run's cost against the budget."""
    if any(pt.device.coulomb_friction > 0 for pt in ports):
        nl["coulomb_friction_N"] = [pt.device.coulomb_friction for pt in ports]
    if sysm.held_f is not None and "resolution" in nl:
        raise ModelError(f"resolution = {nl['resolution']}: encoder quantisation with a measured "
                         "force (a FourChannelLoop's force channel) is not simulated yet; "
                         "allowed: None, or force gains of 0")
    cost = budget.simulation_cost(M, sysm.order, sysm.n_ports, dense)
    if "coulomb_friction_N" in nl:       # the ports' stick-slip is stepped in Python
        extra = 3e-5 * M * sysm.n_ports  # ~30 us per port and sample (measured, 1 core)
        cost = dataclasses.replace(cost, seconds=cost.seconds + extra)
    if "network" in nl:                  # stepped: the run and each free response
        # ~25 us per sample and stepping (measured 18-23 us, HVE and PEB, 1 core)
        extra = 2.5e-5 * M * (2 + sysm.n_ports)
        cost = dataclasses.replace(cost, seconds=cost.seconds + extra)
    budget.check(cost, max_memory, max_seconds)


def _samples(duration: float, T: float, dense: Any) -> tuple[int, int]:
    """Number of samples of the run, and ``dense`` as a Python int (a numpy uint8 would
    overflow the budget's sums); checks ``duration`` and ``dense``."""
    dur = check_real("duration", duration, positive=True)
    if not dur / T <= 50_000_000:
        raise ModelError(f"duration = {duration}: {dur / T:.3g} samples is too many (limit 5e7)")
    M = round(dur / T)
    if M < 8:
        raise ModelError(f"duration = {duration}: gives {M} samples at period T = {T:g} s; "
                         "need >= 8")
    if M > 50_000_000:
        raise ModelError(f"duration = {duration}: {M} samples is too many (limit 5e7)")
    if not isinstance(dense, (int, np.integer)) or isinstance(dense, bool) or dense < 0 or dense == 1:
        raise ModelError(f"dense = {dense!r}: must be 0 (off) or a whole number >= 2 "
                         "(points per sample)")
    return M, int(dense)


def _nonlinear_options(haptic: bool, environment_force: Any, wall: Any, wall_pulls: Any,
                       saturation: Any, resolution: Any, quantizer: Any) -> dict[str, Any]:
    """The nonlinear elements asked for (checked); empty for a linear run."""
    if haptic and environment_force is not None:
        raise ModelError("environment_force: a HapticLoop has no environment port; use a TeleoperationLoop")
    if wall is not None and not haptic:
        raise ModelError("wall: the unilateral wall is the HVE's virtual environment; a "
                         "TeleoperationLoop's environment is its impedance (--environment)")
    if not isinstance(wall_pulls, (bool, np.bool_)):
        raise ModelError(f"wall_pulls = {wall_pulls!r}: must be True or False")
    if not isinstance(quantizer, str) or quantizer not in QUANTIZERS:
        raise ModelError(f"quantizer = {quantizer!r}: allowed: {', '.join(QUANTIZERS)}")
    nl: dict[str, Any] = {}
    if wall is not None:
        nl["wall"] = check_real("wall", wall)
        if wall_pulls:
            nl["wall_pulls"] = True
    if saturation is not None:
        nl["saturation"] = check_real("saturation", saturation, positive=True)
    if resolution is not None:
        nl["resolution"] = check_real("resolution", resolution, positive=True)
        nl["quantizer"] = quantizer
    return nl


#: How an encoder reading is formed from the position (see :func:`simulate`).
QUANTIZERS = ("floor", "nearest")


def _measurement(roles: Any, p: int, nl: dict[str, Any]) -> Any:
    """What the controller reads: quantised positions relative to the wall."""
    offset = np.zeros(p)
    offset[0] = nl.get("wall", 0.0)
    pe_idx, pe_off = roles.pos_entries, offset[roles.pos_port]
    res, how = nl.get("resolution"), nl.get("quantizer", "floor")

    def measure(s: np.ndarray) -> np.ndarray:
        sm = s.copy()
        x = s[pe_idx]
        sm[pe_idx] = (quantize(x, res, how) if res else x) - pe_off
        return sm

    return measure


def _rest(rest_position: Any, initial: np.ndarray, p: int) -> np.ndarray:
    """Rest position of each port's termination spring (default: where it starts)."""
    if rest_position is None:
        return np.array(initial, float)
    v = check_reals("rest_position", rest_position)
    a = v if v.size in (1, p) else None
    if a is None or not np.all(np.isfinite(a)):
        raise ModelError(f"rest_position = {rest_position!r}: must be one finite number or one "
                         f"per port ({p})")
    return np.broadcast_to(a, (p,)).astype(float)


def _free(roles: Any, measure: Any, line: Any, T: float, pos_idx: np.ndarray) -> Any:
    """How a free response is computed and judged: ``free(s0, M, differences)`` ->
    verdict. The linear recurrence, judged on its fitted dominant mode; through a
    network the same delays and losses stepped again (a linear *time-varying* loop),
    judged on the fit where it is linear to a few digits (a constant delay) and else
    on its envelope (:func:`assess_nonlinear`: no single mode describes a switching
    loop)."""
    if line is None:
        return lambda s0, M, d: assess(propagate_linear(roles.A, roles.G, s0, None, M), None,
                                       T, differences=d)

    def free(s0: np.ndarray, M: int, d: bool) -> BoundednessVerdict:
        line.reset()
        S = step_nonlinear(roles, s0, np.zeros((M, roles.G.shape[1])), M, measure, False,
                           None, network=line)[0]
        v = assess(S, None, T, differences=d)
        return v if v.confidence != "low" else assess_nonlinear(S, S[:, pos_idx], T)

    return free


def _linear_verdict(roles: Any, s0: np.ndarray, F: np.ndarray, S: np.ndarray, T: float,
                    labels: Sequence[str], free: Any) -> BoundednessVerdict:
    """Judge a linear run on its free responses (``free(s0, M, differences)``, see
    :func:`_free`): from the initial state (differences: a resting offset is not growth)
    and from an impulse where each force enters (states: a mode at z = 1 that a
    constant force would make drift is marginal)."""
    if not np.all(np.isfinite(S)):
        return assess(S, None, T)                       # observed overflow
    M = S.shape[0] - 1
    parts = [("free response from the initial state", free(s0, M, True))]
    for j in np.flatnonzero(np.any(F != 0, axis=0)):
        with np.errstate(invalid="ignore", over="ignore"):    # a 1e-300 kg device's
            g = roles.G[:, j] / np.abs(roles.G[:, j]).max()   # column: judged as it is
        parts.append((f"response to a force impulse on the {labels[int(j)]}", free(g, M, False)))
    return combine(parts)


def _input_caveat(v: BoundednessVerdict) -> BoundednessVerdict:
    """A verdict on a run whose force keeps growing: it speaks of the loop under a
    bounded force, which this run is not, so it is not confident."""
    return dataclasses.replace(
        v, confidence="low",
        reason=v.reason + "; NOTE: the force itself keeps growing over the run, and the "
        "verdict is about the loop under a bounded force")


def _nonlinear_verdict(loop: HapticLoop | TeleoperationLoop, roles: Any, S: np.ndarray,
                       X: np.ndarray, T: float, nl: dict[str, Any],
                       growing_force: bool) -> BoundednessVerdict:
    """Judge a nonlinear run on its envelope, told how fast the linearised loop grows,
    whether the model bounds the run, and whether a port can drift at all."""
    M = S.shape[0] - 1
    s_rand = np.random.default_rng(0).standard_normal(roles.A.shape[0])
    # on the states, not their differences: a mode at z = 1 (a rigid pair, a free
    # device) is not "stable" for the bounds below
    lin = assess(propagate_linear(roles.A, roles.G, s_rand, None, M), None, T, differences=False)
    ports = structure_of(loop).ports
    can_drift = any(pt.termination.stiffness == 0 for pt in ports)
    bound = None if growing_force else _bound(ports, nl, lin)
    # through a network the loop is time-varying: no one linearisation describes it
    rate = None if "network" in nl else lin.growth_rate
    return assess_nonlinear(S, X, T, linear_rate=rate, bound=bound, can_drift=can_drift)


def _bound(ports: Sequence[Any], nl: dict[str, Any], lin: BoundednessVerdict) -> str | None:
    """Why the run cannot grow (under a bounded force), when the model says so; else None."""
    if "saturation" in nl and all(
            np.linalg.eigvals(port_matrices(pt)[0]).real.max() < 0 for pt in ports):
        return (f"the actuator force is limited to +-{nl['saturation']:g} N and every device "
                "with its operator / environment is stable on its own")
    if set(nl) <= {"resolution", "quantizer", "coulomb_friction_N"} and lin.bounded \
            and lin.confidence == "high":
        what = []
        if "resolution" in nl:
            what.append("quantisation changes what the controller reads by less than one "
                        "encoder step")
        if "coulomb_friction_N" in nl:
            what.append("Coulomb friction is a force of at most f_c on each device")
        return (f"{' and '.join(what)}: a bounded disturbance of the linear loop, which is "
                f"asymptotically stable (its free response decays at {lin.growth_rate:.3g} 1/s)")
    return None


# ------------------------------------------------- the paper's K_max procedure


