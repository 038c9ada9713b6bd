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

The operator's (and the environment's) spring is relaxed at the port's initial
position, where a hand holding the device at rest puts it; ``rest_position``
moves it.

The verdict separates the loop from its input. A linear run is judged on its
free responses (:func:`hapstab.growth.combine`): from the initial state, and
from an impulse where each force enters — a bounded force gives a bounded
response exactly when these decay. A nonlinear run is judged on its envelope
(:func:`hapstab.behaviour.assess_nonlinear`): it settles, oscillates in a limit
cycle, grows, drifts, or the run is too short to tell.

References
----------
The paper, Fig. 2a (HVE), Fig. 3 / eq. (19)-(21) (PEB), eq. (23) (H(z)) and
Section 5 (simulation study).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from itertools import pairwise
from typing import Any

import numpy as np

from hapstab.engine.structure import structure_of
from hapstab.engine.system import build
from hapstab.engine.zoh import port_matrices
from hapstab.errors import AnalysisError, ModelError, check_real
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.results import CriticalStiffnessResult
from hapstab.simulation.behaviour import assess_nonlinear
from hapstab.simulation.growth import BoundednessVerdict, assess, combine
from hapstab.simulation.result import SimulationResult
from hapstab.simulation.stepper import dense_output, roles_of, step_nonlinear
from hapstab.simulation.stepper import initial_state as make_initial_state

__all__ = ["simulate", "SimulationResult", "force_samples", "critical_stiffness_simulation",
           "propagate_linear"]

ForceSpec = Any  # None | float | "step:F[,t0]" | "pulse:F,width[,t0]" | "sine:F,Hz" | callable | array


