"""Re-check a K_max certificate from the loop's numbers alone, in ball arithmetic.

A certificate (:func:`hapstab.analysis.exact.proof.certificate`, ``hapstab kmax ...
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
   of [0, pi] by halving (so they tile [0, pi] by construction: a dropped or altered
   piece breaks the replay), each prove its increment of arg det M (``P``: |P| > |Q|,
   ``Q``: |Q| > |P|, ``F``: 0 not in the ball); the winding gives the poles outside,
   which must equal the count claimed;
2. **gaps** -- each excluded gap's pieces, replayed from ``start_pieces`` x [lo, hi]
   (halving theta at the midpoint, or K at the geometric mean of a wide range, else
   the midpoint), each excluding 0 for the reason given;
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

from hapstab.engine.arb_loop import ArbLoop, base_point, poly_k, working_precision

__all__ = ["verify_certificate", "CertificateCheck", "FORMAT", "VERSIONS"]

#: The certificate's ``format`` and the ``version`` numbers this checker reads.
FORMAT = "hapstab-certificate"
VERSIONS = (1,)
#: Most start pieces a certificate may ask for: the proof uses 32; a higher number
#: only makes the replay slower, so beyond this it is refused (a valve on time).
MAX_START_PIECES = 4096
#: Precision a certificate may ask for (bits): at least double precision, at most
#: the 4096 bits :class:`~hapstab.engine.arb_loop.ArbLoop` raises itself to. A low
#: one cannot forge anything (wider balls only fail more checks); a huge one is a
#: valve on time.
PREC_RANGE = (53, 8192)
#: Largest whole delay (samples) a certificate's loop may have: beyond any loop the
#: analysis takes (the phase w = z^-n is exact whatever n is; a valve on nonsense).
MAX_DELAY = 10 ** 6


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


class _Invalid(Exception):
    pass


# ----------------------------------------------------------------- shapes
def _is_num(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _num(x: Any, what: str, lo: float | None = None, positive: bool = False) -> float:
    """A finite number (not a bool), at least ``lo``, > 0 if ``positive``."""
    if not _is_num(x) or not math.isfinite(x):
        raise _Invalid(f"{what} = {x!r}: not a finite number")
    if positive and not x > 0:
        raise _Invalid(f"{what} = {x!r}: must be > 0")
    if lo is not None and x < lo:
        raise _Invalid(f"{what} = {x!r}: must be >= {lo!r}")
    return float(x)


def _int(x: Any, what: str, lo: int, hi: int | None = None) -> int:
    """A whole number (not a bool, not a float) in [lo, hi]."""
    if not isinstance(x, int) or isinstance(x, bool):
        raise _Invalid(f"{what} = {x!r}: not a whole number")
    if x < lo or (hi is not None and x > hi):
        raise _Invalid(f"{what} = {x!r}: must be in [{lo}, {'inf' if hi is None else hi}]")
    return x


def _obj(x: Any, what: str, keys: tuple[str, ...]) -> dict[str, Any]:
    """A JSON object with (at least) ``keys``."""
    if not isinstance(x, dict):
        raise _Invalid(f"{what}: not an object ({type(x).__name__})")
    missing = [k for k in keys if k not in x]
    if missing:
        raise _Invalid(f"{what}: missing {', '.join(missing)}")
    return x


def _list(x: Any, what: str, nonempty: bool = False) -> list[Any]:
    if not isinstance(x, list):
        raise _Invalid(f"{what}: not a list ({type(x).__name__})")
    if nonempty and not x:
        raise _Invalid(f"{what}: empty")
    return x


_PORT = ("mass_kg", "damping_N_s_per_m", "termination_mass_kg",
         "termination_damping_N_s_per_m", "termination_stiffness_N_per_m")


def _check_loop_shape(loop: Any) -> None:
    """The loop's numbers: the structures :class:`ArbLoop` covers (one port with one
    measured term, or two ports each reading its own position undelayed and the
    other's), every number finite, masses and the period > 0."""
    _obj(loop, "loop", ("period_s", "ports", "channels"))
    _num(loop["period_s"], "loop.period_s", positive=True)
    ports = _list(loop["ports"], "loop.ports", nonempty=True)
    chans = _list(loop["channels"], "loop.channels", nonempty=True)
    if len(ports) not in (1, 2) or len(chans) != len(ports):
        raise _Invalid(f"loop: {len(ports)} port(s) and {len(chans)} channel(s); one or two "
                       "ports, one channel each, are allowed")
    for i, p in enumerate(ports):
        _obj(p, f"loop.ports[{i}]", _PORT)
        _num(p["mass_kg"], f"loop.ports[{i}].mass_kg", positive=True)
        _num(p["termination_mass_kg"], f"loop.ports[{i}].termination_mass_kg", lo=0.0)
        for k in _PORT[1:]:
            _num(p[k], f"loop.ports[{i}].{k}")
    for i, c in enumerate(chans):
        what = f"loop.channels[{i}]"
        _obj(c, what, ("stiffness_ratio", "damping_N_s_per_m", "terms"))
        ratio = _num(c["stiffness_ratio"], f"{what}.stiffness_ratio")
        if i == 0 and ratio != 1.0:
            raise _Invalid(f"{what}.stiffness_ratio = {ratio!r}: the first channel's is 1 "
                           "(K is its stiffness)")
        _num(c["damping_N_s_per_m"], f"{what}.damping_N_s_per_m")
        terms = _list(c["terms"], f"{what}.terms", nonempty=True)
        for j, t in enumerate(terms):
            if not isinstance(t, list) or len(t) != 3:
                raise _Invalid(f"{what}.terms[{j}] = {t!r}: not [port, sign, delay_samples]")
            _int(t[0], f"{what}.terms[{j}] port", 0, len(ports) - 1)
            _num(t[1], f"{what}.terms[{j}] sign")
            _int(t[2], f"{what}.terms[{j}] delay_samples", 0, MAX_DELAY)
        got = sorted(t[0] for t in terms)
        want = [0] if len(ports) == 1 else [0, 1]
        if got != want:
            raise _Invalid(f"{what}.terms read ports {got}; {want} (each port once) is allowed")
        if len(ports) == 2 and next(t for t in terms if t[0] == i)[2] != 0:
            raise _Invalid(f"{what}.terms: the own position is read with a delay; only an "
                           "undelayed own reading is covered")


