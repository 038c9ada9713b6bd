"""The shape of a K_max certificate: every field's type, range and consistency, checked
before any arithmetic (:func:`hapstab.analysis.verify.verify_certificate`); a bad shape
raises :class:`Invalid` with the check that failed."""

from __future__ import annotations

import math
from typing import Any

from hapstab.engine.arb_loop import base_point
from hapstab.errors import MAX_DELAY_SAMPLES

#: The certificate's ``format`` and the ``version`` numbers this checker reads.
FORMAT = "hapstab-certificate"
VERSIONS = (1, 2, 3, 4, 5)
#: The reasons a piece may give for excluding 0, by version: ``N`` (the preconditioned
#: mean-value test) from version 2, for gap pieces only (a count piece has one K).
REASONS = {1: ("P", "Q", "F"), 2: ("P", "Q", "F", "N"), 3: ("P", "Q", "F", "N"),
           4: ("P", "Q", "F", "N"), 5: ("P", "Q", "F", "N", "I")}
#: How a count is proved, by version: from version 3 a count names its ``method``,
#: ``winding`` (its pieces, the argument principle) or ``roots`` (no pieces: the roots
#: of the characteristic polynomial isolated in balls); before, a winding.
COUNT_METHODS = {1: ("winding",), 2: ("winding",), 3: ("winding", "roots"),
                 4: ("winding", "roots"), 5: ("winding", "roots")}
#: Most start pieces a certificate may ask for: the proof uses 32; a higher number
#: only makes the replay slower, so beyond this it is refused (a valve on time).
MAX_START_PIECES = 4096
#: Precision a certificate may ask for (bits): at least double precision, at most
#: the 4096 bits :class:`~hapstab.engine.arb_loop.ArbLoop` raises itself to. A low
#: one cannot forge anything (wider balls only fail more checks); a huge one is a
#: valve on time.
PREC_RANGE = (53, 8192)
#: Largest whole delay (samples) a certificate's loop may have: the largest any loop
#: may have (:data:`hapstab.errors.MAX_DELAY_SAMPLES`). The phase w = z^-n is exact
#: whatever n is, but the replay's count of poles resolves its n turns: a certificate
#: edited to 10^6 samples ran for over 11 minutes (a helper's fuzz).
MAX_DELAY = MAX_DELAY_SAMPLES


class Invalid(Exception):
    """A certificate fails a check (of its shape here, of its arithmetic in
    :mod:`hapstab.analysis.verify`): the message names the check."""


