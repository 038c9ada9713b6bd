"""The loop as :mod:`hapstab.analysis.nonlinear.limit_cycles` sees it: its frequency responses from
the engine's ZOH model, what it refuses, where the device can rest with an encoder, the
phase crossovers and the describing-function plot's curves."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hapstab.analysis.nonlinear.harmonic import QUANTIZER_OFFSET, Balance
from hapstab.engine.structure import structure_of
from hapstab.engine.zoh import discretize, port_matrices
from hapstab.errors import AnalysisError, ModelError
from hapstab.models.controllers import SpringDamper
from hapstab.models.loops import HapticLoop, require_loop

__all__ = ["loop_parts", "check_loop", "rests", "crossovers", "curves", "LENGTHS", "STEPS_MAX"]

#: Lengths (m) an encoder step, or friction's reach f_c/K, may have: a femtometre to a
#: kilometre (outside, the amplitude scan leaves double precision's comfortable range).
LENGTHS = (1e-15, 1e3)
#: The largest amplitude searched with a quantiser, in steps.
STEPS_MAX = 1e4
#: A rest position within this many steps of an encoder line does not count (it is the
#: line, to rounding).
EDGE = 1e-9
#: The phase crossovers reported: those with the least gain margins.
CROSSOVERS = 6


def loop_parts(loop: HapticLoop) -> tuple[Any, Any, float, float]:
    """C(theta), P(theta), the port's mass and its spring to ground."""
    port = structure_of(loop).ports[0]
    A, B, _ = port_matrices(port)
    Ad, Bd = (a[0] for a in discretize(A, B, np.array([loop.period])))
    q, T, n = A.shape[0], loop.period, loop.delay_samples
    c: SpringDamper = loop.controller                    # type: ignore[assignment]
    eye = np.eye(q)

    def C(theta: np.ndarray) -> np.ndarray:
        z = np.exp(1j * np.atleast_1d(theta))
        M = z[:, None, None] * eye - Ad
        Pd = np.linalg.solve(M, np.broadcast_to(Bd, (z.size, q, 1)))[:, 0, 0]
        return Pd * z ** (-n) * (c.stiffness + c.damping * (1 - 1 / z) / T)

    def P(theta: np.ndarray) -> np.ndarray:
        s = 1j * np.atleast_1d(theta) / T
        M = s[:, None, None] * eye - A
        return np.linalg.solve(M, np.broadcast_to(B, (s.size, q, 1)))[:, 0, 0]

    return C, P, port.device.mass + port.termination.mass, port.termination.stiffness


def check_loop(loop: Any, delta: float, fc: float, quantizer: str, harmonics: Any) -> HapticLoop:
    require_loop(loop)
    if len(loop.port_names) != 1:                # one device: the haptic loop
        raise AnalysisError(f"limit cycles: derived for the haptic loop (hve), not a {loop.kind} "
                            "loop")
    if not loop.controller.admits("eq23"):
        raise AnalysisError("limit cycles: derived for a spring-damper virtual environment "
                            "(SpringDamper), not a general H(z)")
    if loop.fractional_delay:
        raise AnalysisError(f"limit cycles: derived for whole samples of delay; this loop has "
                            f"{loop.delay_in_samples:g} samples")
    if loop.controller.stiffness <= 0:
        raise AnalysisError(f"stiffness = {loop.controller.stiffness:g}: limit cycles need a "
                            "virtual spring K > 0")
    if delta == 0 and fc == 0:
        raise AnalysisError("limit cycles: give resolution_m > 0 or a Coulomb friction > 0 "
                            "(the linear loop has no limit cycles)")
    if quantizer not in QUANTIZER_OFFSET:
        raise ModelError(f"quantizer = {quantizer!r}: allowed: {', '.join(QUANTIZER_OFFSET)}")
    if isinstance(harmonics, bool) or not isinstance(harmonics, (int, np.integer)) \
            or not 1 <= harmonics <= 63:
        raise ModelError(f"harmonics = {harmonics!r}: must be a whole number from 1 to 63")
    lo, hi = LENGTHS
    if delta and not lo <= delta <= hi:
        raise ModelError(f"resolution_m = {delta:g}: must be between {lo:g} m and {hi:g} m")
    scale = fc / loop.controller.stiffness               # where friction matches the spring
    if fc and not lo <= scale <= hi:
        raise ModelError(f"coulomb_friction_N = {fc:g}: f_c/K = {scale:g} m, the length friction "
                         f"holds against the spring, must be between {lo:g} m and {hi:g} m")
    return loop


