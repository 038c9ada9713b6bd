"""Re-check a K_max certificate from the loop's numbers alone, in ball arithmetic.

A certificate (:func:`hapstab.analysis.exact.certificate.certificate`, ``hapstab kmax ...
--certificate FILE``) claims: the closed loop is stable for every K in each listed
interval [K_a, K_b], K_max is the upper end of the one from the base point K_0, and
(when given) it is unstable at ``kmax_upper``. This module does not import the search
that produced it: it rebuilds the characteristic function from the certificate's
``loop`` numbers (:class:`~hapstab.engine.arb_loop.ArbLoop`, Arb balls) and checks

0. **shape** -- the format and version (:data:`VERSIONS`), every field's type and
   range (finite numbers, K > 0, a finite K_max >= 0, pieces that advance, stable
   intervals from K_0 up, increasing and disjoint, each count inside its gap); and
   the base point K_0, re-derived from the loop's numbers
   (:func:`~hapstab.engine.arb_loop.base_point`), never taken from the certificate;
1. **counts** -- each count's pieces, replayed from the ``start_pieces`` equal pieces
   of [0, pi] by halving (from version 4 with the start and the halving of the gaps
   below; so they tile [0, pi] by construction: a dropped or altered
   piece breaks the replay), each prove its increment of arg det M (``P``: |P| > |Q|,
   ``Q``: |Q| > |P|, ``F``: 0 not in the ball; its balls by the version's kernel, as
   for the gaps below); the winding gives the poles outside,
   which must equal the count claimed; a count by ``roots`` (version 3) is redone: the
   roots of the characteristic polynomial, rebuilt from the loop's numbers, isolated
   in balls each clear of the circle;
2. **gaps** -- each excluded gap's pieces, replayed from ``start_pieces`` x [lo, hi]
   (halving theta at the midpoint, or K at the geometric mean of a wide range, else
   the midpoint; from version 4 the start pieces have no ladder near theta = 0, a
   piece [a, b] of angles with b > 4a > 0 is halved at its geometric mean and a
   K-range with k1 > 64 k0 cut at k1 / 8), each excluding 0 for the reason given
   (``P``, ``Q``, ``F`` or, from version 2, ``N``:
   :func:`~hapstab.engine.arb_loop.preconditioned_excludes`; from version 5, ``I``:
   the iterated Krawczyk operator, :mod:`~hapstab.engine.arb_krawczyk`), its balls formed as the
   certificate's version says (from version 4 by the angle kernel of precomputed
   ball polynomials, :mod:`~hapstab.engine.arb_kernel`; before, by forward-mode
   derivatives);
3. **the claim** -- every stable interval is a chain of excluded gaps with a verified
   count 0 inside, starting and ending where the interval does; K_max is the upper
   end of the one from K_0; ``kmax_upper`` has a verified count > 0 at it; each
   crossing's direction agrees with the counts either side.

What is verified is stability for K in [K_0, K_max]: K_0 stands for K -> 0+ and
(0, K_0) is not proved. Any failure is ``CertificateCheck(valid=False, reason=...)``
naming the check, never an exception.

References
----------
F. Johansson, "Arb: efficient arbitrary-precision midpoint-radius interval
arithmetic", IEEE Trans. Computers 66 (2017) 1281-1292.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from hapstab.analysis.certificate_shape import (
    FORMAT,
    VERSIONS,
    Invalid,
    check_shape,
)
from hapstab.engine.arb_loop import (
    ArbLoop,
    base_point,
    poly_k,
    preconditioned_excludes,
    working_precision,
)

__all__ = ["verify_certificate", "CertificateCheck", "FORMAT", "VERSIONS"]


@dataclass(frozen=True)
class CertificateCheck:
    """The verdict on a certificate.

    Attributes
    ----------
    valid : bool
        Every check passed.
    reason : str
        What was verified, or the first check that failed.
    kmax : float or None
        The verified K_max (N/m) when valid.
    proved_range : tuple of float or None
        [K_0, K_max] (N/m) proved stable when valid and K_max > 0; K_0 is the base
        point standing for K -> 0+, re-derived from the loop's numbers: (0, K_0) is
        not proved.
    """

    valid: bool
    reason: str
    kmax: float | None = None
    proved_range: tuple[float, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"valid": self.valid, "reason": self.reason, "kmax_N_per_m": self.kmax,
                "proved_range_N_per_m": None if self.proved_range is None
                else list(self.proved_range)}


def _ball(a: float, b: float) -> Any:
    """The ball holding [a, b], an end equal to ``math.pi`` standing for pi: call it at
    the proof's precision, as the search does (``arb.pi()`` is rounded to the precision
    in force: at 53 bits a piece ending at pi, next to a pole 1e-12 from the circle,
    left the winding undecided where the search had proved it: wall-hve#22 of seed 26)."""
    import flint
    arb = flint.arb
    lo = arb.pi() if a == math.pi else arb(a)
    hi = arb.pi() if b == math.pi else arb(b)
    return lo.union(hi)


