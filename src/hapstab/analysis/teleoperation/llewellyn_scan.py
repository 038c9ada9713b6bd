"""Llewellyn's margin of a two-port, and the geometric scan of K for its first failure
(:func:`~hapstab.analysis.teleoperation.twoport.critical_stiffness_llewellyn`'s first
step): the margin at each angle, the scan, and a screen that skips the K at which every
angle surely passes (its proof in :class:`Screen`).

References
----------
F. B. Llewellyn, "Some fundamental properties of transmission systems", Proc. IRE 40,
1952 (the module :mod:`~hapstab.analysis.teleoperation.twoport` explains the margin).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["margin_of", "first_failure", "below", "Screen", "SLACK", "SCAN_STEP",
           "SCAN_START", "CHUNK_PAIRS", "SCREEN_BAND"]

#: Rounding slack of the margin, relative to the largest |p_ij| at the angle: the products
#: carry ~1e-16 of |P| (near w = 0, |P| ~ K T / w is large); 1e-13 |P| is a thousand times
#: that rounding and, even at the grid's first angle, ~1e-6 of a margin's scale K T (a
#: larger slack biased K_max upwards, by 2e-7 at 1e-10).
SLACK = 1e-13


def margin_of(P: np.ndarray) -> np.ndarray:
    """Llewellyn's margin (N*s/m) of P (..., 2, 2) plus its rounding slack."""
    r11, r22 = P[..., 0, 0].real, P[..., 1, 1].real
    q = np.abs((np.sqrt(P[..., 0, 1]) * np.sqrt(P[..., 1, 0])).real)
    cross = np.sqrt(np.maximum(r11, 0) * np.maximum(r22, 0)) - q
    slack = SLACK * np.abs(P).max(axis=(-2, -1))
    return np.minimum(np.minimum(r11, r22), cross) + slack


#: Ratio of successive K of the scan: a failure window narrower than 1 % of K between two
#: scan points on the angle grid would be missed (the conditions are smooth in K).
SCAN_STEP = 1.01


#: The scan's first K (N/m): below any device's K_max.
SCAN_START = 1e-6


def below(K: float) -> float:
    """The scan point before K (0 before the first)."""
    return K / SCAN_STEP if K / SCAN_STEP >= SCAN_START else 0.0


#: Angle-K pairs per chunk of the scan: ~1 MB arrays, which stay in cache (measured on
#: the paper's PEB, n = 0...200: 3-4x faster than 2e6-pair chunks).
CHUNK_PAIRS = 65_536


def first_failure(A: np.ndarray, C: np.ndarray, tol: float) -> float | None:
    """The first K of a geometric scan (1e-6 to 1e12 N/m) whose margin on the angle grid
    is below ``-tol`` (``tol`` >= 0); None if there is none.

    The K that :class:`Screen` passes at every angle are skipped (their margins are
    positive); from the first it does not, :func:`margin_of` itself is evaluated, a few K
    at first, so the K found is the plain scan's."""
    # SCAN_START to 1e12 N/m (beyond any device), SCAN_STEP apart
    Ks = np.exp(np.arange(math.log(SCAN_START), math.log(1e12), math.log(SCAN_STEP)))
    n = A.shape[0]
    size = max(1, CHUNK_PAIRS // n)       # K values per chunk
    screen = Screen(A, C)
    i, exact = 0, max(1, size // 8)
    while i < Ks.size:
        j = screen.first_unsure(Ks[i:i + size])
        if j is None:
            i += size
            continue
        i += j
        chunk = Ks[i:i + exact]
        m = margin_of(A[None] + chunk[:, None, None, None] * C[None]).min(axis=1)
        bad = np.flatnonzero(m < -tol)
        if bad.size:
            return float(chunk[bad[0]])
        i, exact = i + chunk.size, min(2 * exact, size)
    return None


#: The screen's band, relative to the size of the cross term's parts: ~1e4 times the
#: rounding of the screen's own arithmetic and of :func:`margin_of`'s (both a few 1e-16
#: of the same; see :class:`Screen`).
SCREEN_BAND = 1e-12


class Screen:
    """Whether every angle surely passes Llewellyn's conditions at each K of a chunk,
    without the complex square roots of :func:`margin_of`.

    With ``P = A + K C``, ``r_ii = Re p_ii`` (the same doubles as :func:`margin_of`'s)
    and ``w = p12 p21 = u + j v``: ``sqrt(p12) sqrt(p21) = +-sqrt(w)``, so the margin's
    ``q = |Re(sqrt(p12) sqrt(p21))|`` is ``|Re sqrt(w)|``, and ``q^2`` is
    ``(|w| + u) / 2``, or, where ``u < 0`` (there that sum cancels),
    ``v^2 / (2 (|w| - u))`` (from ``x^2 - y^2 = u``, ``2 x y = v`` for
    ``sqrt(w) = x + j y``): a few roundings, no cancellation, so q within ~3e-16
    ``sqrt|w|``. A pair passes the screen when ``r11 > 0``, ``r22 > 0`` and
    ``sqrt(r11 r22) - q > SCREEN_BAND (sqrt(r11 r22) + sqrt|w|)``; the true cross term
    is then above ``(SCREEN_BAND - 6e-16)`` times that sum, and :func:`margin_of`'s
    (the same ``sqrt(r11 r22)``, its q within ~6e-16 ``sqrt|w|``: a difference of two
    products of the roots) positive, so its margin is too. Anything else is left to
    :func:`margin_of`, evaluated (module tests: the scan's K equals the plain one's)."""

    def __init__(self, A: np.ndarray, C: np.ndarray) -> None:
        self.a = (A[:, 0, 0].real, A[:, 1, 1].real, A[:, 0, 1], A[:, 1, 0])
        self.c = (C[:, 0, 0].real, C[:, 1, 1].real, C[:, 0, 1], C[:, 1, 0])

    def first_unsure(self, K: np.ndarray) -> int | None:
        """The index of the first K at which some angle does not surely pass (None: all
        pass)."""
        unsure = np.flatnonzero(~self.sure(K).all(axis=1))
        return int(unsure[0]) if unsure.size else None

    def sure(self, K: np.ndarray) -> np.ndarray:
        """(K, angles) booleans: True where the pair surely passes (class docstring)."""
        k = K[:, None]
        (a11, a22, a12, a21), (c11, c22, c12, c21) = self.a, self.c
        r11, r22 = a11 + k * c11, a22 + k * c22
        w = (a12 + k * c12) * (a21 + k * c21)
        aw, u, v = np.abs(w), w.real, w.imag
        with np.errstate(divide="ignore", invalid="ignore"):
            q2 = np.where(u >= 0, 0.5 * (aw + u), v * v / (2 * (aw - u)))
        rt, q = np.sqrt(np.maximum(r11 * r22, 0.0)), np.sqrt(q2)   # (r's sign: below)
        return (r11 > 0) & (r22 > 0) & (rt - q > SCREEN_BAND * (rt + np.sqrt(aw)))
