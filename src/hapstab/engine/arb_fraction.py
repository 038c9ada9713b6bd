"""The characteristic polynomial of a loop whose delays are not whole samples, in ball
arithmetic (python-flint's Arb), and its poles outside the unit circle from roots
isolated in balls.

Covered: the loops of :class:`~hapstab.engine.arb_loop.ArbLoop` (one or two ports whose
terminations have no internal states, spring-damper controllers, no rigid-body mode,
the own position read undelayed on two ports) with any delay ``n + f`` samples on each
measured term, ``f`` in [0, 1).

**Derivation.** Each port j alone: with the ZOH ``[Phi_t, Gamma_t; 0, 1] = exp([A_j, B_j;
0, 0] t)`` (``arb_mat.exp``), ``E = Phi_T - I``, ``y = z - 1`` and ``d_j(y) = det(yI -
E)``, its position sampled ``fT`` before the instants has the transform ``z X_{j,f} =
-Nt_{j,f}(y) / d_j(y) U_j`` with (Jury's modified z-transform, m = 1 - f; derived in
:mod:`hapstab.analysis.network.modified_z`)

    Nt_{j,f} = c_f adj(yI - E) Gamma_T + g_f d_j,   [c_f, g_f] = row x of exp([A_j, B_j; 0, 0](1 - f)T),

and ``c adj(yI - E) Gamma = det(yI - E + Gamma c) - d_j(y)`` (the matrix determinant
lemma). At f = 0, ``Nt_{j,0} = z N_j``, ``N_j = C adj(yI - E) Gamma_T``, used exactly
(no ball of a polynomial that vanishes at z = 0). A term (j, s, n + f) of channel i
contributes ``s z^-(n+1) Nt_{j,f} / d_j`` to ``x``, and ``H_i = (K r_i z + beta_i (z -
1)) / z``, so with each row i multiplied by ``z^R_i``, ``R_i = 1 + max (n + 1)`` over its
terms, the loop's matrix has polynomial entries

    chi_ij(z) = delta_ij z^R_i d_j(z - 1) + h_i(z) sum_t s_t z^(R_i - 2 - n_t) Nt_{j,f_t}(z - 1),

``h_i = K r_i z + beta_i (z - 1)``; ``chi = det [chi_ij]`` is ``z^(sum R_i)`` times the
characteristic function ``det M`` of :mod:`hapstab.engine.arb_loop` (with the fractional
terms), so its roots are the closed-loop poles and roots at z = 0; the roots at 0 that
come out as exactly zero coefficients at the bottom are divided out. The HVE's chi is
that of :mod:`~hapstab.analysis.network.modified_z` (monic of degree n + 4), the PEB's
that of :mod:`~hapstab.analysis.network.modified_z_peb` for the same delay both ways
(degree 2n + 8 there; here also different delays in each direction).

**The count.** First Weierstrass inclusion discs (:func:`_inclusion_count`): about
approximations x_i of the roots (the closed loop's eigenvalues, or numpy's roots of
the midpoints, refined by Newton's method where needed), the discs |z - x_i| <= deg |W_i|,
W_i = chi(x_i) / (lc prod_{j != i}(x_i - x_j)), hold every root, k of them in each
connected component of k discs (Braess and Hadeler 1973; p / lc is the characteristic
polynomial of diag(x) - W 1^T, and Gershgorin's discs of that matrix lie inside these);
|chi(x_i)| bounded above and |lc| below by ball evaluation, so for every polynomial in
the coefficient balls. Where they cannot decide, Arb's ``acb_poly.roots``
(``acb_poly_find_roots`` refined by ``acb_poly_validate_roots``: a ball of radius
deg |chi(m) / chi'(m)| about each approximation m holds a root of every polynomial in
the balls, and when the deg balls are pairwise disjoint each holds exactly one). The
number outside is decided when every component (ball) lies strictly inside or strictly
outside the unit circle, and is otherwise *undecided* -- never guessed.

References
----------
D. Braess and K. P. Hadeler, "Simultaneous inclusion of the zeros of a polynomial",
Numer. Math. 21 (1973) 161-165. F. Johansson, "Arb: efficient arbitrary-precision
midpoint-radius interval arithmetic", IEEE Trans. Computers 66 (2017) 1281-1292, and the Arb documentation of
``acb_poly_validate_roots`` / ``_acb_poly_root_inclusion``; E. I. Jury, *Theory and
Application of the z-Transform Method*, Wiley 1964, ch. 2; K. J. Astrom and B.
Wittenmark, *Computer-Controlled Systems*, 3rd ed., sec. 2.3 and 7.7.
"""

from __future__ import annotations