def _excludes(al: ArbLoop, a: float, b: float, ka: float, kb: float, how: str,
              polys: bool) -> bool:
    """Whether the box [a, b] x [ka, kb] has no zero of det M, for the reason ``how``
    (``N``: the preconditioned mean-value form, certificate version 2; ``I``: the
    iterated Krawczyk operator, version 5, :mod:`~hapstab.engine.arb_krawczyk`). Any balls that
    hold the box prove it; the search forms them in double precision and the counts at
    the proof's (:func:`_ball`), and the mean-value test is not monotone in the ball
    (its centre moves), so both forms are tried (seed 1796236426's mass-peb#6: an 'N'
    piece the search proved failed with the balls formed at 320 bits). ``polys``: the
    angle kernel of precomputed ball polynomials (certificate version 4,
    :mod:`~hapstab.engine.arb_kernel`), else forward-mode derivatives (versions 1-3)."""
    return any(_excludes_with(al, a, b, ka, kb, how, prec, polys) for prec in (al.prec, None))


def _excludes_with(al: ArbLoop, a: float, b: float, ka: float, kb: float, how: str,
                   prec: int | None, polys: bool) -> bool:
    """:func:`_excludes` with the box's balls formed at ``prec`` bits (None: doubles)."""
    import flint
    arb = flint.arb
    with working_precision(prec or 53):
        th, K = _ball(a, b), arb(ka).union(arb(kb))
    key = (a, b, prec)                    # the angle's kernel, per form of its ball
    if how == "I":                        # version 5 (certificate_shape admits it there)
        return polys and al.krawczyk_excludes(th, K, (a, b, ka, kb))
    if how == "N":
        Fc, Ft, Fk = al.box_derivatives(th, K, key=key, polys=polys)
        with working_precision(al.prec):
            return preconditioned_excludes(Fc, Ft, Fk, th.rad(), K.rad())
    P, Q, F = al.box(th, K, key=key, polys=polys)
    with working_precision(al.prec):
        if how == "P":
            return bool(P.abs_lower() > Q.abs_upper())
        if how == "Q":
            return bool(Q.abs_lower() > P.abs_upper())
        return how == "F" and not F.contains(0)


