"""The two loops of the paper: the HVE (Fig. 2a) and PEB teleoperation (Fig. 3).

References
----------
N. Miandashti and M. Tavakoli, "Stability of Sampled-Data, Delayed Haptic
Interaction and Teleoperation", IEEE Haptics Symposium 2014 (the paper).
Equation and figure numbers below are the paper's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from hapstab.errors import (
    AnalysisError,
    ArgumentTypeError,
    ModelError,
    check_delay,
    check_period,
    check_real,
)
from hapstab.models.controllers import (
    Controller,
    SpringDamper,
    has_stiffness,
    stiffness_controller,
    stiffness_ratios,
)
from hapstab.models.delays import DELAY_SNAP, check_fraction, delay_from_seconds, split_delay
from hapstab.models.interop import check_controller as _check_controller
from hapstab.models.parts import Device, Impedance

__all__ = ["split_delay", "DELAY_SNAP", "HapticLoop", "TeleoperationLoop", "delay_from_seconds",
           "whole_delay", "require_loop", "describe", "parameters"]


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
        The haptic device (mass in kg, damping in N*s/m).
    controller : SpringDamper or DiscreteController
        H(z), eq. (23). Default ``SpringDamper()`` (K = B = 0): enough for
        :func:`~hapstab.critical_stiffness`, which varies K.
    operator : Impedance, str or None
        Z_h(s), rigidly attached to the handle. ``None`` means no operator.
    period : float
        Sampling period T in s, > 0.
    delay_samples : int
        n >= 0, the whole samples of delay.
    fractional_delay : float
        The part of the delay below one sample, in [0, 1) of T: t_d = (n + f) T.
        Usually set through :meth:`with_delay_s`.
    """

    device: Device
    controller: Controller = field(default_factory=SpringDamper)
    operator: Any = None
    period: float = 1e-3
    delay_samples: int = 0
    fractional_delay: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.device, Device):
            raise ModelError(f"device = {self.device!r}: must be a Device")
        object.__setattr__(self, "controller",
                           _check_controller("controller", self.controller, self.period))
        object.__setattr__(self, "operator", Impedance.from_any(self.operator, "operator"))
        object.__setattr__(self, "period", check_period("period", self.period))
        _check_filters(self.controllers, self.period)
        object.__setattr__(self, "delay_samples", check_delay("delay_samples", self.delay_samples))
        object.__setattr__(self, "fractional_delay",
                           check_fraction("fractional_delay", self.fractional_delay))
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

    def with_delay_s(self, seconds: float) -> HapticLoop:
        """The same loop with a delay of ``seconds`` (any t_d >= 0, not only n T)."""
        n, f = delay_from_seconds("delay_s", seconds, self.period)
        return dataclasses.replace(self, delay_samples=n, fractional_delay=f)

    def with_stiffness(self, K: float) -> HapticLoop:
        return dataclasses.replace(self, controller=stiffness_controller(self.controller).with_stiffness(K))

    def replace(self, **changes: Any) -> HapticLoop:
        return dataclasses.replace(self, **changes)

    #: The loop's kind, as the CLI names it.
    kind: ClassVar[str] = "hve"
    #: Its ports' names, and its controllers' (the fields they live in), in their order.
    port_names: ClassVar[tuple[str, ...]] = ("device",)
    controller_names: ClassVar[tuple[str, ...]] = ("controller",)

    def to_dict(self) -> dict[str, Any]:
        """The loop as JSON-ready values (what a result was computed for), units in keys."""
        return {"kind": self.kind, "period_s": self.period,
                "delay_samples": float(self.delay_in_samples), "delay_s": self.delay_s,
                "device": self.device.to_dict(), "operator": self.operator.to_dict(),
                "controller": self.controller.to_dict()}

    def _repr_html_(self) -> str:
        from hapstab.results import html_table

        return html_table(type(self).__name__, parameters(self))

    @property
    def controllers(self) -> tuple[Controller, ...]:
        """The controller of each port (one: the virtual environment)."""
        return (self.controller,)

    def with_controllers(self, controller: Controller) -> HapticLoop:
        """The same loop with ``controller`` on every port."""
        return dataclasses.replace(self, controller=controller)

    def with_whole_delay(self, n: int, period: float | None = None) -> HapticLoop:
        """The same loop with a delay of ``n`` whole samples (and period ``period``)."""
        return dataclasses.replace(self, delay_samples=n, fractional_delay=0.0,
                                   period=self.period if period is None else period)