import math
from typing import Any

from hapstab.engine.arb_base import PortZoh
from hapstab.engine.arb_forms import accuracy_bits
from hapstab.engine.arb_loop import MIN_BITS, PREC, arb_parameters, working_precision

__all__ = ["fractional_polynomial", "outside_count", "outside_poles", "fractional_count",
           "fractional_poles", "MAX_DEGREE"]

#: Largest degree of chi whose roots are isolated here: Arb isolates degree ~100 in
#: ~5 ms and ~1000 in ~0.6 s (measured, python-flint 0.9); beyond, the caller's other
#: count answers (a long delay's degree grows with n).
MAX_DEGREE = 600


def _terms(loop: Any) -> tuple[dict[str, Any], list[list[tuple[int, float, int, float]]]] | None:
    """(the ball core's numbers of the loop at whole delays, each channel's terms as
    (port, sign, n, f)), or None if the loop is outside this model or has no fraction."""
    from hapstab.engine.structure import structure_of
    from hapstab.models.delays import split_delay
    try:
        st = structure_of(loop)
        whole = loop.with_whole_delay(0)
    except Exception:        # not a loop the exact core takes at all
        return None
    params = arb_parameters(whole)
    if params is None or len(params["channels"]) != len(st.channels):
        return None
    terms = [[(int(j), float(s), *split_delay(float(d))) for j, s, d in ch.terms]
             for ch in st.channels]
    if not any(f for ch in terms for *_, f in ch):
        return None
    own = [[t for t in ch if t[0] == i] for i, ch in enumerate(terms)] if len(terms) == 2 else []
    if any(len(o) != 1 or o[0][2] or o[0][3] for o in own):
        return None              # two ports: the own position is read undelayed
    return params, terms


def _port(p: dict[str, Any], T: Any, fractions: set[float]) -> tuple[Any, Any, dict[float, Any]]:
    """(d, N, {f: Nt_f}) of one port, arb_poly in y (module docstring)."""
    import flint
    z = PortZoh(p, T)
    nt = {}
    for f in fractions:
        Xf = z.aug((1 - flint.arb(f)) * T)
        nt[f] = z.numerator((Xf[0, 0], Xf[0, 1])) + z.d * Xf[0, 2]
    return z.d, z.numerator(), nt


def fractional_polynomial(loop: Any, K: float) -> tuple[Any, int] | None:
    """chi(z) of ``loop`` at stiffness ``K`` (module docstring) as an acb_poly in z with
    exact zero coefficients at the bottom divided out, and the precision it was formed
    at; None if the loop is not covered (or has whole delays only: :class:`ArbLoop`).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
    K : float
        The (master's) stiffness, N/m; each channel's is ``K r_i``.

    Returns
    -------
    (acb_poly, int) or None
    """
    got = _terms(loop)
    if got is None:
        return None
    params, terms = got
    prec = PREC
    while True:
        with working_precision(prec):
            chi, ok = _build(params, terms, K)
        if ok or prec >= 4096:       # the accuracy check of ArbLoop (MIN_BITS)
            break
        prec *= 2
    if not ok:
        return None
    low = next((i for i in range(chi.degree() + 1) if not chi[i].is_zero()), None)
    if low is None:
        return None
    import flint
    return flint.acb_poly([chi[i] for i in range(low, chi.degree() + 1)]), prec


def _build(params: dict[str, Any], terms: list[list[tuple[int, float, int, float]]],
           K: float) -> tuple[Any, bool]:
    import flint
    arb, arb_poly = flint.arb, flint.arb_poly
    T = arb(params["period_s"])
    used: list[set[float]] = [set() for _ in params["ports"]]
    for ch in terms:
        for j, _s, _n, f in ch:
            if f:
                used[j].add(f)
    ports = [_port(p, T, used[j]) for j, p in enumerate(params["ports"])]
    ok = all(accuracy_bits(d) >= MIN_BITS and accuracy_bits(N) >= MIN_BITS for d, N, _ in ports)
    y, z = arb_poly([-1, 1]), arb_poly([0, 1])
    dz = [d(y) for d, _, _ in ports]
    rows = []
    for i, (ch, c) in enumerate(zip(terms, params["channels"], strict=True)):
        R = 1 + max(n + 1 for _j, _s, n, _f in ch)
        h = z * (arb(K) * arb(c["stiffness_ratio"])) + (z - 1) * (arb(c["damping_N_s_per_m"]) / T)
        row = [z ** R * dz[j] if j == i else arb_poly([0]) for j in range(len(ports))]
        for j, s, n, f in ch:
            part = z ** (R - 1 - n) * ports[j][1](y) if not f else \
                z ** (R - 2 - n) * ports[j][2][f](y)
            row[j] = row[j] + h * part * s
        rows.append(row)
    if len(rows) == 1:
        return rows[0][0], ok
    return rows[0][0] * rows[1][1] - rows[0][1] * rows[1][0], ok


