"""Transparency of the sampled-data PEB teleoperator: what the operator feels, and how
well the slave follows, over frequency.

The two-port. The paper cuts the loop at its terminations (eq. 30 generalised,
:mod:`hapstab.analysis.teleoperation.twoport`): the device side ``P(z) = diag(b) + Hc(z) X(z)`` takes
the port velocities to the forces the terminations apply on the devices (no masses: each
device's mass is on its termination's side). For the operator the slave's mass belongs
to the environment and the master's is pushed along with the rest, so the teleoperator
between the operator and the environment has the impedance matrix

    Z(w) = P(e^{jwT}) + jw diag(m_m, m_s),   [F_h; -F_e] = Z [V_m; V_s],

with F_h the operator's force on the master and F_e the force the slave applies on the
environment (F_e = Z_e V_s), velocities positive the same way for both devices. Its
hybrid matrix (Hannaford 1989) is

    [F_h; -V_s] = H [V_m; F_e],
    h11 = z11 - z12 z21 / z22,  h12 = -z12 / z22,  h21 = z21 / z22,  h22 = 1 / z22.

In the orientation of Hashtrudi-Zaad and Salcudean, ``[F_h; F_e] = Z' [V_m; -V_s]``,
z'12 = -z12 and z'21 = -z21, and these are the textbook h12 = z'12 / z'22,
h21 = -z'21 / z'22. An ideal teleoperator has H = [[0, 1], [-1, 0]]; PEB tends to
h21 = -1 and h12 = K_m / K_s as w -> 0.

What the operator feels with an environment Z_e is

    Z_felt = m_m jw + Z_t,  Z_t = p11 - p12 p21 / (p22 + m_s jw + Z_e)
           = h11 - h12 h21 Z_e / (1 + h22 Z_e),

between free motion (Z_e = 0: h11) and a rigid environment (Z_e -> inf: m_m jw + p11),
the teleoperator's Z-width at each frequency. The slave tracks the master with
``X_s / X_m = V_s / V_m = -p21 / (p22 + m_s jw + Z_e)``; the tracking error is
``1 - X_s / X_m``. The static (w -> 0) felt stiffness ``lim jw Z_felt`` and tracking
follow from Hc(1) and the environment's spring k_e (jw X(e^{jwT}) -> 1 for every X):
``K_felt = Hc11 - Hc12 Hc21 / (Hc22 + k_e)`` and ``X_s / X_m = -Hc21 / (Hc22 + k_e)``
(PEB with spring-dampers: K_m k_e / (K_s + k_e) and K_s / (K_s + k_e)).

An approximation, said plainly: this is the usual frequency-domain transparency
picture. The controllers and delays are evaluated at z = e^{jwT} and the hold through
the paper's X(z) (forward, backward or Tustin, as in the circle criterion), while the
masses and the environment are evaluated at s = jw, the fundamental frequency: the
sampled-data loop's aliased components (w + 2 pi k / T) are ignored. It is accurate for
w well below the Nyquist frequency pi/T and, like X(z), only indicative near it: against
the exact loop in time (a held sinusoidal force, T = 1 ms, n = 2, a test), the forward
approximation's Z_felt is within 1e-4 at 5 Hz, 1.2e-3 at 20 Hz, 8e-3 at 50 Hz and 3.5e-2
at 100 Hz; backward and Tustin are off by 1.8e-2 and 9e-3 already at 5 Hz.

References
----------
B. Hannaford, "A design framework for teleoperators with kinesthetic feedback", IEEE
Trans. Robot. Autom. 5(4), 1989; K. Hashtrudi-Zaad and S. E. Salcudean, "Analysis of
control architectures for teleoperation systems with impedance/admittance master and
slave manipulators", Int. J. Robotics Research 20(6), 2001; the paper, eq. (20), (30).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.analysis.conditions.device_terms import approximation_name, integrator_response
from hapstab.engine.device_side import DeviceSide, device_side
from hapstab.errors import AnalysisError, ModelError, check_reals
from hapstab.models.loops import TeleoperationLoop, require_loop
from hapstab.models.parts import Impedance
from hapstab.results import Result, jsonable, write_csv

__all__ = ["transparency", "TransparencyResult"]

#: The default grid spans this many decades below the Nyquist frequency 1/(2T).
DECADES = 4

#: Points of the default grid: at least MIN_POINTS, and POINTS_PER_OSCILLATION per
#: oscillation of the delays' phase over (0, pi] (8 points per period of the round trip's
#: e^{-2jwnT} where the log grid is sparsest, at the Nyquist end), at most MAX_POINTS
#: (the curves are then only sampled near the Nyquist frequency for very long delays).
MIN_POINTS, POINTS_PER_OSCILLATION, MAX_POINTS = 400, 40, 20_000

#: At most this many frequencies (each a 2x2 complex matrix, several times over).
MAX_FREQUENCIES = 1_000_000

#: A frequency this close above the Nyquist frequency (relative) is the Nyquist
#: frequency: 1/(2T) computed from a rate in Hz may round either way.
NYQUIST_SLACK = 1e-12


def _side(loop: Any) -> DeviceSide:
    require_loop(loop)
    if len(loop.port_names) != 2:                # a master and a slave
        raise AnalysisError(f"loop: transparency is a teleoperator's (master and slave); got "
                            f"a loop of kind {loop.kind!r}; allowed: 'peb' (TeleoperationLoop) "
                            "or '4ch' (FourChannelLoop)")
    fwd, bwd = loop.forward_delay_in_samples, loop.backward_delay_in_samples
    if fwd != int(fwd) or bwd != int(bwd):
        raise AnalysisError(f"transparency: derived for whole-sample delays (t_d = nT); this "
                            f"loop has delay forward {fwd:g} and delay backward {bwd:g} samples")
    side = device_side(loop, "transparency", forces=True)   # any controllers it supports
    side.check_forces("transparency")
    return side


def _frequencies(frequencies_hz: Any, side: DeviceSide) -> np.ndarray:
    """The grid in Hz: the default (log-spaced, see :data:`DECADES`) or the one given,
    checked, sorted and without repeats."""
    nyquist = 1.0 / (2.0 * side.period_s)
    if frequencies_hz is None:
        count = min(max(MIN_POINTS, POINTS_PER_OSCILLATION * side.oscillations), MAX_POINTS)
        return np.geomspace(nyquist * 10.0 ** -DECADES, nyquist, count)
    f = check_reals("frequencies_hz", frequencies_hz)
    if f.size == 0 or f.size > MAX_FREQUENCIES:
        raise ModelError(f"frequencies_hz: {f.size} values; allowed: 1 to {MAX_FREQUENCIES}")
    if not np.all(np.isfinite(f) & (f > 0)):
        raise ModelError(f"frequencies_hz = {frequencies_hz!r:.60}: every value must be finite "
                         "and > 0 (Hz)")
    if f.max() > nyquist * (1 + NYQUIST_SLACK):
        raise AnalysisError(f"frequencies_hz: {f.max():g} Hz is above the Nyquist frequency "
                            f"1/(2T) = {nyquist:g} Hz; allowed: (0, {nyquist:g}] Hz")
    return np.unique(np.minimum(f, nyquist))


def _impedance(side: DeviceSide, a: str, theta: np.ndarray) -> np.ndarray:
    """P(e^{j theta}) = diag(b) + Hc X, shape (N, 2, 2) (eq. 30 generalised); with force
    channels (I - G_f)^-1 (P + jw M) - jw M (:meth:`DeviceSide.with_forces`)."""
    X = integrator_response(a, theta, side.period_s)[:, None, None]
    return side.with_forces(np.diag(side.damping)[None] + X * side.controller_matrix(theta), theta)


def _hybrid(Z: np.ndarray) -> np.ndarray:
    """H of the impedance matrix Z (N, 2, 2) in the module's orientation."""
    z11, z12, z21, z22 = Z[:, 0, 0], Z[:, 0, 1], Z[:, 1, 0], Z[:, 1, 1]
    H = np.empty_like(Z)
    H[:, 0, 0] = z11 - z12 * z21 / z22
    H[:, 0, 1] = -z12 / z22
    H[:, 1, 0] = z21 / z22
    H[:, 1, 1] = 1.0 / z22
    return H