def _increment(al: ArbLoop, a: float, b: float, K: Any, how: str, version: int) -> Any:
    """The proved increment of arg det M over [a, b] at K (raises Invalid), the piece's
    balls by the kernel of the certificate's ``version`` (as :func:`_excludes`)."""
    with working_precision(al.prec):      # pi at the proof's precision (_ball)
        P, Q, F = al.box(_ball(a, b), K, key=(a, b), polys=version >= 4)
        pa, qa, wa = al.parts(_ball(a, a))
        pb, qb, wb = al.parts(_ball(b, b))
        Pa, Qa, Pb, Qb = poly_k(pa, K), poly_k(qa, K), poly_k(pb, K), poly_k(qb, K)
        if how == "P" and P.abs_lower() > Q.abs_upper():
            return (Pb / Pa).arg() + (1 + wb * Qb / Pb).arg() - (1 + wa * Qa / Pa).arg()
        if how == "Q" and Q.abs_lower() > P.abs_upper():
            return ((Qb / Qa).arg() - al.n_phase * (_ball(b, b) - _ball(a, a))
                    + (1 + Pb / (wb * Qb)).arg() - (1 + Pa / (wa * Qa)).arg())
        if how == "F" and not F.contains(0):
            return ((Pb + wb * Qb) / (Pa + wa * Qa)).arg()
    raise Invalid(f"piece theta in [{a!r}, {b!r}] at K = {float(K.mid())!r}: '{how}' does not "
                   "hold in ball arithmetic")


def _start(n: int) -> list[tuple[float, float]]:
    """The n equal pieces of [0, pi], the first cut again at pi/n 2^-k, k = 1..40."""
    step = math.pi / n
    near = [(0.0, step * 2.0 ** -40)] + [(step * 2.0 ** -k, step * 2.0 ** (1 - k))
                                          for k in range(40, 0, -1)]
    return near + [(i * step, math.pi if i == n - 1 else (i + 1) * step) for i in range(1, n)]


def _root_count(al: ArbLoop, K: float) -> int | None:
    """Poles outside at K from the roots of the characteristic polynomial in balls
    (:meth:`~hapstab.engine.arb_loop.ArbLoop.polynomial`), exact zero coefficients at
    the bottom divided out: Arb's ``acb_poly.roots`` gives disjoint balls holding one
    root each; the count is decided when each ball is strictly inside or outside the
    circle (else None)."""
    import flint
    acb_poly = flint.acb_poly
    with working_precision(al.prec):
        p = al.polynomial(K)
        low = next(i for i in range(p.degree() + 1) if not p[i].is_zero())
        q = acb_poly([p[i] for i in range(low, p.degree() + 1)])
        # Arb's own radii first (cheapest), then 1e-20: a pole nearer the circle than
        # that is left undecided (None), never guessed
        for tol in (None, 1e-20):
            try:
                rs = q.roots(tol=tol, maxprec=4 * al.prec) if q.degree() > 0 else []
            except ValueError:
                return None
            out = sum(1 for r in rs if r.abs_lower() > 1)
            if len(rs) == q.degree() and out + sum(1 for r in rs if r.abs_upper() < 1) == len(rs):
                return out
    return None


def _check_count(al: ArbLoop, c: dict[str, Any], n0: int, version: int) -> int:
    """Replay a count's pieces (or isolate its roots); the verified poles outside."""
    import flint
    arb = flint.arb
    if c.get("method") == "roots":
        out = _root_count(al, c["K_N_per_m"])
        if out is None:
            raise Invalid(f"count at K = {c['K_N_per_m']!r}: the roots are not isolated "
                           "clear of the unit circle")
        if out != c["outside"]:
            raise Invalid(f"count at K = {c['K_N_per_m']!r}: {out} poles outside, not "
                           f"{c['outside']} as claimed")
        return out
    K = arb(c["K_N_per_m"])
    pieces = [tuple(p) for p in c["pieces"]]
    stack = _gap_start(n0, version)[::-1]
    total, i = arb(0), 0
    while stack:
        a, b = stack.pop()
        if i >= len(pieces):
            raise Invalid(f"count at K = {c['K_N_per_m']!r}: pieces missing (theta in "
                           f"[{a!r}, {b!r}] not covered)")
        pa, pb, how = pieces[i]
        if (pa, pb) == (a, b):
            inc = _increment(al, a, b, K, how, version)
            with working_precision(al.prec):
                total = total + inc
            i += 1
        elif a <= pa and pb <= b and (pa, pb) != (a, b):
            m = _split_theta(a, b, version)
            if not a < m < b:
                raise Invalid(f"count at K = {c['K_N_per_m']!r}: halving [{a!r}, {b!r}] does "
                               "not advance (its ends are adjacent doubles)")
            stack += [(m, b), (a, m)]
        else:
            raise Invalid(f"count at K = {c['K_N_per_m']!r}: piece [{pa!r}, {pb!r}] is not "
                           f"part of [{a!r}, {b!r}]")
    if i != len(pieces):
        raise Invalid(f"count at K = {c['K_N_per_m']!r}: pieces beyond [0, pi]")
    with working_precision(al.prec):
        turns = (total / arb.pi()).unique_fmpz()
    if turns is None:
        raise Invalid(f"count at K = {c['K_N_per_m']!r}: the winding is not a whole number")
    out = al.q - int(turns)
    if out != c["outside"]:
        raise Invalid(f"count at K = {c['K_N_per_m']!r}: {out} poles outside, not "
                       f"{c['outside']} as claimed")
    return out


