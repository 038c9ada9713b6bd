"""Margins of a loop at its own stiffness K: how much more delay, stiffness and virtual
damping it takes before it is no longer stable, and the Nyquist / Bode views of its
exact sampled loop.

**Delay margin.** The largest extra delay Delta (s, and samples: Delta / T, any real) such
that the loop is stable for every extra delay in ``[0, Delta]``. The extra delay goes
where the loop's own delay is (:func:`hapstab.models.variations.extra_delay`): in the HVE
the virtual environment acts on the position sampled ``t_d + Delta`` earlier; in
teleoperation both communication channels are lengthened by Delta each. Fractional
delays are the exact modified-z-transform model (:func:`hapstab.build`).

What "stable for every extra delay in [0, margin]" rests on: (1) at every point of a grid
``0, h, 2h, ...`` up to the margin (h = ``step_samples`` T, default T / 4) the loop's
verdict is certified *stable* by :func:`hapstab.stability` (for spring-damper
controllers, no closed-loop pole outside the unit circle, by the argument principle);
(2) the closed-loop poles depend continuously on the delay (an extra fraction of a
sample enters the modified z-transform continuously, and a whole extra sample adds a
pole at z = 0, inside), so between two stable grid points the loop can only be unstable
if a pole leaves the disc and comes back within less than h of delay: that is not
excluded by a proof, only by the grid. (3) The first grid point that is not certified
stable is bisected against the last stable one (:data:`BISECTIONS` steps); the margin is the
stable end of that bracket, the bracket's other end is ``delay_unstable_s``.

**Stiffness margin.** From the exact stable set in K (:func:`hapstab.critical_stiffness`,
a certified enclosure whose safe end is reported): the interval ``(K_lo, K_hi]`` of
stable stiffnesses that contains K; K can grow by ``K_hi - K`` (a factor ``K_hi / K``,
the loop's gain margin in K) and shrink to ``K_lo``.

**Damping margin.** The virtual damping B (added to every port's controller alike,
:func:`hapstab.models.variations.extra_damping`) can move in ``[B_lo, B_hi]`` with the
loop stable at K; found like the delay margin (certified verdicts on a grid that doubles
its step away from B, the last doubling refined on 8 points, then bisected 10 times), with the
same proviso (2).

**Nyquist / Bode views.** With ``A_cl(K) = A0 + K B1 C1`` (:class:`hapstab.SampledSystem`),
``det(zI - A_cl) = det(zI - A0) det(I - K G(z))``, ``G = C1 (zI - A0)^-1 B1``: the
stiffness loop ``L = -K G`` (one port) or ``L = det(I - K G) - 1`` (two ports) has the
closed-loop poles on the unit circle exactly where ``L(e^{j theta}) = -1``, the critical
point; by the argument principle the closed loop has ``P + N`` poles outside, P those of
A0 (the loop at K = 0) and N the clockwise encirclements of -1. The circle criterion for
a gain in the sector [0, K] (A0 stable, one port) asks ``Re L > -1`` at every frequency:
the vertical line drawn in the Nyquist view.

References
----------
The paper, Fig. 2a / Fig. 3, eq. (15) (circle criterion). K. J. Astrom and B.
Wittenmark, *Computer-Controlled Systems*, 3rd ed., sec. 3.4 (Nyquist criterion for
sampled systems) and 7.7 (modified z-transform); H. K. Khalil, *Nonlinear Systems*, 3rd
ed., Theorem 7.1 (circle criterion; its discrete-time form with e^{j theta}).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from hapstab import budget
from hapstab.analysis.exact.core import stability
from hapstab.analysis.margin_result import FrequencyView, MarginResult
from hapstab.analysis.methods import critical_stiffness
from hapstab.engine.system import build
from hapstab.errors import (
    MAX_DELAY_SAMPLES,
    AnalysisError,
    HapstabError,
    ModelError,
    check_flag,
    check_real,
    check_reals,
)
from hapstab.models.loops import require_loop
from hapstab.models.variations import extra_damping, extra_delay, virtual_damping

__all__ = ["margins", "frequency_view", "certified_stable"]

#: |z| beyond 1 by more than this counts a pole of A0 as outside the unit circle in P
#: (eigenvalues of a matrix of norm ~1 are accurate to ~N eps cond; 1e-9 leaves room for
#: the poles that crowd z = 1 at small T; P only labels the Nyquist view).
OUTSIDE = 1e-9


#: Bisections of a margin's last bracket: T/4 / 2^14 ~ 1.5e-5 samples for the delay (the
#: displays show 4 digits; each bisection is one certified verdict, ~0.2 s for PEB).
BISECTIONS = 14

def certified_stable(res: Any) -> bool:
    """Whether a :class:`~hapstab.StabilityResult` says *stable* (or, for a loop with a
    rigid-body mode that no controller moves, no pole outside apart from that mode).

    Parameters
    ----------
    res : StabilityResult

    Returns
    -------
    bool
    """
    if res.verdict == "stable":
        return True
    return (res.verdict == "marginal" and res.rigid_body_modes > 0 and res.spectral_radius < 1
            and "unit circle to the model" not in res.reason)


def _first_loss(ok: Callable[[float], bool], grid: np.ndarray, bisections: int,
                start: float = 0.0, deadline: float = math.inf) -> tuple[float, float | None]:
    """(the last x of ``grid`` before its first point not ``ok``, refined against it by
    ``bisections`` bisections; that point moved in by them), or (the last x checked, None)
    when every point is ``ok`` or the clock (``time.monotonic``) passes ``deadline``
    before the next point. ``start`` is known ``ok``."""
    lo = start
    for x in grid:
        if time.monotonic() > deadline:
            return lo, None
        if not ok(float(x)):
            hi = float(x)
            for _ in range(bisections):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if ok(mid) else (lo, mid)
            return lo, hi
        lo = float(x)
    return lo, None


def delay_margin(loop: Any, step_samples: float = 0.25, max_extra_samples: float = 100.0,
                 bisections: int = BISECTIONS, deadline: float = math.inf
                 ) -> tuple[float, float | None]:
    """The delay margin in samples and the first extra delay found not stable (None: none
    up to ``max_extra_samples``, or up to the first value when the clock passed
    ``deadline``); see the module docstring for what it rests on."""
    h = check_real("step_samples", step_samples, positive=True)
    top = check_real("max_extra_samples", max_extra_samples, positive=True)
    # a floor against division by zero / rounding, far below the answer's own accuracy
    grid = np.arange(1, int(np.floor(top / h + 1e-9)) + 1) * h
    return _first_loss(lambda x: certified_stable(stability(extra_delay(loop, x))), grid,
                       bisections, deadline=deadline)


#: The damping search's doublings: from 1e-3 m/T (m the lightest device) up to
#: 2^23 1e-3 m/T ~ 8e3 m/T, far past the B at which a sampled damper alone rings
#: (B ~ 2 m / T at n = 0, less with delay).
DOUBLINGS = 24


def damping_margin(loop: Any, bisections: int = 10) -> list[tuple[float, float | None]]:
    """[(B_lo, first B below found not stable), (B_hi, first above)] as offsets from
    the loop's B in N*s/m (None: none within the search); see the module docstring."""
    scale = 1e-3 * min(d.mass for d in _devices(loop)) / loop.period
    out: list[tuple[float, float | None]] = []
    for sign in (-1.0, 1.0):
        def ok(x: float, s: float = sign) -> bool:
            return certified_stable(stability(extra_damping(loop, s * x)))

        lo, hi = _first_loss(ok, scale * 2.0 ** np.arange(DOUBLINGS), 0)
        if hi is not None:        # the last doubling, on 8 points, then bisected
            lo, hi = _first_loss(ok, np.linspace(lo, hi, 9)[1:], bisections, start=lo)
        out.append((sign * lo, None if hi is None else sign * hi))
    return out


