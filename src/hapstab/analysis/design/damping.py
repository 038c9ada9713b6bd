"""The virtual damping that lets a loop render the stiffest wall: B* maximising the
exact K_max(B), found on the batched K_max-over-B of :mod:`hapstab.analysis.design.regions`.

References
----------
Gil, Avello, Rubio, Florez 2004; Hulin, Preusche, Hirzinger 2008 (K-B charts);
the paper, eq. (23) for H(z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab import budget, progress
from hapstab.analysis.design.regions import Loop, check_equal_gains, kmax_over_B, with_gains
from hapstab.errors import AnalysisError, check_real
from hapstab.results import Result, jsonable, write_csv

__all__ = ["BestDampingResult", "best_damping"]


@dataclass(frozen=True)
class BestDampingResult(Result):
    """The virtual damping that maximises K_max: "render at most K* N/m, with B* N*s/m".

    Attributes
    ----------
    damping : float
        B* in N*s/m.
    critical_stiffness : float
        K* = K_max(B*) in N/m.
    critical_stiffness_at_zero_damping : float
        K_max(0), for comparison.
    reason : str
        How B* was found, in words.
    B_curve, K_curve : arrays
        K_max over the scanned dampings (N*s/m, N/m), by the float search (not
        re-proved in ball arithmetic: the search's curve; K* and K_max(0) are proved).
    holds_for : str
        The terminations the answer is for (the operator's, and the environment's).
    critical_stiffness_without_operator : float
        K_max at B* with no operator (or environment): the answer does not carry over
        to a hand that lets go when this is below K*.
    passive_up_to : float
        The largest K at B* for which the device side stays passive (Colgate-Schenkel):
        above it stability rests on the terminations.
    """

    damping: float
    critical_stiffness: float
    critical_stiffness_at_zero_damping: float
    reason: str
    B_curve: np.ndarray = field(repr=False)
    K_curve: np.ndarray = field(repr=False)
    holds_for: str = ""
    critical_stiffness_without_operator: float = float("nan")
    passive_up_to: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"virtual_damping": self.damping, "critical_stiffness": self.critical_stiffness,
                         "critical_stiffness_at_zero_damping": self.critical_stiffness_at_zero_damping,
                         "reason": self.reason, "holds_for": self.holds_for,
                         "critical_stiffness_without_operator":
                             self.critical_stiffness_without_operator,
                         "passive_up_to": self.passive_up_to,
                         "curve": {"virtual_damping": self.B_curve, "critical_stiffness": self.K_curve}})

    def to_csv(self, path: Any) -> None:
        """Write the scanned curve: virtual_damping (N*s/m), critical_stiffness (N/m).

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        write_csv(path, ["virtual_damping", "critical_stiffness"],
                  ([repr(float(B)), repr(float(K))]
                   for B, K in zip(self.B_curve, self.K_curve, strict=True)))

    def plot(self, ax: Any = None) -> Any:
        """K_max against the virtual damping, with B* marked.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw; a new figure when omitted.

        Returns
        -------
        matplotlib Axes
        """
        from hapstab.plotting import plot_best_damping
        return plot_best_damping(self, ax)


#: Doublings of :func:`best_damping`'s search for the ends tried per batched call: the
#: paper's loops end after 3-6 (measured), so one call mostly, two at most.
DOUBLINGS = 6


def best_damping(loop: Loop, B_max: float | None = None, resolution: int = 64,
                 B_min: float | None = None, *, max_memory: float | None = None,
                 max_seconds: float | None = None) -> BestDampingResult:
    """The virtual damping B* that maximises K_max, and K* = K_max(B*).

    K_max(B) is computed exactly on a grid of B (batched), then refined by bounded
    Brent iterations around the best grid point. K_max(B) often has a kink at its
    maximum (two crossing branches meet), which Brent's method handles.

    The search covers both signs of B by default. Negative virtual damping usually
    lowers K_max (it takes damping from the device: at n = 0, K_max ~ 2(b - |B|)/T),
    but not always: with delay, B (z - 1)/(Tz) z^-n is rotated by the delay's phase,
    and at a device-operator resonance where that rotation exceeds 90 degrees a
    *negative* B damps (e.g. a 10 g device on a 100 N/m operator with n = 6 has its
    largest K_max at B < 0). So the lower end is found like the upper one, and a
    caller who cannot use B < 0 passes ``B_min=0``.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        C_m = C_s for teleoperation; the loop's own K and B are ignored.
    B_max : float, optional
        Upper end of the search, > 0; default: where K_max first falls to 0 (found
        by doubling from 10 b).
    resolution : int
        Grid points before refinement (B = 0 is always added).
    B_min : float, optional
        Lower end of the search, <= 0; default: where K_max first falls to 0 going
        down (found by doubling from -10 b). ``0`` restricts the search to B >= 0.
    max_memory, max_seconds : float, optional
        Budget in bytes and seconds (default :mod:`hapstab.budget`'s).

    Returns
    -------
    BestDampingResult
        ``B_curve``/``K_curve`` span [B_min, B_max]; the reason says when B* < 0,
        and when K_max = 0 for every B searched (then B* = 0 is reported).

    Raises
    ------
    AnalysisError
        Controllers that are not equal spring-dampers, or ``B_min > 0``.
    ModelError
        ``B_max <= 0`` or a non-finite bound.
    """

    b = check_equal_gains(loop)

    def kmax(Bs: np.ndarray) -> np.ndarray:
        # the search over B runs on the float search (an optimisation of ~60 K_max's);
        # the K* and K_max at B = 0 it reports are then proved (_proved)
        return np.array([r.kmax for r in kmax_over_B(loop, Bs, certify=False)])

    def first_zero(start: float) -> float:
        """Double ``start`` until K_max there is 0 (at most 30 times), DOUBLINGS at a
        time (one batched call: a few ms a row against ~20 ms for one alone)."""
        Bs = start * 2.0 ** np.arange(30)
        for i in range(0, Bs.size, DOUBLINGS):
            zero = np.flatnonzero(kmax(Bs[i:i + DOUBLINGS]) == 0.0)
            if zero.size:
                return float(Bs[i + zero[0]])
        return float(start * 2.0 ** 30)      # (none: the end as thirty doublings leave it)

    if B_max is None:
        B_max = first_zero(max(10 * b, 1e-3))   # b = 0: from 1e-3 N*s/m; doubling finds the end
    else:
        B_max = check_real("B_max", B_max, positive=True)
    if B_min is None:
        B_min = first_zero(-max(10 * b, 1e-3))  # as B_max, on the negative side
    else:
        B_min = check_real("B_min", B_min)
        if B_min > 0:
            raise AnalysisError(f"B_min = {B_min}: must be <= 0 (the search always includes B = 0)")
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) \
            or resolution < 2:
        raise AnalysisError(f"resolution = {resolution!r}: must be a whole number >= 2")
    from hapstab.analysis.methods import order_estimate

    budget.check(budget.exact_points_cost(f"best damping: K_max at {int(resolution) + 60} "
                                          "dampings", int(resolution) + 60,
                                          order_estimate(loop, max(loop_delays(loop)))),
                 max_memory, max_seconds)
    Bs = np.unique(np.concatenate([np.linspace(B_min, B_max, int(resolution)), [0.0]]))
    with progress.steps(Bs.size + 60, "best damping") as advance:
        Ks, best_B, best_K = _search(kmax, Bs, B_max - B_min, advance)
    K0 = float(Ks[int(np.flatnonzero(Bs == 0.0)[0])])
    best_K, K0 = _proved(loop, best_B, best_K), _proved(loop, 0.0, K0)
    if best_K == 0.0:
        best_B = 0.0
        reason = (f"unstable for every K > 0 at every B in [{B_min:.6g}, {B_max:.6g}] N*s/m: no "
                  "virtual damping in this range makes the loop stable (B* = 0 reported)")
    else:
        reason = (f"render at most K* = {best_K:.6g} N/m with B* = {best_B:.6g} N*s/m "
                  f"(K_max = {K0:.6g} N/m at B = 0)")
    if best_B < 0:
        reason += ("; B* < 0: negative virtual damping is best here (with this delay and these "
                   "terminations it damps at the critical frequency; it is not passive)")
    holds, bare, passive, caveat = _caveats(loop, best_B, best_K)
    return BestDampingResult(best_B, best_K, K0, reason + caveat, Bs, Ks, holds, bare, passive)


