"""The numerical tolerances that more than one part of hapstab relies on, named,
each with its reason. (Tolerances that belong to one algorithm stay beside it,
with their reasons, e.g. the floors of :mod:`hapstab.analysis.exact.boxes`.)"""

from __future__ import annotations

__all__ = ["DELAY_SNAP", "POLE_ON_CIRCLE", "ROOT_ON_CIRCLE"]

#: A delay within this (relative to max(1, d)) of a whole number of samples is that
#: whole number: t_d / T carries rounding of ~1e-16 d, and a billionth of a sample
#: is far below any timing a device has.
DELAY_SNAP = 1e-9

#: A closed-loop pole polished by Newton's method on the exact characteristic
#: function is on |z| = 1 when ||z| - 1| is below this: the discretised model's
#: coefficients are good to ~1e-14 relative, a pole's modulus then to ~1e-12 near
#: z = 1, where poles crowd at small T.
POLE_ON_CIRCLE = 1e-12

#: A root of a polynomial found by ``np.roots`` (a controller's or a rational
#: matrix's pole or zero) is on |z| = 1 when ||z| - 1| is below this, and is put
#: exactly on it: simple roots come out to ~1e-15, roots of multiplicity two split
#: by ~1e-8 (sqrt(eps)), and a root 1e-9 from the circle is on it for any
#: frequency sweep.
ROOT_ON_CIRCLE = 1e-9