def _delays(loop: Any) -> list[float]:
    """The loop's delays in samples (one; teleoperation: forward and backward)."""
    return [float(getattr(loop, n)) for n in ("delay_in_samples", "forward_delay_in_samples",
                                             "backward_delay_in_samples") if hasattr(loop, n)]


def _devices(loop: Any) -> list[Any]:
    return [getattr(loop, n) for n in ("device", "master", "slave") if hasattr(loop, n)]


def frequency_view(loop: Any, frequencies_hz: Any = None) -> FrequencyView:
    """The stiffness loop L of the exact sampled loop at its K, on the unit circle.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (spring-damper controllers, K > 0).
    frequencies_hz : array, optional
        Where to evaluate (Hz, in (0, 1/(2T)]); default 800 points, log-spaced from
        1e-4 of the Nyquist frequency and linear up to it.

    Returns
    -------
    FrequencyView

    Raises
    ------
    AnalysisError
        K cannot be varied (a general H(z)) or K = 0 (L is zero).
    """
    require_loop(loop)
    sysm = build(loop)
    K = float(sysm.stiffness[0])
    if not sysm.varies_with_K or K <= 0:
        raise AnalysisError("frequency view: the stiffness loop L = -K G needs a stiffness "
                            f"K > 0 to vary; {sysm.fixed_reason or f'K = {K:g} N/m'}")
    T = loop.period
    fN = 0.5 / T
    # a floor against division by zero / rounding, far below the answer's own accuracy
    f = (np.unique(np.concatenate([np.geomspace(1e-4 * fN, fN, 400),
                                   np.linspace(fN / 400, fN, 400)]))
         if frequencies_hz is None else _frequencies(frequencies_hz))
    A0, B1, C1 = sysm.A0[0], sysm.B1[0], sysm.C1[0]
    keep = np.flatnonzero(np.any(B1 != 0, axis=0))           # ports with a K-part
    B1, C1 = B1[:, keep], C1[keep, :]
    L = np.empty(f.size, complex)
    eye = np.eye(A0.shape[0])
    for s in range(0, f.size, 64):                            # 64 solves at once
        z = np.exp(2j * np.pi * f[s:s + 64] * T)
        G = C1 @ np.linalg.solve(z[:, None, None] * eye - A0, B1)
        L[s:s + 64] = (-K * G[:, 0, 0] if keep.size == 1
                       else np.linalg.det(np.eye(keep.size) - K * G) - 1.0)
    lam = np.abs(np.linalg.eigvals(A0))
    return FrequencyView(f, L, int(keep.size), K, T, int(np.sum(lam > 1 + OUTSIDE)),
                         int(np.sum(np.abs(lam - 1) <= OUTSIDE)))