def _gap_start(n: int, version: int) -> list[tuple[float, float]]:
    """A gap's start pieces: from version 4, [0, pi/n 2^-40], [pi/n 2^-40, pi/n] and
    the other n - 1 equal pieces of [0, pi]; before, :func:`_start`'s."""
    if version < 4:
        return _start(n)
    step = math.pi / n
    return [(0.0, step * 2.0 ** -40), (step * 2.0 ** -40, step), *_start(n)[41:]]


def _split_theta(a: float, b: float, version: int) -> float:
    """Where a gap's piece of angles is halved: from version 4 at the geometric mean
    when 0 < a and b > 4 a, else (and before) the midpoint."""
    return math.sqrt(a * b) if version >= 4 and 0 < a and b > 4 * a else 0.5 * (a + b)


def _split_k(k0: float, k1: float, version: int) -> float:
    """Where a gap's K-range is cut: from version 4 at k1 / 8 when k1 > 64 k0;
    otherwise the geometric mean of a range wider than 4, else the midpoint."""
    if version >= 4 and k1 > 64 * k0:
        return k1 / 8
    return math.sqrt(k0 * k1) if k1 > 4 * k0 else 0.5 * (k0 + k1)


def _check_gap(al: ArbLoop, g: dict[str, Any], n0: int, version: int) -> None:
    """Replay an excluded gap's subdivision of [0, pi] x [lo, hi], boxes taken lowest K
    first (``splits``: per box "x" the next piece excludes it, "t" halve theta, "k"
    split K) and check each piece (with the kernel of the certificate's ``version``)."""
    import heapq
    lo, hi = g["lo_N_per_m"], g["hi_N_per_m"]
    pieces = [tuple(p) for p in g["pieces"]]
    heap = [(lo, a, b, hi) for a, b in _gap_start(n0, version)]   # lowest K first
    heapq.heapify(heap)
    i = 0
    for step in g["splits"]:
        if not heap:
            raise Invalid(f"gap [{lo!r}, {hi!r}]: more steps than boxes")
        k0, a, b, k1 = heapq.heappop(heap)
        box = (a, b, k0, k1)
        if step in "tk":
            m = _split_theta(a, b, version) if step == "t" else _split_k(k0, k1, version)
            if not ((a < m < b) if step == "t" else (k0 < m < k1)):
                raise Invalid(f"gap [{lo!r}, {hi!r}]: splitting the box theta in [{a!r}, "
                               f"{b!r}], K in [{k0!r}, {k1!r}] ('{step}') does not advance")
        if step == "t":
            heapq.heappush(heap, (k0, a, m, k1))
            heapq.heappush(heap, (k0, m, b, k1))
        elif step == "k":
            heapq.heappush(heap, (k0, a, b, m))
            heapq.heappush(heap, (m, a, b, k1))
        elif step == "x":
            if i >= len(pieces) or pieces[i][:4] != box:
                raise Invalid(f"gap [{lo!r}, {hi!r}]: the box theta in [{a!r}, {b!r}], K in "
                               f"[{k0!r}, {k1!r}] has no piece of its own")
            if not _excludes(al, *box, pieces[i][4], version >= 4):
                raise Invalid(f"gap [{lo!r}, {hi!r}]: the piece theta in [{a!r}, {b!r}], K in "
                               f"[{k0!r}, {k1!r}] is not excluded by '{pieces[i][4]}'")
            i += 1
        else:
            raise Invalid(f"gap [{lo!r}, {hi!r}]: a box is not excluded ('{step}')")
    if heap:
        k0, a, b, k1 = heap[0]
        raise Invalid(f"gap [{lo!r}, {hi!r}]: pieces missing (theta in [{a!r}, {b!r}], K in "
                       f"[{k0!r}, {k1!r}] not covered)")
    if i != len(pieces):
        raise Invalid(f"gap [{lo!r}, {hi!r}]: pieces beyond the gap")


