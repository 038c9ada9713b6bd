"""A loop handed to python-control (the optional extra ``control``): its exact sampled
closed loop as a discrete ``control.StateSpace``.

References
----------
The paper, Fig. 2a / Fig. 3 (the loops); K. J. Astrom and B. Wittenmark,
*Computer-Controlled Systems*, 3rd ed., sec. 2.3 (ZOH sampling) and 7.7 (modified
z-transform, fractional delays): the model :func:`hapstab.build` assembles.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hapstab.engine.system import build
from hapstab.errors import ModelError
from hapstab.models.loops import require_loop

__all__ = ["to_control"]


def _control() -> Any:
    """python-control, or a :class:`ModelError` saying how to install it."""
    try:
        import control
    except ImportError:
        raise ModelError("to_control: python-control is not installed; install it with "
                         "`pip install 'hapstab[control]'` (or `pip install control`)") from None
    return control


def to_control(loop: Any) -> Any:
    """The exact sampled-data closed loop of ``loop`` at its own K, as python-control's
    discrete ``StateSpace`` with ``dt = T``.

    ``s[k+1] = A s[k] + B f[k]``, ``y[k] = C s[k]``: the state is hapstab's (each port's
    plant after the zero-order hold, every delay register, the controllers' states and the
    fractional-delay states: :func:`hapstab.build`), so its poles are the loop's exact
    closed-loop poles at the sampling instants, whatever the delay.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (its controllers at their own K and B).

    Returns
    -------
    control.StateSpace
        ``dt`` = the loop's period. Inputs: an exogenous force on each port (N, held over
        the sample: ``f_<port>``); outputs: each port's position (m, ``x_<port>``), then
        the controller's force on it at the same instant (N, ``u_<port>``; the force on the
        device is ``-u``).

    Raises
    ------
    ArgumentTypeError
        Not a loop.
    ModelError
        python-control is not installed.

    Notes
    -----
    The spectral radius of ``A`` is :func:`hapstab.stability`'s (which leaves out a
    rigid-body mode at z = 1 and states the certified count of poles outside). For a
    python-control user this replaces ``feedback(c2d(P, T, 'zoh') * ..., H)``, whose delay
    is a chain of samples on the force and whose ZOH model of the operator's spring or
    the teleoperator's coupling is not the sampled loop's (see docs/guide/python-control.md).
    """
    require_loop(loop)
    control = _control()
    sysm = build(loop)
    A = sysm.closed_loop()[0]
    B = sysm.B_ext[0]
    C = np.vstack([sysm.pos, sysm.force_matrix()[0]])
    D = np.zeros((C.shape[0], B.shape[1]))
    labels = sysm.labels
    return control.ss(A, B, C, D, loop.period,
                      inputs=[f"f_{p}" for p in labels],
                      outputs=[f"x_{p}" for p in labels] + [f"u_{p}" for p in labels],
                      name=f"hapstab {loop.kind} closed loop")