def _check_pieces(ps: Any, what: str, width: int) -> None:
    """Pieces ``[theta_a, theta_b, (K_a, K_b,) how]`` with finite numbers that advance."""
    for j, p in enumerate(_list(ps, what, nonempty=True)):
        if not isinstance(p, list) or len(p) != width or p[-1] not in ("P", "Q", "F"):
            raise _Invalid(f"{what}[{j}] = {p!r}: not {width - 1} numbers and 'P', 'Q' or 'F'")
        nums = [_num(v, f"{what}[{j}]") for v in p[:-1]]
        if not (0.0 <= nums[0] < nums[1] <= math.pi):
            raise _Invalid(f"{what}[{j}]: theta in [{nums[0]!r}, {nums[1]!r}] does not advance "
                           "inside [0, pi]")
        if width == 5 and not (0.0 < nums[2] < nums[3]):
            raise _Invalid(f"{what}[{j}]: K in [{nums[2]!r}, {nums[3]!r}] does not advance "
                           "inside (0, inf)")


def _check_gap_shape(g: Any, i: int) -> None:
    """One gap's fields and their agreement: an excluded gap has lo < hi and pieces; a
    count lies inside its gap."""
    what = f"gaps[{i}]"
    _obj(g, what, ("lo_N_per_m", "hi_N_per_m", "excluded", "pieces", "splits", "count"))
    lo = _num(g["lo_N_per_m"], f"{what}.lo_N_per_m", positive=True)
    hi = _num(g["hi_N_per_m"], f"{what}.hi_N_per_m", positive=True)
    if hi < lo:
        raise _Invalid(f"{what}: [{lo!r}, {hi!r}] does not advance")
    if not isinstance(g["excluded"], bool):
        raise _Invalid(f"{what}.excluded = {g['excluded']!r}: not true/false")
    if not isinstance(g["splits"], str) or set(g["splits"]) - set("xtk"):
        raise _Invalid(f"{what}.splits: not a string of 'x', 't', 'k'")
    if g["excluded"]:
        if not hi > lo:
            raise _Invalid(f"{what}: excluded but [{lo!r}, {hi!r}] is empty")
        _check_pieces(g["pieces"], f"{what}.pieces", 5)
    elif _list(g["pieces"], f"{what}.pieces") or g["splits"]:
        raise _Invalid(f"{what}: pieces given for a gap not excluded")
    c = g["count"]
    if c is None:
        if not g["excluded"]:
            raise _Invalid(f"{what}: neither excluded nor counted")
        return
    _obj(c, f"{what}.count", ("K_N_per_m", "outside", "pieces"))
    K = _num(c["K_N_per_m"], f"{what}.count.K_N_per_m", positive=True)
    _int(c["outside"], f"{what}.count.outside", 0)
    _check_pieces(c["pieces"], f"{what}.count.pieces", 3)
    if not lo <= K <= hi:
        raise _Invalid(f"{what}: its count at K = {K!r} lies outside [{lo!r}, {hi!r}]")