def _terminated(P: np.ndarray, s: np.ndarray, masses: tuple[float, float],
                Ze: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Z_felt, X_s / X_m) with the environment Ze at each s = jw; an infinite Ze (a pole
    of the environment on the axis, or rigid) clamps the slave."""
    rigid = ~np.isfinite(Ze)
    slave = P[:, 1, 1] + masses[1] * s + np.where(rigid, 0.0, Ze)
    felt = masses[0] * s + P[:, 0, 0] - np.where(rigid, 0.0, P[:, 0, 1] * P[:, 1, 0] / slave)
    return felt, np.where(rigid, 0.0, -P[:, 1, 0] / slave)


def _static(side: DeviceSide, k_e: float) -> tuple[float, float]:
    """(felt stiffness N/m, tracking) as w -> 0 against a spring k_e (inf: rigid), from
    Hc(1); NaN where a controller's DC gain is not finite or the slave is held by nothing."""
    # the static stiffness: (I - G_f(1))^-1 Hc(1) with force channels (no mass at DC)
    H = side.with_forces(side.controller_matrix(np.zeros(1)), np.zeros(1), "K")[0]
    if math.isinf(k_e):
        return float(H[0, 0].real), 0.0
    den = H[1, 1] + k_e
    if not (np.all(np.isfinite(H)) and den != 0):
        return math.nan, math.nan
    return float((H[0, 0] - H[0, 1] * H[1, 0] / den).real), float((-H[1, 0] / den).real)


