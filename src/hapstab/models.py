"""Models: devices, terminations (operator / environment impedances), discrete
controllers and the two loops of the paper. Frozen, validated when built, SI units.

References
----------
N. Miandashti and M. Tavakoli, "Stability of Sampled-Data, Delayed Haptic
Interaction and Teleoperation", IEEE Haptics Symposium 2014 (the paper).
Equation and figure numbers below are the paper's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np

from .errors import AnalysisError, ModelError, check_delay, check_period, check_poly, check_real

__all__ = [
    "Device", "Impedance", "NO_IMPEDANCE", "spring", "mass_spring_damper",
    "SpringDamper", "DiscreteController", "Controller", "HapticLoop",
    "TeleoperationLoop", "parse_impedance", "paper_hve", "paper_peb", "delay_from_seconds",
    "whole_delay",
]


# --------------------------------------------------------------------------- devices
@dataclass(frozen=True)
class Device:
    """A 1-DOF haptic interface or robot: ``mass * a + damping * v = force``.

    Parameters
    ----------
    mass : float
        m in kg, > 0.
    damping : float
        Physical viscous damping b in N*s/m, >= 0.
    """

    mass: float
    damping: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass", check_real("mass", self.mass, positive=True))
        object.__setattr__(self, "damping",
                           check_real("damping", self.damping, nonnegative=True))


# ------------------------------------------------------------------------ impedances
_poly = check_poly


@dataclass(frozen=True)
class Impedance:
    """A continuous LTI impedance Z(s) = num(s)/den(s), velocity to force, rigidly
    attached to the device it touches (operator or environment).

    At most one pole at s = 0 (a spring) and numerator degree at most
    ``deg(den) + 1`` (a mass adds to the device's mass).

    Parameters
    ----------
    num, den : sequence of float
        Coefficients in s, highest power first.
    label : str
        Human-readable description.

    Notes
    -----
    Z is split as ``Z(s) = m_z s + d_z + k_z/s + Z_r(s)`` with Z_r strictly proper
    and free of a pole at the origin; the spring acts on the device position
    itself, so no redundant integrator (and no spurious pole at z = 1) appears.
    """

    num: tuple[float, ...]
    den: tuple[float, ...]
    label: str = "custom"
    mass: float = field(init=False)
    damping: float = field(init=False)
    stiffness: float = field(init=False)
    rest_num: tuple[float, ...] = field(init=False)
    rest_den: tuple[float, ...] = field(init=False)

    def __post_init__(self) -> None:
        num, den = _poly("impedance numerator", self.num), _poly("impedance denominator", self.den)
        if not np.any(den):
            raise ModelError(f"impedance denominator = {list(self.den)}: must not be zero")
        if not np.any(num):
            num = np.zeros(1)
        # cancel common factors of s
        while num.size > 1 and den.size > 1 and num[-1] == 0 and den[-1] == 0:
            num, den = num[:-1], den[:-1]
        if num.size - 1 > den.size:  # deg num > deg den + 1
            raise ModelError(
                f"impedance = ({list(self.num)})/({list(self.den)}): numerator degree may exceed "
                "the denominator's by at most 1 (a mass)")
        n_origin = 0
        while den.size > 1 and den[-1] == 0:
            den, n_origin = den[:-1], n_origin + 1
        if n_origin > 1:
            raise ModelError(
                f"impedance = ({list(self.num)})/({list(self.den)}): at most one pole at s = 0 "
                "(a spring) is allowed")
        k = 0.0
        if n_origin == 1:
            k = num[-1] / den[-1]
            full = np.polysub(num, k * den)
            full[-1] = 0.0  # exact by construction of k
            num = full[:-1] if full.size > 1 else np.zeros(1)
        q, r = np.polydiv(num, den) if num.size >= den.size else (np.zeros(1), num)
        q = np.concatenate([np.zeros(max(0, 2 - q.size)), q])
        mz, dz = (float(q[-2]), float(q[-1]))
        r = np.atleast_1d(r)
        nz = np.flatnonzero(np.abs(r) > 1e-14 * max(1.0, np.abs(num).max()))
        r = r[nz[0]:] if nz.size else np.zeros(1)
        lead = den[0]
        object.__setattr__(self, "num", tuple(float(x) for x in _poly("num", self.num)))
        object.__setattr__(self, "den", tuple(float(x) for x in _poly("den", self.den)))
        object.__setattr__(self, "mass", mz)
        object.__setattr__(self, "damping", dz)
        object.__setattr__(self, "stiffness", float(k))
        object.__setattr__(self, "rest_num", tuple(float(x) / lead for x in r))
        object.__setattr__(self, "rest_den", tuple(float(x) / lead for x in den))

    @property
    def is_none(self) -> bool:
        """True for the zero impedance (nothing attached)."""
        return not any(self.num)

    def state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C) of the strictly proper rest Z_r(s), input velocity, output force."""
        r, d = np.array(self.rest_num), np.array(self.rest_den)
        nx = d.size - 1
        if nx == 0 or not np.any(r):
            return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0))
        # controllable canonical form of r(s)/d(s), d monic
        A = np.zeros((nx, nx))
        A[0, :] = -d[1:]
        A[1:, :-1] = np.eye(nx - 1)
        B = np.zeros((nx, 1))
        B[0, 0] = 1.0
        C = np.zeros((1, nx))
        C[0, nx - r.size:] = r
        return A, B, C

    def __call__(self, s: complex | np.ndarray) -> complex | np.ndarray:
        """Evaluate Z(s)."""
        return np.polyval(self.num, s) / np.polyval(self.den, s)

    @classmethod
    def from_any(cls, obj: Any, name: str = "impedance") -> "Impedance":
        """Accept an :class:`Impedance`, ``None`` (nothing attached), a spec string
        (see :func:`parse_impedance`), a ``(num, den)`` pair or a python-control
        continuous SISO ``TransferFunction``."""
        if obj is None:
            return NO_IMPEDANCE
        if isinstance(obj, Impedance):
            return obj
        if isinstance(obj, str):
            return parse_impedance(obj, name)
        if hasattr(obj, "num") and hasattr(obj, "den"):  # python-control TransferFunction
            dt = getattr(obj, "dt", 0)
            if dt not in (0, None):
                raise ModelError(f"{name}: a continuous-time transfer function is required, got dt = {dt}")
            num, den = obj.num, obj.den
            if isinstance(num, list):
                if len(num) != 1 or len(num[0]) != 1:
                    raise ModelError(f"{name}: a SISO transfer function is required")
                num, den = num[0][0], den[0][0]
            return cls(tuple(np.ravel(num)), tuple(np.ravel(den)), label="transfer function")
        if isinstance(obj, (tuple, list)) and len(obj) == 2:
            return cls(tuple(np.ravel(obj[0])), tuple(np.ravel(obj[1])))
        raise ModelError(f"{name} = {obj!r}: expected an Impedance, None, a spec string or (num, den)")

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "num": list(self.num), "den": list(self.den)}


