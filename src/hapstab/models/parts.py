"""Devices and the impedances rigidly attached to them (operator, environment).

References
----------
N. Miandashti and M. Tavakoli, "Stability of Sampled-Data, Delayed Haptic
Interaction and Teleoperation", IEEE Haptics Symposium 2014 (the paper).
Equation and figure numbers below are the paper's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.errors import ModelError, ModelTypeError, ascii_float, check_poly, check_real
from hapstab.tolerances import COEFF_ZERO

__all__ = ['friction_note', 'Device', 'Impedance', 'NO_IMPEDANCE', 'spring', 'mass_spring_damper',
           'parse_impedance', 'quantize']


# --------------------------------------------------------------------------- devices
@dataclass(frozen=True)
class Device:
    """A 1-DOF haptic interface or robot:
    ``mass * a + damping * v + friction = force``.

    Parameters
    ----------
    mass : float
        m in kg, > 0.
    damping : float
        Physical viscous damping b in N*s/m, >= 0.
    coulomb_friction : float
        Coulomb (dry) friction level f_c in N, >= 0 (default 0: none). It acts on the
        velocity of the port's one rigid body (the device with the operator /
        environment rigidly attached to it): ``-f_c sign(v)`` while it slides, and
        while it sticks (v = 0) whatever force up to f_c keeps it there. Only
        :func:`hapstab.simulate` models it (exactly, stick-slip with events located
        between samples); the linear analyses analyse the friction-free loop and say
        so in their results.
    """

    mass: float
    damping: float = 0.0
    coulomb_friction: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass", check_real("mass", self.mass, positive=True))
        object.__setattr__(self, "damping",
                           check_real("damping", self.damping, nonnegative=True))
        object.__setattr__(self, "coulomb_friction",
                           check_real("coulomb_friction", self.coulomb_friction,
                                      nonnegative=True))

    def to_dict(self) -> dict[str, Any]:
        """The device as JSON-ready values, units in the keys (``coulomb_friction_N``
        only when the device has friction)."""
        d: dict[str, Any] = {"mass_kg": self.mass, "damping_N_s_per_m": self.damping}
        if self.coulomb_friction > 0:
            d["coulomb_friction_N"] = self.coulomb_friction
        return d


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
    rest_num: tuple[float, ...] = field(init=False, repr=False)
    rest_den: tuple[float, ...] = field(init=False, repr=False)

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
        nz = np.flatnonzero(np.abs(r) > COEFF_ZERO * max(1.0, np.abs(num).max()))
        r = r[nz[0]:] if nz.size else np.zeros(1)
        lead = den[0]
        object.__setattr__(self, "num", tuple(float(x) for x in _poly("num", self.num)))
        object.__setattr__(self, "den", tuple(float(x) for x in _poly("den", self.den)))
        object.__setattr__(self, "mass", mz)
        object.__setattr__(self, "damping", dz)
        object.__setattr__(self, "stiffness", float(k))
        object.__setattr__(self, "rest_num", tuple(float(x / lead) for x in r))
        object.__setattr__(self, "rest_den", tuple(float(x / lead) for x in den))

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
        """Evaluate Z(s).

        Raises
        ------
        ModelTypeError
            ``s`` is not a number or an array of numbers (``None``, a string).
        """
        if isinstance(s, (str, bytes, bool)) or s is None:
            raise ModelTypeError(f"s = {s!r:.60}: must be a (complex) number or an array of "
                                 f"numbers (got {type(s).__name__})")
        try:
            x = np.asarray(s)
        except (TypeError, ValueError):
            x = np.asarray(None)
        if x.dtype.kind not in "biufc":
            raise ModelTypeError(f"s = {s!r:.60}: must be a (complex) number or an array of "
                                 f"numbers (got {type(s).__name__})")
        with np.errstate(all="ignore"):       # NaN in, NaN out; at a pole inf: values
            return np.polyval(self.num, s) / np.polyval(self.den, s)

    @classmethod
    def from_any(cls, obj: Any, name: str = "impedance") -> Impedance:
        """Accept an :class:`Impedance`, ``None`` (nothing attached), a spec string
        (see :func:`parse_impedance`), a ``(num, den)`` pair or a python-control
        continuous SISO ``TransferFunction``."""
        if obj is None:
            return NO_IMPEDANCE
        if isinstance(obj, Impedance):
            return obj
        if isinstance(obj, str):
            return parse_impedance(obj, name)
        from hapstab.models.interop import continuous, is_control_system

        if is_control_system(obj):        # python-control: a continuous SISO Z(s)
            num, den = continuous(obj, name)
            return cls(tuple(num), tuple(den), label="transfer function")
        if isinstance(obj, (tuple, list)) and len(obj) == 2:
            return cls(tuple(np.ravel(obj[0])), tuple(np.ravel(obj[1])))
        raise ModelError(f"{name} = {obj!r}: expected an Impedance, None, a spec string or (num, den)")

    def to_dict(self) -> dict[str, Any]:
        """The impedance as JSON-ready values: Z(s) = num/den (velocity to force, highest
        power first) and its mass, damping and spring to ground."""
        return {"label": self.label, "num": list(self.num), "den": list(self.den),
                "mass_kg": self.mass, "damping_N_s_per_m": self.damping,
                "stiffness_N_per_m": self.stiffness}


NO_IMPEDANCE = Impedance((0.0,), (1.0,), label="none")


def spring(stiffness: float) -> Impedance:
    """Spring termination Z(s) = k/s (the paper's "1/s" operator is k = 1).

    Parameters
    ----------
    stiffness : float
        k in N/m, >= 0.

    Returns
    -------
    Impedance
    """
    k = check_real("spring stiffness", stiffness, nonnegative=True)
    return Impedance((k,), (1.0, 0.0), label=f"spring k={k:g} N/m")


def mass_spring_damper(mass: float, damping: float, stiffness: float) -> Impedance:
    """Z(s) = m s + b + k/s: a limb or object rigidly attached to the device.

    Parameters
    ----------
    mass : float
        m in kg, >= 0 (added to the device's mass).
    damping : float
        b in N*s/m, >= 0.
    stiffness : float
        k in N/m, >= 0.

    Returns
    -------
    Impedance
    """
    m = check_real("termination mass", mass, nonnegative=True)
    b = check_real("termination damping", damping, nonnegative=True)
    k = check_real("termination stiffness", stiffness, nonnegative=True)
    return Impedance((m, b, k), (1.0, 0.0), label=f"msd m={m:g} kg, b={b:g} Ns/m, k={k:g} N/m")


def parse_impedance(spec: str, name: str = "--operator") -> Impedance:
    """Parse ``none``, ``spring:k`` or ``msd:m,b,k``.

    Parameters
    ----------
    spec : str
        ``none`` (or empty), ``spring:k`` (k in N/m) or ``msd:m,b,k`` (kg, N*s/m, N/m).
    name : str
        What the spec is for, named in the error message (e.g. ``"--operator"``).

    Returns
    -------
    Impedance
        :data:`NO_IMPEDANCE` for ``none``.

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
        vals = [ascii_float(a) for a in args.split(",")] if args else []
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


def friction_note(loop: Any) -> str:
    """What a linear analysis says of a loop whose devices have Coulomb friction: that it
    analysed the friction-free loop, and what that means with friction.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop.

    Returns
    -------
    str
        Empty when no device has friction.

    References
    ----------
    J. E. Colgate and G. G. Schenkel, "Passivity of a class of sampled-data systems:
    application to haptic interfaces", J. Robotic Systems 14(1), 1997 (a device's
    dissipation buys passivity); J. J. Abbott and A. M. Okamura, "Effects of position
    quantization and sampling rate on virtual-wall passivity", IEEE Trans. Robotics
    21(5), 2005 (Coulomb friction enlarges the passive region).
    """
    devs = [(n, getattr(loop, n)) for n in ("device", "master", "slave") if hasattr(loop, n)]
    fc = [f"{n} {d.coulomb_friction:g} N" for n, d in devs if d.coulomb_friction > 0]
    if not fc:
        return ""
    return ("NOTE: this linear analysis is of the friction-free loop; the Coulomb friction "
            f"({', '.join(fc)}) is not in it. Friction is a force of at most f_c that only "
            "dissipates energy: where the linear loop is stable every run stays bounded (a "
            "bounded force on an exponentially stable loop), and a loop passive without "
            "friction stays passive with it, so its limits are conservative (Abbott & Okamura "
            "2005 show friction enlarges the passive region); where it is unstable, large "
            "motions still grow, but friction may hold a small one at rest or in a limit cycle: "
            "simulate to see")


def quantize(x: np.ndarray, resolution: float, quantizer: str = "floor") -> np.ndarray:
    """The encoder's reading of ``x`` (the simulator's encoder and the describing
    function's quantiser, :mod:`hapstab.analysis.nonlinear.harmonic`): ``Δ floor(x/Δ)`` or the
    nearest multiple of Δ (ties away from zero, not to even).

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