#: Relative allowance on a disc's radius in :func:`_inclusion_count` for the rounding
#: of a ball's bound converted to a double (1.2e-16) and of the products by deg and the
#: exponential (a few eps): 1e-12. The log-sum of the n - 1 differences has its own,
#: larger allowance, formed per disc (:func:`_log_sum_error`).
FLOAT_SLACK = 1e-12
#: A bound or product of differences beyond the doubles' safe range (1e-290 ... 1e290):
#: a subnormal or overflowing double would make the relative allowances meaningless, so
#: such a disc is left undecided.
SAFE_LOG = 660.0
#: Relative allowance on a modulus or a distance of complex doubles (|a - b|, |x|):
#: within 4 eps ~ 9e-16 of the exact value (one rounding per part, one in hypot), 1e-14
#: covers it ten times.
MODULUS_SLACK = 1e-14
#: Newton steps on each double approximation at the working precision before its disc
#: is formed: numpy's roots of poles crowding z = 1 are off by ~1e-8; each step squares
#: the error of a simple root (the discs only need good centres).
NEWTON_STEPS = 3


def _centres(chi: Any, deg: int, newton: int, guess: Any = None) -> Any:
    """Approximations of the roots (complex doubles, distinct): the ``deg`` largest of
    ``guess`` (the closed loop's eigenvalues: the roots and poles at z = 0) or numpy's
    roots of the midpoints, refined by ``newton`` steps of Newton's method on the ball
    polynomial's midpoints; None if that fails. (Only the discs' centres: a poor guess
    makes the inclusion test fail, never pass wrongly.)"""
    import flint
    import numpy as np
    if guess is not None:
        g = np.asarray(guess, complex)
        m = g[np.argsort(-np.abs(g), kind="stable")[:deg]].copy()
    else:
        coef = [complex(float(c.real.mid()), float(c.imag.mid())) for c in chi.coeffs()]
        with np.errstate(all="ignore"):
            m = np.roots(coef[::-1])
    if m.size != deg or not np.all(np.isfinite(m)):
        return None
    if not newton:
        return m if np.unique(m).size == deg else None
    dchi = chi.derivative()
    for i, x in enumerate(m):
        xa = flint.acb(float(x.real), float(x.imag))
        for _ in range(newton):
            step = chi(xa) / dchi(xa)
            if not step.is_finite():
                break
            xa = (xa - step).mid()
        m[i] = complex(float(xa.real), float(xa.imag))
    return m if np.unique(m).size == deg else None


def _log_sum_error(logs: Any) -> Any:
    """A bound on |computed - exact| of each row's sum of ``logs`` (logs of moduli of
    complex differences of doubles): each modulus within 4 eps relative, so each log
    within 4 eps + eps |log| (its own rounding); the n - 1 additions of recursive
    summation within (n - 1) eps sum |log| (Higham, *Accuracy and Stability of Numerical
    Algorithms*, 2nd ed., eq. 4.4; numpy's pairwise summation is tighter); doubled for
    the rounding of this bound itself."""
    import numpy as np
    eps = 2.0 ** -52
    n = logs.shape[1]
    a = np.abs(logs)
    np.fill_diagonal(a, 0.0)
    return 2.0 * (n * 4 * eps + eps * a.sum(axis=1) + (n - 1) * eps * a.sum(axis=1))


