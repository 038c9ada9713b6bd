"""The discrete controllers: the spring-damper of eq. (23) and any H(z).

References
----------
N. Miandashti and M. Tavakoli, "Stability of Sampled-Data, Delayed Haptic
Interaction and Teleoperation", IEEE Haptics Symposium 2014 (the paper).
Equation and figure numbers below are the paper's.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, TypeGuard

import numpy as np

from hapstab.errors import ModelError, ascii_float, check_real
from hapstab.models.parts import _poly

__all__ = ['SpringDamper', 'VelocityFilter', 'FilteredSpringDamper', 'AffineController',
           'DiscreteController',
           'Controller', 'spring_damper', 'stiffness_controller', 'has_stiffness',
           'stiffness_ratios']


# ----------------------------------------------------------------------- controllers
@dataclass(frozen=True)
class SpringDamper:
    """Virtual spring-damper H(z) = K + B (z - 1) / (T z)  (eq. 23).

    Parameters
    ----------
    stiffness : float
        K in N/m, >= 0 (default 0: for ``critical_stiffness``, which varies K, only B
        matters, ``SpringDamper(damping=B)``).
    damping : float
        Virtual damping B in N*s/m (backward difference): any finite real.
        B < 0 is used in practice to cancel a device's own damping or friction;
        it subtracts from the device's damping (Colgate-Schenkel's passivity
        condition is b > KT/2 + |B|), and with |B| large enough the loop is
        unstable for every K > 0, which the analyses report with a reason.

    Raises
    ------
    ModelError
        If K is negative or not finite, or B is not finite.
    """

    stiffness: float = 0.0
    damping: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "stiffness", check_real("stiffness", self.stiffness, nonnegative=True))
        object.__setattr__(self, "damping", check_real("virtual damping", self.damping))

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        """(num, den) of H(z) in z, highest power first."""
        K, B, T = self.stiffness, self.damping, period
        return np.array([K * T + B, -B]) / T, np.array([1.0, 0.0])

    def with_stiffness(self, K: float) -> SpringDamper:
        return dataclasses.replace(self, stiffness=K)

    def to_dict(self) -> dict[str, Any]:
        """The controller as JSON-ready values, units in the keys."""
        return {"type": "spring-damper", "stiffness_N_per_m": self.stiffness,
                "virtual_damping_N_s_per_m": self.damping}


#: The smallest gain 1 - a of a low-pass velocity filter: 1000 ulps of 1, so that the
#: pole a = exp(-2 pi f_c T), rounded to a double, still gives 1 - a to 1e-3 (below it
#: the pole is not representable apart from 1, and at a = 1 the loop degenerates).
MIN_FILTER_GAIN = 1000 * float(np.finfo(float).eps)


@dataclass(frozen=True)
class VelocityFilter:
    """The velocity estimate a virtual damper acts on: the backward difference
    ``(x[k] - x[k-1]) / T`` passed through F(z).

    * ``"lowpass"``: a first-order low-pass with cutoff f_c, its pole placed by the
      exponential map, ``F(z) = (1 - a) / (1 - a z^-1)``, ``a = exp(-2 pi f_c T)``:
      ``v[k] = a v[k-1] + (1 - a) (x[k] - x[k-1]) / T``, unit gain at DC; as
      f_c -> infinity, a -> 0 and F -> 1 (the plain backward difference of eq. 23).
    * ``"average"``: the mean of the last N backward differences,
      ``v[k] = (x[k] - x[k-N]) / (N T)``, ``F(z) = (1 - z^-N) / (N (1 - z^-1))``;
      N = 1 is the plain backward difference.

    Parameters
    ----------
    kind : str
        ``"lowpass"`` or ``"average"``.
    cutoff_hz : float
        f_c in Hz, > 0 (``"lowpass"`` only; ``inf`` is the plain difference).
    samples : int
        N >= 1 (``"average"`` only).

    Raises
    ------
    ModelError
        An unknown kind, f_c <= 0 or not a number, N < 1 or not whole.

    References
    ----------
    F. Janabi-Sharifi, V. Hayward and C.-S. J. Chen, "Discrete-time adaptive
    windowing for velocity estimation", IEEE Trans. Control Systems Technology
    8(6), 2000 (backward differences, their averages and low-pass filters as the
    velocity estimators of haptic devices); J. E. Colgate and J. M. Brown, "Factors
    affecting the Z-width of a haptic display", IEEE ICRA 1994 (the filtered
    velocity limits the damping a wall can display).
    """

    kind: str = "lowpass"
    cutoff_hz: float = float("inf")
    samples: int = 1

    def __post_init__(self) -> None:
        if self.kind not in ("lowpass", "average"):
            raise ModelError(f"velocity filter kind = {self.kind!r}: must be 'lowpass' or 'average'")
        if self.kind == "lowpass":
            c = self.cutoff_hz
            if not isinstance(c, (int, float)) or isinstance(c, bool) or not c > 0:
                raise ModelError(f"velocity filter cutoff = {c!r} Hz: must be a number > 0 "
                                 "(inf: no filter)")
            object.__setattr__(self, "cutoff_hz", float(c))
        n = self.samples
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1 or n > 100000:
            raise ModelError(f"velocity filter samples = {n!r}: must be a whole number from 1 "
                             "to 100000")
        object.__setattr__(self, "samples", int(n))

    @classmethod
    def parse(cls, spec: str) -> VelocityFilter:
        """``"lowpass:F"`` (f_c in Hz) or ``"average:N"`` (N samples).

        Raises
        ------
        ModelError
            Anything else, naming the spec and what is allowed.
        """
        kind, _, val = str(spec).partition(":")
        try:
            if kind == "lowpass":
                return cls("lowpass", cutoff_hz=ascii_float(val))
            if kind == "average" and re.fullmatch("[0-9]+", val.strip()):
                return cls("average", samples=int(val))
        except ValueError:
            pass
        raise ModelError(f"velocity filter = {spec!r}: must be lowpass:F (cutoff F Hz > 0) or "
                         "average:N (N >= 1 samples)")

    def pole(self, period: np.ndarray | float) -> np.ndarray:
        """The low-pass pole a = exp(-2 pi f_c T) per period (0 for ``"average"``).

        Raises
        ------
        ModelError
            The cutoff is too low for the period: 1 - a, the filter's gain, is below
            :data:`MIN_FILTER_GAIN` (``lowpass:1e-320`` makes a = 1 exactly: a filter
            that passes nothing, with a pole on the unit circle).
        """
        T = np.asarray(period, float)
        if self.kind != "lowpass":
            return np.zeros(T.shape)
        x = 2.0 * np.pi * self.cutoff_hz * T
        bad = -np.expm1(-x) < MIN_FILTER_GAIN
        if np.any(bad):
            t = float(np.max(np.atleast_1d(T)[np.atleast_1d(bad)]))
            raise ModelError(f"velocity filter cutoff = {self.cutoff_hz:g} Hz: too low for the "
                             f"period {t:g} s (the pole exp(-2 pi f_c T) is 1 to within "
                             f"{MIN_FILTER_GAIN:g}: not representable apart from 1); allowed: "
                             f"f_c >= {MIN_FILTER_GAIN / (2 * np.pi * t):.3g} Hz at this period")
        return np.exp(-x)

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        """(num, den) of F(z) in z, highest power first."""
        if self.kind == "average":
            N = self.samples
            return np.ones(N) / N, np.concatenate([[1.0], np.zeros(N - 1)])
        a = float(self.pole(period))
        return np.array([1.0 - a, 0.0]), np.array([1.0, -a])

    def to_dict(self) -> dict[str, Any]:
        """The filter as JSON-ready values, units in the keys."""
        if self.kind == "average":
            return {"kind": "average", "samples": self.samples}
        return {"kind": "lowpass", "cutoff_Hz": self.cutoff_hz}

    def __str__(self) -> str:
        return f"average:{self.samples}" if self.kind == "average" else f"lowpass:{self.cutoff_hz:g}"


@dataclass(frozen=True)
class FilteredSpringDamper:
    """A virtual spring-damper whose damper acts on a filtered velocity estimate:
    H(z) = K + (B / T)(1 - z^-1) F(z), F the :class:`VelocityFilter`.

    It is affine in the stiffness, H = K P + Q with P = 1, so the exact analyses
    (K_max, stable intervals, regions) and the simulation take it like eq. (23)'s
    :class:`SpringDamper`; the analyses derived for eq. (23) itself (the paper's
    closed forms, passivity, the circle criterion, two-port tests) refuse it.

    Parameters
    ----------
    stiffness : float
        K in N/m, >= 0.
    damping : float
        Virtual damping B in N*s/m: any finite real.
    velocity_filter : VelocityFilter or str
        The velocity estimate (``"lowpass:200"``, ``"average:4"``).

    Raises
    ------
    ModelError
        If K is negative or not finite, B is not finite, or the filter is invalid.

    References
    ----------
    The paper, eq. (23) (the unfiltered H(z)); :class:`VelocityFilter`.
    """

    stiffness: float = 0.0
    damping: float = 0.0
    velocity_filter: Any = field(default_factory=VelocityFilter)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stiffness", check_real("stiffness", self.stiffness, nonnegative=True))
        object.__setattr__(self, "damping", check_real("virtual damping", self.damping))
        f = self.velocity_filter
        if isinstance(f, str):
            f = VelocityFilter.parse(f)
        if not isinstance(f, VelocityFilter):
            raise ModelError(f"velocity_filter = {f!r}: must be a VelocityFilter or a string "
                             "lowpass:F / average:N")
        object.__setattr__(self, "velocity_filter", f)

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        """(num, den) of H(z) in z, highest power first."""
        fn, fd = self.velocity_filter.transfer(period)
        diff = np.convolve(fn, [1.0, -1.0]) * (self.damping / period)   # (z - 1) Fnum / T
        den = np.concatenate([fd, [0.0]])                                # z Fden
        num = np.polyadd(self.stiffness * den, diff)
        return num, den

    def with_stiffness(self, K: float) -> FilteredSpringDamper:
        return dataclasses.replace(self, stiffness=K)

    def to_dict(self) -> dict[str, Any]:
        """The controller as JSON-ready values, units in the keys."""
        return {"type": "filtered-spring-damper", "stiffness_N_per_m": self.stiffness,
                "virtual_damping_N_s_per_m": self.damping,
                "velocity_filter": self.velocity_filter.to_dict()}


@dataclass(frozen=True)
class AffineController:
    """Any discrete controller affine in the stiffness: H(z) = K P(z) + Q(z).

    P and Q are proper transfer functions in z (highest power first) whose
    coefficients belong to the loop's own sampling period (analyses over other periods
    refuse it). K is what the exact analyses vary, as for :class:`SpringDamper` (which
    is P = 1, Q = (B/T)(1 - z^-1)).

    Parameters
    ----------
    stiffness : float
        K >= 0 (N/m when P is dimensionless).
    p_num, p_den : sequence of float
        P(z), not identically zero.
    q_num, q_den : sequence of float
        Q(z) (default 0).

    Raises
    ------
    ModelError
        A coefficient not finite, a zero denominator, an improper P or Q, P = 0.

    References
    ----------
    The paper, eq. (23) (the spring-damper this generalises).
    """

    stiffness: float = 0.0
    p_num: tuple[float, ...] = (1.0,)
    p_den: tuple[float, ...] = (1.0,)
    q_num: tuple[float, ...] = (0.0,)
    q_den: tuple[float, ...] = (1.0,)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stiffness", check_real("stiffness", self.stiffness, nonnegative=True))
        for name in ("p", "q"):
            num = _poly(f"controller {name.upper()} numerator", getattr(self, f"{name}_num"))
            den = _poly(f"controller {name.upper()} denominator", getattr(self, f"{name}_den"))
            if not np.any(den) or num.size > np.trim_zeros(den, "f").size:
                raise ModelError(f"controller {name.upper()} = ({list(num)})/({list(den)}): must "
                                 "have a nonzero denominator and be proper")
            if name == "p" and not np.any(num):
                raise ModelError("controller P = 0: K would do nothing; P must not be zero")
            object.__setattr__(self, f"{name}_num", tuple(map(float, num)))
            object.__setattr__(self, f"{name}_den", tuple(map(float, den)))
        pairs = ((self.p_den, self.q_den, "P and Q share the denominator"),
                 (self.p_num, self.p_den, "P has a numerator and denominator"),
                 (self.q_num, self.q_den, "Q has a numerator and denominator"))
        for x, y, what in pairs:
            r = _common_root(x, y)
            if r is not None:
                raise ModelError(f"controller: {what} root z = {r:.6g} on or outside the unit "
                                 "circle; cancel it (one filter, in lowest terms): the exact "
                                 "analysis cannot count a pole that every K leaves there")

    def parts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(P_num, P_den, Q_num, Q_den) in z^-1, ascending, each pair padded to the
        degree of its denominator (z^-deg times the z-polynomials)."""
        out = []
        for num, den in ((self.p_num, self.p_den), (self.q_num, self.q_den)):
            d = np.trim_zeros(np.array(den), "f")
            n = np.array(num)[-d.size:] if len(num) > d.size else np.array(num)
            out += [np.concatenate([np.zeros(d.size - n.size), n]), d]
        return out[0], out[1], out[2], out[3]

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        """(num, den) of H(z) = K P + Q in z, highest power first."""
        pn, pd, qn, qd = self.parts()
        num = np.polyadd(self.stiffness * np.convolve(pn, qd), np.convolve(qn, pd))
        return num, np.convolve(pd, qd)

    def with_stiffness(self, K: float) -> AffineController:
        return dataclasses.replace(self, stiffness=K)

    def to_dict(self) -> dict[str, Any]:
        """The controller as JSON-ready values: H = K P + Q, highest power first."""
        return {"type": "affine", "stiffness": self.stiffness,
                "P": {"num": list(self.p_num), "den": list(self.p_den)},
                "Q": {"num": list(self.q_num), "den": list(self.q_den)}}