@dataclass(frozen=True)
class TransparencyResult(Result):
    """The teleoperator's transparency over frequency (see the module notes for the model).

    Complex values are ``{"re": ..., "im": ...}`` in :meth:`to_dict` (the one format of
    :func:`hapstab.results.jsonable`) and ``_re``/``_im`` column pairs in :meth:`to_csv`.

    Attributes
    ----------
    frequencies_hz : (N,) array
        The grid, in (0, 1/(2T)] Hz.
    impedance : (N, 2, 2) complex array
        P(e^{jwT}) = diag(b) + Hc X of eq. (30), N*s/m (device side, no masses).
    hybrid : (N, 2, 2) complex array
        H of Z = P + jw diag(m_m, m_s): [F_h; -V_s] = H [V_m; F_e]. h11 in N*s/m, h12 and
        h21 dimensionless, h22 in m/(N*s).
    felt_free, felt_environment, felt_rigid : (N,) complex arrays
        Z_felt = F_h / V_m in N*s/m in free motion, with the environment, against a
        rigid environment.
    tracking : (N,) complex array
        X_s / X_m with the environment.
    felt_stiffness_free, felt_stiffness_environment, felt_stiffness_rigid : float
        lim_{w -> 0} jw Z_felt in N/m (NaN where it is undefined).
    static_tracking : float
        X_s / X_m as w -> 0 with the environment.
    environment : Impedance
        The environment used.
    period_s : float
        T in s.
    delay_samples : (int, int)
        Master -> slave and slave -> master delays in whole samples.
    approximation : str
        X(z).
    masses_kg : (float, float)
        m_m and m_s.
    """

    frequencies_hz: np.ndarray = field(repr=False)
    impedance: np.ndarray = field(repr=False)
    hybrid: np.ndarray = field(repr=False)
    felt_free: np.ndarray = field(repr=False)
    felt_environment: np.ndarray = field(repr=False)
    felt_rigid: np.ndarray = field(repr=False)
    tracking: np.ndarray = field(repr=False)
    felt_stiffness_free: float
    felt_stiffness_environment: float
    felt_stiffness_rigid: float
    static_tracking: float
    environment: Impedance
    period_s: float
    delay_samples: tuple[int, int]
    approximation: str
    masses_kg: tuple[float, float]

    @property
    def frequencies_rad_s(self) -> np.ndarray:
        """The grid in rad/s."""
        return 2 * np.pi * self.frequencies_hz

    @property
    def tracking_error(self) -> np.ndarray:
        """1 - X_s / X_m with the environment."""
        return 1.0 - self.tracking

    @property
    def z_width(self) -> np.ndarray:
        """|Z_felt rigid| / |Z_felt free| at each frequency: the span of impedances the
        operator can feel through the teleoperator."""
        with np.errstate(all="ignore"):
            return np.abs(self.felt_rigid) / np.abs(self.felt_free)

    def to_dict(self) -> dict[str, Any]:
        def entries(M: np.ndarray, name: str, units: tuple[str, ...]) -> dict[str, Any]:
            return {f"{name}{i + 1}{j + 1}{units[2 * i + j]}": M[:, i, j]
                    for i in range(2) for j in range(2)}

        return jsonable({
            "period_s": self.period_s, "delay_forward_samples": float(self.delay_samples[0]),
            "delay_backward_samples": float(self.delay_samples[1]),
            "approximation": self.approximation, "environment": self.environment.to_dict(),
            "felt_stiffness_N_per_m": {"free": self.felt_stiffness_free,
                                       "environment": self.felt_stiffness_environment,
                                       "rigid": self.felt_stiffness_rigid},
            "static_tracking": self.static_tracking,
            "frequencies_hz": self.frequencies_hz,
            "felt_impedance_N_s_per_m": {"free": self.felt_free,
                                         "environment": self.felt_environment,
                                         "rigid": self.felt_rigid},
            "tracking": self.tracking, "tracking_error": self.tracking_error,
            "hybrid": entries(self.hybrid, "h", ("_N_s_per_m", "", "", "_m_per_N_s")),
            "impedance_N_s_per_m": entries(self.impedance, "p", ("",) * 4)})

    def to_csv(self, path: Any) -> None:
        """One row per frequency: frequency_hz, then ``_re`` and ``_im`` of the felt
        impedance (free, environment, rigid; N*s/m), the tracking X_s/X_m and h11..h22.

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        cols = {"felt_free_N_s_per_m": self.felt_free,
                "felt_environment_N_s_per_m": self.felt_environment,
                "felt_rigid_N_s_per_m": self.felt_rigid, "tracking": self.tracking,
                **{f"h{i + 1}{j + 1}": self.hybrid[:, i, j] for i in range(2) for j in range(2)}}
        header = ["frequency_hz"] + [f"{k}_{p}" for k in cols for p in ("re", "im")]
        parts = [self.frequencies_hz] + [c for v in cols.values() for c in (v.real, v.imag)]
        write_csv(path, header, zip(*parts, strict=True))

    def plot(self, ax: Any = None) -> Any:
        from hapstab.plotting import plot_transparency
        return plot_transparency(self, ax)


def transparency(loop: TeleoperationLoop, approximation: str = "forward",
                 frequencies_hz: Any = None, environment: Any = None) -> TransparencyResult:
    """The impedance the operator feels and the slave's position tracking, over frequency.

    Parameters
    ----------
    loop : TeleoperationLoop
        PEB with whole-sample delays (equal or not both ways) and any controllers the
        device side supports (spring-dampers or :class:`~hapstab.models.DiscreteController`);
        its operator does not enter (it is what feels).
    approximation : {"forward", "backward", "tustin"}
        X(z), the approximation of the hold, as in the circle criterion.
    frequencies_hz : float or sequence of float, optional
        Frequencies in Hz, in (0, 1/(2T)] (sorted, repeats dropped). Default: log-spaced
        over :data:`DECADES` decades up to the Nyquist frequency 1/(2T).
    environment : Impedance, str or (num, den), optional
        Z_e(s) on the slave (default: the loop's own).

    Returns
    -------
    TransparencyResult
        The two-port P, its hybrid matrix H (with the masses), Z_felt in free motion, with
        the environment and against a rigid one, X_s/X_m, and their w -> 0 limits.

    Raises
    ------
    ArgumentTypeError
        ``loop`` is not a loop.
    AnalysisError
        A haptic loop, a fractional delay, an unknown ``approximation``, or a frequency
        above the Nyquist frequency.
    ModelError
        ``frequencies_hz`` not numbers, none, NaN, infinite or <= 0; an ``environment``
        that is not an impedance.

    References
    ----------
    Hannaford 1989; Hashtrudi-Zaad and Salcudean 2001 (see the module docstring).
    """
    side = _side(loop)
    a = approximation_name(approximation)
    env = loop.environment if environment is None else Impedance.from_any(environment,
                                                                          "environment")
    f = _frequencies(frequencies_hz, side)
    T = side.period_s
    w = 2 * np.pi * f
    s = 1j * w
    masses = (float(loop.master.mass), float(loop.slave.mass))
    with np.errstate(all="ignore"):     # a pole of Z_e on the axis, or overflow: inf / NaN
        P = _impedance(side, a, w * T)
        Z = P + s[:, None, None] * np.diag(masses)[None]
        H = _hybrid(Z)
        Ze = np.asarray(env(s), complex)
        felt, track = _terminated(P, s, masses, Ze)
        free = _terminated(P, s, masses, np.zeros_like(s))[0]
        rigid = _terminated(P, s, masses, np.full_like(s, np.inf))[0]
        k_free, _ = _static(side, 0.0)
        k_env, x_env = _static(side, env.stiffness)
        k_rigid, _ = _static(side, math.inf)
    delays = (round(loop.forward_delay_in_samples), round(loop.backward_delay_in_samples))
    return TransparencyResult(f, P, H, free, felt, rigid, track, k_free, k_env, k_rigid,
                              x_env, env, T, delays, a, masses)
