"""A proof (:class:`~hapstab.analysis.exact.proof.Proof`) as a certificate anyone can
re-check from the loop's numbers alone (:mod:`hapstab.analysis.verify`; the JSON
schema is ``schemas/certificate.schema.json``; the guide docs/guide/certificate.md).
"""

from __future__ import annotations

import math
from typing import Any

from hapstab.analysis.exact.proof import Proof
from hapstab.analysis.exact.winding import START_PIECES, Count

__all__ = ["certificate", "VERSION"]

#: 2: gap pieces may be excluded by ``N`` (the preconditioned mean-value form); 3: each
#: count names its ``method``, ``winding`` (its pieces) or ``roots`` (the characteristic
#: polynomial's roots isolated in balls, no pieces); 4: the gap pieces are proved with
#: the angle kernel of precomputed ball polynomials (:mod:`~hapstab.engine.arb_kernel`),
#: which the checker then uses; 5: gap pieces may be excluded by ``I`` (the iterated
#: Krawczyk operator, :mod:`~hapstab.engine.arb_krawczyk`). Versions 1 to 4 are still
#: verified.
VERSION = 5

def _count_json(c: Count) -> dict[str, Any]:
    return {"K_N_per_m": c.K, "outside": c.outside, "method": c.method,
            "pieces": [list(p) for p in c.pieces]}


def certificate(pr: Proof) -> dict[str, Any]:
    """The proof as a certificate anyone can re-check from the loop's numbers alone
    (:func:`hapstab.analysis.verify.verify_certificate`; schema
    ``schemas/certificate.schema.json``).

    Parameters
    ----------
    pr : Proof

    Returns
    -------
    dict
        JSON-ready: ``loop`` (the numbers), ``precision_bits``, ``start_pieces``,
        ``base_point_N_per_m`` (K_0, standing for K -> 0+: (0, K_0) is not proved),
        ``proved_range_N_per_m`` ([K_0, K_max], what is proved stable; null when
        K_max = 0), ``claim`` (K_max, its proved upper bound, the stable intervals),
        ``gaps`` (each K-range with its excluded pieces
        ``[theta_a, theta_b, K_a, K_b, how]`` in the order of the subdivision, and its
        count ``[theta_a, theta_b, how]`` pieces), ``crossings`` (window, angle,
        direction). An angle equal to the double nearest pi stands for pi.
    """
    gaps = []
    for g in pr.gaps:
        counted = g.counted if g.counted is not None and g.counted.outside is not None else None
        excluded = g.proved and g.hi > g.lo
        if counted is None and not excluded:
            continue        # nothing proved here: not part of the certificate
        gaps.append({"lo_N_per_m": g.lo, "hi_N_per_m": g.hi, "excluded": excluded,
                     "pieces": [list(p) for p in g.exclusion.pieces] if excluded else [],
                     "splits": "".join(g.exclusion.splits) if excluded else "",
                     "count": None if counted is None else _count_json(counted)})
    crossings = []
    below_of: dict[float, Any] = {}       # the first gap ending / starting at each K
    above_of: dict[float, Any] = {}
    for g in pr.gaps:
        if g.counted and g.proved and g.hi > g.lo:
            below_of.setdefault(g.hi, g.outside)
        if g.counted and (g.proved or g.counted.K == g.lo):
            above_of.setdefault(g.lo, g.outside)
    for lo, hi, th in pr.windows:
        below, above = below_of.get(lo), above_of.get(hi)
        if below is None or above is None:
            continue
        d = "outwards" if above > below else "inwards" if above < below else "touching"
        crossings.append({"K_lo_N_per_m": lo, "K_hi_N_per_m": hi,
                          "theta_rad": th if math.isfinite(th) else None,
                          "poles_outside_below": below, "poles_outside_above": above,
                          "direction": d})
    upper = pr.kmax_hi if math.isfinite(pr.kmax_hi) else None
    # K_max as proved by the pieces: the end of the stable interval from K_0 (finite:
    # when the tail above the top is proved too, the certificate still covers only
    # [K_0, top], which is what its pieces show)
    kmax = next((b for a, b in pr.intervals if a == pr.k0), 0.0)
    return {"format": "hapstab-certificate", "version": pr.version, "loop": pr.params,
            "precision_bits": pr.prec, "start_pieces": START_PIECES,
            "base_point_N_per_m": pr.k0, "top_N_per_m": pr.k_top,
            "proved_range_N_per_m": [pr.k0, kmax] if kmax > 0 else None,
            "claim": {"kmax_N_per_m": kmax,
                      "kmax_upper_N_per_m": upper,
                      "stable_intervals_N_per_m": [list(iv) for iv in pr.intervals]},
            "gaps": gaps, "crossings": crossings}
