"""The test lanes: how much of each seeded draw the default lane runs (one place).

A seeded campaign is one list of cases. ``draw(cases, reduced)`` turns it into pytest
parameters: an evenly spaced ``reduced`` of them (first and last included, so every kind
the draw cycles through keeps a representative) run in the default lane; the rest are
marked ``campaign`` and run on demand.

- ``make test`` (``pytest``, addopts ``-m 'not slow and not campaign'``): the reduced draws;
- ``make test-campaign`` (``pytest -m 'slow or campaign'``): the rest of every draw and the
  long campaigns, so ``make test`` + ``make test-campaign`` run each case once;
- ``HAPSTAB_CAMPAIGN=full``: no case is marked, the default lane runs every draw whole
  (``make test-full``: that, with ``slow`` and ``campaign`` selected too: everything).

The marked cases are the same cases (same seed, same index, same checks): moving a case
out of the default lane never changes what it asserts.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from typing import Any

import pytest

#: ``HAPSTAB_CAMPAIGN=full``: every draw whole in the default lane
FULL = os.environ.get("HAPSTAB_CAMPAIGN", "").strip().lower() == "full"


def reduced_indices(count: int, reduced: int) -> list[int]:
    """``reduced`` evenly spaced indices of ``range(count)``, 0 and count - 1 included."""
    if reduced >= count:
        return list(range(count))
    if reduced <= 1:
        return [0][:reduced]
    step = (count - 1) / (reduced - 1)
    return sorted({round(j * step) for j in range(reduced)})


def draw(cases: Iterable[Any], reduced: int, ids: Any = None) -> list[Any]:
    """The cases as pytest parameters: ``reduced`` in the default lane, the rest ``campaign``.

    Parameters
    ----------
    cases : iterable
        The seeded draw (a case, or a tuple of a parametrization's values, each).
    reduced : int
        How many of them the default lane runs (evenly spaced, see `reduced_indices`).
    ids : callable, optional
        The test id of a case (as ``pytest.mark.parametrize``'s ``ids``).

    Returns
    -------
    list of pytest.param
        Every case once, the ones outside the default lane marked ``campaign`` (none
        under ``HAPSTAB_CAMPAIGN=full``).
    """
    cases = list(cases)
    keep = set(range(len(cases))) if FULL else set(reduced_indices(len(cases), reduced))
    out = []
    for i, c in enumerate(cases):
        values: Sequence[Any] = c if isinstance(c, tuple) else (c,)
        marks = () if i in keep else (pytest.mark.campaign,)
        out.append(pytest.param(*values, marks=marks,
                                id=None if ids is None else ids(c)))
    return out


def size(reduced: int, full: int) -> int:
    """A draw's size inside one test: ``full`` under ``HAPSTAB_CAMPAIGN=full``, else ``reduced``."""
    return full if FULL else reduced


def costly(*values: Any, id: str | None = None) -> Any:
    """One case of a grid that the default lane leaves to ``make test-campaign``, where a
    cheaper sibling of it asks the same question (``peb`` at n = 30 beside n = 120);
    unmarked under ``HAPSTAB_CAMPAIGN=full``.

    Parameters
    ----------
    *values
        The case's parameter values.
    id : str, optional
        Its test id (the one it had in the grid).

    Returns
    -------
    pytest.param
    """
    return pytest.param(*values, marks=() if FULL else (pytest.mark.campaign,), id=id)


def part(cases: Sequence[Any], reduced: int, rest: bool) -> list[Any]:
    """One lane's part of a draw that lives inside one test: the ``reduced`` evenly spaced
    cases (`reduced_indices`), or with ``rest`` the others. Parametrize the test with
    :data:`PARTS`: the default lane checks the reduced part, ``make test-campaign`` the rest,
    so together they check every case once (under ``HAPSTAB_CAMPAIGN=full`` both parts run
    in the default lane).

    Parameters
    ----------
    cases : sequence
        The whole draw, built the same way in both lanes.
    reduced : int
        How many of them the default lane checks.
    rest : bool
        The other cases instead.

    Returns
    -------
    list
    """
    keep = set(reduced_indices(len(cases), reduced))
    return [c for i, c in enumerate(cases) if (i in keep) != rest]


#: ``@pytest.mark.parametrize("rest", PARTS)``: the reduced part of a draw in the default
#: lane, the rest marked ``campaign`` (see `part`)
PARTS = draw([False, True], 1, ids=lambda rest: "rest" if rest else "reduced")


def part_groups(cases: Sequence[Any], keys: Sequence[Any], reduced: int, rest: bool,
                also: Sequence[int] = ()) -> list[Any]:
    """`part` for a draw whose cases act on each other in one call (the batched exact
    core: the loops sharing a structure are one batch): whole groups of the cases with
    equal ``keys`` go to one lane, so every batch of the whole draw's call is one lane's
    batch. The default lane checks ``reduced`` evenly spaced groups of more than one case
    (and the groups of ``also``); with ``rest``, the other groups and the cases alone in
    theirs. Parametrize with :data:`PARTS`, as for `part`.

    Parameters
    ----------
    cases : sequence
        The whole draw, built the same way in both lanes.
    keys : sequence
        Each case's group (its batch's key; a unique value for a case that has none).
    reduced : int
        How many groups of more than one case the default lane checks.
    rest : bool
        The other cases instead.
    also : sequence of int
        Cases whose group (whole) the default lane checks too (a kind to keep there).

    Returns
    -------
    list
        The lane's cases, in the draw's order.
    """
    order: list[Any] = []
    for k in keys:
        if k not in order:
            order.append(k)
    shared = [k for k in order if list(keys).count(k) > 1]
    chosen = {shared[i] for i in reduced_indices(len(shared), reduced)} | {keys[i] for i in also}
    return [c for c, k in zip(cases, keys, strict=True) if (k in chosen) != rest]


def draw_split(cases: Iterable[Any], reduced: int, ids: Any = str) -> list[Any]:
    """``draw(cases, reduced)`` as ``(case, rest)`` parameters, where each of the default
    lane's cases is itself split in two (a test that checks a large grid per case): its
    ``rest=False`` part in the default lane, its ``rest=True`` part ``campaign``; the other
    cases ``rest=None`` (the whole grid) and ``campaign``, as with `draw`.

    Parameters
    ----------
    cases : iterable
        The seeded draw (one value per case).
    reduced : int
        How many cases the default lane checks (their reduced parts).
    ids : callable
        The test id of a case; the split ones get ``-reduced`` / ``-rest`` after it.

    Returns
    -------
    list of pytest.param
    """
    out = []
    for p in draw(cases, reduced):
        case, = p.values
        if p.marks:
            out.append(pytest.param(case, None, marks=p.marks, id=ids(case)))
        else:
            out += [pytest.param(case, False, id=f"{ids(case)}-reduced"),
                    costly(case, True, id=f"{ids(case)}-rest")]
    return out