def _check_claim(cert: dict[str, Any], counts: dict[float, int]) -> float:
    """The claim against the verified gaps and counts; the verified K_max."""
    claim, k0 = cert["claim"], cert["base_point_N_per_m"]
    gaps = [g for g in cert["gaps"] if g["excluded"]]
    for lo, hi in claim["stable_intervals_N_per_m"]:
        edge = lo
        while edge < hi:
            g = next((g for g in gaps if g["lo_N_per_m"] == edge and g["hi_N_per_m"] <= hi),
                     None)
            if g is None:
                raise Invalid(f"stable interval [{lo!r}, {hi!r}]: K = {edge!r} is not the "
                               "start of an excluded gap")
            c = g["count"]
            if c is None or counts.get(c["K_N_per_m"]) != 0:
                raise Invalid(f"stable interval [{lo!r}, {hi!r}]: the gap from {edge!r} has no "
                               "verified count 0 inside it")
            edge = g["hi_N_per_m"]
    ivs = claim["stable_intervals_N_per_m"]
    kmax = claim["kmax_N_per_m"]
    first = ivs[0][1] if ivs and ivs[0][0] == k0 else 0.0
    if kmax != first:
        raise Invalid(f"K_max = {kmax!r} is not the end of the stable interval from "
                       f"K_0 = {k0!r} ({first!r})")
    if kmax == 0 and not counts.get(k0, 0) > 0:
        raise Invalid(f"K_max = 0 claims instability already at K_0 = {k0!r}, but there is no "
                       "verified count > 0 there")
    up = claim["kmax_upper_N_per_m"]
    if up is not None and not counts.get(up, 0) > 0:
        raise Invalid(f"K_max's upper bound {up!r}: no verified count > 0 there")
    for cr in cert["crossings"]:
        below, above = cr["poles_outside_below"], cr["poles_outside_above"]
        d = "outwards" if above > below else "inwards" if above < below else "touching"
        if cr["direction"] != d:
            raise Invalid(f"crossing in [{cr['K_lo_N_per_m']!r}, {cr['K_hi_N_per_m']!r}]: "
                           f"direction '{cr['direction']}' but the counts say '{d}'")
    return float(kmax)


def _check_crossings(cert: dict[str, Any], counts: dict[float, int]) -> None:
    """Each crossing's counts below and above against the verified counts of the gaps
    that end and start at its window."""
    for cr in cert["crossings"]:
        for key, at in (("poles_outside_below", "K_lo_N_per_m"),
                        ("poles_outside_above", "K_hi_N_per_m")):
            near = [g for g in cert["gaps"] if g["count"] is not None and (
                (g["excluded"] and g["hi_N_per_m"] == cr[at]) if key.endswith("below") else
                (g["lo_N_per_m"] == cr[at] and
                 (g["excluded"] or g["count"]["K_N_per_m"] == cr[at])))]
            if not near or any(counts[g["count"]["K_N_per_m"]] != cr[key] for g in near):
                raise Invalid(f"crossing at [{cr['K_lo_N_per_m']!r}, "
                               f"{cr['K_hi_N_per_m']!r}]: '{key}' not verified")


