"""K-B stability regions (D-decomposition); the best virtual damping is in
:mod:`hapstab.analysis.design.damping`.

With C = K + B (z - 1)/(T z) on every port (C_m = C_s), the loop depends on (K, B)
only through the scalar ``h(z) = K + (B/T)(1 - z^-1)``. Its characteristic equation is
``det(I - h(z) G(z)) = 0`` with ``G(z) = C1 (zI - A0)^-1 B1`` the loop of a unit
stiffness (:mod:`hapstab.engine`). A pole sits on |z| = 1 exactly where
``h(e^{j theta}) = 1/mu`` for an eigenvalue mu of ``G(e^{j theta})``, which gives the
boundary in closed form (D-decomposition):

* complex crossings: ``K = Re h - Im h tan(theta/2)``, ``B = T Im h / sin(theta)``;
* z = 1: the vertical lines ``K = 1/mu(G(1))`` (B does not act at DC);
* z = -1: the lines ``K + 2B/T = 1/mu(G(-1))``.

The stable set is then exact along every line B = const (the crossing analysis of
:mod:`hapstab.analysis.exact`, batched over B), and a Schur-Cohn test of the characteristic
polynomial on a grid cross-checks it independently.

References
----------
Gil, Avello, Rubio, Florez 2004; Hulin, Preusche, Hirzinger 2008 (K-B charts);
the paper, eq. (23) for H(z) and (13), (18), (29), (34) for the overlaid lines.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab import budget, progress
from hapstab.analysis.design.kb_plane import (
    Loop,
    check_equal_gains,
    d_decomposition,
    with_gains,
)
from hapstab.analysis.exact.crossings import analyse, winding
from hapstab.analysis.exact.stable_set import StableSet
from hapstab.engine.frequency import LoopResponse, loop_response, stack_responses
from hapstab.engine.system import build
from hapstab.errors import AnalysisError, ArgumentTypeError, check_flag, check_real, ordered_pair
from hapstab.models.loops import headline
from hapstab.results import Result, jsonable, write_csv

__all__ = ["stability_region", "RegionResult", "d_decomposition", "kmax_over_B",
           "check_equal_gains", "with_gains", "Loop"]



# ------------------------------------------------------------------------ helpers
def kmax_over_B(loop: Loop, Bs: Sequence[float] | np.ndarray,
                intervals: bool = False, certify: bool = True) -> list[StableSet]:
    """Exact crossing analysis for each virtual damping in ``Bs`` (batched).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Equal spring-damper controllers; their K and B are replaced.
    Bs : array of float
        Virtual dampings in N*s/m.
    intervals : bool
        Every stable interval (True) or K_max alone (False).
    certify : bool
        Re-prove each row in ball arithmetic (default True, as
        :func:`~hapstab.analysis.exact.core.exact_critical_stiffness`); False: the float
        search alone, faster and not proved -- except one row of a one-port loop, whose
        proved answer is the faster one (:func:`_proof_is_faster`).

    Returns
    -------
    list of StableSet
        One per damping.
    """
    resp = _row_responses(loop, Bs)
    return analyse(resp, full=intervals, proof=certify or _proof_is_faster(resp))


def _proof_is_faster(resp: LoopResponse) -> bool:
    """One row of a one-port loop: its proved answer (the angle grid's candidates, then
    the ball proof) costs less than the float branch-and-prune's (the paper's HVE at
    n = 4: 8.5 against 22 ms, measured), and is the safe end of the same K_max, so it is
    the one given even where the caller did not ask for a proof. Batches and two ports:
    the float search (batched it costs ~2 ms a row)."""
    return resp.size == 1 and len(resp.ports) == 1 and bool(resp.params) and \
        resp.params[0] is not None


def _row_responses(loop: Loop, Bs: Sequence[float] | np.ndarray) -> LoopResponse:
    """The characteristic functions of the loop at each virtual damping, stacked: one
    structure for every B (B enters only as beta = B/T), so one batched analysis."""
    return stack_responses([loop_response(with_gains(loop, 1.0, float(B)))
                            for B in np.asarray(Bs, float)])


# -------------------------------------------------------------- grid cross-check
def _char_poly_grid(loop: Loop, Kg: np.ndarray, Bg: np.ndarray) -> np.ndarray:
    """Coefficients (descending, monic) of det(zI - A(K, B)) at every grid point.

    A(K, B) = A00 + K AK + B AB with rank(AK, AB) = p, so the determinant is a
    polynomial of total degree <= p in (K, B): fitted exactly from its values
    (eigenvalue products) at the points of a small simplex in scaled units.
    """
    s1, s2 = build(with_gains(loop, 0.0, 1.0)), build(with_gains(loop, 0.0, 2.0))
    AB = s2.A0[0] - s1.A0[0]
    A00 = s1.A0[0] - AB
    AK = (s1.B1 @ s1.C1)[0]
    p = s1.n_ports
    Ks = max(np.abs(Kg).max(), 1e-12)  # an all-zero K grid: any unit > 0 fits it exactly
    Bs = max(np.abs(Bg).max(), 1e-12)  # an all-zero B grid: any unit > 0 fits it exactly
    pts = [(i, j) for i in range(p + 1) for j in range(p + 1 - i)]   # monomials K'^i B'^j
    V = np.array([[a ** i * b ** j for (i, j) in pts] for (a, b) in pts], float)
    vals = []
    for a, b in pts:
        ev = np.linalg.eigvals(A00 + a * Ks * AK + b * Bs * AB)
        vals.append(np.poly(ev).real)
    coef = np.linalg.solve(V, np.array(vals))                          # (monomials, N+1)
    Kn, Bn = (Kg / Ks).ravel(), (Bg / Bs).ravel()
    mono = np.stack([Kn ** i * Bn ** j for (i, j) in pts], axis=1)     # (G, monomials)
    c = mono @ coef
    # rigid-body modes are z = 1 roots for every (K, B): divide them out, as the exact
    # analysis does, so the check judges the same poles
    for _ in range(s1.rigid_modes):
        q = np.zeros((c.shape[0], c.shape[1] - 1))
        q[:, 0] = c[:, 0]
        for i in range(1, q.shape[1]):
            q[:, i] = c[:, i] + q[:, i - 1]                                # synthetic division by (z - 1)
        c = q
    return c


def _schur_cohn(c: np.ndarray) -> np.ndarray:
    """True where every root of the polynomial (rows, descending) has |z| < 1."""
    a = c / c[:, :1]
    ok = np.ones(a.shape[0], bool)
    for m in range(a.shape[1] - 1, 0, -1):
        k = a[:, m] / a[:, 0]
        ok &= np.abs(k) < 1
        with np.errstate(all="ignore"):
            a = (a[:, :m] - k[:, None] * a[:, m:0:-1]) / (1 - k * k)[:, None]
        a = np.where(ok[:, None], a, 1.0)
    return ok


# --------------------------------------------------------------------- results
@dataclass(frozen=True)
class RegionResult(Result):
    """The exact stable region in the (K, B) plane.

    Attributes
    ----------
    kind : {"hve", "peb"}
        The loop kind.
    period : float
        Sampling period T in s.
    delay_samples : float
        The delay in samples (t_d / T).
    K_range, B_range : (float, float)
        The window in N/m and N*s/m.
    B_rows : array
        Virtual dampings of the rows.
    intervals : tuple
        Exact stable K-intervals on each row (clipped to K_range).
    boundary : dict
        The D-decomposition: ``curves``, ``z1``, ``zm1`` (see :func:`d_decomposition`).
    K_grid : array
        K values of the cross-check grid; ``stable_grid[i, j]`` is the Schur-Cohn
        verdict at (K_grid[j], B_rows[i]) and ``stable_exact`` the exact one.
    stable_exact, stable_grid : (len(B_rows), len(K_grid)) bool arrays
        The two verdicts on the grid.
    agreement : dict
        Cross-check counts: points compared, disagreements beyond ``margin``.
    overlays : dict
        name -> K_max on each row (passivity, circle, the paper's line).
    disagreement : bool array or None
        Grid points where the verdicts differ away from the boundary (None: not
        compared).
    model : str
        The loop in one line (devices, terminations, T, delay), for titles.
    """

    kind: str
    period: float
    delay_samples: float
    K_range: tuple[float, float]
    B_range: tuple[float, float]
    B_rows: np.ndarray
    intervals: tuple
    boundary: dict = field(repr=False)
    K_grid: np.ndarray = field(repr=False)
    stable_exact: np.ndarray = field(repr=False)
    stable_grid: np.ndarray = field(repr=False)
    agreement: dict = field(default_factory=dict)
    overlays: dict = field(default_factory=dict, repr=False)
    disagreement: np.ndarray | None = field(default=None, repr=False)
    model: str = ""

    def kmax(self) -> np.ndarray:
        """K_max on each row (end of the stable interval starting at 0)."""
        return np.array([iv[0][1] if iv and iv[0][0] == 0.0 else 0.0 for iv in self.intervals])

    def to_dict(self) -> dict[str, Any]:
        return jsonable({
            "loop": self.kind, "period_s": self.period, "delay_samples": float(self.delay_samples),
            "K_range": self.K_range, "B_range": self.B_range,
            "rows": [{"virtual_damping": b, "stable_intervals": [list(x) for x in iv]}
                     for b, iv in zip(self.B_rows, self.intervals, strict=True)],
            "crossings_z1_K": self.boundary["z1"], "crossings_zm1_K_plus_2B_over_T": self.boundary["zm1"],
            "crossings_zm1_B_per_s": self.boundary.get("zm1_B_per_s"),
            "agreement": self.agreement,
            "overlays": {k: v for k, v in self.overlays.items()},
        })

    def to_csv(self, path: Any) -> None:
        """Write one row per grid point: stiffness, virtual_damping, stable_exact,
        stable_grid (0/1).

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path is written atomically, see :mod:`hapstab.outputs`).
        """
        write_csv(path, ["stiffness", "virtual_damping", "stable_exact", "stable_grid"],
                  ([f"{K:.10g}", f"{B:.10g}", int(self.stable_exact[i, j]),
                    int(self.stable_grid[i, j])]
                   for i, B in enumerate(self.B_rows) for j, K in enumerate(self.K_grid)))

    def plot(self, ax: Any = None) -> Any:
        from hapstab.plotting import plot_region
        return plot_region(self, ax=ax)


def _window(name: str, w: Any) -> tuple[float, float]:
    """A (lo, hi) pair of finite numbers, or an error naming the window."""
    try:
        lo, hi = ordered_pair(w)
    except (TypeError, ValueError):
        raise AnalysisError(f"{name} = {w!r:.60}: must be a pair (lo, hi) of numbers") from None
    return check_real(f"{name} range start", lo), check_real(f"{name} range end", hi)


def _region_cost(loop: Loop, n: int) -> budget.Cost:
    """Peak memory and time of :func:`stability_region` at ``n`` x ``n``."""
    N = build(with_gains(loop, 1.0, 0.0)).order
    grid = float(n) * n
    memory = 3 * 8 * grid * (N + 1) + 64e6 + n * budget.POINT_BYTES_PER_STATE * N   # grid, rows
    # Schur-Cohn grid; D-decomposition: 4000 angles and up to 4000 more where refined
    flops = 2 * grid * (N + 1) ** 2 + 8000 * 2 * N ** 3
    rows = n * 5e-3 * (1 + N / 100)       # the exact stable set per row: ~5 ms at N ~ 50
    return budget.Cost(f"region: a {n} x {n} grid of a {N}-state loop", memory,
                       flops / budget.FLOPS + rows)


# ------------------------------------------------------------------- the front
def stability_region(loop: Loop, K: tuple[float, float], B: tuple[float, float],
                     resolution: int = 200, overlays: Sequence[str] = (), *,
                     max_memory: float | None = None,
                     max_seconds: float | None = None, certify: bool = True) -> RegionResult:
    """Exact K-B stability region of ``loop`` (its own K and B are ignored).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Device(s), impedances, T and delay(s); C_m = C_s for teleoperation.
    K, B : (float, float)
        Window in N/m (K >= 0) and N*s/m. B may have either sign and the window
        may straddle 0 (e.g. ``(-2, 20)``): the D-decomposition, the rows and the
        grid check hold for any real B; rows where the device damping does not
        cover a negative B have no stable interval.
    resolution : int
        Rows (values of B) and grid columns (values of K).
    overlays : sequence of str
        Also compute K_max per row by these methods: ``"paper"`` (eq. 13/18 or
        29/34), ``"passivity"``, ``"circle"`` (when available).
    max_memory, max_seconds : float, optional
        Budget in bytes and seconds (default :mod:`hapstab.budget`'s); the cost
        (the grid check's characteristic polynomials, resolution^2 of degree N, and
        the D-decomposition's 4000 N x N solves) is estimated first.
    certify : bool
        Re-prove each row's stable intervals in ball arithmetic (default True, as
        :func:`~hapstab.analysis.exact.core.exact_critical_stiffness`); False: the float
        search alone (for 200 rows of the paper's HVE, 0.15 s instead of 2.7 s), not
        proved.

    Returns
    -------
    RegionResult

    Raises
    ------
    AnalysisError
        Controllers that are not equal spring-dampers, or an empty window.
    """
    certify = check_flag("certify", certify)
    check_equal_gains(loop)
    K_lo, K_hi = _window("K", K)
    B_lo, B_hi = _window("B", B)
    if K_lo < 0:
        raise AnalysisError(f"K = {K!r}: the window must start at K >= 0")
    if not (K_hi > K_lo and B_hi >= B_lo):
        raise AnalysisError(f"K = {K}, B = {B}: the window is empty (need lo < hi)")
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) \
            or resolution < 2:
        raise AnalysisError(f"resolution = {resolution!r}: must be a whole number >= 2")
    n = int(resolution)
    for name, lo, hi in (("K", K_lo, K_hi), ("B", B_lo, B_hi)):
        # n values from lo to hi must be n different doubles (a few ulps apart, so that
        # each grid step is a number, not rounding): a window of 5e-324 N/m is not a plane
        if hi > lo and (hi - lo) / (n - 1) < 4 * np.spacing(max(abs(lo), abs(hi))):
            raise AnalysisError(f"{name} = ({lo!r}, {hi!r}): too narrow for {n} values "
                                f"(resolution = {n}): neighbouring values would coincide; "
                                "widen the window or lower the resolution")
    budget.check(_region_cost(loop, n), max_memory, max_seconds)
    with progress.steps(4, f"region: {n} x {n}") as advance:
        return _region(loop, (K_lo, K_hi), (B_lo, B_hi), n, _overlays(overlays), advance,
                       certify)


def _overlays(overlays: Any) -> tuple[str, ...]:
    """The overlay names: a sequence of strings."""
    if isinstance(overlays, str) or not isinstance(overlays, (list, tuple)) \
            or not all(isinstance(o, str) for o in overlays):
        raise ArgumentTypeError(f"overlays = {overlays!r:.60}: must be a list of names "
                                "('paper', 'passivity', 'circle')")
    return tuple(overlays)


def _region(loop: Loop, Kw: tuple[float, float], Bw: tuple[float, float], n: int,
            overlays: Sequence[str], advance: Any, certify: bool = True) -> RegionResult:
    """The rows' exact stable sets, the grid check, the overlays and the boundary, with
    progress after each (see :func:`stability_region`)."""
    (K_lo, K_hi), (B_lo, B_hi) = Kw, Bw
    Brows = np.linspace(B_lo, B_hi, n)
    resp = _row_responses(loop, Brows)
    rows = analyse(resp, full=True, proof=certify)
    advance(1)
    intervals = tuple(tuple((max(a, K_lo), min(b, K_hi)) for a, b in r.intervals
                            if b > K_lo and a < K_hi) for r in rows)
    Kg = np.linspace(K_lo, K_hi, n)
    KK, BB = np.meshgrid(Kg, Brows)
    exact = np.zeros(KK.shape, bool)
    for i, r in enumerate(rows):
        for a, b in r.intervals:
            exact[i] |= (Kg > a) & (Kg < b)
    if np.any(Kg == 0):
        # K = 0 itself (the intervals are for K > 0): the certified count at K = 0
        zero_ok = winding(resp, np.arange(n), np.zeros(n)) == 0
        exact[:, Kg == 0] = zero_ok[:, None]
    grid = _schur_cohn(_char_poly_grid(loop, KK, BB)).reshape(KK.shape)
    advance(1)
    # near an exact boundary either verdict is within rounding: compare away from it
    # (a thousandth of the window, a fifth of the default grid step: this sets aside
    # only grid points practically on a boundary)
    margin = 1e-3 * (K_hi - K_lo)
    near = np.zeros(KK.shape, bool)
    for i, r in enumerate(rows):
        for e in {e for iv in r.intervals for e in iv if math.isfinite(e)}:
            near[i] |= np.abs(Kg - e) <= margin
    bad = (exact != grid) & ~near
    agreement = {"compared": int((~near).sum()), "disagree": int(bad.sum()),
                 "margin_N_per_m": margin}
    ov = {name: _overlay(loop, name, Brows) for name in overlays}
    advance(1)
    boundary = d_decomposition(loop, window=(Kw, Bw))
    advance(1)
    return RegionResult(loop.kind, loop.period, loop.delay_in_samples, Kw, Bw, Brows, intervals,
                        boundary, Kg, exact, grid, agreement, ov, bad, headline(loop))


def _overlay(loop: Loop, name: str, Bs: np.ndarray) -> np.ndarray:
    from hapstab.analysis.conditions import closed_forms
    from hapstab.analysis.methods import METHODS, critical_stiffness

    out = np.full(Bs.size, np.nan)
    if name == "paper":
        f = closed_forms.paper_condition(loop).function
        try:
            return np.array([f(with_gains(loop, 1.0, B)).critical_stiffness for B in Bs])
        except AnalysisError:
            return out                # the paper's line does not apply (e.g. unequal delays)
    if name not in METHODS:
        raise AnalysisError(f"overlay = {name!r}: unknown; allowed: paper, "
                            + ", ".join(m for m in ("passivity", "circle") if m in METHODS))
    rows = _affine_rows(loop, name, Bs)
    if rows is not None:
        return rows
    for i, B in enumerate(Bs):
        with contextlib.suppress(AnalysisError):   # does not apply at this B: leave a gap
            out[i] = critical_stiffness(with_gains(loop, 1.0, float(B)),
                                        method=name).critical_stiffness
    return out


def _affine_rows(loop: Loop, name: str, Bs: np.ndarray) -> np.ndarray | None:
    """Every row's K_max by ``name`` at once, where its matrix is affine in K
    (:data:`~hapstab.analysis.methods.AFFINE_PARTS`) and so, on the K-B plane, in B: the
    loop at B = 1 gives the fixed part, the controller's per unit B and the part per unit
    K (neither the first nor the last depends on B). None where the method is not such,
    or refuses the loop (then row by row)."""
    from hapstab.analysis.conditions.frequency_grid import affine_kmax_rows
    from hapstab.analysis.methods import AFFINE_PARTS
    from hapstab.tolerances import PSD_SLACK

    of = AFFINE_PARTS.get(name)
    if of is None:
        return None
    try:
        parts, oscillations = of(with_gains(loop, 1.0, 1.0))
    except AnalysisError:
        return None
    return affine_kmax_rows(parts, Bs, oscillations, PSD_SLACK)[0]