NO_IMPEDANCE = Impedance((0.0,), (1.0,), label="none")


def spring(stiffness: float) -> Impedance:
    """Spring termination Z(s) = k/s (the paper's "1/s" operator is k = 1)."""
    k = check_real("spring stiffness", stiffness, nonnegative=True)
    return Impedance((k,), (1.0, 0.0), label=f"spring k={k:g} N/m")


def mass_spring_damper(mass: float, damping: float, stiffness: float) -> Impedance:
    """Z(s) = m s + b + k/s: a limb or object rigidly attached to the device."""
    m = check_real("termination mass", mass, nonnegative=True)
    b = check_real("termination damping", damping, nonnegative=True)
    k = check_real("termination stiffness", stiffness, nonnegative=True)
    return Impedance((m, b, k), (1.0, 0.0), label=f"msd m={m:g} kg, b={b:g} Ns/m, k={k:g} N/m")


def parse_impedance(spec: str, name: str = "--operator") -> Impedance:
    """Parse ``none``, ``spring:k`` or ``msd:m,b,k``.

    Raises
    ------
    ModelError
        Naming ``name`` and the spec when it is malformed.
    """
    allowed = "allowed: none, spring:k, msd:m,b,k (SI units)"
    s = str(spec).strip().lower()
    if s in ("none", ""):
        return NO_IMPEDANCE
    kind, _, args = s.partition(":")
    try:
        vals = [float(a) for a in args.split(",")] if args else []
    except ValueError:
        raise ModelError(f"{name} = {spec!r}: malformed number; {allowed}") from None
    try:
        if kind == "spring" and len(vals) == 1:
            return spring(vals[0])
        if kind == "msd" and len(vals) == 3:
            return mass_spring_damper(*vals)
    except ModelError as e:
        raise ModelError(f"{name} = {spec!r}: {e}; {allowed}") from None
    raise ModelError(f"{name} = {spec!r}: not understood; {allowed}")