@dataclass(frozen=True)
class DiscreteController:
    """Any proper discrete transfer function H(z) = num(z)/den(z) (highest power first).
    It has no stiffness parameter, so :func:`critical_stiffness` does not apply.

    Parameters
    ----------
    num : sequence of float
        Numerator coefficients in z, highest power first; force in N per m of input.
    den : sequence of float
        Denominator coefficients in z, highest power first, not all zero; the degree
        of ``num`` must not exceed that of ``den`` (proper).

    Raises
    ------
    ModelError
        If a coefficient is not finite, the denominator is zero or H is improper.
    """

    num: tuple[float, ...]
    den: tuple[float, ...]

    def __post_init__(self) -> None:
        num, den = _poly("controller numerator", self.num), _poly("controller denominator", self.den)
        if not np.any(den):
            raise ModelError(f"controller denominator = {list(self.den)}: must not be zero")
        if num.size > den.size:
            raise ModelError(
                f"controller = ({list(self.num)})/({list(self.den)}): must be proper "
                "(numerator degree <= denominator degree)")
        object.__setattr__(self, "num", tuple(map(float, num)))
        object.__setattr__(self, "den", tuple(map(float, den)))

    def to_dict(self) -> dict[str, Any]:
        """The controller as JSON-ready values: H(z) = num/den, highest power first."""
        return {"type": "discrete", "num": list(self.num), "den": list(self.den)}

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.num), np.array(self.den)