def _inclusion_count(chi: Any, deg: int, newton: int = 0, guess: Any = None
                     ) -> tuple[int, Any] | None:
    """The roots outside the unit circle from Weierstrass inclusion discs: with distinct
    centres x_i and W_i = chi(x_i) / (lc prod_{j != i} (x_i - x_j)), the union of the
    discs |z - x_i| <= deg |W_i| holds every root, and each connected component of k of
    them holds exactly k (D. Braess and K. P. Hadeler, "Simultaneous inclusion of the
    zeros of a polynomial", Numer. Math. 21 (1973) 161-165). |chi(x_i)| is bounded above
    and |lc| below by ball evaluation, so the discs hold those of every polynomial in the
    coefficient balls. (the count, the centres), or None when a component meets the
    circle."""
    import numpy as np
    m = _centres(chi, deg, newton, guess)
    if m is None:
        return None
    import flint
    lc = chi[deg].abs_lower()
    if not lc > 0:
        return None
    diff = m[:, None] - m[None, :]
    np.fill_diagonal(diff, 1.0)
    with np.errstate(all="ignore"):
        logs = np.log(np.abs(diff))
    logprod = np.sum(logs, axis=1)
    if not np.all(np.abs(logprod) < SAFE_LOG):
        return None
    radius = np.empty(deg)
    for i, x in enumerate(m):
        up = chi(flint.acb(float(x.real), float(x.imag))).abs_upper() / lc
        radius[i] = float(up.mid()) + float(up.rad())
    if not np.all((radius > math.exp(-SAFE_LOG)) & (radius < math.exp(SAFE_LOG))):
        return None
    radius = deg * radius * np.exp(-logprod + _log_sum_error(logs)) * (1 + FLOAT_SLACK)
    if not np.all(np.isfinite(radius)):
        return None
    touch = np.abs(diff) * (1 - MODULUS_SLACK) <= radius[:, None] + radius[None, :]
    np.fill_diagonal(touch, True)
    size = np.abs(m)
    outside = size * (1 - MODULUS_SLACK) - radius > 1
    inside = size * (1 + MODULUS_SLACK) + radius < 1
    # each component (overlapping discs, by reachability) must lie on one side
    group = np.arange(deg)
    for _ in range(deg):
        new = np.min(np.where(touch, group[None, :], deg), axis=1)
        if np.array_equal(new, group):
            break
        group = new
    for g in np.unique(group):
        k = group == g
        if not (np.all(outside[k]) or np.all(inside[k])):
            return None
    return int(np.sum(outside)), m


def outside_poles(chi: Any, prec: int, guess: Any = None) -> tuple[int | None, Any]:
    """(the roots of ``chi`` outside the unit circle, approximations of all its roots):
    the count from balls isolating the roots (module docstring), None when a ball touches
    the circle, the roots cannot be isolated (a multiple or very close pair) or the
    degree is above :data:`MAX_DEGREE`; the approximations (complex doubles, accurate to
    the balls' radii) None where no isolation succeeded. ``guess``: approximations to
    try first (e.g. the closed loop's eigenvalues, already computed)."""
    import numpy as np
    deg = chi.degree()
    if deg > MAX_DEGREE or chi[deg].contains(0):
        return None, None
    if deg == 0:
        return 0, np.zeros(0, complex)
    with working_precision(prec):
        # numpy's centres; refined (poles crowding z = 1 or a close pair); Arb's roots
        tries = [(g, newton) for g in ((guess, None) if guess is not None else (None,))
                 for newton in (0, NEWTON_STEPS)]
        for g, newton in tries:
            if g is not None and len(g) < deg:
                continue
            fast = _inclusion_count(chi, deg, newton, g)
            if fast is not None:
                return fast
    with working_precision(prec):
        # Arb's own radii first (cheapest), then refined to 1e-20: a pole nearer the
        # circle than that is left undecided (None), never guessed
        for tol in (None, 1e-20):
            try:
                rs = chi.roots(tol=tol, maxprec=4 * prec)
            except ValueError:
                return None, None
            out = sum(1 for r in rs if r.abs_lower() > 1)
            if len(rs) == deg and out + sum(1 for r in rs if r.abs_upper() < 1) == deg:
                return out, np.array([complex(float(r.real.mid()), float(r.imag.mid()))
                                      for r in rs])
    return None, None


def outside_count(chi: Any, prec: int) -> int | None:
    """The roots of ``chi`` (acb_poly, leading coefficient clear of 0) outside the unit
    circle (:func:`outside_poles`), or None if undecided."""
    return outside_poles(chi, prec)[0]


def fractional_poles(loop: Any, K: float, guess: Any = None) -> tuple[int, Any] | None:
    """(poles of ``loop`` outside the unit circle at ``K``, the poles but those at z = 0):
    the count an int (proved) or -1 (a pole within the balls' width of the circle:
    undecided), the poles complex doubles or None (not isolated); None if not covered
    (no fractional delay, outside the model, or a degree above :data:`MAX_DEGREE`).
    ``guess``: the closed loop's eigenvalues, if at hand (:func:`outside_poles`)."""
    got = fractional_polynomial(loop, K)
    if got is None or got[0].degree() > MAX_DEGREE:
        return None
    out, poles = outside_poles(*got, guess=guess)
    return (-1 if out is None else out), poles


def fractional_count(loop: Any, K: float) -> int | None:
    """Poles of ``loop`` outside the unit circle at ``K``: an int (proved), -1 (a pole
    within the balls' width of the circle: undecided), None (not covered: no fractional
    delay, outside the model, or a degree above :data:`MAX_DEGREE`)."""
    got = fractional_poles(loop, K)
    return None if got is None else got[0]