# ----------------------------------------------------------------- shapes
def _is_num(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _num(x: Any, what: str, lo: float | None = None, positive: bool = False) -> float:
    """A finite number (not a bool), at least ``lo``, > 0 if ``positive``."""
    try:
        finite = _is_num(x) and math.isfinite(x)
    except OverflowError:            # an integer beyond double precision (JSON allows it)
        finite = False
    if not finite:
        raise Invalid(f"{what} = {x!r:.40}: not a finite number")
    if positive and not x > 0:
        raise Invalid(f"{what} = {x!r}: must be > 0")
    if lo is not None and x < lo:
        raise Invalid(f"{what} = {x!r}: must be >= {lo!r}")
    return float(x)


def _int(x: Any, what: str, lo: int, hi: int | None = None) -> int:
    """A whole number (not a bool, not a float) in [lo, hi]."""
    if not isinstance(x, int) or isinstance(x, bool):
        raise Invalid(f"{what} = {x!r}: not a whole number")
    if x < lo or (hi is not None and x > hi):
        raise Invalid(f"{what} = {x!r}: must be in [{lo}, {'inf' if hi is None else hi}]")
    return x


def _obj(x: Any, what: str, keys: tuple[str, ...]) -> dict[str, Any]:
    """A JSON object with (at least) ``keys``."""
    if not isinstance(x, dict):
        raise Invalid(f"{what}: not an object ({type(x).__name__})")
    missing = [k for k in keys if k not in x]
    if missing:
        raise Invalid(f"{what}: missing {', '.join(missing)}")
    return x


def _list(x: Any, what: str, nonempty: bool = False) -> list[Any]:
    if not isinstance(x, list):
        raise Invalid(f"{what}: not a list ({type(x).__name__})")
    if nonempty and not x:
        raise Invalid(f"{what}: empty")
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
        raise Invalid(f"loop: {len(ports)} port(s) and {len(chans)} channel(s); one or two "
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
            raise Invalid(f"{what}.stiffness_ratio = {ratio!r}: the first channel's is 1 "
                           "(K is its stiffness)")
        _num(c["damping_N_s_per_m"], f"{what}.damping_N_s_per_m")
        terms = _list(c["terms"], f"{what}.terms", nonempty=True)
        for j, t in enumerate(terms):
            if not isinstance(t, list) or len(t) != 3:
                raise Invalid(f"{what}.terms[{j}] = {t!r}: not [port, sign, delay_samples]")
            _int(t[0], f"{what}.terms[{j}] port", 0, len(ports) - 1)
            _num(t[1], f"{what}.terms[{j}] sign")
            _int(t[2], f"{what}.terms[{j}] delay_samples", 0, MAX_DELAY)
        got = sorted(t[0] for t in terms)
        want = [0] if len(ports) == 1 else [0, 1]
        if got != want:
            raise Invalid(f"{what}.terms read ports {got}; {want} (each port once) is allowed")
        if len(ports) == 2 and next(t for t in terms if t[0] == i)[2] != 0:
            raise Invalid(f"{what}.terms: the own position is read with a delay; only an "
                           "undelayed own reading is covered")


def _check_pieces(ps: Any, what: str, width: int, version: int | None = None) -> None:
    """Pieces ``[theta_a, theta_b, (K_a, K_b,) how]`` with finite numbers that advance;
    ``how`` one of the gap reasons of ``version`` (:data:`REASONS`), or of a count piece
    (``P``, ``Q``, ``F``) when ``version`` is None."""
    hows = REASONS[version] if version is not None else REASONS[1]
    where = f" (certificate version {version})" if version is not None else ""
    for j, p in enumerate(_list(ps, what, nonempty=True)):
        if not isinstance(p, list) or len(p) != width or p[-1] not in hows:
            raise Invalid(f"{what}[{j}] = {p!r}: not {width - 1} numbers and one of "
                           f"{', '.join(map(repr, hows))}{where}")
        nums = [_num(v, f"{what}[{j}]") for v in p[:-1]]
        if not (0.0 <= nums[0] < nums[1] <= math.pi):
            raise Invalid(f"{what}[{j}]: theta in [{nums[0]!r}, {nums[1]!r}] does not advance "
                           "inside [0, pi]")
        if width == 5 and not (0.0 < nums[2] < nums[3]):
            raise Invalid(f"{what}[{j}]: K in [{nums[2]!r}, {nums[3]!r}] does not advance "
                           "inside (0, inf)")


def _check_gap_shape(g: Any, i: int, version: int) -> None:
    """One gap's fields and their agreement: an excluded gap has lo < hi and pieces; a
    count lies inside its gap."""
    what = f"gaps[{i}]"
    _obj(g, what, ("lo_N_per_m", "hi_N_per_m", "excluded", "pieces", "splits", "count"))
    lo = _num(g["lo_N_per_m"], f"{what}.lo_N_per_m", positive=True)
    hi = _num(g["hi_N_per_m"], f"{what}.hi_N_per_m", positive=True)
    if hi < lo:
        raise Invalid(f"{what}: [{lo!r}, {hi!r}] does not advance")
    if not isinstance(g["excluded"], bool):
        raise Invalid(f"{what}.excluded = {g['excluded']!r}: not true/false")
    if not isinstance(g["splits"], str) or set(g["splits"]) - set("xtk"):
        raise Invalid(f"{what}.splits: not a string of 'x', 't', 'k'")
    if g["excluded"]:
        if not hi > lo:
            raise Invalid(f"{what}: excluded but [{lo!r}, {hi!r}] is empty")
        _check_pieces(g["pieces"], f"{what}.pieces", 5, version)
    elif _list(g["pieces"], f"{what}.pieces") or g["splits"]:
        raise Invalid(f"{what}: pieces given for a gap not excluded")
    c = g["count"]
    if c is None:
        if not g["excluded"]:
            raise Invalid(f"{what}: neither excluded nor counted")
        return
    _obj(c, f"{what}.count", ("K_N_per_m", "outside", "pieces"))
    K = _num(c["K_N_per_m"], f"{what}.count.K_N_per_m", positive=True)
    _int(c["outside"], f"{what}.count.outside", 0)
    method = c.get("method", "winding")
    if method not in COUNT_METHODS[version] or (version >= 3 and "method" not in c):
        raise Invalid(f"{what}.count.method = {c.get('method')!r}: not one of "
                       f"{', '.join(map(repr, COUNT_METHODS[version]))} (certificate version "
                       f"{version})")
    if method == "roots":
        if _list(c["pieces"], f"{what}.count.pieces"):
            raise Invalid(f"{what}.count: pieces given for a count by roots")
    else:
        _check_pieces(c["pieces"], f"{what}.count.pieces", 3)
    if not lo <= K <= hi:
        raise Invalid(f"{what}: its count at K = {K!r} lies outside [{lo!r}, {hi!r}]")


def _check_claim_shape(cert: dict[str, Any], k0: float) -> None:
    """The claim's numbers: K_max finite >= 0, its upper bound null or above it, the
    stable intervals finite, from K_0 up, increasing and disjoint, below the top."""
    claim = _obj(cert["claim"], "claim",
                 ("kmax_N_per_m", "kmax_upper_N_per_m", "stable_intervals_N_per_m"))
    if claim["kmax_N_per_m"] is None:
        raise Invalid("claim.kmax_N_per_m is null: a certificate claims a finite K_max")
    kmax = _num(claim["kmax_N_per_m"], "claim.kmax_N_per_m", lo=0.0)
    top = _num(cert["top_N_per_m"], "top_N_per_m", positive=True)
    up = claim["kmax_upper_N_per_m"]
    if up is not None and not _num(up, "claim.kmax_upper_N_per_m", positive=True) >= kmax:
        raise Invalid(f"claim.kmax_upper_N_per_m = {up!r}: below K_max = {kmax!r}")
    prev = -math.inf
    for j, iv in enumerate(_list(claim["stable_intervals_N_per_m"], "claim.stable_intervals")):
        what = f"claim.stable_intervals_N_per_m[{j}]"
        if not isinstance(iv, list) or len(iv) != 2:
            raise Invalid(f"{what} = {iv!r}: not [K_a, K_b]")
        a, b = _num(iv[0], what, positive=True), _num(iv[1], what, positive=True)
        if not (k0 <= a < b <= top):
            raise Invalid(f"{what} = [{a!r}, {b!r}]: not an interval inside [K_0, top] = "
                           f"[{k0!r}, {top!r}]")
        if a < prev:
            raise Invalid(f"{what} = [{a!r}, {b!r}]: overlaps or precedes the interval before")
        prev = b


def check_shape(cert: Any) -> None:
    """Everything but the arithmetic: the format and version, every field's type and
    range, and the agreements between fields that need no balls.

    Parameters
    ----------
    cert : object
        The certificate as read from JSON.

    Raises
    ------
    Invalid
        At the first check that fails, naming it.
    """
    if not isinstance(cert, dict) or cert.get("format") != FORMAT:
        raise Invalid(f"not a hapstab certificate (format != {FORMAT!r})")
    if not isinstance(cert.get("version"), int) or isinstance(cert.get("version"), bool) or \
            cert["version"] not in VERSIONS:
        raise Invalid(f"version = {cert.get('version')!r}: unknown format version (this checker "
                       f"reads {', '.join(map(str, VERSIONS))})")
    _obj(cert, "certificate", ("loop", "precision_bits", "start_pieces", "base_point_N_per_m",
                               "top_N_per_m", "claim", "gaps", "crossings"))
    _check_loop_shape(cert["loop"])
    _int(cert["precision_bits"], "precision_bits", *PREC_RANGE)
    _int(cert["start_pieces"], "start_pieces", 1, MAX_START_PIECES)
    k0 = _num(cert["base_point_N_per_m"], "base_point_N_per_m", positive=True)
    if k0 != base_point(cert["loop"]):
        raise Invalid(f"base_point_N_per_m = {k0!r}: the loop's numbers give the base point "
                       f"K_0 = {base_point(cert['loop'])!r} (1e-14 times the smaller of m/T^2 "
                       "and b/T)")
    for i, g in enumerate(_list(cert["gaps"], "gaps", nonempty=True)):
        _check_gap_shape(g, i, cert["version"])
    _check_claim_shape(cert, k0)
    for i, cr in enumerate(_list(cert["crossings"], "crossings")):
        what = f"crossings[{i}]"
        _obj(cr, what, ("K_lo_N_per_m", "K_hi_N_per_m", "poles_outside_below",
                        "poles_outside_above", "direction"))
        lo = _num(cr["K_lo_N_per_m"], f"{what}.K_lo_N_per_m", positive=True)
        hi = _num(cr["K_hi_N_per_m"], f"{what}.K_hi_N_per_m", positive=True)
        if hi < lo:
            raise Invalid(f"{what}: window [{lo!r}, {hi!r}] does not advance")
        _int(cr["poles_outside_below"], f"{what}.poles_outside_below", 0)
        _int(cr["poles_outside_above"], f"{what}.poles_outside_above", 0)
        if cr["direction"] not in ("outwards", "inwards", "touching"):
            raise Invalid(f"{what}.direction = {cr['direction']!r}: not outwards, inwards or "
                           "touching")


# ----------------------------------------------------------------- arithmetic