Controller = SpringDamper | FilteredSpringDamper | AffineController | DiscreteController


def _common_root(x: Any, y: Any) -> complex | None:
    """A root that polynomials ``x`` and ``y`` (z, highest power first) share on or
    outside the unit circle, or None. Roots agree to 1e-9 relative (np.roots resolves
    the simple roots of these low-degree polynomials to ~1e-12), and 1 - 1e-9 counts
    as on the circle."""
    rx = np.roots(np.asarray(x, float)) if len(x) > 1 else np.zeros(0)
    ry = np.roots(np.asarray(y, float)) if len(y) > 1 else np.zeros(0)
    for a in rx:
        for b in ry:
            on_or_out = abs(a) >= 1 - 1e-9      # np.roots' accuracy: ~1e-12 for simple roots
            if on_or_out and abs(a - b) <= 1e-9 * max(1.0, abs(a)):   # the same root, to it
                return complex(a)
    return None

#: The controllers with a stiffness K to vary (affine in K: H = K + Q(z)).
StiffnessController = SpringDamper | FilteredSpringDamper | AffineController


def has_stiffness(controller: Any) -> TypeGuard[StiffnessController]:
    """Whether ``controller`` has a stiffness K that the exact analyses can vary
    (a :class:`SpringDamper`, :class:`FilteredSpringDamper` or :class:`AffineController`).

    Parameters
    ----------
    controller : Any
        A controller.

    Returns
    -------
    bool
    """
    return isinstance(controller, (SpringDamper, FilteredSpringDamper, AffineController))


