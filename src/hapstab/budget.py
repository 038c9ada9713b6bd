"""What a computation may cost before it asks: memory and time, estimated from the
inputs before any work starts.

Every analysis whose cost grows with its inputs (the delay, the grid, the duration,
the number of points) estimates its peak memory and its run time first and refuses
with one line, saying what it would need, when that exceeds the budget: by default
:data:`MEMORY_BYTES` and :data:`SECONDS`. Ask for more with ``max_memory=`` /
``max_seconds=`` on the call, for a block of code with :func:`limits` (or
:func:`unlimited`), or on the command line with ``--yes``.

The time estimates count the dominant operations (dense eigenvalue problems, the
samples of a simulation, the points of a grid) at a rate measured on the project's
2-core machine; they are meant to be right within a factor of a few, which is what a
budget needs. The memory estimates count the arrays held at the peak.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
from collections.abc import Iterator
from dataclasses import dataclass
from numbers import Real
from typing import Any

from hapstab.errors import ArgumentTypeError, HapstabError

__all__ = ["BudgetError", "Cost", "check", "limits", "unlimited", "MEMORY_BYTES", "SECONDS",
           "EIG_SECONDS_PER_N3", "eig_seconds", "FLOPS", "RUN_SECONDS", "POINT_SECONDS", "simulation_cost",
           "exact_points_cost", "POINT_BYTES_PER_STATE", "build_cost", "seconds_allowed"]

#: Default memory budget: 2 GiB, a twelfth of the project's 24 GiB machine and what
#: any laptop spares.
MEMORY_BYTES = 2 * 1024 ** 3
#: Default time budget: 1 minute -- no accepted input runs longer without a refusal
#: or a budgeted stop (issue 27); ``--yes`` / ``max_seconds=`` ask for more.
SECONDS = 60.0
#: Seconds per N^3 of one dense eigenvalue problem (numpy's eigvals): 0.8e-9 to 1.1e-9
#: measured at N = 300...600 on the project's 2-core machine, doubled for a busy machine.
EIG_SECONDS_PER_N3 = 2e-9
#: ... and from N = 600 on, the floor. A PEB loop with 2000 samples of delay took 3.1e-10
#: at N = 2004 and 2.9e-10 at N = 4004 (18.8 s), but an HVE loop's delay chain converges
#: far slower in LAPACK's QR: 3.7e-9 at N = 2002 (29.7 s, ``paper_hve(delay_samples=2000)``,
#: issue 27); the floor is that measurement rounded up (the slow structure), not the PEB's.
EIG_SECONDS_PER_N3_LARGE = 4e-9


def eig_seconds(states: int) -> float:
    """Seconds of one dense eigenvalue problem of ``states`` states (see the constants)."""
    per = max(EIG_SECONDS_PER_N3_LARGE, EIG_SECONDS_PER_N3 * min(1.0, 600.0 / max(states, 1)))
    return 0.01 + per * float(states) ** 3
#: Operations per second of numpy's batched products and solves: 6.6e9 counted
#: operations in 0.27 s (1e5 samples of a 102-state loop) and a 200-state region's
#: D-decomposition in about 6 s, on the project's machine; taken as 1e10.
FLOPS = 1e10
#: Fixed cost of one simulated run (setup, the verdict's fit): a K_max search of about
#: 18 runs of 2000 samples of a 12-state loop takes 0.044 s.
RUN_SECONDS = 2e-3
#: One certified K_max in a batch (the float search, then the ball proof loop by loop):
#: 18.7 ms (100 HVE loops) and 38 ms (100 PEB loops; a PEB boundary 39 ms a point),
#: measured on the 2-core machine with the proof the default; taken as 40 ms. A closed
#: form or the circle criterion costs less.
POINT_SECONDS = 0.04
#: Bytes one item of a batched exact analysis holds per state of the loop (its
#: polynomials and cells): about 10 MB per period at N = 4004 (a review's measurement).
POINT_BYTES_PER_STATE = 3000.0


def exact_points_cost(what: str, points: int, states: int) -> Cost:
    """The cost of ``points`` certified K_max of a loop with about ``states`` states, run
    as one batch: 20 ms plus 50 us per state each (0.2 s at N = 4000), and
    :data:`POINT_BYTES_PER_STATE` per state each.

    Parameters
    ----------
    what : str
        The computation, in words.
    points : int
        How many K_max (periods, dampings, ...).
    states : int
        The loop's order, about.

    Returns
    -------
    Cost
    """
    return Cost(what, points * (1e5 + POINT_BYTES_PER_STATE * states),
                points * (POINT_SECONDS + 5e-5 * states))   # 0.2 s a point at N = 4000

#: The exact core's K_max of one loop at a long delay, per sample of the phase
#: e^{-j n theta} (det M's delay power, the round trip for PEB) and per port squared:
#: measured (peak RSS, wall time, float search and ball proof, quiet machine) HVE at
#: n = 2e4 / 5e4: 0.22 / 0.36 GB, 1.1 / 2.7 s; PEB round trip 1e4 / 4e4: 0.61 / 1.89 GB,
#: 3.3 / 15.4 s. Taken as 12 kB and 100 us per phase sample per port^2 plus 0.15 GB,
#: above every measurement (1.05-2x).
EXACT_BYTES_PER_PHASE = 12e3
#: (the time per phase sample per port^2, from the same measurements)
EXACT_SECONDS_PER_PHASE = 1e-4
EXACT_BASE_BYTES = 1.5e8


def exact_search_cost(phase_samples: int, ports: int, periods: int = 1) -> Cost:
    """The cost of the exact core's K_max (its float search and ball proof) of a loop
    whose characteristic function carries e^{-j n theta} with n = ``phase_samples``,
    at ``periods`` sampling periods (see the constants above). Below a few thousand
    samples it is well inside any budget; it grows linearly with the delay.

    Parameters
    ----------
    phase_samples : int
        The delay power of det M (HVE: the delay; PEB: the round trip), samples.
    ports : int
        Device ports (1 HVE, 2 teleoperation).
    periods : int
        How many sampling periods are analysed in one batch.

    Returns
    -------
    Cost
    """
    per = float(phase_samples) * ports * ports
    return Cost(f"exact K_max: a delay power of {phase_samples} samples "
                f"({ports} port{'s' if ports > 1 else ''}) at {periods} period"
                f"{'s' if periods > 1 else ''}",
                EXACT_BASE_BYTES + periods * EXACT_BYTES_PER_PHASE * per,
                periods * EXACT_SECONDS_PER_PHASE * per)


def build_cost(periods: int, states: float) -> Cost:
    """The cost of building the exact closed loop (:func:`hapstab.build`) at ``periods``
    sampling periods with about ``states`` states.

    Measured on the project's machine (tracemalloc's peak, wall time): 1e5 periods of a
    4-state loop 75 MB and 23.6 s; 2000 of 52 states 54 MB and 0.90 s; 50 of 402 states
    74 MB and 0.97 s. Taken as 1000 bytes and 0.4 ms per period (the discretisation of
    each period) plus 8 matrices of N^2 doubles and 6e-10 N^3 s (the products) per
    period: above every measurement (1.1-1.7 x).

    Parameters
    ----------
    periods : int
        How many periods.
    states : float
        N, about.

    Returns
    -------
    Cost
    """
    P, N = float(periods), float(states)
    return Cost(f"build: the exact model of a {int(N)}-state loop at {periods} periods",
                # a floor against division by zero / rounding, far below the answer's own accuracy
                P * (1000.0 + 64.0 * N * N), P * (4e-4 + 6e-10 * N ** 3))


_LIMITS: contextvars.ContextVar[tuple[float, float]] = contextvars.ContextVar(
    "hapstab_budget", default=(MEMORY_BYTES, SECONDS))


class BudgetError(HapstabError):
    """A computation would need more memory or time than the budget allows."""


@dataclass(frozen=True)
class Cost:
    """The estimated peak memory and run time of one computation.

    Attributes
    ----------
    what : str
        The computation and the sizes that drive its cost, in words.
    memory_bytes : float
        Peak memory held by its arrays.
    seconds : float
        Run time on the project's machine.
    """

    what: str
    memory_bytes: float
    seconds: float


def _size(b: float) -> str:
    for unit, f in (("TiB", 2.0 ** 40), ("GiB", 2.0 ** 30), ("MiB", 2.0 ** 20)):
        if b >= f:
            return f"{b / f:.3g} {unit}"
    return f"{b / 1024:.3g} KiB"


def _time(s: float) -> str:
    if s >= 3600:
        return f"{s / 3600:.3g} h"
    return f"{s / 60:.3g} min" if s >= 120 else f"{s:.3g} s"


def check(cost: Cost, max_memory: float | None = None, max_seconds: float | None = None) -> Cost:
    """Refuse ``cost`` if it exceeds the budget.

    Parameters
    ----------
    cost : Cost
        The estimate.
    max_memory : float, optional
        Budget in bytes for this call (default: the current :func:`limits`).
    max_seconds : float, optional
        Budget in seconds for this call (default: the current :func:`limits`).

    Returns
    -------
    Cost
        ``cost``, when within the budget.

    Raises
    ------
    BudgetError
        One line: what it would need, the budget, and how to ask for more.
    """
    mem, sec = _LIMITS.get()
    mem = mem if max_memory is None else _limit("max_memory", max_memory)
    sec = sec if max_seconds is None else _limit("max_seconds", max_seconds)
    over = []
    if cost.memory_bytes > mem:
        over.append(f"about {_size(cost.memory_bytes)} of memory (budget {_size(mem)})")
    if cost.seconds > sec:
        over.append(f"about {_time(cost.seconds)} (budget {_time(sec)})")
    if over:
        raise BudgetError(f"{cost.what}: would need {' and '.join(over)}; run it anyway with "
                          "--yes (Python: max_memory= / max_seconds=, or "
                          "hapstab.budget.unlimited())")
    return cost


def seconds_allowed(max_seconds: float | None = None) -> float:
    """The time budget in force: ``max_seconds`` if given, else the current :func:`limits`'
    (``math.inf`` under :func:`unlimited`). An open-ended search (robust K_max) runs
    until it converges or this many seconds have passed, then answers with its gap.

    Parameters
    ----------
    max_seconds : float, optional
        The call's own budget.

    Returns
    -------
    float
    """
    return _LIMITS.get()[1] if max_seconds is None else _limit("max_seconds", max_seconds)


def _limit(name: str, value: Any) -> float:
    """A budget given by the user: a real number > 0 (``math.inf``: no limit)."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ArgumentTypeError(f"{name} = {value!r:.60}: must be a number > 0 (math.inf: no "
                                f"limit; got {type(value).__name__})")
    try:
        v = float(value)
    except OverflowError:          # an integer beyond double precision: no limit, in effect
        v = -math.inf if str(value).startswith("-") else math.inf   # (-10**400: refused)
    if not v > 0:
        raise BudgetError(f"{name} = {value!r:.40}: must be > 0 (math.inf: no limit)")
    return v


