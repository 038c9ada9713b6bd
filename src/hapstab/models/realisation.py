"""State-space realisations of discrete transfer functions, batched over periods: what a
controller answers when the engine asks for its states (:meth:`realisation`)."""

from __future__ import annotations

import numpy as np

__all__ = ["Realisation", "realize", "replicate", "spring_damper_states"]

#: (Ah, Bh, Ch, D_fixed, D_per_K, Ch_K), each batched over P periods: the controller's
#: u = Ch xi + D_fixed e + K (Ch_K xi + D_per_K e), xi[k+1] = Ah xi + Bh e.
Realisation = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def realize(num: np.ndarray, den: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Controllable canonical (Ah, Bh, Ch, D) of num/den (P, q+1), highest power first.

    Parameters
    ----------
    num, den : (P, q+1) array
        Numerator and denominator in z, highest power first, one row per period.

    Returns
    -------
    (Ah, Bh, Ch, D) : arrays (P, q, q), (P, q, 1), (P, 1, q), (P,)
    """
    num, den = num / den[:, :1], den / den[:, :1]
    P, q = den.shape[0], den.shape[1] - 1
    d = num[:, 0]
    Ah = np.zeros((P, q, q))
    Bh = np.zeros((P, q, 1))
    if q:
        Ah[:, 0, :] = -den[:, 1:]
        Ah[:, 1:, :-1] = np.eye(q - 1)
        Bh[:, 0, 0] = 1.0
    Ch = (num[:, 1:] - d[:, None] * den[:, 1:])[:, None, :]
    return Ah, Bh, Ch, d


def replicate(a: np.ndarray, P: int) -> np.ndarray:
    """``a`` repeated for P periods (a leading axis), writable.

    Parameters
    ----------
    a : array
        Coefficients that do not depend on the period.
    P : int
        The number of periods.

    Returns
    -------
    array (P, *a.shape)
    """
    return np.broadcast_to(a, (P, *a.shape)).copy()


def spring_damper_states(damping: float, periods: np.ndarray) -> Realisation:
    """Eq. (23)'s H = K + B/T - (B/T) z^-1: one state, and K only in the direct
    feed-through; a state with zero output (B = 0) is dropped.

    Parameters
    ----------
    damping : float
        B in N*s/m.
    periods : (P,) array
        The sampling periods in s.

    Returns
    -------
    Realisation
    """
    P = periods.size
    if damping == 0:
        return (np.zeros((P, 0, 0)), np.zeros((P, 0, 1)), np.zeros((P, 1, 0)),
                np.zeros(P), np.ones(P), np.zeros((P, 1, 0)))
    BT = damping / periods
    return (np.zeros((P, 1, 1)), np.ones((P, 1, 1)), -BT[:, None, None],
            BT.copy(), np.ones(P), np.zeros((P, 1, 1)))
