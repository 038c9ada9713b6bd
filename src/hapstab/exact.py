"""Exact stability and exact critical stiffness of the sampled-data loop.

``stability(loop)`` reads the closed-loop poles of the exact model
(:mod:`hapstab.engine`); ``exact_critical_stiffness(loop)`` finds every K at which a
pole reaches |z| = 1 (:mod:`hapstab.crossings`: no grid, no bracket, polished to
rounding) and the stable set in K. Rigid-body modes (poles at z = 1 that no K
moves) are reported as marginal, never as unstable.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .crossings import exact_kmax_batch  # re-exported: the public batched core
from .engine import SampledSystem, build
from .models import HapticLoop, TeleoperationLoop
from .results import CriticalStiffnessResult, StabilityResult

__all__ = ["stability", "exact_critical_stiffness", "exact_kmax_batch", "rigid_body_modes",
           "spectral_radius"]

#: |z| - 1 below this (relative to rounding of the eigenvalue solver) is "on the circle".
MARGINAL_TOL = 1e-9

def rigid_body_modes(A0: np.ndarray, A1: np.ndarray) -> int:
    """Number of independent modes at z = 1 that no K moves: dim null([I - A0; A1])."""
    N = A0.shape[-1]
    S = np.linalg.svd(np.vstack([np.eye(N) - A0, A1]), compute_uv=False)
    scale = max(1.0, float(S[0]))
    return int(np.sum(S < 1e-10 * scale))


def _spectral_radius(eigs: np.ndarray, n_rigid: int) -> np.ndarray:  # noqa: D401
    """Spectral radius over the last axis, excluding the n_rigid eigenvalues nearest 1."""
    if n_rigid:
        order = np.argsort(np.abs(eigs - 1.0), axis=-1)
        eigs = np.take_along_axis(eigs, order[..., n_rigid:], axis=-1)
    return np.abs(eigs).max(axis=-1)


def spectral_radius(sysm: SampledSystem, K: np.ndarray | float) -> np.ndarray:
    """Spectral radius of A(K) for each period (rigid-body modes excluded)."""
    A = sysm.closed_loop(K)
    m = rigid_body_modes(sysm.A0[0], sysm.A1()[0]) if sysm.varies_with_K else 0
    return _spectral_radius(np.linalg.eigvals(A), m)


# ---------------------------------------------------------------------- stability
def stability(loop: HapticLoop | TeleoperationLoop) -> StabilityResult:
    """Exact stability of the sampled-data loop at its own parameters.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop

    Returns
    -------
    StabilityResult
        ``stable`` if every closed-loop pole has |z| < 1, ``unstable`` if one has
        |z| > 1, ``marginal`` if the largest is on the circle (within 1e-9) or a
        rigid-body mode sits at z = 1.

    References
    ----------
    Exact ZOH model of Fig. 2a / Fig. 3 with H(z) of eq. (23).
    """
    sysm = build(loop)
    A = sysm.closed_loop()[0]
    eigs = np.linalg.eigvals(A)
    m = rigid_body_modes(sysm.A0[0], sysm.A1()[0]) if sysm.varies_with_K else 0
    rest = eigs
    if m:
        order = np.argsort(np.abs(eigs - 1.0))
        rest = eigs[order[m:]]
    k = int(np.argmax(np.abs(rest))) if rest.size else 0
    dom = complex(rest[k]) if rest.size else complex(1.0)
    rho = abs(dom)
    T = loop.period
    freq = abs(math.atan2(dom.imag, dom.real)) / (2 * math.pi * T)
    K = float(sysm.stiffness[0])
    if sysm.varies_with_K and K > 0 and abs(rho - 1) < 1e-6:
        # closer to the circle than eigenvalues of poles crowding z = 1 resolve:
        # let the exact crossing analysis place K (consistent with K_max by design)
        ex = exact_kmax_batch(sysm)[0]
        ends = [e for iv in ex["intervals"] for e in iv if 0 < e < math.inf]
        note = (f"; |z| = {rho:.12g} is within 1e-6 of the circle, so the verdict comes from "
                "the exact crossing analysis")
        if any(abs(K - e) <= 1e-12 * e for e in ends):
            return StabilityResult("marginal", rho, dom, freq, "K is at a stability boundary: a pole "
                                   f"is on the unit circle ({_describe(dom, T)}){note}", T,
                                   tuple(complex(e) for e in eigs), m)
        inside = any(a < K < b for a, b in ex["intervals"])
        rho_verdict = min(rho, 1 - 1e-16) if inside else max(rho, 1 + 1e-16)
        reason_extra = note
    else:
        reason_extra, rho_verdict = "", rho
    if rho_verdict > 1 + MARGINAL_TOL or (reason_extra and rho_verdict > 1):
        verdict = "unstable"
        reason = (f"closed-loop pole at |z| = {rho:.10g} ({_describe(dom, T)}): "
                  "the response grows")
    elif rho_verdict >= 1 - MARGINAL_TOL and not reason_extra:
        verdict = "marginal"
        reason = f"closed-loop pole on the unit circle ({_describe(dom, T)}): sustained oscillation or drift"
    elif m:
        verdict = "marginal"
        reason = (f"{m} rigid-body mode(s) at z = 1: nothing ties the masses to ground, so a "
                  "constant offset persists; all other poles have |z| <= "
                  f"{rho:.6g} < 1")
    else:
        verdict = "stable"
        reason = f"all closed-loop poles inside the unit circle (largest |z| = {rho:.10g})"
    if m and verdict != "marginal":
        reason += f"; {m} rigid-body mode(s) at z = 1 excluded"
    reason += reason_extra
    return StabilityResult(verdict, rho, dom, freq, reason, T, tuple(complex(e) for e in eigs), m)


def _describe(z: complex, T: float) -> str:
    th = abs(math.atan2(z.imag, z.real))
    if th < 1e-12:
        return "real pole at z = +1 side (non-oscillatory)"
    if abs(th - math.pi) < 1e-9:
        return f"real pole at z = -1 side (oscillation at the Nyquist frequency {1 / (2 * T):.6g} Hz)"
    return f"complex pair, oscillation at {th / (2 * math.pi * T):.6g} Hz"


def exact_critical_stiffness(loop: HapticLoop | TeleoperationLoop) -> CriticalStiffnessResult:
    """Exact K_max of the sampled-data loop (see the module docstring).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controller(s); B, T, n and impedances fixed. For
        teleoperation, K is the master's stiffness and K_s/K_m is kept.

    Returns
    -------
    CriticalStiffnessResult
        ``method="exact"``; ``stable_intervals`` lists every stable interval.

    Raises
    ------
    AnalysisError
        If the controller is not a spring-damper.
    """
    sysm = build(loop)
    res = exact_kmax_batch(sysm)[0]
    return _to_result(res, loop.period, loop.delay_in_samples)


def _to_result(res: dict[str, Any], T: float, n: int | float) -> CriticalStiffnessResult:
    kmax, th = res["kmax"], res["theta"]
    freq = th / (2 * math.pi * T) if np.isfinite(th) else math.nan
    if kmax == 0.0:
        reason = (f"unstable for every K > 0: already as K -> 0+ the spectral radius is "
                  f"{res['rho_small_K']:.6g} > 1 (the virtual damping, delay and terminations "
                  "alone destabilise the loop)")
    elif math.isinf(kmax):
        reason = "stable for every K > 0 (no closed-loop pole reaches the unit circle)"
    elif th == 0.0:
        reason = "a real closed-loop pole crosses z = +1 at K_max (static divergence)"
    elif th == math.pi:
        reason = (f"a real closed-loop pole crosses z = -1 at K_max (oscillation at the "
                  f"Nyquist frequency, {1 / (2 * T):.6g} Hz)")
    else:
        reason = f"a complex pole pair crosses |z| = 1 at K_max, oscillating at {freq:.6g} Hz"
    if len(res["intervals"]) > 1:
        reason += f"; the stable set in K is not one interval ({len(res['intervals'])} intervals)"
    if res["rigid"]:
        reason += f"; {res['rigid']} rigid-body mode(s) at z = 1 (marginal, K-independent) excluded"
    return CriticalStiffnessResult(kmax, "exact", res["intervals"], reason, T, n, freq,
                                   {"rigid_body_modes": res["rigid"]})