def _check_claim_shape(cert: dict[str, Any], k0: float) -> None:
    """The claim's numbers: K_max finite >= 0, its upper bound null or above it, the
    stable intervals finite, from K_0 up, increasing and disjoint, below the top."""
    claim = _obj(cert["claim"], "claim",
                 ("kmax_N_per_m", "kmax_upper_N_per_m", "stable_intervals_N_per_m"))
    if claim["kmax_N_per_m"] is None:
        raise _Invalid("claim.kmax_N_per_m is null: a certificate claims a finite K_max")
    kmax = _num(claim["kmax_N_per_m"], "claim.kmax_N_per_m", lo=0.0)
    top = _num(cert["top_N_per_m"], "top_N_per_m", positive=True)
    up = claim["kmax_upper_N_per_m"]
    if up is not None and not _num(up, "claim.kmax_upper_N_per_m", positive=True) >= kmax:
        raise _Invalid(f"claim.kmax_upper_N_per_m = {up!r}: below K_max = {kmax!r}")
    prev = -math.inf
    for j, iv in enumerate(_list(claim["stable_intervals_N_per_m"], "claim.stable_intervals")):
        what = f"claim.stable_intervals_N_per_m[{j}]"
        if not isinstance(iv, list) or len(iv) != 2:
            raise _Invalid(f"{what} = {iv!r}: not [K_a, K_b]")
        a, b = _num(iv[0], what, positive=True), _num(iv[1], what, positive=True)
        if not (k0 <= a < b <= top):
            raise _Invalid(f"{what} = [{a!r}, {b!r}]: not an interval inside [K_0, top] = "
                           f"[{k0!r}, {top!r}]")
        if a < prev:
            raise _Invalid(f"{what} = [{a!r}, {b!r}]: overlaps or precedes the interval before")
        prev = b


