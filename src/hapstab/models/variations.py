"""A loop with one parameter moved: more delay, more virtual damping (what the margins
of :mod:`hapstab.analysis.margins` vary).

Where the extra delay goes: in the HVE (Fig. 2a) the virtual environment acts on the
position sampled ``t_d + x T`` earlier (the loop's own delay, lengthened); in
teleoperation (Fig. 3) both communication channels, master -> slave and slave -> master,
are lengthened by ``x T`` each (the round trip by ``2 x T``); the local measurements stay
undelayed.
"""

from __future__ import annotations

import dataclasses
from typing import Any, cast

from hapstab.errors import AnalysisError, check_real
from hapstab.models.controllers import Controller
from hapstab.models.delays import split_delay

__all__ = ["extra_delay", "extra_damping", "virtual_damping"]


def extra_delay(loop: Any, samples: float) -> Any:
    """The same loop with its delay lengthened by ``samples`` samples.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop.
    samples : float
        The extra delay in samples (any real >= 0; t_d + samples T), split into whole
        samples and a fraction by :func:`~hapstab.models.delays.split_delay`'s rule.

    Returns
    -------
    HapticLoop or TeleoperationLoop
    """
    x = check_real("extra delay", samples, nonnegative=True)
    if len(loop.port_names) == 1:                 # one delay (the HVE's)
        n, f = split_delay(loop.delay_in_samples + x)
        return dataclasses.replace(loop, delay_samples=n, fractional_delay=f)
    n, f = split_delay(loop.forward_delay_in_samples + x)
    nb, fb = split_delay(loop.backward_delay_in_samples + x)
    return dataclasses.replace(loop, delay_samples=n, fractional_delay=f,
                               delay_backward_samples=nb, fractional_delay_backward=fb)


def _more_damping(c: Controller, damping: float, name: str) -> Controller:
    """``c`` with ``damping`` added to its virtual damping B."""
    gains = c.gains()
    if gains is None:
        raise AnalysisError(f"{name}: a virtual damping B to vary needs a SpringDamper or "
                            f"FilteredSpringDamper; got {type(c).__name__}")
    return dataclasses.replace(cast(Any, c), damping=gains[1] + damping)


def extra_damping(loop: Any, damping: float) -> Any:
    """The same loop with ``damping`` N*s/m added to every port's virtual damping B
    (the HVE's controller; teleoperation's master and slave controllers alike).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (spring-damper controllers).
    damping : float
        Delta B in N*s/m, either sign.

    Returns
    -------
    HapticLoop or TeleoperationLoop

    Raises
    ------
    AnalysisError
        A controller without a virtual damping (a general H(z)).
    """
    names = loop.controller_names[:2]             # the HVE's; the master's and the slave's
    return dataclasses.replace(loop, **{name: _more_damping(getattr(loop, name), damping, name)
                                        for name in names})


def virtual_damping(loop: Any) -> float:
    """The virtual damping B of the loop's first controller (the HVE's, the master's), in
    N*s/m; ``nan`` for a controller without one."""
    return float(getattr(loop.controllers[0], "damping", float("nan")))