def _check(cert: dict[str, Any], loop: Any) -> CertificateCheck:
    """Every check in order (module doc); raises Invalid at the first that fails."""
    check_shape(cert)
    params = cert["loop"]
    if loop is not None:
        from hapstab.engine.arb_loop import arb_parameters
        if arb_parameters(loop) != params:
            raise Invalid("the certificate is about another loop")
    k0 = base_point(params)         # re-derived, and equal to the certificate's (shape)
    al = ArbLoop(params, cert["precision_bits"])
    n0 = cert["start_pieces"]
    counts: dict[float, int] = {}
    for g in cert["gaps"]:
        if g["count"] is not None:
            counts[g["count"]["K_N_per_m"]] = _check_count(al, g["count"], n0, cert["version"])
        if g["excluded"]:
            _check_gap(al, g, n0, cert["version"])
    _check_crossings(cert, counts)
    kmax = _check_claim(cert, counts)
    said = cert.get("proved_range_N_per_m", [k0, kmax] if kmax > 0 else None)
    if said != ([k0, kmax] if kmax > 0 else None):
        raise Invalid(f"proved_range_N_per_m = {said!r}: the proved range is [K_0, K_max] = "
                       f"[{k0!r}, {kmax!r}]" if kmax > 0 else "K_max = 0: no range is proved stable")
    n_pieces = sum(len(g["pieces"]) for g in cert["gaps"])
    what = (f"proved stable for K in [K_0, K_max] = [{k0!r}, {kmax!r}] N/m, K_0 the base point "
            "standing for K -> 0+ ((0, K_0) is not proved)" if kmax > 0 else
            f"K_max = 0: {counts[k0]} pole(s) outside already at K_0 = {k0!r}, the base point "
            "standing for K -> 0+")
    return CertificateCheck(True, f"valid: {len(counts)} count(s) and {n_pieces} excluded pieces "
                                  f"re-checked in {al.prec}-bit ball arithmetic; {what}", kmax,
                            (k0, kmax) if kmax > 0 else None)


def verify_certificate(cert: dict[str, Any], loop: Any = None) -> CertificateCheck:
    """Re-check a certificate in ball arithmetic (module doc).

    Nothing the checker can recompute is taken from the certificate: the base point
    K_0 is re-derived from the loop's numbers, every subdivision is replayed, every
    piece and count re-checked; a malformed certificate (a wrong type, a missing or
    non-finite number, an unknown version) is invalid with the reason, never an
    exception.

    Parameters
    ----------
    cert : dict
        The certificate (as written by ``hapstab kmax ... --certificate FILE``).
    loop : HapticLoop or TeleoperationLoop, optional
        If given, the certificate must be about this loop's numbers.

    Returns
    -------
    CertificateCheck
        ``valid`` with what was verified, or invalid with the first failed check.
    """
    try:
        return _check(_as_json(cert), loop)
    except Invalid as e:
        return CertificateCheck(False, str(e))
    except Exception as e:      # a bad certificate is a verdict, never a crash
        return CertificateCheck(False, f"malformed certificate: {type(e).__name__}: {e}")


def _as_json(cert: Any) -> Any:
    """The certificate as its JSON file holds it: a dict built in Python with numpy
    numbers (``np.int64(320)``) or a Fraction reads as the int or float it stands for (it
    was called invalid, "not a whole number"); anything JSON cannot hold is invalid."""
    import json
    from numbers import Integral, Real

    def plain(x: Any) -> Any:
        if isinstance(x, Integral) and not isinstance(x, bool):
            return int(x)
        if isinstance(x, Real):
            return float(x)
        if hasattr(x, "item") and hasattr(x, "dtype") and x.dtype.kind == "b":
            return bool(x)
        raise Invalid(f"a value of type {type(x).__name__} ({x!r:.40}): not JSON data")
    return json.loads(json.dumps(cert, default=plain))