def _check_shape(cert: Any) -> None:
    """Everything but the arithmetic: the format and version, every field's type and
    range, and the agreements between fields that need no balls."""
    if not isinstance(cert, dict) or cert.get("format") != FORMAT:
        raise _Invalid(f"not a hapstab certificate (format != {FORMAT!r})")
    if not isinstance(cert.get("version"), int) or isinstance(cert.get("version"), bool) or \
            cert["version"] not in VERSIONS:
        raise _Invalid(f"version = {cert.get('version')!r}: unknown format version (this checker "
                       f"reads {', '.join(map(str, VERSIONS))})")
    _obj(cert, "certificate", ("loop", "precision_bits", "start_pieces", "base_point_N_per_m",
                               "top_N_per_m", "claim", "gaps", "crossings"))
    _check_loop_shape(cert["loop"])
    _int(cert["precision_bits"], "precision_bits", *PREC_RANGE)
    _int(cert["start_pieces"], "start_pieces", 1, MAX_START_PIECES)
    k0 = _num(cert["base_point_N_per_m"], "base_point_N_per_m", positive=True)
    if k0 != base_point(cert["loop"]):
        raise _Invalid(f"base_point_N_per_m = {k0!r}: the loop's numbers give the base point "
                       f"K_0 = {base_point(cert['loop'])!r} (1e-14 times the smaller of m/T^2 "
                       "and b/T)")
    for i, g in enumerate(_list(cert["gaps"], "gaps", nonempty=True)):
        _check_gap_shape(g, i)
    _check_claim_shape(cert, k0)
    for i, cr in enumerate(_list(cert["crossings"], "crossings")):
        what = f"crossings[{i}]"
        _obj(cr, what, ("K_lo_N_per_m", "K_hi_N_per_m", "poles_outside_below",
                        "poles_outside_above", "direction"))
        lo = _num(cr["K_lo_N_per_m"], f"{what}.K_lo_N_per_m", positive=True)
        hi = _num(cr["K_hi_N_per_m"], f"{what}.K_hi_N_per_m", positive=True)
        if hi < lo:
            raise _Invalid(f"{what}: window [{lo!r}, {hi!r}] does not advance")
        _int(cr["poles_outside_below"], f"{what}.poles_outside_below", 0)
        _int(cr["poles_outside_above"], f"{what}.poles_outside_above", 0)
        if cr["direction"] not in ("outwards", "inwards", "touching"):
            raise _Invalid(f"{what}.direction = {cr['direction']!r}: not outwards, inwards or "
                           "touching")


# ----------------------------------------------------------------- arithmetic
def _ball(a: float, b: float) -> Any:
    from flint import arb
    lo = arb.pi() if a == math.pi else arb(a)
    hi = arb.pi() if b == math.pi else arb(b)
    return lo.union(hi)


def _excludes(al: ArbLoop, a: float, b: float, ka: float, kb: float, how: str) -> bool:
    """Whether the box [a, b] x [ka, kb] has no zero of det M, for the reason ``how``."""
    from flint import arb
    P, Q, F = al.box(_ball(a, b), arb(ka).union(arb(kb)))
    with working_precision(al.prec):
        if how == "P":
            return bool(P.abs_lower() > Q.abs_upper())
        if how == "Q":
            return bool(Q.abs_lower() > P.abs_upper())
        return how == "F" and not F.contains(0)


def _increment(al: ArbLoop, a: float, b: float, K: Any, how: str) -> Any:
    """The proved increment of arg det M over [a, b] at K (raises _Invalid)."""
    P, Q, F = al.box(_ball(a, b), K)
    pa, qa, wa = al.parts(_ball(a, a))
    pb, qb, wb = al.parts(_ball(b, b))
    with working_precision(al.prec):
        Pa, Qa, Pb, Qb = poly_k(pa, K), poly_k(qa, K), poly_k(pb, K), poly_k(qb, K)
        if how == "P" and P.abs_lower() > Q.abs_upper():
            return (Pb / Pa).arg() + (1 + wb * Qb / Pb).arg() - (1 + wa * Qa / Pa).arg()
        if how == "Q" and Q.abs_lower() > P.abs_upper():
            return ((Qb / Qa).arg() - al.n_phase * (_ball(b, b) - _ball(a, a))
                    + (1 + Pb / (wb * Qb)).arg() - (1 + Pa / (wa * Qa)).arg())
        if how == "F" and not F.contains(0):
            return ((Pb + wb * Qb) / (Pa + wa * Qa)).arg()
    raise _Invalid(f"piece theta in [{a!r}, {b!r}] at K = {float(K.mid())!r}: '{how}' does not "
                   "hold in ball arithmetic")


def _start(n: int) -> list[tuple[float, float]]:
    """The n equal pieces of [0, pi], the first cut again at pi/n 2^-k, k = 1..40."""
    step = math.pi / n
    near = [(0.0, step * 2.0 ** -40)] + [(step * 2.0 ** -k, step * 2.0 ** (1 - k))
                                          for k in range(40, 0, -1)]
    return near + [(i * step, math.pi if i == n - 1 else (i + 1) * step) for i in range(1, n)]