def rests(bal: Balance) -> str:
    """Where the quantised loop can rest: a position where the spring's pull and the
    controller's force on the reading balance (within friction's f_c) ``"inside a step"``,
    only ``"on a line"`` (a step's edge: the device rests there only if it arrives without
    overshooting it) or ``"nowhere"`` (the spring relaxed just below a floor encoder's line:
    the device must chatter across it, a motion the describing function does not
    describe). Without an operator's spring the device is ``"free in a step"`` unless
    friction covers quantisation (f_c >= K Δ/2, Abbott and Okamura): it coasts between two
    lines and may bounce across them, each crossing sensed late giving energy (seen in the
    simulator at about Δ/2, not described by the describing function)."""
    d, k, K, r, fc = (bal.resolution_m, bal.spring_N_per_m, bal.stiffness_N_per_m, bal.rest_m,
                      bal.friction_N)
    if d == 0:
        return "inside a step"
    if k == 0:      # a whole step of rest positions, and nothing but friction to hold it there
        return "inside a step" if fc >= K * d / 2 else "free in a step"
    sig = QUANTIZER_OFFSET[bal.quantizer]
    j0 = round(k * r / ((k + K) * d))
    found = "nowhere"
    for j in range(j0 - 3, j0 + 4):        # the reading j*d of a resting device, near r
        a, b = ((j - 0.5) * d, (j + 0.5) * d) if sig else (j * d, (j + 1) * d)   # its step
        # |k (x - r) + K j d| <= f_c somewhere in the step: strictly inside, or on its edge
        lo, hi = r - (K * j * d + fc) / k, r - (K * j * d - fc) / k
        if max(lo, a + EDGE * d) <= min(hi, b - EDGE * d):
            return "inside a step"
        if max(lo, a - EDGE * d) <= min(hi, b + EDGE * d):
            found = "on a line"
    return found


def crossovers(C: Any, theta: np.ndarray, T: float) -> tuple[tuple[float, float], ...]:
    """The phase crossovers of C (real and negative): (frequency in Hz, gain margin 1/|C|),
    the :data:`CROSSOVERS` with the least margins, by frequency."""
    from scipy.optimize import brentq

    c = C(theta)
    j = np.flatnonzero((np.sign(c.imag[:-1]) * np.sign(c.imag[1:]) < 0) & (c.real[:-1] < 0))
    out = []
    for i in j:
        t = brentq(lambda x: float(C(np.array([x]))[0].imag), theta[i], theta[i + 1],
                   xtol=1e-15 * theta[i])   # to rounding: the angle is ~1e-16 exact
        out.append((float(t / (2 * math.pi * T)), float(1 / abs(C(np.array([t]))[0].real))))
    cp = C(np.array([math.pi]))[0]
    if cp.real < 0:
        out.append((1 / (2 * T), float(1 / abs(cp.real))))
    return tuple(sorted(sorted(out, key=lambda c: c[1])[:CROSSOVERS]))


def curves(bal: Balance, amps: np.ndarray, N: np.ndarray, theta: np.ndarray
           ) -> dict[str, np.ndarray]:
    """What the describing-function plot draws: the loop the nonlinearity sees and -1/N
    (N the quantiser's describing function at the amplitudes ``amps``).

    Parameters
    ----------
    bal : Balance
        The loop.
    amps, N : array
        Amplitudes (m) and the quantiser's gain at each.
    theta : array
        Angles per sample (rad).

    Returns
    -------
    dict of arrays
        ``theta``, ``loop``, ``amplitude_m``, ``minus_inverse``; with quantisation and
        friction also the balance's terms ``gain`` (N), ``relay`` (4 f_c/(pi A)) and
        ``plant`` (P), from which the figure draws F = 1 + N C + j (4 f_c/(pi A)) P.
    """
    if bal.resolution_m:
        out = {"theta": theta, "loop": bal.controller(theta), "amplitude_m": amps,
               "minus_inverse": -1 / np.where(N > 0, N, np.nan)}
        if bal.friction_N:      # both: the balance itself (F over amplitude and angle)
            out.update(gain=N, relay=4 * bal.friction_N / (math.pi * amps),
                       plant=bal.plant(theta))
        return out
    # friction alone: the loop seen by the relay, j P/(1 + C), against -pi A/(4 f_c)
    return {"theta": theta, "loop": 1j * bal.plant(theta) / (1 + bal.controller(theta)),
            "amplitude_m": amps, "minus_inverse": -math.pi * amps / (4 * bal.friction_N)}
