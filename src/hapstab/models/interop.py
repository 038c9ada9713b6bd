"""python-control transfer functions as hapstab's parts (the optional extra ``control``).

A continuous ``control.TransferFunction`` Z(s) (force over velocity) is an impedance
(operator, environment); a discrete one with ``dt`` equal to the loop's period is a
controller H(z) (force over position, the sign of a spring: ``K`` is a restoring force
``K x``). python-control is never imported here: its objects are read through their
attributes (``num``/``den`` or ``num_list``/``den_list``, ``dt``; a ``StateSpace`` through
its ``A, B, C, D``), so ``import hapstab`` stays light and works without it.

References
----------
python-control, ``control.TransferFunction`` and ``control.StateSpace`` (``dt = 0``:
continuous; ``dt = True``: discrete with an unspecified period; ``dt > 0``: the period).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hapstab.errors import ModelError

__all__ = ["is_control_system", "siso_coefficients", "controller_from_control"]

#: Relative difference allowed between a discrete system's dt and the loop's period: the
#: same period written two ways (1e-3 against 1 / 1000) differs by a few ulps (~1e-16);
#: 1e-9 accepts those and refuses any period a user would call different.
DT_RTOL = 1e-9


def is_control_system(obj: Any) -> bool:
    """Whether ``obj`` is a python-control LTI system (``TransferFunction``, ``StateSpace``).

    Parameters
    ----------
    obj : object
        Anything.

    Returns
    -------
    bool
    """
    return type(obj).__module__.split(".")[0] == "control" and hasattr(obj, "dt")


def siso_coefficients(obj: Any, name: str) -> tuple[np.ndarray, np.ndarray, Any]:
    """(num, den, dt) of a SISO python-control system, highest power first.

    Parameters
    ----------
    obj : control.TransferFunction or control.StateSpace
        The system.
    name : str
        The parameter it was given for (``"operator"``), named in errors.

    Returns
    -------
    num, den : arrays
        The transfer function's coefficients.
    dt : float, bool or None
        python-control's sampling time (0 or None: continuous).

    Raises
    ------
    ModelError
        Not single-input single-output.
    """
    if hasattr(obj, "A") and not hasattr(obj, "den"):      # a StateSpace: its transfer function
        return _ss_coefficients(obj, name)
    num: Any = getattr(obj, "num_list", None)
    den: Any = getattr(obj, "den_list", None)
    if num is None:
        num, den = obj.num, obj.den
    if len(num) != 1 or len(num[0]) != 1:
        raise ModelError(f"{name}: a single-input single-output system is required; this one "
                         f"has {len(num)} output(s) and {len(num[0]) if num else 0} input(s)")
    return (np.asarray(num[0][0], dtype=float).ravel(),
            np.asarray(den[0][0], dtype=float).ravel(), obj.dt)


def _ss_coefficients(obj: Any, name: str) -> tuple[np.ndarray, np.ndarray, Any]:
    """(num, den, dt) of a SISO state-space system: den = det(sI - A), num = C adj(sI - A) B
    + D den (scipy's ``ss2tf``)."""
    from scipy.signal import ss2tf

    B, C = np.atleast_2d(obj.B), np.atleast_2d(obj.C)
    if B.shape[1] != 1 or C.shape[0] != 1:
        raise ModelError(f"{name}: a single-input single-output system is required; this "
                         f"state-space system has {C.shape[0]} output(s) and {B.shape[1]} "
                         "input(s)")
    num, den = ss2tf(np.atleast_2d(obj.A), B, C, np.atleast_2d(obj.D))
    return np.asarray(num, float).ravel(), np.asarray(den, float).ravel(), obj.dt


def continuous(obj: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of a continuous SISO system (an impedance Z(s), force over velocity).

    Raises
    ------
    ModelError
        A discrete system (``dt`` not 0), or not SISO.
    """
    num, den, dt = siso_coefficients(obj, name)
    if dt not in (0, None):
        raise ModelError(f"{name}: an impedance is a continuous-time Z(s) (dt = 0); this system "
                         f"is discrete (dt = {dt}); a discrete H(z) is a controller")
    return num, den


def controller_from_control(obj: Any, name: str, period: float) -> Any:
    """A discrete python-control system as a :class:`~hapstab.models.controllers.DiscreteController`.

    Parameters
    ----------
    obj : control.TransferFunction or control.StateSpace
        H(z), force over position (a spring K is ``control.tf([K], [1], dt)``), with
        ``dt`` equal to ``period`` (or ``True``: the loop's period).
    name : str
        The parameter (``"controller"``, ``"master_controller"``), named in errors.
    period : float
        The loop's sampling period T in s.

    Returns
    -------
    DiscreteController

    Raises
    ------
    ModelError
        A continuous system, a dt other than the period, not SISO or improper.
    """
    from hapstab.models.controllers import DiscreteController

    num, den, dt = siso_coefficients(obj, name)
    if dt in (0, None, False):
        raise ModelError(f"{name}: a controller is a discrete H(z) with dt = the period "
                         f"{period:g} s; this system is continuous (dt = {dt}); a continuous "
                         "Z(s) is an impedance (operator, environment)")
    if dt is not True and abs(float(dt) - period) > DT_RTOL * period:
        raise ModelError(f"{name}: dt = {dt:g} s differs from the loop's period {period:g} s; "
                         "sample the controller at the loop's period")
    return DiscreteController(tuple(num), tuple(den))


def check_controller(name: str, c: Any, period: Any = None) -> Any:
    """The controller ``c`` (a hapstab controller, or a discrete python-control H(z) with
    dt = the period), checked."""
    from hapstab.errors import ModelError, check_period
    from hapstab.models.controllers import (
        AffineController,
        DiscreteController,
        FilteredSpringDamper,
        SpringDamper,
    )

    if is_control_system(c):            # a discrete python-control H(z), dt = the period
        return controller_from_control(c, name, check_period("period", period))
    if not isinstance(c, (SpringDamper, FilteredSpringDamper, AffineController,
                          DiscreteController)):
        raise ModelError(f"{name} = {c!r}: must be a SpringDamper, FilteredSpringDamper, "
                         "AffineController or DiscreteController")
    return c
