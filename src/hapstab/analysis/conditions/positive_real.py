"""Discrete positive-realness of a square, proper, rational transfer matrix G(z)
(the paper's Definition 1) and the circle criterion of Theorem 2.1.

G(z) is positive real (PR) if
(i)   every pole of every element lies in the closed unit disk;
(ii)  every pole on |z| = 1 is simple, with a Hermitian positive-semidefinite
      residue matrix;
(iii) G(e^{jw}) + G^H(e^{jw}) is positive semidefinite wherever defined.

:func:`positive_real` reports which condition fails, the worst frequency and the
smallest eigenvalue there (the margin), not only a boolean.

References
----------
The paper, Definition 1 and Theorem 2.1; H. Khalil, Nonlinear Systems, 2002
(the paper's [11]); L. Hitz and B. D. O. Anderson, "Discrete positive-real
functions and their application to system stability", Proc. IEE 116(1), 1969
(the paper's [7]).
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.analysis.conditions.frequency_grid import min_eig, refine_minimum, theta_grid
from hapstab.errors import (
    AnalysisError,
    ArgumentTypeError,
    ModelError,
    check_period,
    check_poly,
    check_real,
)
from hapstab.results import Result, jsonable
from hapstab.tolerances import COEFF_ZERO, DIVISOR_FLOOR, ROOT_ON_CIRCLE

__all__ = ["RationalMatrix", "PositiveRealResult", "positive_real", "circle_criterion"]

# | |p| - 1 | below this: a unit-circle root, put exactly on it (hapstab.tolerances).
# Every element's poles and zeros are snapped when it is built, so this same
# tolerance then picks exactly the snapped ones.
_ON_CIRCLE = ROOT_ON_CIRCLE
_CANCEL = 1e-7       # a pole and a zero closer than this (relative) cancel: sqrt(eps)-level root errors
_SIMPLE = 1e-6       # two unit-circle poles closer than this are one multiple pole (double roots split ~1e-8)
_RTOL = 1e-9         # eigenvalue slack relative to the matrix scale: eigvalsh/roundoff is ~1e-13 of it
_POLE_GAP = 1e-9     # the sweep keeps this far (rad/sample) from unit-circle poles, where G is undefined


_coeffs = check_poly


@dataclass(frozen=True)
class _Element:
    """num/den in product form ``gain * prod(z - zeros) / prod(z - poles)``, with
    common roots cancelled."""

    gain: float
    zeros: np.ndarray
    poles: np.ndarray

    @classmethod
    def from_poly(cls, num: np.ndarray, den: np.ndarray,
                  roots: Callable[[np.ndarray], np.ndarray] = np.roots) -> _Element:
        if not np.any(num):
            return cls(0.0, np.zeros(0, complex), np.zeros(0, complex))
        zs, ps = list(_snap(roots(num))), list(_snap(roots(den)))
        keep = []
        for p in ps:  # cancel common roots (e.g. (z-1) in B(z-1)/(Tz) * T/(z-1))
            d = [abs(p - z) for z in zs]
            j = int(np.argmin(d)) if d else -1
            if j >= 0 and d[j] <= _CANCEL * max(1.0, abs(p)):
                zs.pop(j)
            else:
                keep.append(p)
        return cls(float(num[0] / den[0]), np.array(zs, complex), np.array(keep, complex))

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        return self.gain * _factors(theta, self.zeros) / _factors(theta, self.poles)


def _snap(r: np.ndarray) -> np.ndarray:
    """Put roots within _ON_CIRCLE of the unit circle exactly on it."""
    r = np.asarray(r, complex)
    m = np.abs(np.abs(r) - 1.0) <= _ON_CIRCLE
    r[m] = np.exp(1j * np.angle(r[m]))
    return r


def _factors(theta: np.ndarray, roots: np.ndarray) -> np.ndarray:
    """prod(e^{j theta} - r) evaluated without cancellation for |r| = 1:
    e^{ja} - e^{jb} = 2j sin((a-b)/2) e^{j(a+b)/2} (so 1 - cos w never appears)."""
    out = np.ones(np.shape(theta), complex)
    z = np.exp(1j * theta)
    for r in roots:
        if abs(abs(r) - 1.0) <= _ON_CIRCLE:
            phi = np.angle(r)
            out *= 2j * np.sin((theta - phi) / 2) * np.exp(0.5j * (theta + phi))
        else:
            out *= z - r
    return out


class RationalMatrix:
    """A square matrix of real rational functions of z, ``G[i][j] = num/den``
    (coefficients highest power first).

    Parameters
    ----------
    nums, dens : m x m nested sequences of coefficient sequences

    Raises
    ------
    ModelError
        Non-square, non-finite, zero denominator, or improper element.
    """

    def __init__(self, nums: Sequence[Sequence[Any]], dens: Sequence[Sequence[Any]]) -> None:
        m = len(nums)
        if m == 0 or len(dens) != m or any(len(r) != m for r in nums) or any(len(r) != m for r in dens):
            raise ModelError("G(z): nums and dens must be square m x m nested lists of the same size")
        self.m = m
        self.num = [[_coeffs(f"G[{i}][{j}] numerator", nums[i][j]) for j in range(m)] for i in range(m)]
        self.den = [[_coeffs(f"G[{i}][{j}] denominator", dens[i][j]) for j in range(m)] for i in range(m)]
        for i in range(m):
            for j in range(m):
                if not np.any(self.den[i][j]):
                    raise ModelError(f"G[{i}][{j}] denominator: must not be zero")
                if np.any(self.num[i][j]) and self.num[i][j].size > self.den[i][j].size:
                    raise ModelError(f"G[{i}][{j}]: must be proper (deg num <= deg den)")

    @functools.cached_property
    def elements(self) -> list[list[_Element]]:
        """Each element in product form, found when first needed (one eigenvalue problem
        per distinct polynomial: elements sharing a denominator share its roots)."""
        found: dict[bytes, np.ndarray] = {}

        def roots(p: np.ndarray) -> np.ndarray:
            key = p.tobytes()
            if key not in found:
                found[key] = np.roots(p)
            return found[key].copy()

        return [[_Element.from_poly(self.num[i][j], self.den[i][j], roots) for j in range(self.m)]
                for i in range(self.m)]

    @classmethod
    def scalar(cls, num: Any, den: Any) -> RationalMatrix:
        return cls([[num]], [[den]])

    def __call__(self, theta: np.ndarray | float) -> np.ndarray:
        """G(e^{j theta}), shape ``(len(theta), m, m)``."""
        th = np.atleast_1d(np.asarray(theta, dtype=float))
        out = np.empty((th.size, self.m, self.m), complex)
        for i in range(self.m):
            for j in range(self.m):
                out[:, i, j] = self.elements[i][j](th)
        return out

    def poles(self) -> np.ndarray:
        """Poles of all elements (after cancellation), with repetition across elements."""
        return np.concatenate([e.poles for row in self.elements for e in row] + [np.zeros(0, complex)])

    def critical_angles(self) -> np.ndarray:
        """Angles of poles/zeros near the circle, with geometric offsets so that a
        narrow resonance or notch (width ~ 1 - |r|) is sampled densely."""
        pts = []
        for row in self.elements:
            for e in row:
                for r in np.concatenate([e.poles, e.zeros]):
                    rad = abs(r)
                    if rad < 0.5 or rad > 2.0:
                        continue
                    # a root on the circle has no width: 1e-6, the nearest offset kept below
                    phi, w = abs(np.angle(r)), max(abs(rad - 1.0), 1e-6)
                    off = w * np.geomspace(0.05, 200.0, 24)
                    off = off[off >= 1e-6]  # closer to a unit-circle pole G + G^H is all rounding
                    pts.append(np.concatenate([phi - off, phi + off, [phi]]))
        return np.concatenate(pts) if pts else np.zeros(0)

    def degree(self) -> int:
        return max(max(d.size for d in row) for row in self.den) - 1

    def add_diagonal(self, values: Sequence[float]) -> RationalMatrix:
        """G + diag(values) (e.g. K^{-1} + G of Theorem 2.1)."""
        nums = [[self.num[i][j].copy() for j in range(self.m)] for i in range(self.m)]
        for i, v in enumerate(values):
            nums[i][i] = np.polyadd(nums[i][i], v * self.den[i][i])
        return RationalMatrix(nums, self.den)

    def inverse(self) -> RationalMatrix:
        """G^{-1} for m = 1 or 2 (polynomial adjugate over the determinant).

        Raises
        ------
        AnalysisError
            If m > 2 or G is singular.
        """
        n, d = self.num, self.den
        if self.m == 1:
            if not np.any(n[0][0]):
                raise AnalysisError("G(z) = 0: not invertible")
            return RationalMatrix([[d[0][0]]], [[n[0][0]]])
        if self.m != 2:
            raise AnalysisError(f"G(z) is {self.m}x{self.m}: inversion is implemented for 1x1 and 2x2")
        pm = np.polymul
        den_all = pm(pm(d[0][0], d[1][1]), pm(d[0][1], d[1][0]))
        det_num: np.ndarray = np.polysub(pm(pm(n[0][0], n[1][1]), pm(d[0][1], d[1][0])),
                             pm(pm(n[0][1], n[1][0]), pm(d[0][0], d[1][1])))
        if not np.any(np.abs(det_num) > COEFF_ZERO * np.abs(det_num).max(initial=0.0)):
            raise AnalysisError("G(z) is singular: not invertible")
        # (G^{-1})_ij = adj_ij / det = adj_ij * den_all / det_num
        adj = [[(n[1][1], d[1][1]), (-n[0][1], d[0][1])], [(-n[1][0], d[1][0]), (n[0][0], d[0][0])]]
        nums = [[pm(a, den_all) for a, _ in row] for row in adj]
        dens = [[pm(b, det_num) for _, b in row] for row in adj]
        return RationalMatrix(nums, dens)


@dataclass(frozen=True)
class PositiveRealResult(Result):
    """Outcome of the positive-real test of Definition 1.

    Attributes
    ----------
    positive_real : bool
    failed_condition : str or None
        The first failing condition: ``"poles"`` (i), ``"unit-circle poles"`` (ii),
        ``"hermitian part"`` (iii), or None.
    failed_conditions : tuple of str
        All failing conditions.
    margin : float
        Smallest eigenvalue of G(e^{jw}) + G^H(e^{jw}) over w (condition (iii));
        >= 0 when (iii) holds.
    worst_frequency_rad_s, worst_frequency_hz : float
        Where that smallest eigenvalue occurs (w/T and w/(2 pi T)).
    reason : str
        In words, naming the condition.
    period : float
        T used to convert rad/sample to rad/s (1 if none was given).
    poles : tuple of complex
        The poles of G(z).
    frequencies_rad_s : array
        The frequencies (rad/s) of the sweep for condition (iii).
    min_eigenvalues : array
        The smallest eigenvalue of G + G^H at each of them (for plotting).
    """

    positive_real: bool
    failed_condition: str | None
    failed_conditions: tuple[str, ...]
    margin: float
    worst_frequency_rad_s: float
    worst_frequency_hz: float
    reason: str
    period: float = 1.0
    poles: tuple[complex, ...] = field(default=(), repr=False)
    frequencies_rad_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False, compare=False)
    min_eigenvalues: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False, compare=False)

    @property
    def verdict(self) -> str:
        return "positive real" if self.positive_real else "not positive real"

    def to_dict(self) -> dict[str, Any]:
        return jsonable({
            "verdict": self.verdict, "positive_real": self.positive_real,
            "failed_condition": self.failed_condition,
            "failed_conditions": list(self.failed_conditions), "margin": self.margin,
            "worst_frequency_rad_s": self.worst_frequency_rad_s,
            "worst_frequency_hz": self.worst_frequency_hz, "reason": self.reason,
            "period_s": self.period})

    def plot(self, ax: Any = None) -> Any:
        from hapstab.plotting import plot_positive_real
        return plot_positive_real(self, ax=ax)


def _unit_circle_check(G: RationalMatrix) -> tuple[bool, str]:
    """Condition (ii): unit-circle poles simple, normalised residues Hermitian PSD.

    The residue is taken as R = lim (z - p) G(z) / p: the z -> s bilinear map
    turns it into the continuous-time residue up to a positive factor, so R (not
    the raw residue) must be Hermitian PSD; at p = 1 they coincide (eq. 25).
    """
    m = G.m
    found: list[complex] = []
    for row in G.elements:
        for e in row:
            on = [p for p in e.poles if abs(abs(p) - 1.0) <= _ON_CIRCLE]
            for p in on:
                if sum(abs(p - q) <= _SIMPLE for q in on) > 1:
                    return False, f"pole at z = {p:.6g} is not simple"
                if not any(abs(p - q) <= _SIMPLE for q in found):
                    found.append(p)
    for p in found:
        R = np.zeros((m, m), complex)
        for i in range(m):
            for j in range(m):
                e = G.elements[i][j]
                k = [q for q in e.poles if abs(p - q) <= _SIMPLE]
                if not k:
                    continue
                others = np.array([q for q in e.poles if abs(p - q) > _SIMPLE], complex)
                R[i, j] = e.gain * np.prod(p - e.zeros) / np.prod(p - others) / p
        scale = max(np.abs(R).max(), DIVISOR_FLOOR)
        if np.abs(R - R.conj().T).max() > 1e-7 * scale:  # roots carry ~1e-8 relative error
            return False, f"residue at z = {p:.6g} is not Hermitian ({np.round(R, 12).tolist()})"
        if np.linalg.eigvalsh((R + R.conj().T) / 2)[0] < -1e-7 * scale:  # roots' ~1e-8 error
            return False, f"residue at z = {p:.6g} is not positive semidefinite"
    return True, ""


def _require_matrix(G: Any) -> None:
    if not isinstance(G, RationalMatrix):
        raise ArgumentTypeError(f"G = {G!r:.60}: must be a RationalMatrix (got {type(G).__name__})")


def positive_real(G: RationalMatrix, period: float | None = None, grid: int | None = None,
                  rtol: float = _RTOL, *, max_memory: float | None = None,
                  max_seconds: float | None = None) -> PositiveRealResult:
    """Test Definition 1 for a square proper rational G(z).

    Parameters
    ----------
    G : RationalMatrix
    period : float, optional
        Sampling period T (s), to report frequencies in rad/s and Hz.
    grid : int, optional
        Minimum number of grid angles on (0, pi] (default: 48 per unit of degree,
        at least 1024), refined near every pole/zero close to the circle and then
        at each local minimum by golden section (so a narrow dip between grid
        points is not missed).
    rtol : float
        Condition (iii) fails when the smallest eigenvalue is below ``-rtol``
        times the median Hermitian-part eigenvalue magnitude, plus 1e-13 times
        ||G|| at the worst frequency (the rounding of G + G^H next to a pole).
    max_memory, max_seconds : float, optional
        Budget in bytes and seconds (default :mod:`hapstab.budget`'s) of the frequency
        sweep (grid angles x elements x degree), estimated first.

    Returns
    -------
    PositiveRealResult

    References
    ----------
    The paper, Definition 1.
    """
    _require_matrix(G)
    T = 1.0 if period is None else check_period("period", period)   # (5e-324: overflowed)
    rtol = check_real("rtol", rtol, positive=True)
    _charge(G, grid, max_memory, max_seconds)
    poles = G.poles()
    fails: list[str] = []
    reasons: list[str] = []
    outside = poles[np.abs(poles) > 1.0 + _ON_CIRCLE]
    if outside.size:
        fails.append("poles")
        reasons.append(f"(i) pole outside the unit circle at z = {outside[np.argmax(np.abs(outside))]:.6g}")
    ok2, why2 = _unit_circle_check(G)
    if not ok2:
        fails.append("unit-circle poles")
        reasons.append("(ii) " + why2)

    on_circle = np.abs(np.angle(poles[np.abs(np.abs(poles) - 1.0) <= _ON_CIRCLE]))
    extra = G.critical_angles()
    th = theta_grid(G.degree() + 1, minimum=grid or 1024, extra=extra)
    if on_circle.size:  # stay just off unit-circle poles, where G is undefined
        d = np.min(np.abs(th[:, None] - on_circle[None, :]), axis=1)
        th = th[d > _POLE_GAP]
        th = np.unique(np.concatenate([th, _near(on_circle)]))
    # the w -> 0 limit is reached to O(w^2): 1e-6/(deg+1) is within ~1e-12 of it,
    # while staying far enough from a pole at z = 1 for G + G^H to be accurate
    th = th[(th >= 1e-6 / (G.degree() + 1)) & (th <= np.pi)]

    def lam(t: np.ndarray) -> np.ndarray:
        Gz = G(t)
        out = min_eig(Gz + np.conj(np.swapaxes(Gz, 1, 2)))
        if on_circle.size:
            # within _POLE_GAP of a unit-circle pole G + G^H is rounding (|G| ~ 1/gap): the
            # golden-section refinement must stay out of that band just as the grid does,
            # or it walks onto the pole and both the minimum and its tolerance are noise
            gap = np.min(np.abs(np.asarray(t, float)[:, None] - on_circle[None, :]), axis=1)
            out = np.where(gap > _POLE_GAP, out, np.nan)
        return out

    vals = lam(th)
    finite = np.isfinite(vals)
    scale = float(np.median(np.abs(vals[finite]))) if finite.any() else 1.0
    # next to a pole at z = 1 the eigenvalues carry ~1e-9 relative rounding (see below)
    t_min, margin = refine_minimum(lam, th, vals, zero_rtol=1e-8)
    # eigenvalues of G + G^H carry an absolute error ~ eps ||G(e^{jw})||, which is
    # large next to a unit-circle pole even where the Hermitian part is small
    t_eval = max(t_min, float(th[0]))  # t_min = 0 stands for the limit at th[0]
    g_norm = float(np.abs(G(t_eval)).sum()) if math.isfinite(t_min) else 0.0
    if not (math.isfinite(margin) and math.isfinite(g_norm)):
        fails.append("hermitian part")          # overflow: nothing can be certified
        reasons.append("(iii) G + G^H is not finite on the circle (overflow): not certified")
    elif margin < -(rtol * scale + 1e-13 * g_norm):  # ~500 eps: a few roundings per element
        fails.append("hermitian part")
        reasons.append(f"(iii) G + G^H has eigenvalue {margin:.6g} < 0 at w = {t_min / T:.6g} rad/s")
    ok = not fails
    reason = ("positive real: (i) poles in the closed unit disk, (ii) unit-circle poles simple with "
              f"Hermitian PSD residues, (iii) min eig of G + G^H = {margin:.6g} >= 0") if ok \
        else "not positive real: " + "; ".join(reasons)
    return PositiveRealResult(ok, fails[0] if fails else None, tuple(fails), float(margin),
                              t_min / T, t_min / (2 * math.pi * T), reason, T,
                              tuple(complex(p) for p in poles), th / T, vals)


def _charge(G: RationalMatrix, grid: int | None, max_memory: float | None,
            max_seconds: float | None) -> None:
    """Refuse a sweep beyond the budget: every angle evaluates m^2 elements, each a
    product of ~degree complex factors (an angles x degree array of 16 bytes at a time),
    about 8 operations per factor."""
    from hapstab import budget

    if grid is not None and (isinstance(grid, bool) or not isinstance(grid, (int, np.integer))
                             or grid < 2):
        raise ArgumentTypeError(f"grid = {grid!r:.40}: must be a whole number >= 2 (or None)")
    deg = G.degree() + 1
    points = max(int(grid or 1024), 48 * deg)       # (a numpy int8 grid overflowed below)
    work = points * G.m * G.m * deg
    budget.check(budget.Cost(f"positive_real: {points} angles of a {G.m}x{G.m} matrix of "
                             f"degree {deg - 1}", 16.0 * points * (deg + 8 * G.m * G.m),
                             8.0 * work / budget.FLOPS), max_memory, max_seconds)


def _near(angles: np.ndarray) -> np.ndarray:
    # 1e-6 rad/sample at the nearest (closer, G + G^H is rounding: |G| ~ 1/distance) to
    # 1e-2, a few steps of the grid (pi/1024 ~ 3e-3 at most), which takes over from there
    off = np.geomspace(1e-6, 1e-2, 9)
    return np.concatenate([np.concatenate([a - off, a + off]) for a in angles])


def circle_criterion(G: RationalMatrix, sector: Sequence[float] | float | None = None,
                     period: float | None = None) -> PositiveRealResult:
    """Theorem 2.1: the loop of G(z) with a feedback nonlinearity in the sector
    [0, k_i] on each channel is absolutely stable if ``K^{-1} + G(z)`` is PR.

    Parameters
    ----------
    G : RationalMatrix
        The forward LTI system C(zI - A)^{-1}B, m x m.
    sector : float, sequence of float or None
        Upper sector bounds k_i > 0 (``inf`` allowed per channel). ``None`` is
        the passive limit k_i -> inf, where the test is "G(z) is PR".
    period : float, optional
        T for frequency reporting.

    Returns
    -------
    PositiveRealResult
    """
    _require_matrix(G)
    if sector is None:
        return positive_real(G, period)
    try:
        if np.iscomplexobj(sector):     # (its imaginary part would be dropped silently)
            raise TypeError
        with warnings.catch_warnings():     # an overflowing cast: refused below (not finite)
            warnings.simplefilter("ignore")
            ks = np.broadcast_to(np.asarray(sector, dtype=float), (G.m,))
    except (TypeError, ValueError, OverflowError):
        raise ModelError(f"sector = {sector!r}: one bound k > 0, or one per channel ({G.m})") from None
    for k in ks:
        if not k > 0:
            raise ModelError(f"sector = {list(ks)}: every k_i must be > 0 (inf for the passive limit)")
    return positive_real(G.add_diagonal([0.0 if math.isinf(k) else 1.0 / k for k in ks]), period)
