"""Describing functions and harmonic balance of the haptic loop's two nonlinearities: the
encoder's quantiser (on the sampled position) and Coulomb friction (a relay on the
device's velocity), for :mod:`hapstab.analysis.nonlinear.limit_cycles`.

Both are *staircases*: piecewise-constant functions of their input with jumps at
thresholds (the encoder's lines; zero velocity). For an input that is a trigonometric
polynomial, ``x(phi) = x0 + Re sum_k X_k e^{jk phi}``, the output is piecewise constant
in phi between the instants where x crosses a threshold, so its Fourier coefficients are
exact sums over those instants (:func:`staircase_harmonics`): no sampling of the output,
and coefficients that vary smoothly with the input's, which Newton's method needs.

* Quantiser with step Δ: thresholds ``(j + sigma) Δ`` for every integer j, sigma = 1/2
  for the nearest multiple (ties away from zero, as the simulator) and sigma = 0 for the
  encoder's count ``Δ floor(x/Δ)``; so floor is nearest shifted by Δ/2 at its input, and
  its limit cycles sit about Δ/2 off centre (a bias the DC balance finds, not assumes).
  For ``x0 + A sin`` (:func:`quantizer_describing_function`) the first harmonic gain is
  ``N1 = (2Δ/(pi A)) sum_j sqrt(1 - s_j^2)`` and the mean output
  ``q(x0 - A) + Δ sum_j (1/2 - arcsin(s_j)/pi)``, ``s_j = (c_j - x0)/A`` over the
  thresholds c_j within the swing; at x0 = 0 (nearest) this is the textbook
  ``(4Δ/(pi A)) sum_i sqrt(1 - ((2i - 1)Δ/(2A))^2)``, at most 4/pi (at A = Δ/sqrt 2).
* Coulomb friction f_c sign(v): the relay, ``4 f_c/(pi V)`` for a velocity amplitude V.

References
----------
A. Gelb and W. E. Vander Velde, *Multiple-Input Describing Functions and Nonlinear
System Design*, McGraw-Hill, 1968 (the quantiser's and the relay's describing functions,
dual-input with a bias); J.-J. E. Slotine and W. Li, *Applied Nonlinear Control*,
Prentice Hall, 1991, ch. 5 (harmonic balance, Loeb's criterion).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from hapstab.models.parts import quantize

__all__ = ["QUANTIZER_OFFSET", "quantize", "quantizer_describing_function",
           "staircase_harmonics", "Balance", "solve_balance", "waveform", "fundamental_residual",
           "loeb_stable"]

#: Where a quantiser's thresholds lie, in steps: (j + offset) Δ.
QUANTIZER_OFFSET = {"floor": 0.0, "nearest": 0.5}

#: The residual returned for unknowns outside the model (an angle outside (0, pi], a
#: non-finite value): far larger than any residual near a cycle, so the solver steps back.
OUTSIDE = 1e3
#: Points per period on which crossings are first bracketed (then polished by Newton's
#: method): enough for trigonometric polynomials of a few tens of harmonics.
GRID = 1024


def quantizer_describing_function(amplitude: float, offset: float, delta: float,
                                  quantizer: str) -> tuple[float, float]:
    """First-harmonic gain and mean output of the quantiser for ``offset + A sin``.

    Parameters
    ----------
    amplitude : float
        A in m (> 0).
    offset : float
        x0 in m.
    delta : float
        Δ in m.
    quantizer : {"floor", "nearest"}
        Which reading.

    Returns
    -------
    (float, float)
        N1 (dimensionless) and the mean output (m).
    """
    A, x0, sig = float(amplitude), float(offset), QUANTIZER_OFFSET[quantizer]
    first, last = math.ceil((x0 - A) / delta - sig), math.floor((x0 + A) / delta - sig)
    low = float(quantize(np.array(x0 - A), delta, quantizer))    # the encoder's reading
    if last - first < FEW:
        # the same terms summed in the same order as np.sum does below 8 (one by one)
        s = [v for v in (((j + sig) * delta - x0) / A for j in range(first, last + 1))
             if abs(v) < 1]
        roots = asins = 0.0
        for v in s:
            roots += math.sqrt(1 - v * v)
            asins += 0.5 - math.asin(v) / math.pi
        return 2 * delta / (math.pi * A) * roots, low + delta * asins
    sa = ((np.arange(first, last + 1) + sig) * delta - x0) / A
    sa = sa[np.abs(sa) < 1]
    n1 = 2 * delta / (math.pi * A) * float(np.sum(np.sqrt(1 - sa * sa)))
    return n1, low + delta * float(np.sum(0.5 - np.arcsin(sa) / math.pi))


#: Below this many thresholds in the swing the describing function is summed in Python
#: (a scalar call is ~10x cheaper than through numpy's small arrays; the brentq of the
#: cycle's mean calls it ~40 times per amplitude): a choice of speed, not a tolerance.
FEW = 8


@lru_cache(maxsize=16)
def _basis(H: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    phi = np.linspace(0.0, 2 * math.pi, GRID, endpoint=False)
    k = np.arange(1, H + 1)
    return phi, k, np.exp(1j * np.outer(phi, k))


def waveform(x0: float, X: np.ndarray, phi: np.ndarray, derivative: int = 0) -> np.ndarray:
    """``x0 + Re sum_k (jk)^d X_k e^{jk phi}`` (d = ``derivative``) at the angles ``phi``.

    Parameters
    ----------
    x0 : float
        The mean (used for d = 0 only).
    X : (H,) complex array
        One-sided complex amplitudes of harmonics 1..H.
    phi : array
        Angles in rad (one period is 2 pi).
    derivative : int
        Order of the derivative with respect to phi.

    Returns
    -------
    array
    """
    k = np.arange(1, len(X) + 1)
    E = np.exp(1j * np.outer(np.atleast_1d(phi), k)) * (1j * k) ** derivative
    return (x0 if derivative == 0 else 0.0) + _dot(E, np.asarray(X, complex)).real


def _dot(E: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``E @ X`` without BLAS: for these small products a threaded BLAS on a busy machine
    spends milliseconds in thread hand-over where einsum's loop takes microseconds."""
    return np.einsum("ij,j->i", E, X)


