"""Results of the network analyses: mean-square K_max under packet loss, and its
curve against the loss rate."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapstab.results import Result, jsonable, write_csv

__all__ = ["LossStiffnessResult", "LossCurveResult"]


@dataclass(frozen=True)
class LossStiffnessResult(Result):
    """Mean-square K_max of a loop with packet loss.

    Parameters
    ----------
    critical_stiffness : float
        K_max in N/m: every scanned K in (0, K_max] has computed rho < 1 (the stable
        end of the bisection). 0 if the smallest K scanned is already unstable; the
        scan's last K if none is unstable (a lower bound then).
    upper_bound : float
        The bisection's unstable end (computed rho >= 1), N/m; inf if none was found.
    loss : float
        P, the long-run fraction of packets lost on each networked term.
    burst : float or None
        Mean burst length L in samples (Gilbert-Elliott), None: independent losses.
    loss_free_critical_stiffness : float
        The exact core's certified K_max with no loss, N/m.
    rho_at, rho_above : float
        Spectral radius of the second-moment operator at ``critical_stiffness`` and at
        ``upper_bound`` (nan when not computed).
    certified : bool
        True only for P = 0 (the exact core's answer); the mean-square search is a
        floating-point evaluation of an exact criterion (:mod:`.loss`).
    period : float
        T in s.
    terms : tuple of str
        The networked terms, each losing packets.
    modes, order : int
        Modes of the jump system and its state dimension N (the operator has N^2, or
        M N^2 with bursts, dimensions).
    scan_K, scan_rho : arrays
        K (N/m) and rho where rho was computed (the checks around the root, or the scan
        up to its first unstable point).
    seconds : float
        Wall time.
    search : str
        ``"roots"``: K_max is the first real root of det(I - T(K)) = 0 (every K where
        rho can reach 1; no window can be stepped over); ``"scan"``: a grid scan of rho
        and bisection (operators too large for the root solve).
    loop_dict : dict
        The loop analysed (``loop.to_dict()``).
    """

    critical_stiffness: float
    upper_bound: float
    loss: float
    burst: float | None
    loss_free_critical_stiffness: float
    rho_at: float
    rho_above: float
    certified: bool
    period: float
    terms: tuple[str, ...]
    modes: int
    order: int
    scan_K: np.ndarray = field(repr=False, compare=False)
    scan_rho: np.ndarray = field(repr=False, compare=False)
    seconds: float = 0.0
    search: str = "roots"
    loop_dict: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def method(self) -> str:
        return "exact" if self.certified else "mean-square"

    @property
    def reason(self) -> str:
        """The answer in words, with what it rests on."""
        chain = ("independent losses" if self.burst is None
                 else f"Gilbert-Elliott bursts of mean length {self.burst:g} samples")
        where = ", ".join(self.terms)
        if self.certified:
            return ("no packet loss: the exact core's certified K_max "
                    f"({where} always received)")
        if self.critical_stiffness == 0.0:
            return (f"with {self.loss:g} of the packets lost ({chain}; {where}) the loop is "
                    f"not mean-square stable at the smallest K scanned "
                    f"({self.upper_bound:.4g} N/m, rho = {self.rho_above:.8g})")
        if math.isinf(self.upper_bound):
            return (f"mean-square stable at every K scanned up to {self.critical_stiffness:.6g} "
                    f"N/m with {self.loss:g} lost ({chain}); K_max is at least that")
        how = ("the first K at which the second-moment operator has the eigenvalue 1 "
               "(det(I - T(K)) = 0)" if self.search == "roots"
               else "the first unstable K of a scan, then bisection")
        return (f"mean-square stable for K in (0, {self.critical_stiffness:.10g}] N/m with "
                f"{self.loss:g} of the packets lost ({chain}; {where}): {how}; rho = "
                f"{self.rho_at:.12f} there and {self.rho_above:.12f} at "
                f"{self.upper_bound:.10g} N/m. Exact criterion (Costa et al. 2005, Thm 3.9) "
                "evaluated in floating point, not certified (docs/guide/networks.md); "
                f"without loss K_max = {self.loss_free_critical_stiffness:.10g} N/m (certified)")

    def to_dict(self) -> dict[str, Any]:
        return jsonable({
            "critical_stiffness": self.critical_stiffness, "method": self.method,
            "upper_bound": self.upper_bound, "loss": self.loss,
            "burst_samples": self.burst,
            "loss_free_critical_stiffness": self.loss_free_critical_stiffness,
            "rho_at_critical_stiffness": self.rho_at, "rho_at_upper_bound": self.rho_above,
            "certified": self.certified, "search": self.search, "period_s": self.period,
            "networked_terms": list(self.terms), "modes": self.modes, "state_dimension": self.order,
            "seconds": self.seconds, "reason": self.reason})

    def to_csv(self, path: Any) -> None:
        """Write the scan: stiffness_N_per_m, rho (the second-moment spectral radius).

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write (a path atomically, :mod:`hapstab.outputs`).
        """
        write_csv(path, ["stiffness_N_per_m", "rho"],
                  [[repr(float(k)), repr(float(r))] for k, r in zip(self.scan_K, self.scan_rho,
                                                                     strict=True)])

    def plot(self, ax: Any = None) -> Any:
        """rho of the second-moment operator against K (the scan), rho = 1 and K_max.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw; a new figure when omitted.

        Returns
        -------
        matplotlib Axes
        """
        from hapstab.plotting import axes_or_new

        ax = axes_or_new(ax)
        ax.plot(self.scan_K, self.scan_rho, "o-", ms=3, label="rho (second moment)")
        ax.axhline(1.0, color="k", lw=0.8)
        if math.isfinite(self.critical_stiffness) and self.critical_stiffness > 0:
            ax.axvline(self.critical_stiffness, color="C3", ls="--",
                       label=f"mean-square K_max = {self.critical_stiffness:.5g} N/m")
        ax.set_xlabel("K (N/m)")
        ax.set_ylabel("spectral radius")
        ax.set_title(f"packet loss {self.loss:g}")
        ax.legend(loc="best")
        return ax


@dataclass(frozen=True)
class LossCurveResult(Result):
    """Mean-square K_max against the loss rate.

    Parameters
    ----------
    rows : tuple of LossStiffnessResult
        One per loss rate.
    """

    rows: tuple[LossStiffnessResult, ...]

    @property
    def losses(self) -> np.ndarray:
        return np.array([r.loss for r in self.rows])

    @property
    def critical_stiffness(self) -> np.ndarray:
        """K_max (N/m) at each loss rate."""
        return np.array([r.critical_stiffness for r in self.rows])

    def to_dict(self) -> dict[str, Any]:
        return jsonable({"losses": self.losses, "critical_stiffness": self.critical_stiffness,
                         "upper_bound": [r.upper_bound for r in self.rows],
                         "certified": [r.certified for r in self.rows],
                         "burst_samples": self.rows[0].burst if self.rows else None})

    def to_csv(self, path: Any) -> None:
        """Write loss, critical_stiffness_N_per_m, upper_bound_N_per_m, certified.

        Parameters
        ----------
        path : str, os.PathLike or file object
            Where to write.
        """
        write_csv(path, ["loss", "critical_stiffness_N_per_m", "upper_bound_N_per_m",
                         "certified"],
                  [[repr(r.loss), repr(r.critical_stiffness), repr(r.upper_bound),
                    str(r.certified)] for r in self.rows])

    def plot(self, ax: Any = None) -> Any:
        """K_max against the loss rate.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw.

        Returns
        -------
        matplotlib Axes
        """
        from hapstab.plotting import axes_or_new

        ax = axes_or_new(ax)
        ax.plot(self.losses, self.critical_stiffness, "o-", label="mean-square K_max")
        ax.set_xlabel("packet loss P")
        ax.set_ylabel("K_max (N/m)")
        ax.legend(loc="best")
        return ax
