"""What the frequency-domain stiffness tests share (the circle criterion, Llewellyn's
two-port test, transparency): the integrator approximations of the paper's Section 3,
X(z) = X_h(z)/V_h(z), and the device side a test of spring-damper controllers sees.

References
----------
The paper, Section 3 (forward, backward and Tustin integrators) and Fig. 2a / Fig. 3.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hapstab.engine.device_side import DeviceSide, device_side
from hapstab.errors import AnalysisError
from hapstab.models.loops import require_loop, whole_delay

__all__ = ["APPROXIMATIONS", "approximation_name", "integrator_polynomial",
           "integrator_response", "whole_delay_side", "stiffness_side"]

#: The integrator approximations of Section 3.
APPROXIMATIONS = ("forward", "backward", "tustin")


def approximation_name(approximation: Any) -> str:
    """The integrator approximation by its name, checked.

    Parameters
    ----------
    approximation : str or None
        ``"forward"``, ``"backward"`` or ``"tustin"`` (any case); None: forward.

    Returns
    -------
    str

    Raises
    ------
    AnalysisError
        An unknown name.
    """
    a = str(approximation).strip().lower() if approximation is not None else "forward"
    if a not in APPROXIMATIONS:
        raise AnalysisError(f"approximation = {approximation!r}: unknown; allowed: "
                            + ", ".join(APPROXIMATIONS))
    return a


def integrator_polynomial(a: str, T: float) -> tuple[np.ndarray, np.ndarray]:
    """X(z) = X_h(z)/V_h(z) of approximation ``a`` as (num, den) in z (Section 3).

    Parameters
    ----------
    a : str
        An :func:`approximation_name`.
    T : float
        Sampling period (s).

    Returns
    -------
    num, den : ndarray
        Coefficients, highest power first.
    """
    num = {"forward": [T], "backward": [T, 0.0], "tustin": [T / 2, T / 2]}[a]
    return np.array(num), np.array([1.0, -1.0])


def integrator_response(a: str, theta: np.ndarray, T: float) -> np.ndarray:
    """X(e^{jw}) of approximation ``a`` without cancellation: z - 1 = 2j sin(w/2) e^{jw/2},
    never cos(w) - 1.

    Parameters
    ----------
    a : str
        An :func:`approximation_name`.
    theta : ndarray
        Angles w in (0, pi] (rad/sample).
    T : float
        Sampling period (s).

    Returns
    -------
    ndarray of complex
    """
    s = np.sin(theta / 2)
    if a == "forward":
        return T * np.exp(-0.5j * theta) / (2j * s)
    if a == "backward":
        return T * np.exp(0.5j * theta) / (2j * s)
    return -0.5j * T * np.cos(theta / 2) / s + 0j


def whole_delay_side(loop: Any, what: str = "the circle criterion", forces: bool = False,
                     equal_delays: bool = True) -> DeviceSide:
    """The loop's device side, with whole samples of delay on every channel.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
    what : str
        The test's name, for the error message.
    forces : bool
        Whether the test needs the ports' forces too.
    equal_delays : bool
        Whether the test needs the paper's t_d = nT, equal both ways.

    Returns
    -------
    DeviceSide
    """
    require_loop(loop)
    if equal_delays:
        whole_delay(loop, what)  # the paper's t_d = nT, equal both ways
    return device_side(loop, what, forces)   # whole samples of delay on every channel


def stiffness_side(loop: Any, what: str = "the circle criterion", forces: bool = False,
                   equal_delays: bool = True) -> DeviceSide:
    """:func:`whole_delay_side` for a test that varies the stiffness K of spring-damper
    controllers.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
    what : str
        The test's name, for the error message.
    forces : bool
        Whether the test needs the ports' forces too.
    equal_delays : bool
        Whether the test needs equal delays in both directions.

    Returns
    -------
    DeviceSide

    Raises
    ------
    AnalysisError
        A controller that is not a plain SpringDamper, or K_s/K_m undefined.
    """
    side = whole_delay_side(loop, what, forces, equal_delays)
    other = [ch.controller for ch in side.channels if not ch.controller.admits("eq23")]
    if other and all(c.gains() is not None for c in other):     # a spring-damper, filtered
        raise AnalysisError(f"{what}: needs SpringDamper controller(s) without a velocity "
                            "filter; this loop's damper is filtered (a FilteredSpringDamper, "
                            "a velocity filter): the exact K_max and sampled-data passivity "
                            "take it")
    if other:
        raise AnalysisError(f"{what}: needs SpringDamper controller(s); this loop has "
                            f"{type(other[0]).__name__} (a DiscreteController has no stiffness to vary)")
    if side.ratios is None:
        raise AnalysisError("controllers: the master's stiffness is 0 and the slave's is not, so "
                            "K_s/K_m is undefined; give the master a stiffness > 0 to vary K")
    return side
