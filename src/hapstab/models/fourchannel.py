"""Lawrence's 4-channel teleoperator, sampled and delayed: PEB, force reflection and
the 2- and 3-channel architectures are parameter choices of it.

References
----------
D. A. Lawrence, "Stability and transparency in bilateral teleoperation", IEEE Trans.
Robot. Autom. 9(5), 1993 (the architecture). K. Hashtrudi-Zaad and S. E. Salcudean,
"Analysis of control architectures for teleoperation systems with impedance/admittance
master and slave manipulators", Int. J. Robot. Res. 20(6), 2001 (the sign convention
of C_1 ... C_6 used here).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

from hapstab.errors import AnalysisError, ModelError, check_real
from hapstab.models.controllers import Controller, SpringDamper, spring_damper, stiffness_ratios
from hapstab.models.interop import check_controller
from hapstab.models.loops import FORCE_NAMES, TeleoperationLoop

__all__ = ["FourChannelLoop", "FORCE_GAINS"]

#: The four force gains (dimensionless, N per N), Lawrence's name of each.
FORCE_GAINS = FORCE_NAMES


@dataclass(frozen=True)
class FourChannelLoop(TeleoperationLoop):
    """Sampled-data 4-channel bilateral teleoperator (Lawrence 1993) with delay.

    Every controller acts on positions sampled every T (as PEB's, eq. 20) and on
    forces measured at the same instants; the actuators' forces are held (ZOH):

    * master: ``F_cm = -C_m x_m + C_4' z^-n_b x_s + C_6 F_h - C_2 z^-n_b F_e``
    * slave: ``F_cs = -C_s x_s + C_1 z^-n_f x_m + C_3 z^-n_f F_h - C_5 F_e``

    with F_h the force the operator applies to the master and F_e the force the slave
    applies to the environment, each measured just before the sample (kT^-; a
    termination with mass feels the force held over the previous sample). Here
    ``C_4' = -C_4`` in Lawrence's and Hashtrudi-Zaad & Salcudean's convention
    (``F_cm = -C_m V_h - C_4 V_e + ...``), so that every position controller is a
    :class:`SpringDamper` with K >= 0. PEB (eq. 20) is ``C_1 = C_s``, ``C_4' = C_m`` and
    no force channel (the defaults); position-force (force reflection) is ``C_m = 0``
    (or a damper), ``C_4' = 0``, ``C_1 = C_s``, ``C_2 = k_f``; transparency needs
    ``C_1 = Z_s + C_s``, ``C_4' = Z_m + C_m``, ``C_2 = 1 + C_6``, ``C_3 = 1 + C_5``
    (Lawrence), which with position controllers holds only approximately.

    K (``with_stiffness``, K_max) is the master's local stiffness, or the slave's
    when the master's is 0; every other position controller keeps its stiffness
    ratio to it. The force gains do not vary with K.

    Parameters
    ----------
    master, slave, master_controller, slave_controller, operator, environment, period
        As for :class:`~hapstab.models.TeleoperationLoop`; the two controllers are the
        local position controllers C_m and C_s.
    delay_samples, delay_backward_samples : int
        Whole samples of delay master -> slave (C_1, C_3) and slave -> master (C_4, C_2).
    fractional_delay, fractional_delay_backward : float
        Must be 0: whole samples only (refused otherwise).
    position_scale, force_scale : float
        Must be 1: scale the channels' gains instead (refused otherwise).
    slave_from_master : SpringDamper or None
        C_1: the slave's controller on the delayed master position (``None``: C_s).
    master_from_slave : SpringDamper or None
        C_4' = -C_4: the master's controller on the delayed slave position (``None``: C_m).
    force_to_master, force_to_slave, slave_force_feedback, master_force_feedback : float
        C_2, C_3, C_5, C_6 (N/N, default 0).

    Raises
    ------
    ModelError
        A fractional delay or position/force scaling (express scaling in the gains).
    """

    slave_from_master: Any = None
    master_from_slave: Any = None
    force_to_master: float = 0.0
    force_to_slave: float = 0.0
    slave_force_feedback: float = 0.0
    master_force_feedback: float = 0.0

    #: The loop's kind, as the CLI names it.
    kind: ClassVar[str] = "4ch"
    #: Its position controllers' names, in :attr:`controllers`' order.
    controller_names: ClassVar[tuple[str, ...]] = ("master_controller", "slave_controller",
                                                   "slave_from_master", "master_from_slave")

    def __post_init__(self) -> None:
        super().__post_init__()
        for nm in ("slave_from_master", "master_from_slave"):   # None: follows C_s / C_m
            if getattr(self, nm) is not None:
                check_controller(nm, getattr(self, nm))
        for nm in FORCE_GAINS:
            object.__setattr__(self, nm, check_real(nm, getattr(self, nm)))
        for nm in ("position_scale", "force_scale"):
            if getattr(self, nm) != 1.0:
                raise ModelError(f"{nm} = {getattr(self, nm):g}: a FourChannelLoop has no scaling "
                                 "factors; allowed: 1 (scale the channels' gains instead)")
        for nm in ("fractional_delay", "fractional_delay_backward"):
            if getattr(self, nm):
                raise ModelError(f"{nm} = {getattr(self, nm):g}: a FourChannelLoop takes whole "
                                 "samples of delay only; allowed: 0")

    @property
    def position_controllers(self) -> tuple[Controller, ...]:
        """C_m, C_s, C_1, C_4' (a C_1 or C_4' left None is C_s or C_m, also after
        ``replace``), in the order K's rule reads them."""
        c1 = self.slave_controller if self.slave_from_master is None else self.slave_from_master
        c4 = self.master_controller if self.master_from_slave is None else self.master_from_slave
        return (self.master_controller, self.slave_controller, c1, c4)

    @property
    def controllers(self) -> tuple[Controller, ...]:
        """The position controllers (C_m, C_s, C_1, C_4')."""
        return self.position_controllers

    @property
    def stiffness_reference(self) -> int:
        """Which controller K names: 0 (C_m) unless its stiffness is 0, then 1 (C_s)."""
        cm = self.master_controller
        return 1 if isinstance(cm, SpringDamper) and cm.stiffness == 0 else 0

    def with_stiffness(self, K: float) -> FourChannelLoop:
        """K on the reference controller (C_m, or C_s when C_m's stiffness is 0); every
        other position controller keeps its stiffness ratio to it."""
        names = self.controller_names
        cs = [spring_damper(c, nm) for c, nm in zip(self.position_controllers, names, strict=True)]
        ref = self.stiffness_reference
        order = [ref] + [i for i in range(4) if i != ref]
        ratios = stiffness_ratios([cs[i].stiffness for i in order])
        if ratios is None:
            raise AnalysisError("master_controller, slave_controller: both local stiffnesses are 0 "
                                "while a transmitted one is not, so K is undefined; give C_m or "
                                "C_s a stiffness > 0 to vary K")
        new: dict[str, Any] = {names[i]: cs[i].with_stiffness(K * r)
                               for i, r in zip(order, ratios, strict=True)
                               if getattr(self, names[i]) is not None}   # None follows
        return dataclasses.replace(self, **new)

    def with_controllers(self, controller: Controller) -> FourChannelLoop:
        """The same loop with ``controller`` as every position controller (PEB's
        C_1 = C_s, C_4' = C_m, with C_m = C_s)."""
        return dataclasses.replace(self, master_controller=controller, slave_controller=controller,
                                   slave_from_master=None, master_from_slave=None)

    def force_gains(self) -> dict[str, float]:
        """The force gains by name (C_2, C_3, C_5, C_6)."""
        return {nm: getattr(self, nm) for nm in FORCE_GAINS}

    def to_dict(self) -> dict[str, Any]:
        """The loop as JSON-ready values: PEB's, plus C_1, C_4' and the force gains."""
        d = super().to_dict()
        for nm in ("position_scale", "force_scale"):
            d.pop(nm)
        c1, c4 = self.position_controllers[2:]
        d["slave_from_master"] = c1.to_dict()
        d["master_from_slave"] = c4.to_dict()
        d.update(self.force_gains())
        return d