# ------------------------------------------------------------------ inputs
def force_samples(spec: ForceSpec, times: np.ndarray, name: str = "force") -> np.ndarray:
    """Exogenous force at each sampling instant, held over the sample (ZOH).

    Parameters
    ----------
    spec : None, float, str, callable or array
        ``None`` (no force); a number F (step of F N at t = 0); ``"step:F[,t0]"``;
        ``"pulse:F,width[,t0]"`` (F N for ``width`` s from ``t0``); ``"sine:F,Hz"``;
        a callable ``f(t)``; or an array with one value per sample.
    times : (M,) array
        Sampling instants t_k = k T.
    name : str
        Parameter name for messages.

    Returns
    -------
    (M,) array

    Raises
    ------
    ModelError
        A malformed spec or an array of the wrong length.

    Notes
    -----
    The force is sampled at t_k and held, like the controller's output; a sine is
    therefore seen with the hold's half-sample lag.
    """
    M = times.size
    allowed = "allowed: a number, step:F[,t0], pulse:F,width[,t0], sine:F,Hz, a callable or an array"
    if spec is None:
        return np.zeros(M)
    if isinstance(spec, (int, float, np.floating, np.integer)) and not isinstance(spec, bool):
        return np.full(M, check_real(name, spec))
    if isinstance(spec, str):
        kind, _, args = spec.strip().lower().partition(":")
        try:
            v = [float(a) for a in args.split(",")] if args else []
        except ValueError:
            raise ModelError(f"{name} = {spec!r}: malformed number; {allowed}") from None
        if not all(math.isfinite(x) for x in v):
            raise ModelError(f"{name} = {spec!r}: numbers must be finite; {allowed}")
        if kind == "step" and len(v) in (1, 2):
            t0 = v[1] if len(v) == 2 else 0.0
            return np.where(times >= t0 - 1e-12, v[0], 0.0)
        if kind == "pulse" and len(v) in (2, 3) and v[1] > 0:
            t0 = v[2] if len(v) == 3 else 0.0
            return np.where((times >= t0 - 1e-12) & (times < t0 + v[1] - 1e-12), v[0], 0.0)
        if kind == "sine" and len(v) == 2 and v[1] >= 0:
            return v[0] * np.sin(2 * np.pi * v[1] * times)
        raise ModelError(f"{name} = {spec!r}: not understood; {allowed}")
    if callable(spec):
        return np.array([float(spec(t)) for t in times])
    try:
        a = np.asarray(spec, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ModelError(f"{name} = {spec!r}: {allowed}") from None
    if a.size != M or not np.all(np.isfinite(a)):
        raise ModelError(f"{name}: array of {a.size} values; need {M} finite values (one per sample)")
    return a


# ------------------------------------------------------------ linear engine
def propagate_linear(A: np.ndarray, B: np.ndarray, s0: np.ndarray, F: np.ndarray | None,
                     n_samples: int, block: int = 64) -> np.ndarray:
    """The exact recurrence ``s[k+1] = A s[k] + B f[k]``, ``block`` samples per product.

    Parameters
    ----------
    A : (N, N) array
        One-sample state transition.
    B : (N, p) array
        Input matrix of the held forces.
    s0 : (N,) array
        Initial state.
    F : (M, p) array or None
        Held inputs (None: free response).
    n_samples : int
        M.
    block : int
        Samples per block; powers A^1..A^block are formed once.

    Returns
    -------
    (M+1, N) array of states; rows after an overflow are inf/nan.
    """
    N = A.shape[0]
    m = max(1, min(block, n_samples))
    pw = np.empty((m, N, N))
    pw[0] = A
    for j in range(1, m):
        pw[j] = A @ pw[j - 1]
    Pw = pw.reshape(m * N, N)
    forced = F is not None and np.any(F)
    if forced:
        p = B.shape[1]
        H = np.empty((m, N, p))                      # H[j] = A^j B
        H[0] = B
        H[1:] = pw[:-1] @ B
        Toe: np.ndarray = np.zeros((m, N, m, p))
        for i in range(m):
            Toe[i:, :, i, :] = H[:m - i]             # s[k+1+j] gets A^(j-i) B f[k+i]
        Toe = Toe.reshape(m * N, m * p)
        nb = -(-n_samples // m)
        Fp = np.zeros((nb * m, p))
        Fp[:n_samples] = F
        Fb = Fp.reshape(nb, m * p)
    S = np.empty((n_samples + 1, N))
    S[0] = s0
    s = np.asarray(s0, float)
    with np.errstate(over="ignore", invalid="ignore"):
        # the forced part of every block at once; only the free part is sequential
        Fc = (Fb @ Toe.T).reshape(-1, m, N) if forced else None
        k = b = 0
        while k < n_samples:
            blk = (Pw @ s).reshape(m, N)
            if Fc is not None:                       # forced
                blk += Fc[b]
            take = min(m, n_samples - k)
            S[k + 1:k + 1 + take] = blk[:take]
            s = blk[take - 1]
            k += take
            b += 1
            if not np.isfinite(s).all():
                S[k + 1:] = np.inf
                break
    return S


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
             dense: int = 0) -> SimulationResult:
    """Simulate the sampled-data loop for ``duration`` seconds.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
    duration : float
        Seconds; ``round(duration / T)`` samples are taken.
    force : force spec, optional
        Exogenous operator force on the device (HVE) / master (PEB); see
        :func:`force_samples`. Held over each sample.
    environment_force : force spec, optional
        Exogenous environment force on the slave (PEB only).
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
        Encoder resolution Δ (m).
    quantizer : {"floor", "nearest"}
        ``floor``: the controller sees ``Δ floor(x / Δ)`` (an encoder's count);
        ``nearest``: the nearest multiple of Δ, ties away from zero.
    dense : int
        If >= 2, also return the exact trajectory at ``dense`` points per sample.

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

    References
    ----------
    The paper, Fig. 2a, Fig. 3, eq. (19)-(23), Section 5.
    """
    T = loop.period
    M = _samples(duration, T, dense)
    haptic = isinstance(loop, HapticLoop)
    nl = _nonlinear_options(haptic, environment_force, wall, wall_pulls, saturation, resolution,
                            quantizer)
    sysm = build(loop)
    p = sysm.n_ports
    roles = roles_of(loop, sysm)
    t = np.arange(M + 1) * T
    F = np.zeros((M, p))
    F[:, 0] = force_samples(force, t[:-1], "force")
    if p > 1:
        F[:, 1] = force_samples(environment_force, t[:-1], "environment_force")
    pos_idx = np.argmax(sysm.pos, axis=1)
    measure = _measurement(roles, p, nl)
    s0 = make_initial_state(sysm, roles, initial_position, initial_velocity, initial_state, measure)
    springs = np.array([pt.termination.stiffness for pt in structure_of(loop).ports])
    rest = _rest(rest_position, s0[pos_idx], p)
    Fd = F + springs * rest              # a spring relaxed at r: -k (x - r) = -k x + k r
    contact = None
    if not nl:
        S = propagate_linear(roles.A, roles.G, s0, Fd, M)
        with np.errstate(over="ignore", invalid="ignore"):
            U = S @ roles.Fu.T
    else:
        S, U, contact = step_nonlinear(roles, s0, Fd, M, measure, wall is not None,
                                       nl.get("saturation"), wall_pulls)
    X, V = S[:, pos_idx], S[:, pos_idx + 1]
    with np.errstate(over="ignore", invalid="ignore"):
        dX = np.diff(X, axis=0)
        pe = np.vstack([np.zeros(p), np.cumsum(U[:-1] * dX, axis=0)])
        ee = np.vstack([np.zeros(p), np.cumsum(F * dX, axis=0)])
    Fx = np.vstack([F, F[-1:]])
    if not nl:
        verdict = _linear_verdict(roles, s0, Fd, S, T, sysm.labels)
    else:
        verdict = _nonlinear_verdict(loop, roles, S, X, T, nl, _force_grows(F))
    if _force_grows(F):
        verdict = _input_caveat(verdict)
    dt = dx = dv = None
    if dense >= 2 and np.all(np.isfinite(S)):
        dt, dx, dv = dense_output(sysm, S, Fd - U[:-1], T, dense)
    arrays = [t, X, V, U, Fx, pe, ee, S]
    for a in arrays:
        a.setflags(write=False)
    K = float(sysm.stiffness[0])
    return SimulationResult(t, X, V, U, Fx, pe, ee, S, verdict, tuple(sysm.labels), T,
                            loop.delay_in_samples, K, nl, contact, dt, dx, dv,
                            rest=tuple(float(r) for r in rest))


def _samples(duration: float, T: float, dense: Any) -> int:
    """Number of samples of the run; checks ``duration`` and ``dense``."""
    dur = check_real("duration", duration, positive=True)
    M = round(dur / T)
    if M < 8:
        raise ModelError(f"duration = {duration}: gives {M} samples at T = {T:g} s; need >= 8")
    if M > 50_000_000:
        raise ModelError(f"duration = {duration}: {M} samples is too many (limit 5e7)")
    if not isinstance(dense, (int, np.integer)) or isinstance(dense, bool) or dense < 0 or dense == 1:
        raise ModelError(f"dense = {dense!r}: must be 0 (off) or a whole number >= 2 "
                         "(points per sample)")
    return M


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
    if quantizer not in QUANTIZERS:
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


def quantize(x: np.ndarray, resolution: float, quantizer: str = "floor") -> np.ndarray:
    """The encoder's reading of ``x``: ``Δ floor(x/Δ)`` or the nearest multiple of Δ
    (ties away from zero, not to even).

    Parameters
    ----------
    x : array
        Positions in m.
    resolution : float
        Δ, the encoder's resolution in m (> 0).
    quantizer : {"floor", "nearest"}
        ``"floor"`` (an incremental encoder) or anything else for the nearest multiple.

    Returns
    -------
    array
        The readings, multiples of Δ in m.
    """
    if quantizer == "floor":
        return resolution * np.floor(x / resolution)
    return resolution * np.sign(x) * np.floor(np.abs(x) / resolution + 0.5)


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
    a = np.asarray(rest_position, float).ravel() if np.size(rest_position) in (1, p) else None
    if a is None or not np.all(np.isfinite(a)):
        raise ModelError(f"rest_position = {rest_position!r}: must be one finite number or one "
                         f"per port ({p})")
    return np.broadcast_to(a, (p,)).astype(float)


def _linear_verdict(roles: Any, s0: np.ndarray, F: np.ndarray, S: np.ndarray, T: float,
                    labels: Sequence[str]) -> BoundednessVerdict:
    """Judge a linear run on its free responses: from the initial state (differences:
    a resting offset is not growth) and from an impulse where each force enters
    (states: a mode at z = 1 that a constant force would make drift is marginal)."""
    if not np.all(np.isfinite(S)):
        return assess(S, None, T)                       # observed overflow
    M = S.shape[0] - 1
    parts = [("free response from the initial state",
              assess(propagate_linear(roles.A, roles.G, s0, None, M), None, T))]
    for j in np.flatnonzero(np.any(F != 0, axis=0)):
        g = roles.G[:, j] / np.abs(roles.G[:, j]).max()
        imp = propagate_linear(roles.A, roles.G, g, None, M)
        parts.append((f"response to a force impulse on the {labels[int(j)]}",
                      assess(imp, None, T, differences=False)))
    return combine(parts)


def _force_grows(F: np.ndarray) -> bool:
    """Whether the exogenous force still grows at the end of the run: its largest
    size per tenth of the run rises in every tenth of the second half (a ramp, a
    growing sine; not a step, a pulse or a sine, however late they start)."""
    M = F.shape[0]
    if M < 10 or not np.any(F):
        return False
    tenths = np.linspace(0, M, 11).astype(int)
    peaks = np.array([np.abs(F[a:b]).max() for a, b in pairwise(tenths)])
    return bool(np.all(np.diff(peaks[4:]) > 0))


def _input_caveat(v: BoundednessVerdict) -> BoundednessVerdict:
    """A verdict on a run whose force keeps growing: it speaks of the loop under a
    bounded force, which this run is not, so it is not confident."""
    return dataclasses.replace(
        v, confidence="low",
        reason=v.reason + "; NOTE: the force itself keeps growing over the run, and the "
        "verdict is about the loop under a bounded force")


def _nonlinear_verdict(loop: HapticLoop | TeleoperationLoop, roles: Any, S: np.ndarray,
                       X: np.ndarray, T: float, nl: dict[str, Any],
                       force_grows: bool) -> BoundednessVerdict:
    """Judge a nonlinear run on its envelope, told how fast the linearised loop grows,
    whether the model bounds the run, and whether a port can drift at all."""
    M = S.shape[0] - 1
    s_rand = np.random.default_rng(0).standard_normal(roles.A.shape[0])
    # on the states, not their differences: a mode at z = 1 (a rigid pair, a free
    # device) is not "stable" for the bounds below
    lin = assess(propagate_linear(roles.A, roles.G, s_rand, None, M), None, T, differences=False)
    ports = structure_of(loop).ports
    can_drift = any(pt.termination.stiffness == 0 for pt in ports)
    bound = None if force_grows else _bound(ports, nl, lin)
    return assess_nonlinear(S, X, T, linear_rate=lin.growth_rate, bound=bound,
                            can_drift=can_drift)


def _bound(ports: Sequence[Any], nl: dict[str, Any], lin: BoundednessVerdict) -> str | None:
    """Why the run cannot grow (under a bounded force), when the model says so; else None."""
    if "saturation" in nl and all(
            np.linalg.eigvals(port_matrices(pt)[0]).real.max() < 0 for pt in ports):
        return (f"the actuator force is limited to +-{nl['saturation']:g} N and every device "
                "with its operator / environment is stable on its own")
    if set(nl) <= {"resolution", "quantizer"} and lin.bounded and lin.confidence == "high":
        return ("quantisation changes what the controller reads by less than one encoder step, "
                "a bounded disturbance of the linear loop, which is asymptotically stable (its "
                f"free response decays at {lin.growth_rate:.3g} 1/s)")
    return None


# ------------------------------------------------- the paper's K_max procedure
def _stiffness_scale(loop: HapticLoop | TeleoperationLoop) -> float:
    """m/T^2 of the lightest port: the stiffness that moves a mass by its own
    sample-scale motion, the natural unit of K."""
    st = structure_of(loop)
    m = min(pt.device.mass + pt.termination.mass for pt in st.ports)
    return m / loop.period ** 2


#: The downward scan of :func:`critical_stiffness_simulation` stops at this many m/T^2:
#: the exact analysis resolves K from 1e-6 of its own scale (about 2 m/T^2), and a
#: stiffness this small moves the poles by less than the 2000-sample growth fit sees.
_K_FLOOR = 1e-10


def critical_stiffness_simulation(loop: HapticLoop | TeleoperationLoop, *,
                                  n_samples: int = 2000, window: int = 500, rtol: float = 1e-4,
                                  seed: int = 0, ratio: float = 4.0) -> CriticalStiffnessResult:
    """The paper's procedure: the largest K for which the simulated loop stays bounded.

    K is raised from ``1e-6 m/T^2`` by factors of ``ratio`` until the simulated
    free response (from a seeded random initial state, which excites every mode)
    is unbounded, then the last bounded / first unbounded pair is bisected in
    log K to relative width ``rtol``. If the loop is unbounded already at the
    start (e.g. a negative virtual damping B that nearly cancels the device
    damping b leaves K_max ~ (b + B)/(T/2 + t_d), arbitrarily small), K is
    lowered by ``ratio`` down to ``1e-10 m/T^2`` before K_max = 0 is reported. Each verdict
    is :func:`hapstab.growth.assess` on ``n_samples`` samples (observed explosion, else the
    fitted growth rate).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controller(s); K is varied as in :meth:`with_stiffness`.
    n_samples : int
        Samples per simulated run.
    window : int
        Final samples the growth rate is fitted on.
    rtol : float
        Relative width of the final bracket.
    seed : int
        Seed of the initial state.
    ratio : float
        Step of the upward scan (> 1); like the paper, a stable island between two
        scan points could be missed.

    Returns
    -------
    CriticalStiffnessResult
        ``method="simulation"``; ``details`` has the number of runs, the horizon
        and the verdicts at the final bracket.

    Raises
    ------
    AnalysisError
        If a controller is not a spring-damper.

    References
    ----------
    The paper, Section 5 and the stars of Fig. 5 / Fig. 6.
    """
    sysm = build(loop)
    if not sysm.varies_with_K:
        raise AnalysisError("method = 'simulation': needs SpringDamper controller(s) to vary K")
    if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 64):
        raise AnalysisError(f"n_samples = {n_samples!r}: must be a whole number >= 64")
    if not (isinstance(window, (int, np.integer)) and 16 <= window <= n_samples):
        raise AnalysisError(f"window = {window!r}: must be a whole number in [16, n_samples]")
    if not (0 < rtol < 0.1) or not ratio > 1:
        raise AnalysisError(f"rtol = {rtol}, ratio = {ratio}: need 0 < rtol < 0.1 and ratio > 1")
    T = loop.period
    s0 = np.random.default_rng(seed).standard_normal(sysm.order)
    Bz = np.zeros((sysm.order, 1))
    runs = 0

    def verdict(K: float) -> BoundednessVerdict:
        nonlocal runs
        runs += 1
        S = propagate_linear(sysm.closed_loop(K)[0], Bz, s0, None, n_samples, block=128)
        return assess(S, None, T, window=window)

    Ks = _stiffness_scale(loop)
    lo, hi = 1e-6 * Ks, None
    v_lo = verdict(lo)
    v_hi = None
    if not v_lo.bounded:
        # a negative virtual damping that nearly cancels the device's leaves K_max far
        # below the usual start: scan down before concluding that no K is stable
        hi, v_hi = lo, v_lo
        while not v_lo.bounded and lo > _K_FLOOR * Ks:
            hi, v_hi = lo, v_lo
            lo /= ratio
            v_lo = verdict(lo)
        if not v_lo.bounded:
            return CriticalStiffnessResult(
                0.0, "simulation", (), f"unbounded already at K = {lo:.4g} N/m: {v_lo.reason}", T,
                loop.delay_in_samples, details={"runs": runs, "horizon_samples": n_samples})
    K = lo
    while hi is None and K < 1e4 * Ks:
        K *= ratio
        v = verdict(K)
        if not v.bounded:
            hi, v_hi = K, v
            break
        lo, v_lo = K, v
    if hi is None:
        return CriticalStiffnessResult(
            math.inf, "simulation", ((0.0, math.inf),),
            f"bounded for every K tried up to {lo:.4g} N/m", T, loop.delay_in_samples,
            details={"runs": runs, "horizon_samples": n_samples})
    while hi / lo - 1 > rtol:
        mid = math.sqrt(lo * hi)
        v = verdict(mid)
        if v.bounded:
            lo, v_lo = mid, v
        else:
            hi, v_hi = mid, v
    assert v_hi is not None                             # set together with hi
    reason = (f"largest K whose simulated free response ({n_samples} samples) stays bounded; "
              f"at K = {lo:.6g}: {v_lo.reason}; at K = {hi:.6g}: {v_hi.reason}")
    return CriticalStiffnessResult(
        lo, "simulation", ((0.0, lo),), reason, T, loop.delay_in_samples,
        details={"runs": runs, "horizon_samples": n_samples, "bracket": [lo, hi],
                 "confidence": min((v_lo.confidence, v_hi.confidence),
                                   key=["low", "medium", "high"].index)})