def _proved(loop: Loop, B: float, K_float: float) -> float:
    """K_max at virtual damping ``B`` proved in ball arithmetic (the safe end, at most
    the float search's ``K_float``); 0 and inf as the float search found them."""
    if not (K_float > 0 and math.isfinite(K_float)):
        return K_float
    from hapstab.analysis.exact.core import exact_critical_stiffness
    return float(exact_critical_stiffness(with_gains(loop, 1.0, B)).critical_stiffness)


def _search(kmax: Any, Bs: np.ndarray, span: float, advance: Any
            ) -> tuple[np.ndarray, float, float]:
    """K_max on the grid ``Bs``, then a bounded search around its best point:
    (the grid's K_max, B*, K*)."""
    from scipy.optimize import minimize_scalar

    Ks = kmax(Bs)
    advance(Bs.size)
    i = int(np.argmax(Ks))
    lo, hi = Bs[max(i - 1, 0)], Bs[min(i + 1, Bs.size - 1)]
    best_B, best_K = float(Bs[i]), float(Ks[i])
    if hi > lo and math.isfinite(best_K):
        def minus_kmax(x: float) -> float:
            advance(1)
            return -float(kmax(np.array([x]))[0])

        res = minimize_scalar(minus_kmax, bounds=(lo, hi), method="bounded",
                              # B* to ~10 digits of the range (far below the grid step it
                              # refines): the bounded search needs a few dozen K_max's
                              options={"xatol": 1e-10 * span})
        if -res.fun > best_K:
            best_B, best_K = float(res.x), float(-res.fun)
    return Ks, best_B, best_K


