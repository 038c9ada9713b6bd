"""The paper's own loops: the parameters of its simulation study (Section 5).

References
----------
N. Miandashti and M. Tavakoli, "Stability of Sampled-Data, Delayed Haptic
Interaction and Teleoperation", IEEE Haptics Symposium 2014 (the paper).
Equation and figure numbers below are the paper's.
"""

from __future__ import annotations

from hapstab.models.controllers import SpringDamper
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.models.parts import Device, spring

__all__ = ['paper_hve', 'paper_peb']


def paper_hve(period: float = 1e-3, delay_samples: int = 0, stiffness: float = 100.0,
              damping: float = 0.0) -> HapticLoop:
    """The HVE of the paper's simulation study (Fig. 5): m = 0.15, b = 0.1, operator 1/s.

    Parameters
    ----------
    period : float
        Sampling period T in s.
    delay_samples : int
        Delay n in samples (t_d = n T).
    stiffness : float
        Virtual stiffness K in N/m.
    damping : float
        Virtual damping B in N*s/m.

    Returns
    -------
    HapticLoop
        Device m = 0.15 kg, b = 0.1 N*s/m; operator a 1 N/m spring (the paper's 1/s).
    """
    return HapticLoop(Device(0.15, 0.1), SpringDamper(stiffness, damping), spring(1.0),
                      period, delay_samples)


def paper_peb(period: float = 1e-3, delay_samples: int = 0, stiffness: float = 10.0,
              damping: float = 0.0) -> TeleoperationLoop:
    """The PEB teleoperator of the paper's simulation study (Fig. 6): m = 0.015,
    b = 0.02 for both robots, operator and environment 1/s.

    Parameters
    ----------
    period : float
        Sampling period T in s.
    delay_samples : int
        One-way delay n in samples, the same in both directions.
    stiffness : float
        Stiffness K in N/m of both controllers (C_m = C_s).
    damping : float
        Virtual damping B in N*s/m of both controllers.

    Returns
    -------
    TeleoperationLoop
        Master and slave m = 0.015 kg, b = 0.02 N*s/m; operator and environment
        1 N/m springs (the paper's 1/s).
    """
    dev = Device(0.015, 0.02)
    c = SpringDamper(stiffness, damping)
    return TeleoperationLoop(dev, dev, c, c, spring(1.0), spring(1.0), period, delay_samples)