@dataclass(frozen=True)
class TeleoperationLoop:
    """Sampled-data position-error-based bilateral teleoperation (Fig. 3, eq. 19-21),
    optionally with position and force scaling.

    F_m = beta C_m(z) [alpha X_m - z^-n X_s],  F_s = C_s(z) [X_s - alpha z^-n X_m];

    with alpha = beta = 1 this is eq. (20) exactly. The scaled ideal response is
    x_s = alpha x_m in free motion and, with C_m = C_s, a master force beta times the
    slave's in steady contact: the operator feels beta times the environment's force
    (Yokokohji & Yoshikawa's scaled ideal response; the paper's ref. [10], Jazayeri
    & Tavakoli 2013, analyses scaled sampled-data teleoperators). K (``with_stiffness``,
    K_max) is still the master controller's stiffness, so the master's net position gain
    is alpha beta K.

    Parameters
    ----------
    master, slave : Device
        The two robots (mass in kg, damping in N*s/m).
    master_controller, slave_controller : SpringDamper or DiscreteController
        C_m(z), C_s(z) (eq. 23); they may differ. Default ``SpringDamper()`` each.
    operator, environment : Impedance, str or None
        Z_h(s) on the master, Z_e(s) on the slave.
    period : float
        T in s, > 0.
    delay_samples : int
        One-way delay n >= 0 in each direction (master -> slave; also slave -> master
        unless ``delay_backward_samples`` is given).
    delay_backward_samples : int or None
        Slave -> master delay in whole samples; ``None``: the same as ``delay_samples``.
    fractional_delay : float
        The part of the master -> slave delay below one sample, in [0, 1) of T.
    fractional_delay_backward : float or None
        The same for slave -> master; ``None``: the same as ``fractional_delay``.
        Usually set through :meth:`with_delays_s`.
    position_scale : float
        alpha > 0: the slave follows alpha times the master's motion (default 1).
    force_scale : float
        beta > 0: the master's controller force is scaled by beta (default 1).

    References
    ----------
    Y. Yokokohji and T. Yoshikawa, "Bilateral control of master-slave manipulators for
    ideal kinesthetic coupling", IEEE Trans. Robot. Autom. 10(5), 1994 (scaled ideal
    response); A. Jazayeri and M. Tavakoli, Control Engineering Practice 21(8), 2013
    (the paper's [10]).
    """

    master: Device
    slave: Device
    master_controller: Controller = field(default_factory=SpringDamper)
    slave_controller: Controller = field(default_factory=SpringDamper)
    operator: Any = None
    environment: Any = None
    period: float = 1e-3
    delay_samples: int = 0
    delay_backward_samples: int | None = None
    fractional_delay: float = 0.0
    fractional_delay_backward: float | None = None
    position_scale: float = 1.0
    force_scale: float = 1.0

    def __post_init__(self) -> None:
        for nm in ("position_scale", "force_scale"):
            object.__setattr__(self, nm, check_real(nm, getattr(self, nm), positive=True))
        for nm in ("master", "slave"):
            if not isinstance(getattr(self, nm), Device):
                raise ModelError(f"{nm} = {getattr(self, nm)!r}: must be a Device")
        for nm in ("master_controller", "slave_controller"):
            object.__setattr__(self, nm, _check_controller(nm, getattr(self, nm), self.period))
        object.__setattr__(self, "operator", Impedance.from_any(self.operator, "operator"))
        object.__setattr__(self, "environment", Impedance.from_any(self.environment, "environment"))
        object.__setattr__(self, "period", check_period("period", self.period))
        _check_filters(self.controllers, self.period)
        object.__setattr__(self, "delay_samples", check_delay("delay_samples", self.delay_samples))
        object.__setattr__(self, "fractional_delay",
                           check_fraction("fractional_delay", self.fractional_delay))
        if self.delay_backward_samples is not None:
            object.__setattr__(self, "delay_backward_samples",
                               check_delay("delay_backward_samples", self.delay_backward_samples))
        if self.fractional_delay_backward is not None:
            object.__setattr__(self, "fractional_delay_backward",
                               check_fraction("fractional_delay_backward",
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

    def with_delays_s(self, forward_s: float, backward_s: float | None = None) -> TeleoperationLoop:
        """The same loop with master->slave and slave->master delays in seconds
        (any values >= 0; ``backward_s`` defaults to ``forward_s``)."""
        n, f = delay_from_seconds("delay_forward_s", forward_s, self.period)
        if backward_s is None:
            return dataclasses.replace(self, delay_samples=n, fractional_delay=f,
                                       delay_backward_samples=None, fractional_delay_backward=None)
        nb, fb = delay_from_seconds("delay_backward_s", backward_s, self.period)
        return dataclasses.replace(self, delay_samples=n, fractional_delay=f,
                                   delay_backward_samples=nb, fractional_delay_backward=fb)

    def with_delay_s(self, seconds: float) -> TeleoperationLoop:
        """The same loop with a delay of ``seconds`` in both directions (as the HVE's
        :meth:`HapticLoop.with_delay_s`)."""
        return self.with_delays_s(seconds)

    def with_stiffness(self, K: float) -> TeleoperationLoop:
        """Master stiffness K; the slave's scales with it, keeping K_s/K_m (equal
        stiffnesses, the paper's C_m = C_s case, stay equal)."""
        cm = stiffness_controller(self.master_controller, "master_controller")
        cs = stiffness_controller(self.slave_controller, "slave_controller")
        ratios = stiffness_ratios((cm.stiffness, cs.stiffness))
        if ratios is None:
            raise AnalysisError("master_controller: stiffness 0 with a slave stiffness > 0 leaves "
                                "K_s/K_m undefined; set the master's stiffness to vary K")
        return dataclasses.replace(self, master_controller=cm.with_stiffness(K),
                                   slave_controller=cs.with_stiffness(K * ratios[1]))

    def replace(self, **changes: Any) -> TeleoperationLoop:
        return dataclasses.replace(self, **changes)

    #: The loop's kind, as the CLI names it.
    kind: ClassVar[str] = "peb"
    #: Its ports' names, and its controllers' (the fields they live in), in their order.
    port_names: ClassVar[tuple[str, ...]] = ("master", "slave")
    controller_names: ClassVar[tuple[str, ...]] = ("master_controller", "slave_controller")

    def to_dict(self) -> dict[str, Any]:
        """The loop as JSON-ready values (what a result was computed for), units in keys."""
        return {"kind": self.kind, "period_s": self.period,
                "delay_forward_samples": float(self.forward_delay_in_samples),
                "delay_backward_samples": float(self.backward_delay_in_samples),
                "master": self.master.to_dict(), "slave": self.slave.to_dict(),
                "operator": self.operator.to_dict(), "environment": self.environment.to_dict(),
                "master_controller": self.master_controller.to_dict(),
                "slave_controller": self.slave_controller.to_dict(),
                "position_scale": self.position_scale, "force_scale": self.force_scale}

    @property
    def scaled(self) -> bool:
        """Whether position or force scaling is on (alpha or beta not 1)."""
        return self.position_scale != 1.0 or self.force_scale != 1.0

    def _repr_html_(self) -> str:
        from hapstab.results import html_table

        return html_table(type(self).__name__, parameters(self))

    @property
    def controllers(self) -> tuple[Controller, ...]:
        """The controller of each port: master, slave."""
        return (self.master_controller, self.slave_controller)

    def with_controllers(self, controller: Controller) -> TeleoperationLoop:
        """The same loop with ``controller`` on every port (C_m = C_s)."""
        return dataclasses.replace(self, master_controller=controller, slave_controller=controller)

    def with_whole_delay(self, n: int, period: float | None = None) -> TeleoperationLoop:
        """The same loop with ``n`` whole samples of delay in both directions (and
        period ``period``)."""
        return dataclasses.replace(self, delay_samples=n, fractional_delay=0.0,
                                   delay_backward_samples=None, fractional_delay_backward=None,
                                   period=self.period if period is None else period)


Loop = HapticLoop | TeleoperationLoop


def parameters(loop: HapticLoop | TeleoperationLoop) -> list[tuple[str, str]]:
    """The loop's parameters as (name, value with unit) pairs, e.g. ``("device mass",
    "0.15 kg")``.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop.

    Returns
    -------
    list of (str, str)
    """
    units = {"kg": "kg", "N_s_per_m": "N*s/m", "N_per_m": "N/m", "s": "s", "samples": "samples",
             "N": "N"}

    def flat(d: dict[str, Any], prefix: str) -> list[tuple[str, str]]:
        out: list[tuple[str, str]] = []
        for k, v in d.items():
            if isinstance(v, dict):
                out += flat(v, f"{prefix}{k} ")
            elif isinstance(v, (int, float)) and not isinstance(v, bool):
                name, unit = k, ""
                for suffix, u in units.items():
                    if k.endswith("_" + suffix):
                        name, unit = k[: -len(suffix) - 1], " " + u
                out.append((f"{prefix}{name}".replace("_", " "), f"{v:g}{unit}"))
            elif isinstance(v, str) and k in ("kind", "label", "type"):
                out.append((f"{prefix}{k}".replace("_", " "), v))
        return out

    return flat(loop.to_dict(), "")


def describe(loop: HapticLoop | TeleoperationLoop) -> str:
    """The loop's parameters in one line, for messages (``device mass 0.15 kg, ...``).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop.

    Returns
    -------
    str
    """
    return ", ".join(f"{k} {v}" for k, v in parameters(loop) if not k.endswith(("kind", "label",
                                                                                 "type")))


def headline(loop: HapticLoop | TeleoperationLoop) -> str:
    """The model in a figure title's line: devices, terminations, T and the delay
    (``device 0.3 kg, 0.5 N*s/m; operator msd m=0.5 kg, ...; T = 1 ms, t_d = 20 ms``).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop.

    Returns
    -------
    str
    """
    def dev(name: str, d: Device) -> str:
        fc = f", f_c {d.coulomb_friction:g} N" if d.coulomb_friction else ""
        return f"{name} {d.mass:g} kg, {d.damping:g} N*s/m{fc}"

    def term(name: str, z: Any) -> str:
        return f"{name} {getattr(z, 'label', 'none') if z is not None else 'none'}"

    if isinstance(loop, TeleoperationLoop):
        parts = [dev("master", loop.master), dev("slave", loop.slave),
                 term("operator", loop.operator), term("environment", loop.environment)]
        delay = f"t_d = {loop.delay_s * 1e3:.4g} ms" + (
            f" / {loop.delay_backward_s * 1e3:.4g} ms" if loop.delay_backward_s != loop.delay_s
            else "")
        if loop.scaled:
            parts.append(f"scaling alpha = {loop.position_scale:g}, beta = {loop.force_scale:g}")
        gains = getattr(loop, "force_gains", None)        # Lawrence's 4-channel loop
        if gains is not None:
            c1, c4 = loop.controllers[2:]
            parts.append(f"C_1 {_gain(c1)}, C_4' {_gain(c4)}, " + ", ".join(
                f"{FORCE_NAMES[k]} = {v:g}" for k, v in gains().items() if v))
    else:
        parts = [dev("device", loop.device), term("operator", loop.operator)]
        delay = f"t_d = {loop.delay_s * 1e3:.4g} ms"
    filters = {str(vf) for c in loop.controllers[:2]
               if (vf := getattr(c, "velocity_filter", None)) is not None}
    if filters:
        parts.append("damper on " + " / ".join(sorted(filters)) + " velocity")
    back = getattr(loop, "backward_delay_in_samples", loop.delay_in_samples)
    n = f"{loop.delay_in_samples:.4g}" + (f" / {back:.4g}" if back != loop.delay_in_samples
                                          else "")      # unequal delays: both, as t_d
    return "; ".join([*parts, f"T = {loop.period * 1e3:.4g} ms, {delay} ({n} samples)"])


#: Lawrence's names of the 4-channel loop's force gains (for headlines).
FORCE_NAMES = {"force_to_master": "C_2", "force_to_slave": "C_3", "slave_force_feedback": "C_5",
               "master_force_feedback": "C_6"}


def _gain(c: Controller) -> str:
    """A position controller in a headline: ``K 10, B 0.5`` or ``H(z)``."""
    gains = c.gains()
    if gains is None:
        return f"K {c.stiffness:g} P(z) + Q(z)" if has_stiffness(c) else "H(z)"
    vf = getattr(c, "velocity_filter", None)
    return f"K {gains[0]:g}, B {gains[1]:g}" + (f" on {vf}" if vf else "")


def _check_filters(controllers: tuple[Controller, ...], period: float) -> None:
    """Refuse a velocity filter degenerate at ``period`` (its pole; see
    :meth:`VelocityFilter.pole`)."""
    for c in controllers:
        vf = getattr(c, "velocity_filter", None)
        if vf is not None:
            vf.pole(period)


def require_loop(loop: Any, name: str = "loop") -> None:
    """Refuse anything that is not a loop, with the one message every analysis gives.

    Parameters
    ----------
    loop : object
        What the caller was given.
    name : str
        The argument's name in the message.

    Raises
    ------
    ArgumentTypeError
        (a :class:`TypeError` and a :class:`~hapstab.errors.HapstabError`) if ``loop`` is
        neither a :class:`HapticLoop` nor a :class:`TeleoperationLoop`.
    """
    if not isinstance(loop, (HapticLoop, TeleoperationLoop)):
        raise ArgumentTypeError(f"{name} = {_short(loop)}: must be a HapticLoop or a "
                                f"TeleoperationLoop (got {type(loop).__name__})")


def _short(x: Any) -> str:
    r = repr(x)
    return r if len(r) <= 60 else r[:57] + "..."


def whole_delay(loop: HapticLoop | TeleoperationLoop, what: str) -> int:
    """The delay in whole samples (equal both ways for teleoperation), for methods
    derived for t_d = nT only; otherwise an :class:`AnalysisError` naming ``what``.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop whose delay is needed.
    what : str
        The method that needs it, named in the error (e.g. ``"the circle criterion"``).

    Returns
    -------
    int
        n, the delay in samples (t_d = n T).
    """
    if isinstance(loop, TeleoperationLoop):
        if not loop.symmetric_delay:
            raise AnalysisError(f"{what}: derived for equal delays in both directions; this loop has "
                                f"delay forward {loop.forward_delay_in_samples:g} and delay "
                                f"backward {loop.backward_delay_in_samples:g} samples")
        d = loop.forward_delay_in_samples
    else:
        d = loop.delay_in_samples
    if d != int(d):
        raise AnalysisError(f"{what}: derived for a whole number of samples of delay "
                            f"(t_d = nT); this loop has t_d = {d:g} T")
    return int(d)