def _on_grid(x0: float, X: np.ndarray) -> np.ndarray:
    """The waveform on the grid of :data:`GRID` angles."""
    return x0 + _dot(_basis(len(X))[2], X).real


def _crossings(x0: float, X: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Every angle in [0, 2 pi) where the waveform crosses one of ``levels``: bracketed on
    the grid, then three Newton steps kept inside their bracket (all levels at once, in
    chunks of :data:`LEVELS` levels)."""
    phi, k, _ = _basis(len(X))
    x = _on_grid(x0, X)
    h = phi[1]
    levels = np.asarray(levels, float)
    # a level at or above the top, or below the bottom, is never crossed
    levels = levels[(levels >= x.min()) & (levels < x.max())]
    out = [np.zeros(0)]
    for start in range(0, levels.size, LEVELS):
        c_all = levels[start:start + LEVELS]
        s = x[None, :] - c_all[:, None]
        up = s > 0
        li, i = np.nonzero(up != np.roll(up, -1, axis=1))
        s0, s1, c = s[li, i], s[li, (i + 1) % GRID], c_all[li]
        t = phi[i] + h * np.where(s0 != s1, s0 / np.where(s0 != s1, s0 - s1, 1.0), 0.5)
        for _ in range(3):
            e = np.exp(1j * np.outer(t, k))
            f = _dot(e, X).real + x0 - c
            d = _dot(e * (1j * k), X)
            t = np.clip(t - np.divide(f, d.real, out=np.zeros_like(f), where=d.real != 0),
                        phi[i], phi[i] + h)
        out.append(t % (2 * math.pi))
    return np.sort(np.concatenate(out))


#: Levels bracketed together in :func:`_crossings` (memory: LEVELS x GRID values).
LEVELS = 256


def staircase_harmonics(x0: float, X: np.ndarray, levels: np.ndarray,
                        output: Callable[[np.ndarray], np.ndarray]) -> tuple[float, np.ndarray]:
    """Mean and harmonics 1..H of ``output(x(phi))`` for a staircase ``output`` whose jumps
    lie at ``levels``, x the trigonometric polynomial (``x0``, ``X``).

    Parameters
    ----------
    x0 : float
        The input's mean.
    X : (H,) complex array
        The input's harmonics.
    levels : array
        The thresholds at which ``output`` jumps (those outside the swing are ignored).
    output : callable
        The staircase, vectorised.

    Returns
    -------
    (float, (H,) complex array)
        The mean output and its one-sided complex harmonics
        ``Q_k = (1/pi) int output e^{-jk phi} d phi``.
    """
    X = np.asarray(X, complex)
    H = len(X)
    cut = _crossings(x0, X, levels)
    if cut.size == 0:
        return float(output(np.array([waveform(x0, X, np.zeros(1))[0]]))[0]), np.zeros(H, complex)
    bounds = np.concatenate([cut, [cut[0] + 2 * math.pi]])
    lv = output(waveform(x0, X, (bounds[:-1] + bounds[1:]) / 2))
    k = np.arange(1, H + 1)
    ea, eb = np.exp(-1j * np.outer(bounds[:-1], k)), np.exp(-1j * np.outer(bounds[1:], k))
    Q = (lv[:, None] * (eb - ea) / (-1j * k)).sum(axis=0) / math.pi
    return float(np.sum(lv * np.diff(bounds)) / (2 * math.pi)), Q


@dataclass(frozen=True)
class Balance:
    """The loop as harmonic balance sees it (HVE, whole-sample delay, spring-damper).

    Parameters
    ----------
    controller : callable
        ``C(theta)``: the sampled position's response to what the quantiser reads, through
        the delayed controller, the hold and the ZOH-discretised port (the loop the
        quantiser sees, exact at the samples), at theta = w T.
    plant : callable
        ``P(theta)``: the port's continuous position response to a force at w = theta/T
        (how friction, a continuous force, moves it; aliases neglected).
    spring_N_per_m : float
        The port's spring to ground k (the operator's).
    stiffness_N_per_m : float
        K.
    resolution_m : float
        Δ (0: no quantiser, the controller reads the position).
    quantizer : str
        ``"floor"`` or ``"nearest"``.
    friction_N : float
        f_c (0: none).
    rest_m : float
        Where the spring to ground is relaxed (m): the DC balance is
        ``k (x0 - rest) + K q0 + f0 = 0``.
    """

    controller: Callable[[np.ndarray], np.ndarray]
    plant: Callable[[np.ndarray], np.ndarray]
    spring_N_per_m: float
    stiffness_N_per_m: float
    resolution_m: float
    quantizer: str
    friction_N: float
    rest_m: float = 0.0

    def read(self, x0: float, X: np.ndarray) -> tuple[float, np.ndarray]:
        """Mean and harmonics of what the controller reads (quantised or not)."""
        if self.resolution_m == 0:
            return x0, np.asarray(X, complex)
        d, sig = self.resolution_m, QUANTIZER_OFFSET[self.quantizer]
        w = _on_grid(x0, np.asarray(X, complex))
        j = np.arange(math.floor(w.min() / d - sig), math.ceil(w.max() / d - sig) + 1)
        return staircase_harmonics(x0, X, (j + sig) * d,
                                   lambda x: quantize(x, d, self.quantizer))

    def friction(self, X: np.ndarray) -> tuple[float, np.ndarray]:
        """Mean and harmonics of the friction force f_c sign(v) (pure sliding)."""
        if self.friction_N == 0:
            return 0.0, np.zeros(len(X), complex)
        k = np.arange(1, len(X) + 1)
        fc = self.friction_N
        return staircase_harmonics(0.0, 1j * k * np.asarray(X), np.zeros(1),
                                   lambda v: fc * np.sign(v))

    def residual(self, theta: float, x0: float, X: np.ndarray) -> np.ndarray:
        """Harmonic balance, DC first, in m: ``X_k + C Q_k + P F_k`` for k = 1..H."""
        q0, Q = self.read(x0, X)
        f0, F = self.friction(X)
        th = theta * np.arange(1, len(X) + 1)
        k, K = self.spring_N_per_m, self.stiffness_N_per_m
        r = np.asarray(X) + self.controller(th) * Q + self.plant(th) * F
        return np.concatenate([[(k * (x0 - self.rest_m) + K * q0 + f0) / (k + K)], r])


def solve_balance(bal: Balance, theta: float, x0: float, X: np.ndarray, scale: float
                  ) -> tuple[bool, float, float, np.ndarray, float]:
    """Newton-type solution (MINPACK's hybrid method) of the balance with ``len(X)``
    harmonics from a start; the fundamental is kept real (it fixes the phase).

    Parameters
    ----------
    bal : Balance
        The loop.
    theta, x0 : float
        Start: angle per sample (rad) and mean (m).
    X : (H,) complex array
        Start harmonics (X[0] real).
    scale : float
        A length (m) the unknowns are measured in.

    Returns
    -------
    (converged, theta, x0, X, residual)
        ``residual`` is the largest equation's, relative to ``scale``.
    """
    from scipy.optimize import root

    H = len(X)

    def unpack(p: np.ndarray) -> tuple[float, float, np.ndarray]:
        Xc = np.zeros(H, complex)
        Xc[0] = p[2] * scale
        Xc[1:] = (p[3::2] + 1j * p[4::2]) * scale
        return p[0] * theta, p[1] * scale, Xc

    def res(p: np.ndarray) -> np.ndarray:
        th, m, Xc = unpack(p)
        if not (0 < th <= math.pi and np.all(np.isfinite(p)) and _near(p[2:])):
            return np.full(p.size, OUTSIDE)      # a step out of (0, pi] or far: pushed back
        r = bal.residual(th, m, Xc) / scale
        return np.concatenate([r[:1].real, np.column_stack([r[1:].real, r[1:].imag]).ravel()])

    X = np.asarray(X, complex)
    p0 = np.concatenate([[1.0, x0 / scale, X[0].real / scale],
                         np.column_stack([X[1:].real, X[1:].imag]).ravel() / scale])
    sol = root(res, p0, method="hybr")
    th, m, Xc = unpack(sol.x)
    err = float(np.max(np.abs(res(sol.x))))
    return bool(sol.success) and th > 0 and Xc[0].real > 0, th, m, Xc, err


#: A solver's step to harmonics this many times the length they are measured in (the
#: fundamental it started from) is outside the model: a cycle's refinement moves it by
#: tens of percent, and a quantised waveform's every encoder line is a term of the
#: balance (a step to 1e10 steps asked for arrays of 200 GB).
FAR = 1e3


def _near(p: np.ndarray) -> bool:
    """Harmonics (real and imaginary parts, in units of the start's length) within FAR."""
    return bool(np.abs(p).max(initial=0.0) <= FAR)


def _pack(x0: float, X: np.ndarray, scale: float) -> np.ndarray:
    """x0 and the harmonics from the second as one real vector, in units of ``scale``."""
    return np.concatenate([[x0], np.column_stack([X[1:].real, X[1:].imag]).ravel()]) / scale


def fundamental_residual(bal: Balance, A: float, theta: float, x0: float, X: np.ndarray
                         ) -> tuple[complex, float, np.ndarray]:
    """The fundamental's balance ``1 + (C Q_1 + P F_1)/A`` with the fundamental held at
    ``A`` (real) and ``theta``, the mean and harmonics 2..H solved for (from a start).

    Parameters
    ----------
    bal : Balance
        The loop.
    A, theta : float
        The fundamental's amplitude (m) and angle per sample (rad).
    x0 : float
        Start of the mean (m).
    X : (H,) complex array
        Start of the harmonics (the first is replaced by A).

    Returns
    -------
    (complex, float, (H,) complex array)
        The residual (0 on a cycle), the mean and the harmonics.
    """
    from scipy.optimize import root

    H = len(X)

    def unpack(p: np.ndarray) -> tuple[float, np.ndarray]:
        Xc = np.zeros(H, complex)
        Xc[0] = A
        Xc[1:] = (p[1::2] + 1j * p[2::2]) * A
        return p[0] * A, Xc

    def res(p: np.ndarray) -> np.ndarray:
        m, Xc = unpack(p)
        if not (np.all(np.isfinite(p)) and _near(p[1:])):
            return np.full(p.size, OUTSIDE)
        r = bal.residual(theta, m, Xc)[np.r_[0, 2:H + 1]] / A
        return np.concatenate([r[:1].real, np.column_stack([r[1:].real, r[1:].imag]).ravel()])

    sol = root(res, _pack(x0, np.asarray(X, complex), A), method="hybr")
    m, Xc = unpack(sol.x)
    return complex(bal.residual(theta, m, Xc)[1] / A), m, Xc


def loeb_stable(bal: Balance, A: float, theta: float, x0: float, X: np.ndarray,
                period_s: float) -> bool:
    """Loeb's criterion on a harmonic-balance cycle: ``U_A V_w - U_w V_A > 0`` for the
    fundamental's residual U + jV, its A-derivative with the other harmonics re-solved
    at fixed w, its w-derivative with the nonlinearities frozen (the quantiser's output,
    and friction as the damper that gives its fundamental).

    Parameters
    ----------
    bal : Balance
        The loop.
    A, theta, x0 : float
        The cycle's fundamental (m), angle per sample (rad) and mean (m).
    X : (H,) complex array
        Its harmonics.
    period_s : float
        T in s.

    Returns
    -------
    bool
        True: a stable cycle (an attractor); False: a threshold.
    """
    h = 1e-4 * A          # a central difference: the residual is smooth in A at a cycle
    FA = (fundamental_residual(bal, A + h, theta, x0, X)[0]
          - fundamental_residual(bal, A - h, theta, x0, X)[0]) / (2 * h)
    Q1 = bal.read(x0, X)[1][0]
    F1 = bal.friction(X)[1][0]
    dt = 1e-6 * theta     # relative step for the derivatives of the linear parts in theta
    t3 = np.array([theta - dt, theta, theta + dt])
    C, P = bal.controller(t3), bal.plant(t3)
    w = theta / period_s
    Fw = ((C[2] - C[0]) / (2 * dt) * period_s * Q1
          + F1 * (P[1] / w + (P[2] - P[0]) / (2 * dt) * period_s)) / A
    return bool(FA.real * Fw.imag - Fw.real * FA.imag > 0)