def _check_count(al: ArbLoop, c: dict[str, Any], n0: int) -> int:
    """Replay a count's pieces; the verified number of poles outside."""
    from flint import arb
    K = arb(c["K_N_per_m"])
    pieces = [tuple(p) for p in c["pieces"]]
    stack = _start(n0)[::-1]
    total, i = arb(0), 0
    while stack:
        a, b = stack.pop()
        if i >= len(pieces):
            raise _Invalid(f"count at K = {c['K_N_per_m']!r}: pieces missing (theta in "
                           f"[{a!r}, {b!r}] not covered)")
        pa, pb, how = pieces[i]
        if (pa, pb) == (a, b):
            inc = _increment(al, a, b, K, how)
            with working_precision(al.prec):
                total = total + inc
            i += 1
        elif a <= pa and pb <= b and (pa, pb) != (a, b):
            m = 0.5 * (a + b)
            if not a < m < b:
                raise _Invalid(f"count at K = {c['K_N_per_m']!r}: halving [{a!r}, {b!r}] does "
                               "not advance (its ends are adjacent doubles)")
            stack += [(m, b), (a, m)]
        else:
            raise _Invalid(f"count at K = {c['K_N_per_m']!r}: piece [{pa!r}, {pb!r}] is not "
                           f"part of [{a!r}, {b!r}]")
    if i != len(pieces):
        raise _Invalid(f"count at K = {c['K_N_per_m']!r}: pieces beyond [0, pi]")
    with working_precision(al.prec):
        turns = (total / arb.pi()).unique_fmpz()
    if turns is None:
        raise _Invalid(f"count at K = {c['K_N_per_m']!r}: the winding is not a whole number")
    out = al.q - int(turns)
    if out != c["outside"]:
        raise _Invalid(f"count at K = {c['K_N_per_m']!r}: {out} poles outside, not "
                       f"{c['outside']} as claimed")
    return out


def _split_k(k0: float, k1: float) -> float:
    return math.sqrt(k0 * k1) if k1 > 4 * k0 else 0.5 * (k0 + k1)


