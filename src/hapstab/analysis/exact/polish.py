"""Newton's method on det M(e^{j theta}, K) = 0 at the working precision: places a
crossing's window for the proof (:mod:`~hapstab.analysis.exact.proof`); not itself a proof."""

from __future__ import annotations

import math

from hapstab.engine.arb_loop import ArbLoop, working_precision

__all__ = ["polish"]


def polish(al: ArbLoop, theta: float, K: float, real: bool) -> tuple[float, float] | None:
    """Newton's method on det M(e^{j theta}, K) = 0 from a float guess (theta, K);
    ``real``: theta stays 0 or pi (a real pole through z = +-1). Not a proof (it
    places the windows). None if it does not converge."""
    from flint import arb
    with working_precision(al.prec):
        th, k = arb(theta), arb(K)
        h = arb(2.0 ** -90)
        for _ in range(60):
            F = al.value(th, k).mid()
            Fk = al.dvalue_dk(th, k).mid()
            if real:
                dk = -(F.real / Fk.real)
                dth = arb(0)
            else:
                Ft = ((al.value(th + h, k) - al.value(th - h, k)) / (2 * h)).mid()
                det = Ft.real * Fk.imag - Ft.imag * Fk.real
                if det == 0:
                    return None
                dth = -(F.real * Fk.imag - F.imag * Fk.real) / det
                dk = -(Ft.real * F.imag - Ft.imag * F.real) / det
            th, k = (th + dth).mid(), (k + dk).mid()
            # converged: steps below 1e-40 are far under double's 1e-16 the result keeps
            if abs(float(dk)) <= 1e-40 * abs(float(k)) and abs(float(dth)) <= 1e-40:
                t, kk = float(th), float(k)
                if not (math.isfinite(t) and math.isfinite(kk)) or kk <= 0:
                    return None
                return t % (2 * math.pi) if not real else t, kk
    return None


# ----------------------------------------------------------------- the proof