def loop_delays(loop: Loop) -> list[float]:
    """The loop's delays in samples (one for the HVE, both directions for a
    teleoperator: PEB or the 4-channel loop)."""
    if len(loop.port_names) == 2:                # a delay each way
        return [loop.forward_delay_in_samples, loop.backward_delay_in_samples]  # type: ignore[union-attr]
    return [loop.delay_in_samples]


def _caveats(loop: Loop, B: float, K: float) -> tuple[str, float, float, str]:
    """For which terminations the answer holds, K_max at B without them, and how far the
    device side stays passive at B; the words a designer needs beside K*."""
    from hapstab.analysis.conditions.passivity import critical_stiffness_passivity
    from hapstab.analysis.exact.core import exact_critical_stiffness

    at_B = with_gains(loop, K, B)
    ends = {"operator": at_B.operator, "environment": getattr(at_B, "environment", None)}
    ends = {k: v for k, v in ends.items() if v is not None}
    terms = [f"{k} {v.label}" for k, v in ends.items()]
    bare = at_B.replace(**{k: None for k in ends})
    holds = "for " + " and ".join(terms)
    K_bare = exact_critical_stiffness(bare).critical_stiffness
    try:
        K_pass = critical_stiffness_passivity(at_B).critical_stiffness
    except AnalysisError:
        K_pass = float("nan")
    words = f"; this holds {holds}"
    if K > 0 and K_bare < K:
        words += (f" (without them, K_max at this B is {K_bare:.6g} N/m: a hand that lets go "
                  "leaves an unstable loop)")
    if K > 0 and K_pass == 0:
        words += ("; at this B the device side is passive for no K (B takes more than the "
                  "device damping gives): stability rests on these terminations")
    elif K > 0 and math.isfinite(K_pass) and K_pass < K:
        words += f"; passivity is lost above K = {K_pass:.6g} N/m"
    return holds, float(K_bare), float(K_pass), words