def stiffness_controller(controller: Controller, name: str = "controller") -> StiffnessController:
    """``controller`` itself if it has a stiffness K to vary (:func:`has_stiffness`).

    Parameters
    ----------
    controller : Controller
        The controller to vary K of.
    name : str
        Its name in the error message.

    Returns
    -------
    SpringDamper or FilteredSpringDamper

    Raises
    ------
    ModelError
        If it is a general :class:`DiscreteController`.
    """
    if not has_stiffness(controller):
        raise ModelError(f"{name}: a SpringDamper or FilteredSpringDamper is needed to vary "
                         "the stiffness")
    return controller


def spring_damper(controller: Controller, name: str = "controller") -> SpringDamper:
    """``controller`` itself if it is a :class:`SpringDamper` (the only controller with a
    stiffness K to vary).

    Parameters
    ----------
    controller : SpringDamper or DiscreteController
        The controller to vary K of.
    name : str
        Its name in the error message (``"controller"``, ``"master_controller"``, ...).

    Raises
    ------
    ModelError
        If it is not a :class:`SpringDamper`.
    """
    if not isinstance(controller, SpringDamper):
        raise ModelError(f"{name}: a SpringDamper is needed to vary the stiffness")
    return controller


def stiffness_ratios(stiffnesses: Sequence[float]) -> tuple[float, ...] | None:
    """The one K_s/K_m convention: each controller's stiffness per unit K.

    K is the first controller's (the master's) stiffness; every other controller
    keeps its ratio to it, so equal stiffnesses (the paper's C_m = C_s) stay equal.
    Every loop builder, the engine and the frequency-domain analyses vary K by this
    rule and by no other.

    Parameters
    ----------
    stiffnesses : sequence of float
        The controllers' stiffnesses in N/m, first the one that K names.

    Returns
    -------
    tuple of float or None
        ``k_i`` with ``k_0 = 1`` (all ones when every stiffness is 0); ``None`` when
        the ratio is undefined: the first stiffness is 0 and another is not.
    """
    ks = [float(k) for k in stiffnesses]
    if ks[0] > 0:
        return tuple(k / ks[0] for k in ks)
    return None if any(k > 0 for k in ks) else tuple(1.0 for _ in ks)
