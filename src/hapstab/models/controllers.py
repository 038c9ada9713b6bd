"""The discrete controllers: the spring-damper of eq. (23) and any H(z).

References
----------
N. Miandashti and M. Tavakoli, "Stability of Sampled-Data, Delayed Haptic
Interaction and Teleoperation", IEEE Haptics Symposium 2014 (the paper).
Equation and figure numbers below are the paper's.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, TypeGuard

import numpy as np

from hapstab.errors import ModelError, check_poly, check_real
from hapstab.models.protocol import check_analysis
from hapstab.models.realisation import Realisation, realize, replicate, spring_damper_states
from hapstab.models.velocity_filter import MIN_FILTER_GAIN, VelocityFilter

__all__ = ['SpringDamper', 'VelocityFilter', 'FilteredSpringDamper', 'AffineController',
           'DiscreteController',
           'Controller', 'spring_damper', 'stiffness_controller', 'has_stiffness',
           'stiffness_ratios', 'MIN_FILTER_GAIN']


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

    def gains(self) -> tuple[float, float]:
        """(K, B)."""
        return self.stiffness, self.damping

    def affine_parts(self) -> None:
        """None: its Q = (B/T)(1 - z^-1) depends on T (it answers :meth:`gains`)."""
        return None

    def response(self, theta: np.ndarray, period: float, part: str | None = None,
                 ratio: float = 1.0) -> np.ndarray:
        """H(e^{j theta}), or its K-part (times ``ratio``) or B-part (``part``)."""
        return _damper_response(self, theta, period, part, ratio, None)

    def realisation(self, periods: np.ndarray) -> Realisation:
        """One state (none when B = 0), K only in the direct feed-through."""
        return spring_damper_states(self.damping, periods)

    def admits(self, analysis: str) -> bool:
        """Every analysis of :data:`~hapstab.models.protocol.ANALYSES`."""
        check_analysis(analysis)
        return True

    def to_dict(self) -> dict[str, Any]:
        """The controller as JSON-ready values, units in the keys."""
        return {"type": "spring-damper", "stiffness_N_per_m": self.stiffness,
                "virtual_damping_N_s_per_m": self.damping}


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

    def gains(self) -> tuple[float, float]:
        """(K, B); B acts on the filtered velocity."""
        return self.stiffness, self.damping

    def affine_parts(self) -> None:
        """None: its Q depends on T (it answers :meth:`gains`)."""
        return None

    def response(self, theta: np.ndarray, period: float, part: str | None = None,
                 ratio: float = 1.0) -> np.ndarray:
        """H(e^{j theta}), or its K-part (times ``ratio``) or B-part (``part``)."""
        return _damper_response(self, theta, period, part, ratio, self.velocity_filter)

    def realisation(self, periods: np.ndarray) -> Realisation:
        """K + Q(z), Q = (B/T)(1 - z^-1) F(z) realised per period (the low-pass pole
        depends on T); eq. (23)'s when B = 0."""
        if self.damping == 0:
            return spring_damper_states(0.0, periods)
        nums, dens = [], []
        for T in periods:
            fn, fd = self.velocity_filter.transfer(float(T))
            nums.append(np.convolve(fn, [1.0, -1.0]) * (self.damping / T))
            dens.append(np.concatenate([fd, [0.0]]))
        Ah, Bh, Ch, D = realize(np.array(nums), np.array(dens))
        return Ah, Bh, Ch, D, np.ones(periods.size), np.zeros_like(Ch)

    def admits(self, analysis: str) -> bool:
        """K to vary; the network models only without a damper (B = 0: H = K)."""
        return check_analysis(analysis) == "stiffness" or (
            analysis == "packet-loss" and self.damping == 0)

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
            num = check_poly(f"controller {name.upper()} numerator", getattr(self, f"{name}_num"))
            den = check_poly(f"controller {name.upper()} denominator", getattr(self, f"{name}_den"))
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

    def gains(self) -> None:
        """None: not a spring-damper."""
        return None

    def affine_parts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`parts`."""
        return self.parts()

    def response(self, theta: np.ndarray, period: float, part: str | None = None,
                 ratio: float = 1.0) -> np.ndarray:
        """H(e^{j theta}), or ``ratio`` P (``part="K"``) or Q (``part="B"``)."""
        z = np.exp(1j * theta)
        if part is None:
            num, den = self.transfer(period)
            return np.polyval(num, z) / np.polyval(den, z)
        pn, pd, qn, qd = self.parts()
        if part == "K":
            return ratio * np.polyval(pn, z) / np.polyval(pd, z)
        return np.polyval(qn, z) / np.polyval(qd, z)

    def realisation(self, periods: np.ndarray) -> Realisation:
        """P's and Q's states side by side, K on P's output."""
        P = periods.size
        pn, pd, qn, qd = self.parts()
        Ap, Bp, Cp, Dp = realize(replicate(pn, P), replicate(pd, P))
        Aq, Bq, Cq, Dq = realize(replicate(qn, P), replicate(qd, P))
        p, q = Ap.shape[1], Aq.shape[1]
        Ah = np.zeros((P, p + q, p + q))
        Ah[:, :p, :p], Ah[:, p:, p:] = Ap, Aq
        z = np.zeros((P, 1, p + q))
        Ch, ChK = z.copy(), z.copy()
        Ch[:, :, p:], ChK[:, :, :p] = Cq, Cp
        return Ah, np.concatenate([Bp, Bq], axis=1), Ch, Dq, Dp, ChK

    def admits(self, analysis: str) -> bool:
        """K to vary, and nothing derived for eq. (23) itself."""
        return check_analysis(analysis) == "stiffness"

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
        num = check_poly("controller numerator", self.num)
        den = check_poly("controller denominator", self.den)
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

    def gains(self) -> None:
        """None: not a spring-damper."""
        return None

    def affine_parts(self) -> None:
        """None: no stiffness K."""
        return None

    def response(self, theta: np.ndarray, period: float, part: str | None = None,
                 ratio: float = 1.0) -> np.ndarray:
        """H(e^{j theta}) (it has no K- or B-part: ``part`` and ``ratio`` are unused)."""
        z = np.exp(1j * theta)
        num, den = self.transfer(period)
        return np.polyval(num, z) / np.polyval(den, z)

    def realisation(self, periods: np.ndarray) -> Realisation:
        """num/den's controllable canonical form; no K."""
        P = periods.size
        num, den = np.array(self.num), np.array(self.den)
        num = np.concatenate([np.zeros(den.size - num.size), num])
        Ah, Bh, Ch, D = realize(replicate(num, P), replicate(den, P))
        return Ah, Bh, Ch, D, np.zeros(P), np.zeros_like(Ch)

    def admits(self, analysis: str) -> bool:
        """None of :data:`~hapstab.models.protocol.ANALYSES` (no K to vary)."""
        check_analysis(analysis)
        return False


Controller = SpringDamper | FilteredSpringDamper | AffineController | DiscreteController


def _damper_response(c: SpringDamper | FilteredSpringDamper, theta: np.ndarray, T: float,
                     part: str | None, ratio: float, vf: VelocityFilter | None) -> np.ndarray:
    """A spring-damper's H(e^{j theta}) (or its K- or B-part). ``1 - e^{-j theta}`` is
    ``2j sin(theta/2) e^{-j theta/2}``: no cancellation as theta -> 0."""
    z = np.exp(1j * theta)
    one_minus = 2j * np.sin(theta / 2) * np.exp(-0.5j * theta)
    k = ratio if part == "K" else (0.0 if part == "B" else c.stiffness)
    B = 0.0 if part == "K" else c.damping
    if vf is not None and B:
        fn, fd = vf.transfer(T)
        one_minus = one_minus * np.polyval(fn, z) / np.polyval(fd, z)
    return k + B * one_minus / T


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
    admits = getattr(controller, "admits", None)
    return callable(admits) and bool(admits("stiffness"))


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
