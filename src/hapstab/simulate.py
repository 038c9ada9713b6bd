"""Time-domain simulation of the sampled-data loops, exact between samples.

The continuous part (device, operator / environment impedance) is discretised
exactly for the zero-order hold (matrix exponential, :mod:`hapstab.engine`); then
come the sampler, the delay line and the discrete controller, as in the paper's
Simulink models of Fig. 2a and Fig. 3. The linear loop is propagated by the exact
recurrence ``s[k+1] = A_cl s[k] + B_ext f[k]``, many samples per matrix product
(block recurrence); with nonlinear elements the loop is stepped sample by sample.

Optional nonlinear elements act at the sampling instants, where a real
controller sees and commands them:

* ``resolution``: the controller sees positions quantised to the encoder step;
* ``wall``: the virtual environment (HVE) pushes only while the (delayed,
  measured) position it sees penetrates ``x > wall``;
* ``saturation``: each actuator force is clipped to +-saturation.

References
----------
The paper, Fig. 2a (HVE), Fig. 3 / eq. (19)-(21) (PEB), eq. (23) (H(z)) and
Section 5 (simulation study).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from .engine import SampledSystem, build, discretize, structure_of
from .errors import AnalysisError, ModelError, check_real
from .growth import BoundednessVerdict, assess
from .models import HapticLoop, SpringDamper, TeleoperationLoop
from .results import CriticalStiffnessResult, jsonable

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
    A : (N, N), B : (N, p), s0 : (N,)
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
        Toe = np.zeros((m, N, m, p))
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
    k = 0
    with np.errstate(over="ignore", invalid="ignore"):
        while k < n_samples:
            blk = Pw @ s
            if forced:
                blk = blk + Toe @ Fb[k // m]
            blk = blk.reshape(m, N)
            take = min(m, n_samples - k)
            S[k + 1:k + 1 + take] = blk[:take]
            s = blk[take - 1]
            k += take
            if not np.all(np.isfinite(s)):
                S[k + 1:] = np.inf
                break
    return S


def _error_selectors(loop: HapticLoop | TeleoperationLoop, sysm: SampledSystem) -> np.ndarray:
    """E (p, N): the controller input of each port, ``e_i = E_i s`` (engine layout:
    registers after the plant, register l of port j holds x_j[k-1-l])."""
    st = structure_of(loop)
    p = len(st.ports)
    depth = [0] * p
    for ch in st.channels:
        for j, _, n in ch.terms:
            depth[j] = max(depth[j], n)
    off = sysm.n_plant + np.concatenate([[0], np.cumsum(depth)]).astype(int)
    E = np.zeros((p, sysm.order))
    for ch in st.channels:
        for j, sgn, n in ch.terms:
            if n == 0:
                E[ch.port] += sgn * sysm.pos[j]
            else:
                E[ch.port, off[j] + n - 1] += sgn
    return E


# ------------------------------------------------------------------ result
@dataclass(frozen=True)
class SimulationResult:
    """A simulated run: time series at the sampling instants (and optionally between).

    Attributes
    ----------
    time : (M+1,) s
    position, velocity : (M+1, p) m, m/s, one column per port (``labels``)
    controller_force : (M+1, p) N
        u[k], computed at t_k and held over [t_k, t_k+1); it acts on the device as -u.
    exogenous_force : (M+1, p) N
        Operator (port 0) / environment (port 1) force held over each sample.
    port_energy : (M+1, p) J
        Energy that has flowed from each device port into the sampled-data
        controller, ``sum u[i] (x[i+1] - x[i])`` (exact: u is held). A passivity
        observer: negative means the controller has delivered net energy.
    exogenous_energy : (M+1, p) J
        Work done by the exogenous forces on each port.
    states : (M+1, N)
        Full closed-loop state (plant, delay registers, controller).
    verdict : BoundednessVerdict
    contact : (M+1,) bool or None
        Wall engaged at each sample (with ``wall``).
    dense_time, dense_position, dense_velocity : arrays or None
        Exact output between samples (``dense`` points per sample).
    """

    time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    controller_force: np.ndarray
    exogenous_force: np.ndarray
    port_energy: np.ndarray
    exogenous_energy: np.ndarray
    states: np.ndarray = field(repr=False)
    verdict: BoundednessVerdict
    labels: tuple[str, ...]
    period: float
    delay_samples: int
    stiffness: float
    nonlinear: dict[str, Any] = field(default_factory=dict)
    contact: np.ndarray | None = field(default=None, repr=False)
    dense_time: np.ndarray | None = field(default=None, repr=False)
    dense_position: np.ndarray | None = field(default=None, repr=False)
    dense_velocity: np.ndarray | None = field(default=None, repr=False)

    @property
    def bounded(self) -> bool:
        return self.verdict.bounded

    def summary(self) -> dict[str, Any]:
        """Scalars: verdict, peaks and final energies per port."""
        out: dict[str, Any] = {"samples": self.time.size - 1, "duration_s": float(self.time[-1]),
                               "period_s": self.period, "delay_samples": self.delay_samples,
                               "stiffness": self.stiffness, "nonlinear": self.nonlinear,
                               **self.verdict.to_dict()}
        for j, lab in enumerate(self.labels):
            out[f"max_abs_position_{lab}"] = float(np.abs(self.position[:, j]).max())
            out[f"max_abs_force_{lab}"] = float(np.abs(self.controller_force[:, j]).max())
            out[f"final_port_energy_{lab}"] = float(self.port_energy[-1, j])
        return jsonable(out)

    def to_dict(self, series: bool = False) -> dict[str, Any]:
        d = self.summary()
        if series:
            d["series"] = {k: jsonable(v) for k, v in self._columns().items()}
        return d

    def _columns(self, dense: bool = False) -> dict[str, np.ndarray]:
        if dense:
            if self.dense_time is None:
                raise AnalysisError("dense output was not requested: simulate(..., dense=m)")
            cols = {"time_s": self.dense_time}
            for j, lab in enumerate(self.labels):
                cols[f"x_{lab}_m"] = self.dense_position[:, j]
                cols[f"v_{lab}_m_per_s"] = self.dense_velocity[:, j]
            return cols
        cols = {"time_s": self.time}
        for j, lab in enumerate(self.labels):
            cols[f"x_{lab}_m"] = self.position[:, j]
            cols[f"v_{lab}_m_per_s"] = self.velocity[:, j]
            cols[f"u_{lab}_N"] = self.controller_force[:, j]
            cols[f"f_ext_{lab}_N"] = self.exogenous_force[:, j]
            cols[f"port_energy_{lab}_J"] = self.port_energy[:, j]
        if self.contact is not None:
            cols["contact"] = self.contact.astype(int)
        return cols

    def to_csv(self, path: str, dense: bool = False) -> None:
        """Write the sampled (or, with ``dense``, the between-sample) series as CSV."""
        cols = self._columns(dense)
        data = np.column_stack(list(cols.values()))
        np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="", fmt="%.17g")

    def plot(self, path: str | None = None) -> Any:
        """Position, controller force and port energy against time (matplotlib figure)."""
        from .plotting import plot_simulation
        return plot_simulation(self, path)


# --------------------------------------------------------------- simulate
def simulate(loop: HapticLoop | TeleoperationLoop, duration: float, *,
             force: ForceSpec = None, environment_force: ForceSpec = None,
             initial_position: float | Sequence[float] = 0.0,
             initial_velocity: float | Sequence[float] = 0.0,
             initial_state: Sequence[float] | None = None,
             wall: float | None = None, saturation: float | None = None,
             resolution: float | None = None, dense: int = 0) -> SimulationResult:
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
    wall : float, optional
        HVE only: the virtual environment acts only while the position it sees
        (delayed, quantised) penetrates ``x > wall``; it then acts on ``x - wall``.
    saturation : float, optional
        Actuator force limit |u| <= saturation (N), each port.
    resolution : float, optional
        Encoder resolution (m): the controller sees ``resolution * round(x / resolution)``.
    dense : int
        If >= 2, also return the exact trajectory at ``dense`` points per sample.

    Returns
    -------
    SimulationResult

    Raises
    ------
    ModelError
        Invalid duration, forces, initial state or nonlinear parameters.

    References
    ----------
    The paper, Fig. 2a, Fig. 3, eq. (19)-(23), Section 5.
    """
    T = loop.period
    dur = check_real("duration", duration, positive=True)
    M = int(round(dur / T))
    if M < 8:
        raise ModelError(f"duration = {duration}: gives {M} samples at T = {T:g} s; need >= 8")
    if M > 50_000_000:
        raise ModelError(f"duration = {duration}: {M} samples is too many (limit 5e7)")
    if not isinstance(dense, (int, np.integer)) or isinstance(dense, bool) or dense < 0:
        raise ModelError(f"dense = {dense!r}: must be a whole number >= 0 (points per sample)")
    haptic = isinstance(loop, HapticLoop)
    if haptic and environment_force is not None:
        raise ModelError("environment_force: a HapticLoop has no environment port; use a TeleoperationLoop")
    if wall is not None and not haptic:
        raise ModelError("wall: the unilateral wall is the HVE's virtual environment; a "
                         "TeleoperationLoop's environment is its impedance (--environment)")
    wall = None if wall is None else check_real("wall", wall)
    sat = None if saturation is None else check_real("saturation", saturation, positive=True)
    res = None if resolution is None else check_real("resolution", resolution, positive=True)

    sysm = build(loop)
    p, N, npl = sysm.n_ports, sysm.order, sysm.n_plant
    A = sysm.closed_loop()[0]
    Fu = sysm.force_matrix()[0]
    t = np.arange(M + 1) * T
    F = np.zeros((M, p))
    F[:, 0] = force_samples(force, t[:-1], "force")
    if p > 1:
        F[:, 1] = force_samples(environment_force, t[:-1], "environment_force")
    pos_idx = np.argmax(sysm.pos, axis=1)
    offset = np.zeros(p)
    if wall is not None:
        offset[0] = wall

    def measured(s: np.ndarray) -> np.ndarray:
        sm = s.copy()
        x = s[pos_idx]
        sm[pos_idx] = (res * np.round(x / res) if res else x) - offset
        return sm

    s0 = _initial_state(sysm, A, initial_position, initial_velocity, initial_state, measured)
    nonlinear = {k: v for k, v in (("wall", wall), ("saturation", sat), ("resolution", res))
                 if v is not None}
    contact = None
    if not nonlinear:
        S = propagate_linear(A, sysm.B_ext[0], s0, F, M)
        with np.errstate(over="ignore", invalid="ignore"):
            U = S @ Fu.T
    else:
        S, U, contact = _step_nonlinear(sysm, A, Fu, s0, F, M, measured, wall is not None,
                                        _error_selectors(loop, sysm)[0], sat)
    X, V = S[:, pos_idx], S[:, pos_idx + 1]
    with np.errstate(over="ignore", invalid="ignore"):
        dX = np.diff(X, axis=0)
        pe = np.vstack([np.zeros(p), np.cumsum(U[:-1] * dX, axis=0)])
        ee = np.vstack([np.zeros(p), np.cumsum(F * dX, axis=0)])
    Fx = np.vstack([F, F[-1:]])
    verdict = assess(S, F, T)
    dt = dx = dv = None
    if dense >= 2 and np.all(np.isfinite(S)):
        dt, dx, dv = _dense(sysm, S, F - U[:-1], T, dense, pos_idx)
    arrays = [t, X, V, U, Fx, pe, ee, S]
    for a in arrays:
        a.setflags(write=False)
    K = float(sysm.stiffness[0])
    return SimulationResult(*arrays, verdict, tuple(sysm.labels), T, loop.delay_samples, K,
                            nonlinear, contact, dt, dx, dv)