def _frequencies(value: Any) -> np.ndarray:
    """The frequencies asked for: finite real numbers (Hz), else ModelError naming them."""
    f = check_reals("frequencies_hz", value)
    if f.size == 0 or not np.all(np.isfinite(f)):
        raise ModelError(f"frequencies_hz = {value!r:.60}: must be finite frequencies in Hz "
                         "(at least one)")
    return f


def margins(loop: Any, *, step_samples: float = 0.25, max_extra_samples: float = 100.0,
            view: bool = True, max_seconds: float | None = None) -> MarginResult:
    """The delay, stiffness and damping margins of ``loop`` at its own K, and its Nyquist /
    Bode view (see the module docstring for each definition and what it rests on).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop at its own K, B, T and delay.
    step_samples : float
        h / T, the delay grid's step (default 0.25 sample).
    max_extra_samples : float
        How far the delay search goes (default 100 samples more).
    view : bool
        Compute the Nyquist / Bode view too (default True).
    max_seconds : float, optional
        Stop the delay search once this much time has gone (a long delay's verdict is an
        eigenvalue problem of ~2 states per sample per direction): the margin then holds
        up to the extra delay reached (``delay_searched_samples``), and the reason says
        the search was cut short. Default: the whole search.

    Returns
    -------
    MarginResult
        Margins of 0 when the loop is not stable at its own parameters.

    References
    ----------
    See :mod:`hapstab.analysis.margins`.
    """
    from hapstab.models.parts import friction_note

    require_loop(loop)
    # Python numbers from here (an array or a numpy scalar would reach the wording)
    step_samples = check_real("step_samples", step_samples, positive=True)
    max_extra_samples = check_real("max_extra_samples", max_extra_samples, positive=True)
    view = check_flag("view", view)
    # the budget's own reading (inf: no limit), also where the loop is not stable
    limit = None if max_seconds is None else budget.seconds_allowed(max_seconds)
    base = stability(loop)
    K = float(getattr(loop.controllers[0], "stiffness", float("nan")))
    B = virtual_damping(loop)
    why: list[str] = []
    dm: float
    du: float | None
    damp: tuple[float | None, float | None]
    if not certified_stable(base):
        why.append(f"the loop is not stable at its own parameters ({base.verdict}): no margin")
        dm, du, damp = 0.0, 0.0, (None, None)
    else:
        try:
            extra_delay(loop, 0.5)
            bis = BISECTIONS
        except ModelError:           # a model of whole samples of delay only (4-channel)
            step_samples, bis = 1.0, 0
            why.append("this loop takes whole samples of delay only: the delay margin is "
                       "in whole samples")
        room = MAX_DELAY_SAMPLES - max(_delays(loop))     # the model's longest delay
        if room < max_extra_samples:
            max_extra_samples = max(room, step_samples)
            why.append(f"the delay search stops at hapstab's longest delay, "
                       f"{MAX_DELAY_SAMPLES} samples")
        deadline = math.inf if limit is None else time.monotonic() + limit
        dm, du = delay_margin(loop, step_samples, max_extra_samples, bis, deadline)
        # the grid's last point (as delay_margin forms it)
        end = math.floor(max_extra_samples / step_samples + 1e-9) * step_samples
        if du is None and dm < end:
            why.append(f"the delay search stopped at +{dm:g} samples, after max_seconds = "
                       f"{max_seconds:g} s; ask for the margins alone for the whole search")
            max_extra_samples = dm
        damp = _damping(loop, B, why)
    iv = _stiffness_interval(loop, K, why)
    fv = None
    if view:
        try:
            fv = frequency_view(loop)
        except HapstabError as e:
            why.append(str(e))
    why.insert(0, _words(dm, du, step_samples, max_extra_samples))
    return MarginResult(base.verdict, K, loop.period, loop.delay_s, dm, du, max_extra_samples,
                        iv, B, damp, fv, "; ".join(why), friction_note(loop))


