"""The loop seen from its terminations: the devices' damping and the controller
matrix H(z), for the frequency-domain analyses (circle criterion, passivity).

Cut the loop at the operator and the environment. What is left at the ports is
each device's viscous damping b_i and the controllers, which push on port i with

    u_i = H_i(z) sum_j s_ij z^-n_ij x_j,     i.e.  u = Hc(z) x,  Hc_ij = s_ij z^-n_ij H_i(z)

(:class:`~hapstab.engine.structure.Channel`). The circle criterion's inverse
transfer function is ``G^-1(z) = diag(b) + Hc(z) X(z)`` with X(z) an
approximation of Z{v/s} (eq. 15, eq. 24/30), and sampled-data passivity is a
condition on ``diag(b)`` and ``(1 - z^-1) Hc(z)`` (Colgate and Schenkel). Both
take Hc from here, built from the same :class:`~hapstab.engine.structure.LoopStructure`
as the time-domain engine, so a new loop kind needs only its structure.

K is varied by :func:`~hapstab.engine.structure.channel_ratios` (K_s/K_m kept). A port
may have several position channels (Lawrence's 4-channel architecture without force
gains); their forces add in row i of Hc. Force channels are refused here.

References
----------
The paper, eq. (14)-(15), (20)-(24), (30); J. E. Colgate and G. G. Schenkel, J. Robotic
Systems 14(1), 1997.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hapstab.engine.structure import Channel, channel_ratios, structure_of
from hapstab.errors import AnalysisError
from hapstab.models.loops import HapticLoop, TeleoperationLoop, split_delay

__all__ = ["DeviceSide", "device_side", "PARTS"]

#: What :meth:`DeviceSide.controller_matrix` evaluates: the whole H, its part per unit
#: K (``"K"``, K_s/K_m kept) or its part at K = 0 (``"B"``).
PARTS = (None, "K", "B")


@dataclass(frozen=True)
class DeviceSide:
    """The devices' damping and the controller matrix of one loop.

    Attributes
    ----------
    period_s : float
        Sampling period T in s.
    names : tuple of str
        Port names (``"device"``; ``"master"``, ``"slave"``).
    damping : (p,) array
        Each device's viscous damping b_i in N*s/m.
    channels : tuple of Channel
        One controller per port and what it measures (whole-sample delays).
    ratios : tuple of float or None
        Each controller's stiffness per unit K; ``None`` when K cannot be varied
        (a controller that is not a spring-damper, or K_m = 0 < K_s).
    forces : tuple of Channel
        Force channels (constant gains on the terminations' measured forces), only
        where the analysis asked for them (:meth:`with_forces`).
    masses : (p,) array
        Each device's mass in kg (used with force channels only).
    extra_damping : (p,) array or None
        Least damping of the terminations (bounded impedance), added to the device side
        after the force feedback (:meth:`with_forces`); without force channels it is
        added to ``damping`` instead.
    """

    period_s: float
    names: tuple[str, ...]
    damping: np.ndarray
    channels: tuple[Channel, ...]
    ratios: tuple[float, ...] | None
    forces: tuple[Channel, ...] = ()
    masses: np.ndarray | None = None
    extra_damping: np.ndarray | None = None

    def force_matrix(self, theta: np.ndarray) -> np.ndarray:
        """G_f(e^{j theta}), (N, p, p): u = Hc x + G_f F_t (F_t the terminations' forces)."""
        th = np.atleast_1d(np.asarray(theta, float))
        out = np.zeros((th.size, self.ports, self.ports), complex)
        for ch in self.forces:
            g = float(ch.controller.num[0])                   # type: ignore[union-attr]
            for j, s, d in ch.terms:
                out[:, ch.port, j] += s * g * np.exp(-1j * int(d) * th)
        return out

    def with_forces(self, P: np.ndarray, theta: np.ndarray, part: str | None = None
                    ) -> np.ndarray:
        """The device side seen by the terminations once the measured forces are fed back.

        The sensor sits between device and termination: m s v + P v = F_t - G_f F_t, so
        F_t = (I - G_f)^-1 (P + j w M) v (M the devices' masses, s = j w). The masses
        are moved back to the terminations (as without force channels), which leaves
        det(P + Z_terminations) and Llewellyn's conditions unchanged: the result is
        ``(I - G_f)^-1 (P + j w M) - j w M``, or ``(I - G_f)^-1 P`` for the K-part
        (``part="K"``, no mass). Without force channels, ``P`` itself.
        """
        if not self.forces:
            return P
        th = np.atleast_1d(np.asarray(theta, float))
        L = np.linalg.inv(np.eye(self.ports)[None] - self.force_matrix(th))
        if part == "K":
            return L @ P
        assert self.masses is not None
        jwM = (1j * th / self.period_s)[:, None, None] * np.diag(self.masses)[None]
        out = L @ (P + jwM) - jwM
        return out if self.extra_damping is None else out + np.diag(self.extra_damping)[None]

    def check_forces(self, what: str) -> None:
        """Refuse force feedback that is unstable on its own: a zero of
        det(I - z^-1 G_f(z)) (:func:`_force_determinant`) on or outside the unit circle
        makes the sampled force loop unstable, which Llewellyn's conditions (and
        transparency) assume it is not."""
        if not self.forces:
            return
        poly = _force_determinant(self.forces, self.ports)
        roots: np.ndarray = (np.polynomial.polynomial.polyroots(poly) if np.count_nonzero(poly[1:])
                             else np.zeros(0))
        # |r| = |1/z| <= 1 + 1e-9: a zero on or outside the circle to the roots' accuracy
        # (a few digits short of double precision for these low-degree polynomials)
        if (len(roots) == 0 and poly[0] == 0) or np.any(np.abs(roots) <= 1.0 + 1e-9):
            bad = max((1.0 / abs(r) for r in roots if r != 0), default=math.inf)
            names = {(0, 0): "C6", (0, 1): "C2", (1, 0): "C3", (1, 1): "C5"}
            gains = ", ".join(f"{names.get((ch.port, j), 'gain')} = "
                              f"{-float(ch.controller.num[0]) * s:g}"  # type: ignore[union-attr]
                              for ch in self.forces for j, s, _ in ch.terms)
            raise AnalysisError(f"{what}: the force feedback alone is unstable with {gains} "
                                f"(det(I - z^-1 G_f(z)) has a zero at |z| = {bad:.6g} >= 1: "
                                "|C5|, |C6| must be below 1 and C2 C3 small enough); the test "
                                "needs a stable two-port")

    @property
    def ports(self) -> int:
        """Number of ports p."""
        return len(self.names)

    @property
    def oscillations(self) -> int:
        """Oscillations over theta in [0, pi] of a p x p determinant of Hc: the sum over
        channels of the longest delay, plus 2 (a grid density for sweeps)."""
        most = [0] * self.ports
        for ch in (*self.channels, *self.forces):
            most[ch.port] = max(most[ch.port], *(int(d) for _, _, d in ch.terms))
        return sum(most) + 2

    def port_weights(self, scaling: str | None = "auto") -> tuple[float, ...]:
        """Diagonal port weights D that make the residue of D Hc X at z = 1 Hermitian.

        The residue is T Hc_K(1) K with ``Hc_K(1)_ij = k_i S_ij`` (k_i a channel's
        stiffness per unit K, S_ij the sum of its signs on port j). For two ports the
        master is weighted by ``d_0 = k_1 S_10 / (k_0 S_01)`` (the slave by 1), so that
        ``D Hc_K(1)`` is symmetric: K_s/K_m for unequal PEB controllers, times
        alpha/beta with position and force scaling. Equal, unscaled controllers give
        D = I. See :func:`hapstab.analysis.conditions.circle.port_scaling` for why stability still
        follows (D must be positive: S_01 and S_10 of one sign).

        Parameters
        ----------
        scaling : {"auto", None}
            ``None`` (or ``"none"``): no weighting, D = I.

        Returns
        -------
        tuple of float

        Raises
        ------
        AnalysisError
            Any other ``scaling``.
        """
        if not (scaling is None or isinstance(scaling, str)) or scaling not in ("auto", None, "none"):
            raise AnalysisError(f"scaling = {scaling!r}: allowed: 'auto' or None")
        ones = tuple(1.0 for _ in range(self.ports))
        if scaling != "auto" or self.ratios is None or self.ports != 2:
            return ones
        S = np.zeros((2, 2))
        for c, ch in enumerate(self.channels):
            for j, s, _ in ch.terms:
                S[ch.port, j] += self.ratios[c] * s
        if S[0, 1] * S[1, 0] > 0 and S[0, 1] != S[1, 0]:
            return (float(S[1, 0] / S[0, 1]), 1.0)
        return ones

    def controller_matrix(self, theta: np.ndarray, part: str | None = None) -> np.ndarray:
        """Hc(e^{j theta}), shape ``(N, p, p)``.

        Parameters
        ----------
        theta : array of float
            Angles in rad/sample.
        part : {None, "K", "B"}
            The whole H (None), its part per unit K (``"K"``) or at K = 0 (``"B"``).

        Returns
        -------
        (N, p, p) complex array

        Raises
        ------
        AnalysisError
            ``part`` given for a loop whose K cannot be varied.
        """
        th = np.atleast_1d(np.asarray(theta, float))
        if part not in PARTS:
            raise AnalysisError(f"part = {part!r}: allowed: None, 'K' or 'B'")
        if part is not None and self.ratios is None:
            raise AnalysisError("controllers: K cannot be varied in this loop (needs spring-damper "
                                "controllers with the master's stiffness > 0 if the slave's is)")
        out = np.zeros((th.size, self.ports, self.ports), complex)
        for c, ch in enumerate(self.channels):
            h = ch.controller.response(th, self.period_s, part,
                                       self.ratios[c] if self.ratios is not None else 1.0)
            for j, s, d in ch.terms:
                out[:, ch.port, j] += s * np.exp(-1j * int(d) * th) * h
        return out

    def controller_polynomials(self) -> tuple[list[list[np.ndarray]], list[list[np.ndarray]]]:
        """Hc(z) as rational functions: ``(nums, dens)``, p x p, highest power first.

        Returns
        -------
        (list of list of array, list of list of array)
            ``Hc_ij = nums[i][j] / dens[i][j]``; an entry without a term is ``0 / 1``.
        """
        p = self.ports
        nums = [[np.zeros(1) for _ in range(p)] for _ in range(p)]
        dens = [[np.ones(1) for _ in range(p)] for _ in range(p)]
        for ch in self.channels:
            i = ch.port
            hn, hd = (np.asarray(a, float) for a in ch.controller.transfer(self.period_s))
            for j, s, d in ch.terms:
                if np.any(nums[i][j]):
                    raise AnalysisError(f"{self.names[i]}: measures port {j} twice")
                zn = np.concatenate([[1.0], np.zeros(int(d))])  # z^-n: z^n into the denominator
                nums[i][j], dens[i][j] = s * hn, np.polymul(hd, zn)
        return nums, dens


def _force_determinant(forces: tuple[Channel, ...], p: int) -> np.ndarray:
    """det(I - z^-1 G_f) as a polynomial in r = 1/z (ascending coefficients): the force
    read at kT^- is the one the held input of the previous sample produced, so a port
    held still (a rigid termination) closes the force loop through one sample; C_6 = 2
    alone has its pole at z = -2."""
    P = np.polynomial.polynomial
    depth = 2 + max(int(d) for ch in forces for _, _, d in ch.terms)
    E = [[np.eye(1, depth, 0)[0] * float(i == j) for j in range(p)] for i in range(p)]
    for ch in forces:
        g = float(ch.controller.num[0])                       # type: ignore[union-attr]
        for j, s, d in ch.terms:
            E[ch.port][j][int(d) + 1] -= s * g      # measured one sample after it acts
    if p == 1:
        return E[0][0]
    return P.polysub(P.polymul(E[0][0], E[1][1]), P.polymul(E[0][1], E[1][0]))


def device_side(loop: HapticLoop | TeleoperationLoop, what: str,
                forces: bool = False) -> DeviceSide:
    """The loop cut at its terminations (see the module notes).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Any loop kind the engine's :func:`~hapstab.engine.structure.structure_of` builds.
    what : str
        The analysis that needs it, named in errors (e.g. ``"the circle criterion"``).
    forces : bool
        Whether the analysis takes force channels (:meth:`DeviceSide.with_forces`);
        otherwise they are refused.

    Returns
    -------
    DeviceSide

    Raises
    ------
    AnalysisError
        A delay that is not a whole number of samples: the frequency-domain
        conditions are derived for t_d = nT; force channels where not taken.
    """
    st = structure_of(loop)
    if not forces and any(ch.measures != "position" for ch in st.channels):
        raise AnalysisError(f"{what}: derived for controllers that measure positions; this loop "
                            "also feeds back measured forces (force gains C_2, C_3, C_5, C_6), "
                            "use the exact analysis")
    channels: list[Channel] = []
    force_channels: list[Channel] = []
    for ch in st.channels:
        terms = []
        for j, s, d in ch.terms:
            n, f = split_delay(d)
            if f:
                name = ("" if len(st.ports) == 1 or j == ch.port else
                        "delay forward = " if ch.port == 1 else "delay backward = ")
                raise AnalysisError(f"{what}: derived for a whole number of samples of delay "
                                    f"(t_d = nT); this loop has {name}t_d = {d:g} T")
            terms.append((j, s, float(n)))
        ch_whole = Channel(ch.port, ch.controller, tuple(terms), ch.measures)
        (channels if ch.measures == "position" else force_channels).append(ch_whole)
    ratios = channel_ratios(st)
    if ratios is not None:
        ratios = tuple(r for r, ch in zip(ratios, st.channels, strict=True)
                       if ch.measures == "position")
    return DeviceSide(float(loop.period), tuple(pt.name for pt in st.ports),
                      np.array([pt.device.damping for pt in st.ports], float), tuple(channels),
                      ratios, tuple(force_channels),
                      np.array([pt.device.mass for pt in st.ports], float))