def _initial_state(sysm: SampledSystem, A: np.ndarray, x0: Any, v0: Any, full: Any,
                   measured: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    p, N, npl = sysm.n_ports, sysm.order, sysm.n_plant
    if full is not None:
        s = np.asarray(full, float).ravel()
        if s.size != N or not np.all(np.isfinite(s)):
            raise ModelError(f"initial_state: {s.size} values; need {N} finite values "
                             f"(plant {npl}, then delay registers and controller states)")
        return s
    pos_idx = np.argmax(sysm.pos, axis=1)
    s = np.zeros(N)
    for nm, val, idx in (("initial_position", x0, pos_idx), ("initial_velocity", v0, pos_idx + 1)):
        a = np.broadcast_to(np.asarray(val, float).ravel(), (p,)) if np.size(val) in (1, p) else None
        if a is None or not np.all(np.isfinite(a)):
            raise ModelError(f"{nm} = {val!r}: must be one finite number or one per port ({p})")
        s[idx] = a
    # a history at rest: registers and controller states are the fixed point of their
    # own update for the measured initial positions
    sm = measured(s)
    R = A[npl:]
    rhs = R[:, :npl] @ sm[:npl]
    rest = np.linalg.lstsq(np.eye(N - npl) - R[:, npl:], rhs, rcond=None)[0] if N > npl else rhs
    s[npl:] = rest
    return s


def _step_nonlinear(sysm: SampledSystem, A: np.ndarray, Fu: np.ndarray, s0: np.ndarray,
                    F: np.ndarray, M: int, measured: Callable[[np.ndarray], np.ndarray],
                    has_wall: bool, E0: np.ndarray, sat: float | None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Sample-by-sample loop with the nonlinear elements at the sampling instants.

    The plant is stepped with its exact ZOH matrices and the applied force; the
    delay registers and controller states see the plant only through the measured
    positions, so they are updated from the measured state."""
    npl = sysm.n_plant
    Ad, Bd = discretize(sysm.Ac, sysm.Bc, np.array([sysm.periods[0]]))
    Ad, Bd = Ad[0], Bd[0]
    R = A[npl:]
    S = np.empty((M + 1, s0.size))
    U = np.empty((M + 1, Fu.shape[0]))
    C = np.zeros(M + 1, bool) if has_wall else None
    s = s0.copy()
    for k in range(M + 1):
        S[k] = s
        sm = measured(s)
        u = Fu @ sm
        if has_wall:
            c = (E0 @ sm) > 0
            C[k] = c
            if not c:
                u[0] = 0.0
        if sat is not None:
            u = np.clip(u, -sat, sat)
        U[k] = u
        if k == M:
            break
        nxt = np.empty_like(s)
        nxt[:npl] = Ad @ s[:npl] + Bd @ (F[k] - u)
        nxt[npl:] = R @ sm
        s = nxt
        if not np.all(np.isfinite(s)):
            S[k + 1:] = np.inf
            U[k + 1:] = np.nan
            break
    return S, U, C


def _dense(sysm: SampledSystem, S: np.ndarray, G: np.ndarray, T: float, m: int,
           pos_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact plant trajectory at m points per sample: the held net force G[k] acts
    on the plant from its sampled state."""
    npl = sysm.n_plant
    taus = T * np.arange(1, m) / m
    Adt, Bdt = discretize(sysm.Ac, sysm.Bc, taus)
    Pk = S[:-1, :npl]
    inner = np.einsum("inj,kj->kin", Adt, Pk) + np.einsum("inj,kj->kin", Bdt, G)
    M = Pk.shape[0]
    allp = np.concatenate([Pk[:, None, :], inner], axis=1).reshape(M * m, npl)
    allp = np.vstack([allp, S[-1:, :npl]])
    t = np.concatenate([(np.arange(M)[:, None] * T + np.r_[0.0, taus][None, :]).ravel(), [M * T]])
    return t, allp[:, pos_idx], allp[:, pos_idx + 1]


# ------------------------------------------------- the paper's K_max procedure
def _stiffness_scale(loop: HapticLoop | TeleoperationLoop) -> float:
    """m/T^2 of the lightest port: the stiffness that moves a mass by its own
    sample-scale motion, the natural unit of K."""
    st = structure_of(loop)
    m = min(pt.device.mass + pt.termination.mass for pt in st.ports)
    return m / loop.period ** 2


def critical_stiffness_simulation(loop: HapticLoop | TeleoperationLoop, *,
                                  n_samples: int = 2000, window: int = 500, rtol: float = 1e-4,
                                  seed: int = 0, ratio: float = 4.0) -> CriticalStiffnessResult:
    """The paper's procedure: the largest K for which the simulated loop stays bounded.

    K is raised from ``1e-6 m/T^2`` by factors of ``ratio`` until the simulated
    free response (from a seeded random initial state, which excites every mode)
    is unbounded, then the last bounded / first unbounded pair is bisected in
    log K to relative width ``rtol``. Each verdict is :func:`hapstab.growth.assess`
    on ``n_samples`` samples (observed explosion, else the fitted growth rate).

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
    if not v_lo.bounded:
        return CriticalStiffnessResult(
            0.0, "simulation", (), f"unbounded already at K = {lo:.4g} N/m: {v_lo.reason}", T,
            loop.delay_samples, details={"runs": runs, "horizon_samples": n_samples})
    v_hi = None
    K = lo
    while K < 1e4 * Ks:
        K *= ratio
        v = verdict(K)
        if not v.bounded:
            hi, v_hi = K, v
            break
        lo, v_lo = K, v
    if hi is None:
        return CriticalStiffnessResult(
            math.inf, "simulation", ((0.0, math.inf),),
            f"bounded for every K tried up to {lo:.4g} N/m", T, loop.delay_samples,
            details={"runs": runs, "horizon_samples": n_samples})
    while hi / lo - 1 > rtol:
        mid = math.sqrt(lo * hi)
        v = verdict(mid)
        if v.bounded:
            lo, v_lo = mid, v
        else:
            hi, v_hi = mid, v
    reason = (f"largest K whose simulated free response ({n_samples} samples) stays bounded; "
              f"at K = {lo:.6g}: {v_lo.reason}; at K = {hi:.6g}: {v_hi.reason}")
    return CriticalStiffnessResult(
        lo, "simulation", ((0.0, lo),), reason, T, loop.delay_samples,
        details={"runs": runs, "horizon_samples": n_samples, "bracket": [lo, hi],
                 "confidence": min((v_lo.confidence, v_hi.confidence),
                                   key=["low", "medium", "high"].index)})
