"""What the engine and the analyses ask a controller and a loop, in place of asking its
class.

A controller answers for itself: its transfer function, its frequency response and the
parts of it that K and B scale, its state-space realisation, whether it is a
spring-damper (and its K and B), whether it is given as K P(z) + Q(z), and which
analyses it admits. A loop answers its kind, its ports' and its controllers' names.
Adding a controller is a class in :mod:`hapstab.models.controllers` that answers
:class:`ControllerProtocol` (docs/architecture.md, "how to add a controller"); no
module outside ``models/`` and the engine's builder names a controller or loop class.
"""

from __future__ import annotations

from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from hapstab.errors import ModelError

__all__ = ["ANALYSES", "ControllerProtocol", "LoopProtocol", "check_analysis"]

#: The analyses a controller may admit (:meth:`ControllerProtocol.admits`), each with
#: what it needs of the controller.
ANALYSES = {
    "stiffness": "a stiffness K to vary, H = K P(z) + Q(z): the exact K_max, stable "
                 "intervals, regions and margins",
    "eq23": "eq. (23)'s spring-damper itself, H = K + B (z - 1)/(T z): the paper's closed "
            "forms, the device-side conditions (circle, Llewellyn, transparency), the "
            "nonlinear passivity and the limit cycles",
    "packet-loss": "u = K y + B (y[k] - y[k-1]) / T exactly (an unfiltered spring-damper): "
                   "the jump-linear network models",
}


def check_analysis(analysis: str) -> str:
    """``analysis`` if it is one of :data:`ANALYSES`.

    Parameters
    ----------
    analysis : str
        The name asked.

    Returns
    -------
    str

    Raises
    ------
    ModelError
        An unknown name, with the known ones.
    """
    if analysis not in ANALYSES:
        raise ModelError(f"analysis = {analysis!r}: unknown; allowed: {', '.join(ANALYSES)}")
    return analysis


@runtime_checkable
class ControllerProtocol(Protocol):
    """A discrete controller u = H(z) e, as the engine and the analyses see it.

    ``transfer(T)``
        (num, den) of H(z) in z, highest power first, at the period T.
    ``gains()``
        (K, B) of a spring-damper (eq. (23), its damper possibly on a filtered
        velocity: ``velocity_filter``); None for any other H(z).
    ``affine_parts()``
        (P_num, P_den, Q_num, Q_den) in z^-1 of a controller given as K P(z) + Q(z)
        with coefficients fixed in z; None otherwise (a spring-damper's Q depends on T:
        it answers ``gains()``).
    ``response(theta, T, part, ratio)``
        H(e^{j theta}); with ``part="K"`` the part K scales (times ``ratio``), with
        ``part="B"`` the rest.
    ``realisation(periods)``
        Its states batched over the periods,
        :data:`~hapstab.models.realisation.Realisation`.
    ``admits(analysis)``
        Whether the analysis named (one of :data:`ANALYSES`) applies to it.
    """

    def transfer(self, period: float) -> tuple[np.ndarray, np.ndarray]: ...

    def gains(self) -> tuple[float, float] | None: ...

    def affine_parts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None: ...

    def response(self, theta: np.ndarray, period: float, part: str | None = None,
                 ratio: float = 1.0) -> np.ndarray: ...

    def realisation(self, periods: np.ndarray) -> tuple[np.ndarray, ...]: ...

    def admits(self, analysis: str) -> bool: ...

    def to_dict(self) -> dict[str, Any]: ...


@runtime_checkable
class LoopProtocol(Protocol):
    """A loop as the engine and the analyses see it: its kind (``"hve"``, ``"peb"``,
    ``"4ch"``, the CLI's names), its ports' names (one port: a haptic loop; two: a
    teleoperator), its controllers and their names (the dataclass fields the
    controllers live in, for messages)."""

    kind: ClassVar[str]
    port_names: ClassVar[tuple[str, ...]]
    controller_names: ClassVar[tuple[str, ...]]

    @property
    def controllers(self) -> tuple[Any, ...]: ...