@contextlib.contextmanager
def limits(memory_bytes: float | None = None, seconds: float | None = None) -> Iterator[None]:
    """Set the budget for the computations inside the block.

    Parameters
    ----------
    memory_bytes : float, optional
        Bytes (``math.inf``: no limit); default: keep the current one.
    seconds : float, optional
        Seconds (``math.inf``: no limit); default: keep the current one.

    Yields
    ------
    None
    """
    mem, sec = _LIMITS.get()
    token = _LIMITS.set((mem if memory_bytes is None else _limit("memory_bytes", memory_bytes),
                         sec if seconds is None else _limit("seconds", seconds)))
    try:
        yield
    finally:
        _LIMITS.reset(token)


def unlimited() -> contextlib.AbstractContextManager[None]:
    """No budget inside the block (what ``--yes`` does on the command line).

    Returns
    -------
    context manager
    """
    return limits(math.inf, math.inf)


def simulation_cost(samples: int, states: int, ports: int, dense: int = 0,
                    runs: int = 1) -> Cost:
    """The cost of ``runs`` simulations of ``samples`` samples of a loop with ``states``
    states (see :func:`hapstab.simulation.run.simulate`).

    Memory: the state trajectory, one free and one impulse response per port for the
    verdict (8 bytes each), the per-port series, and the dense output. Time: one
    block propagation per response, ``2 N^2 + 128 p N`` operations per sample, the
    verdict's fit (about ``300 N^3``) and a fixed :data:`RUN_SECONDS` per run.

    Parameters
    ----------
    samples : int
        Samples per run.
    states : int
        N, the closed loop's order.
    ports : int
        p, the devices.
    dense : int
        Points per sample of the dense output (0: none).
    runs : int
        How many runs (a search runs many, one after the other).

    Returns
    -------
    Cost
    """
    M, N, p = float(samples), float(states), float(ports)
    # words per sample, fitted above tracemalloc's peaks of simulate (N = 2...62, dense 50)
    memory = 8 * M * (N * (3 + 2 * p) + 24 * p + 3 * dense * (1 + 2 * p))
    fit = 300 * N ** 3       # the verdict's fit on a window of ~4 N snapshots (SVD, eigenvalues)
    seconds = runs * (((1 + p) * M * (2 * N * N + 128 * p * N) + fit) / FLOPS + RUN_SECONDS)
    return Cost(f"{runs} simulation(s) of {samples} samples of a {states}-state loop",
                memory, seconds)