def _check_gap(al: ArbLoop, g: dict[str, Any], n0: int) -> None:
    """Replay an excluded gap's subdivision of [0, pi] x [lo, hi], boxes taken lowest K
    first (``splits``: per box "x" the next piece excludes it, "t" halve theta, "k"
    split K) and check each piece."""
    import heapq
    lo, hi = g["lo_N_per_m"], g["hi_N_per_m"]
    pieces = [tuple(p) for p in g["pieces"]]
    heap = [(lo, a, b, hi) for a, b in _start(n0)]       # lowest K first, as written
    heapq.heapify(heap)
    i = 0
    for step in g["splits"]:
        if not heap:
            raise _Invalid(f"gap [{lo!r}, {hi!r}]: more steps than boxes")
        k0, a, b, k1 = heapq.heappop(heap)
        box = (a, b, k0, k1)
        if step in "tk":
            m = 0.5 * (a + b) if step == "t" else _split_k(k0, k1)
            if not ((a < m < b) if step == "t" else (k0 < m < k1)):
                raise _Invalid(f"gap [{lo!r}, {hi!r}]: splitting the box theta in [{a!r}, "
                               f"{b!r}], K in [{k0!r}, {k1!r}] ('{step}') does not advance")
        if step == "t":
            heapq.heappush(heap, (k0, a, m, k1))
            heapq.heappush(heap, (k0, m, b, k1))
        elif step == "k":
            heapq.heappush(heap, (k0, a, b, m))
            heapq.heappush(heap, (m, a, b, k1))
        elif step == "x":
            if i >= len(pieces) or pieces[i][:4] != box:
                raise _Invalid(f"gap [{lo!r}, {hi!r}]: the box theta in [{a!r}, {b!r}], K in "
                               f"[{k0!r}, {k1!r}] has no piece of its own")
            if not _excludes(al, *box, pieces[i][4]):
                raise _Invalid(f"gap [{lo!r}, {hi!r}]: the piece theta in [{a!r}, {b!r}], K in "
                               f"[{k0!r}, {k1!r}] is not excluded by '{pieces[i][4]}'")
            i += 1
        else:
            raise _Invalid(f"gap [{lo!r}, {hi!r}]: a box is not excluded ('{step}')")
    if heap:
        k0, a, b, k1 = heap[0]
        raise _Invalid(f"gap [{lo!r}, {hi!r}]: pieces missing (theta in [{a!r}, {b!r}], K in "
                       f"[{k0!r}, {k1!r}] not covered)")
    if i != len(pieces):
        raise _Invalid(f"gap [{lo!r}, {hi!r}]: pieces beyond the gap")


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
                raise _Invalid(f"stable interval [{lo!r}, {hi!r}]: K = {edge!r} is not the "
                               "start of an excluded gap")
            c = g["count"]
            if c is None or counts.get(c["K_N_per_m"]) != 0:
                raise _Invalid(f"stable interval [{lo!r}, {hi!r}]: the gap from {edge!r} has no "
                               "verified count 0 inside it")
            edge = g["hi_N_per_m"]
    ivs = claim["stable_intervals_N_per_m"]
    kmax = claim["kmax_N_per_m"]
    first = ivs[0][1] if ivs and ivs[0][0] == k0 else 0.0
    if kmax != first:
        raise _Invalid(f"K_max = {kmax!r} is not the end of the stable interval from "
                       f"K_0 = {k0!r} ({first!r})")
    if kmax == 0 and not counts.get(k0, 0) > 0:
        raise _Invalid(f"K_max = 0 claims instability already at K_0 = {k0!r}, but there is no "
                       "verified count > 0 there")
    up = claim["kmax_upper_N_per_m"]
    if up is not None and not counts.get(up, 0) > 0:
        raise _Invalid(f"K_max's upper bound {up!r}: no verified count > 0 there")
    for cr in cert["crossings"]:
        below, above = cr["poles_outside_below"], cr["poles_outside_above"]
        d = "outwards" if above > below else "inwards" if above < below else "touching"
        if cr["direction"] != d:
            raise _Invalid(f"crossing in [{cr['K_lo_N_per_m']!r}, {cr['K_hi_N_per_m']!r}]: "
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
                raise _Invalid(f"crossing at [{cr['K_lo_N_per_m']!r}, "
                               f"{cr['K_hi_N_per_m']!r}]: '{key}' not verified")


def _check(cert: dict[str, Any], loop: Any) -> CertificateCheck:
    """Every check in order (module doc); raises _Invalid at the first that fails."""
    _check_shape(cert)
    params = cert["loop"]
    if loop is not None:
        from hapstab.engine.arb_loop import arb_parameters
        if arb_parameters(loop) != params:
            raise _Invalid("the certificate is about another loop")
    k0 = base_point(params)         # re-derived, and equal to the certificate's (shape)
    al = ArbLoop(params, cert["precision_bits"])
    n0 = cert["start_pieces"]
    counts: dict[float, int] = {}
    for g in cert["gaps"]:
        if g["count"] is not None:
            counts[g["count"]["K_N_per_m"]] = _check_count(al, g["count"], n0)
        if g["excluded"]:
            _check_gap(al, g, n0)
    _check_crossings(cert, counts)
    kmax = _check_claim(cert, counts)
    said = cert.get("proved_range_N_per_m", [k0, kmax] if kmax > 0 else None)
    if said != ([k0, kmax] if kmax > 0 else None):
        raise _Invalid(f"proved_range_N_per_m = {said!r}: the proved range is [K_0, K_max] = "
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
        return _check(cert, loop)
    except _Invalid as e:
        return CertificateCheck(False, str(e))
    except Exception as e:      # a bad certificate is a verdict, never a crash
        return CertificateCheck(False, f"malformed certificate: {type(e).__name__}: {e}")