def _words(dm: float, du: float | None, h: float, top: float) -> str:
    if du is None:
        return (f"stable for every extra delay up to the search's end, +{top:g} samples (grid "
                f"of {h:g} sample; stability() verdicts, certified for spring-dampers)")
    return (f"stable for every extra delay in [0, {dm:.6g}] samples on a grid of {h:g} sample "
            f"(stability() verdicts, certified for spring-dampers), not stable at +{du:.6g} samples")


def _damping(loop: Any, B: float, why: list[str]) -> tuple[float | None, float | None]:
    """The damping interval [B_lo, B_hi] (N*s/m), or (None, None) said in ``why``."""
    if not np.isfinite(B):
        why.append("damping margin: the controller has no virtual damping B to vary")
        return None, None
    (lo, lo_bad), (hi, hi_bad) = damping_margin(loop)
    return (B + lo if lo_bad is not None else None, B + hi if hi_bad is not None else None)


def _stiffness_interval(loop: Any, K: float, why: list[str]) -> tuple[float, float] | None:
    """The exact stable interval of K containing the loop's K, or None (said in ``why``)."""
    try:
        res = critical_stiffness(loop)
    except HapstabError as e:
        why.append(f"stiffness margin: {e}")
        return None
    for a, b in res.stable_intervals:
        if a < K <= b or (K == 0 and a == 0):
            return float(a), float(b)
    why.append(f"stiffness margin: K = {K:g} N/m is in no stable interval of K")
    return None
