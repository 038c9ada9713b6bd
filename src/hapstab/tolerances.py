"""The numerical tolerances that more than one part of hapstab relies on, named,
each with its reason. (Tolerances that belong to one algorithm stay beside it,
with their reasons, e.g. the floors of :mod:`hapstab.analysis.exact.boxes`;
tests/project/test_tolerances.py checks that every small literal has its reason beside it.)"""

from __future__ import annotations

__all__ = ["DELAY_SNAP", "POLE_ON_CIRCLE", "ROOT_ON_CIRCLE", "PSD_SLACK", "COEFF_ZERO",
           "NEWTON_ANGLE_STEP", "DIVISOR_FLOOR"]

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

#: A Hermitian matrix (a passivity or circle-criterion matrix at one frequency, or its
#: part at K = 0) counts as positive semidefinite when its least eigenvalue is
#: >= -PSD_SLACK times the matrix's scale (its largest |entry|, or that of its sampled
#: part): the few products and sums that build it and the eigenvalue solver leave
#: ~1e-15..1e-13 of that scale, and 1e-12 of it is still far below any damping margin
#: that matters, so a margin that is 0 in exact arithmetic reads as PSD, not as a
#: failure by rounding.
PSD_SLACK = 1e-12

#: A coefficient produced by polynomial arithmetic (np.polydiv, polymul, polysub on a
#: model's coefficients) is zero when below this relative to the largest coefficient
#: involved: each operation leaves a few unit round-offs (eps = 2.2e-16) per term, and
#: 1e-14 (~45 eps) covers a handful of them while any coefficient the model really
#: has is far larger.
COEFF_ZERO = 1e-14

#: Newton's method on a crossing angle theta (rad/sample, 0..pi) has converged when
#: its step is below this relative to max(1, theta) (or 1 + theta): about 4.5 unit
#: round-offs, i.e. the angle is as good as the characteristic function's own
#: rounding allows; further steps only move it by rounding.
NEWTON_ANGLE_STEP = 1e-15

#: A scale, norm or determinant that may be exactly 0 is floored at this before it is
#: divided by (or its log taken), and one at or below it counts as 0: it is just
#: above the smallest normal double (2.2e-308), so no genuine scale is ever changed,
#: and a quotient by it still fits in a double for any operand below ~1e8.
DIVISOR_FLOOR = 1e-300