# ----------------------------------------------------------------------- controllers
@dataclass(frozen=True)
class SpringDamper:
    """Virtual spring-damper H(z) = K + B (z - 1) / (T z)  (eq. 23).

    Parameters
    ----------
    stiffness : float
        K in N/m, >= 0.
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

    stiffness: float
    damping: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "stiffness", check_real("stiffness", self.stiffness, nonnegative=True))
        object.__setattr__(self, "damping", check_real("virtual damping", self.damping))

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        """(num, den) of H(z) in z, highest power first."""
        K, B, T = self.stiffness, self.damping, period
        return np.array([K * T + B, -B]) / T, np.array([1.0, 0.0])

    def with_stiffness(self, K: float) -> "SpringDamper":
        return dataclasses.replace(self, stiffness=K)


@dataclass(frozen=True)
class DiscreteController:
    """Any proper discrete transfer function H(z) = num(z)/den(z) (highest power first).
    It has no stiffness parameter, so :func:`critical_stiffness` does not apply."""

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

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.num), np.array(self.den)


Controller = Union[SpringDamper, DiscreteController]


def _check_fraction(name: str, value: Any) -> float:
    v = check_real(name, value, nonnegative=True)
    if not v < 1.0:
        raise ModelError(f"{name} = {v}: must be in [0, 1) (the part of t_d/T beyond whole samples)")
    return v


def delay_from_seconds(name: str, seconds: Any, period: float) -> tuple[int, float]:
    """Split a delay in seconds into whole samples and a fraction in [0, 1); a
    fraction within 1e-9 of a whole sample snaps to it (t_d = nT is exactly integer)."""
    t = check_real(name, seconds, nonnegative=True)
    d = t / period
    n = int(round(d))
    if abs(d - n) <= 1e-9 * max(1.0, d):
        return n, 0.0
    n = int(np.floor(d))
    return n, min(d - n, np.nextafter(1.0, 0.0))


def _check_controller(name: str, c: Any) -> Controller:
    if not isinstance(c, (SpringDamper, DiscreteController)):
        raise ModelError(f"{name} = {c!r}: must be a SpringDamper or a DiscreteController")
    return c


# ----------------------------------------------------------------------------- loops
@dataclass(frozen=True)
class HapticLoop:
    """Sampled-data haptic virtual environment (Fig. 2a).

    The device position is sampled every ``period`` seconds, the virtual
    environment H(z) is computed with ``delay_samples`` samples of delay
    (t_d = n T) and its force is returned through a zero-order hold.

    Parameters
    ----------
    device : Device
    controller : SpringDamper or DiscreteController
        H(z), eq. (23).
    operator : Impedance, str or None
        Z_h(s), rigidly attached to the handle. ``None`` means no operator.
    period : float
        Sampling period T in s, > 0.
    delay_samples : int
        n >= 0.
    """

    device: Device
    controller: Controller
    operator: Any = None
    period: float = 1e-3
    delay_samples: int = 0
    fractional_delay: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.device, Device):
            raise ModelError(f"device = {self.device!r}: must be a Device")
        _check_controller("controller", self.controller)
        object.__setattr__(self, "operator", Impedance.from_any(self.operator, "operator"))
        object.__setattr__(self, "period", check_period("period", self.period))
        object.__setattr__(self, "delay_samples", check_delay("delay_samples", self.delay_samples))
        object.__setattr__(self, "fractional_delay",
                           _check_fraction("fractional_delay", self.fractional_delay))
        if self.device.mass + self.operator.mass <= 0:
            raise ModelError("operator mass: device mass plus operator mass must be > 0")

    @property
    def delay_in_samples(self) -> float:
        """t_d / T = n + fractional_delay."""
        return self.delay_samples + self.fractional_delay

    @property
    def delay_s(self) -> float:
        """t_d = (n + fractional_delay) T in seconds."""
        return self.delay_in_samples * self.period

    def with_delay_s(self, seconds: float) -> "HapticLoop":
        """The same loop with a delay of ``seconds`` (any t_d >= 0, not only n T)."""
        n, f = delay_from_seconds("delay_s", seconds, self.period)
        return dataclasses.replace(self, delay_samples=n, fractional_delay=f)

    def with_stiffness(self, K: float) -> "HapticLoop":
        if not isinstance(self.controller, SpringDamper):
            raise ModelError("controller: a SpringDamper is needed to vary the stiffness")
        return dataclasses.replace(self, controller=self.controller.with_stiffness(K))

    def replace(self, **changes: Any) -> "HapticLoop":
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class TeleoperationLoop:
    """Sampled-data position-error-based bilateral teleoperation (Fig. 3, eq. 19-21).

    F_m = C_m(z) [X_m - z^-n X_s],  F_s = C_s(z) [X_s - z^-n X_m]  (eq. 20).

    Parameters
    ----------
    master, slave : Device
    master_controller, slave_controller : SpringDamper or DiscreteController
        C_m(z), C_s(z) (eq. 23); they may differ.
    operator, environment : Impedance, str or None
        Z_h(s) on the master, Z_e(s) on the slave.
    period : float
        T in s, > 0.
    delay_samples : int
        One-way delay n >= 0 in each direction.
    """

    master: Device
    slave: Device
    master_controller: Controller
    slave_controller: Controller
    operator: Any = None
    environment: Any = None
    period: float = 1e-3
    delay_samples: int = 0
    delay_backward_samples: int | None = None
    fractional_delay: float = 0.0
    fractional_delay_backward: float | None = None

    def __post_init__(self) -> None:
        for nm in ("master", "slave"):
            if not isinstance(getattr(self, nm), Device):
                raise ModelError(f"{nm} = {getattr(self, nm)!r}: must be a Device")
        _check_controller("master_controller", self.master_controller)
        _check_controller("slave_controller", self.slave_controller)
        object.__setattr__(self, "operator", Impedance.from_any(self.operator, "operator"))
        object.__setattr__(self, "environment", Impedance.from_any(self.environment, "environment"))
        object.__setattr__(self, "period", check_period("period", self.period))
        object.__setattr__(self, "delay_samples", check_delay("delay_samples", self.delay_samples))
        object.__setattr__(self, "fractional_delay",
                           _check_fraction("fractional_delay", self.fractional_delay))
        if self.delay_backward_samples is not None:
            object.__setattr__(self, "delay_backward_samples",
                               check_delay("delay_backward_samples", self.delay_backward_samples))
        if self.fractional_delay_backward is not None:
            object.__setattr__(self, "fractional_delay_backward",
                               _check_fraction("fractional_delay_backward",
                                               self.fractional_delay_backward))
        for dev, z, nm in ((self.master, self.operator, "operator"),
                           (self.slave, self.environment, "environment")):
            if dev.mass + z.mass <= 0:
                raise ModelError(f"{nm} mass: device mass plus {nm} mass must be > 0")

    @property
    def forward_delay_in_samples(self) -> float:
        """Master -> slave delay / T (the slave's controller sees x_m this late)."""
        return self.delay_samples + self.fractional_delay

    @property
    def backward_delay_in_samples(self) -> float:
        """Slave -> master delay / T (the master's controller sees x_s this late)."""
        n = self.delay_samples if self.delay_backward_samples is None else self.delay_backward_samples
        f = self.fractional_delay if self.fractional_delay_backward is None \
            else self.fractional_delay_backward
        return n + f

    @property
    def symmetric_delay(self) -> bool:
        return self.forward_delay_in_samples == self.backward_delay_in_samples

    @property
    def delay_in_samples(self) -> float:
        """The one-way delay / T when both directions are equal (else the forward one)."""
        return self.forward_delay_in_samples

    @property
    def delay_s(self) -> float:
        return self.forward_delay_in_samples * self.period

    @property
    def delay_backward_s(self) -> float:
        return self.backward_delay_in_samples * self.period

    def with_delays_s(self, forward_s: float, backward_s: float | None = None) -> "TeleoperationLoop":
        """The same loop with master->slave and slave->master delays in seconds
        (any values >= 0; ``backward_s`` defaults to ``forward_s``)."""
        n, f = delay_from_seconds("delay_forward_s", forward_s, self.period)
        if backward_s is None:
            return dataclasses.replace(self, delay_samples=n, fractional_delay=f,
                                       delay_backward_samples=None, fractional_delay_backward=None)
        nb, fb = delay_from_seconds("delay_backward_s", backward_s, self.period)
        return dataclasses.replace(self, delay_samples=n, fractional_delay=f,
                                   delay_backward_samples=nb, fractional_delay_backward=fb)

    def with_stiffness(self, K: float) -> "TeleoperationLoop":
        """Master stiffness K; the slave's scales with it, keeping K_s/K_m (equal
        stiffnesses, the paper's C_m = C_s case, stay equal)."""
        for nm in ("master_controller", "slave_controller"):
            if not isinstance(getattr(self, nm), SpringDamper):
                raise ModelError(f"{nm}: a SpringDamper is needed to vary the stiffness")
        km, ks = self.master_controller.stiffness, self.slave_controller.stiffness
        if km == 0 and ks > 0:
            raise AnalysisError("master_controller: stiffness 0 with a slave stiffness > 0 leaves "
                                "K_s/K_m undefined; set the master's stiffness to vary K")
        ratio = ks / km if km > 0 else 1.0
        return dataclasses.replace(self, master_controller=self.master_controller.with_stiffness(K),
                                   slave_controller=self.slave_controller.with_stiffness(K * ratio))

    def replace(self, **changes: Any) -> "TeleoperationLoop":
        return dataclasses.replace(self, **changes)


Loop = Union[HapticLoop, TeleoperationLoop]


def whole_delay(loop: "HapticLoop | TeleoperationLoop", what: str) -> int:
    """The delay in whole samples (equal both ways for teleoperation), for methods
    derived for t_d = nT only; otherwise an :class:`AnalysisError` naming ``what``."""
    if isinstance(loop, TeleoperationLoop):
        if not loop.symmetric_delay:
            raise AnalysisError(f"{what}: derived for equal delays in both directions; this loop has "
                                f"{loop.forward_delay_in_samples:g} and "
                                f"{loop.backward_delay_in_samples:g} samples")
        d = loop.forward_delay_in_samples
    else:
        d = loop.delay_in_samples
    if d != int(d):
        raise AnalysisError(f"{what}: derived for a whole number of samples of delay "
                            f"(t_d = nT); this loop has t_d = {d:g} T")
    return int(d)


def paper_hve(period: float = 1e-3, delay_samples: int = 0, stiffness: float = 100.0,
              damping: float = 0.0) -> HapticLoop:
    """The HVE of the paper's simulation study (Fig. 5): m = 0.15, b = 0.1, operator 1/s."""
    return HapticLoop(Device(0.15, 0.1), SpringDamper(stiffness, damping), spring(1.0),
                      period, delay_samples)


def paper_peb(period: float = 1e-3, delay_samples: int = 0, stiffness: float = 10.0,
              damping: float = 0.0) -> TeleoperationLoop:
    """The PEB teleoperator of the paper's simulation study (Fig. 6): m = 0.015,
    b = 0.02 for both robots, operator and environment 1/s."""
    dev = Device(0.015, 0.02)
    c = SpringDamper(stiffness, damping)
    return TeleoperationLoop(dev, dev, c, c, spring(1.0), spring(1.0), period, delay_samples)
