"""Independent brute-force references for the tests (no hapstab code at all).

Two layers, both written from scratch (nothing here imports hapstab):

1. The original helpers (:func:`closed_loop_matrix`, :func:`hve`, :func:`peb`,
   :func:`spectral_radius`, :func:`kmax`): each device + termination as a transfer
   function from net force to position, discretised for a zero-order hold by
   ``scipy.signal.cont2discrete``, realised in state space and closed with
   hand-written delay registers and u[k] = K e[k-n] + (B/T)(e[k-n] - e[k-n-1]).

2. The campaign reference (:class:`Loop`, :func:`hve_loop`, :func:`peb_loop`,
   :func:`matrices`, :func:`radius`, :func:`stable_intervals`, :func:`robust`,
   :func:`char_poly_mp`): devices with terminations none / spring / msd as physical
   states [x, v] (ZOH by ``cont2discrete``), any controller per port
   C_i = g_i K + B_i (z - 1)/(T z) (g_i: the slave's stiffness ratio, B_i any sign),
   integer delays in every path, the closed loop ``A(K) = A0 + K A1`` and

   * the spectral radius on stacks of K (one batched ``np.linalg.eigvals``);
   * the stable set by a geometric scan of K plus batched bisection of every sign
     change of rho - 1 (narrow windows between grid points can be missed: the
     campaign compares both ways for that reason);
   * a referee for points close to the circle: eigenvalues whose |z| - 1 is within
     their own rounding bound (100 eps ||A|| kappa, kappa the eigenvalue condition
     number) are re-solved at 50 digits by Aberth iterations on the characteristic
     function det(zI - A(K)) = z^R det(D(z) + C(z) E(z) N(z)) evaluated with mpmath
     (ZOH by ``mpmath.expm``), which needs no N x N matrix at high precision.

3. The 4-channel extension (:func:`four_channel_loop`, :func:`step_loop`): a
   :class:`Control` may act on another port than its index (a port's controls add), and
   may measure the force F_t the port's termination applies to its device just before
   the sample, with a fixed (K-independent) gain. The termination (mass m_z, damping
   b_z, spring k_z) is pushed by the exogenous force f and pushes the device with F_t,
   so m_z a = f - b_z v - k_z x - F_t; the whole port obeys M a = f - u - b v - k x
   (M, b, k the totals). Just before the sample both forces still hold their previous-sample values, so
   a(kT^-) = (f_old - u_old - b v - k x) / M and F_t = f_old - m_z a - b_z v - k_z x:
   two more states per measured port, u_old (the port's controller force over the
   previous sample) and f_old, and one register per sample of delay of F_t.
   :func:`step_loop` steps the same physics sample by sample with explicit histories,
   no closed-loop matrix.

Rigid-body mode (free PEB: no operator, no environment, every error a difference of
positions). The vector with every position and every delay register equal to 1 and
every velocity 0 is an exact eigenvector of A(K) at z = 1 for every K (equal
positions give zero errors, hence zero forces, hence nothing moves). It is removed
by an exact similarity: a Householder reflector H maps it to e1, H A H has first
column e1, and its trailing block carries all other eigenvalues. In the 50-digit
characteristic function the same mode is the factor (z - 1), divided out.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import mpmath
import numpy as np
from scipy import linalg as sla
from scipy import signal


def _plant_tf(m: float, b: float, znum, zden) -> tuple[np.ndarray, np.ndarray]:
    """x/(f_net) = 1 / (s (m s + b + Z(s))) as a minimal (num, den), Z = znum/zden."""
    znum = np.trim_zeros(np.atleast_1d(np.asarray(znum, float)), "f")
    zden = np.trim_zeros(np.atleast_1d(np.asarray(zden, float)), "f")
    if znum.size == 0:
        znum = np.zeros(1)
    # s (m s + b) zden + s znum  over  zden ... x/f = zden / (s ((m s + b) zden + znum))
    inner = np.polyadd(np.polymul([m, b], zden), znum)
    den = np.polymul([1.0, 0.0], inner)
    num = zden.copy()
    while num.size > 1 and num[-1] == 0 and den[-1] == 0:   # cancel common s (a spring)
        num, den = num[:-1], den[:-1]
    return num, den


def _key(coeffs) -> tuple:
    return tuple(float(c) for c in np.atleast_1d(np.asarray(coeffs, float)))


@functools.lru_cache(maxsize=256)
def _zoh_block(m: float, b: float, zn: tuple, zd: tuple, T: float):
    """(Ad, Bd, Cd) of one device + termination, ZOH (cached: K_max scans rebuild the
    same plant for every K)."""
    num, den = _plant_tf(m, b, zn, zd)
    A, Bm, C, D = signal.tf2ss(num, den)
    Ad, Bd, Cd, _Dd, _ = signal.cont2discrete((A, Bm, C, D), T, method="zoh")
    for M in (Ad, Bd, Cd):
        M.setflags(write=False)
    return Ad, Bd, Cd


def closed_loop_matrix(ports: list[tuple[float, float, tuple, tuple]], channels, K,
                       B, T: float) -> np.ndarray:
    """Closed-loop matrix of a loop.

    ports: [(mass, damping, Z_num, Z_den)], channels: for each port i a list of
    (j, sign, delay) terms of its error signal e_i = sum sign * x_j[k - delay].
    K, B: one stiffness and virtual damping (any sign) for every port, or one per port.
    """
    p = len(ports)
    Kp = np.broadcast_to(np.asarray(K, float), (p,))
    Bp = np.broadcast_to(np.asarray(B, float), (p,))
    blocks = [_zoh_block(float(m), float(b), _key(zn), _key(zd), float(T)) for m, b, zn, zd in ports]
    nxs = [bl[0].shape[0] for bl in blocks]
    # registers of each measured position: depth = max delay + 1 (the B term needs e[k-n-1])
    depth = [0] * p
    for terms in channels:
        for j, _, n in terms:
            depth[j] = max(depth[j], n + 1)
    # state order here: registers first, then plants (hapstab puts plants first)
    off_r = np.concatenate([[0], np.cumsum(depth)]).astype(int)
    off_x = off_r[-1] + np.concatenate([[0], np.cumsum(nxs)]).astype(int)
    N = int(off_x[-1])

    def pos_row(j: int) -> np.ndarray:
        r = np.zeros(N)
        r[off_x[j]:off_x[j + 1]] = blocks[j][2][0]
        return r

    def delayed(j: int, d: int) -> np.ndarray:
        """Row giving x_j[k - d] from the state (register l holds x_j[k-1-l])."""
        if d == 0:
            return pos_row(j)
        r = np.zeros(N)
        r[off_r[j] + d - 1] = 1.0
        return r

    M = np.zeros((N, N))
    for j in range(p):
        if depth[j]:
            M[off_r[j]] = pos_row(j)
            for step in range(1, depth[j]):
                M[off_r[j] + step, off_r[j] + step - 1] = 1.0
    for i, terms in enumerate(channels):
        u = np.zeros(N)
        for j, sgn, n in terms:
            u += sgn * ((Kp[i] + Bp[i] / T) * delayed(j, n) - (Bp[i] / T) * delayed(j, n + 1))
        Ad, Bd, _ = blocks[i]
        sl = slice(off_x[i], off_x[i + 1])
        M[sl, sl] += Ad
        M[sl] -= np.outer(Bd[:, 0], u)
    return M


def hve(m: float, b: float, zn, zd, n: int, B: float, T: float):
    ports = [(m, b, zn, zd)]
    channels = [[(0, 1.0, n)]]
    return lambda K: closed_loop_matrix(ports, channels, K, B, T)


def peb(mm: float, bm: float, ms: float, bs: float, op, env, n: int, B: float, T: float,
        ratio: float = 1.0, B_s: float | None = None):
    """PEB with C_m = K + B(z-1)/(Tz) and C_s = ratio K + B_s(z-1)/(Tz) (B_s defaults to B)."""
    ports = [(mm, bm, *op), (ms, bs, *env)]
    channels = [[(0, 1.0, 0), (1, -1.0, n)], [(1, 1.0, 0), (0, -1.0, n)]]
    Bs = B if B_s is None else B_s
    return lambda K: closed_loop_matrix(ports, channels, [K, ratio * K], [B, Bs], T)


def spectral_radius(make, K: float) -> float:
    return float(np.abs(np.linalg.eigvals(make(K))).max())


def kmax(make, lo: float = 1e-6, hi: float = 1e7, grid: int = 800) -> float:
    """First K where the spectral radius reaches 1 (grid scan + bisection)."""
    Ks = np.geomspace(lo, hi, grid)
    prev = lo
    if spectral_radius(make, lo) >= 1:
        return 0.0
    for K in Ks[1:]:
        if spectral_radius(make, K) >= 1:
            a, b = prev, K
            for _ in range(80):
                mid = 0.5 * (a + b)
                if spectral_radius(make, mid) < 1:
                    a = mid
                else:
                    b = mid
            return a
        prev = K
    return float("inf")


# =============================================================================
# Campaign reference: any pair of controllers, any B, integer delays both ways
# =============================================================================

_EPS = np.finfo(float).eps

#: grid points per decade of K in :func:`stable_intervals` (a ratio of 1.10 between
#: neighbours: windows narrower than that can fall between two points)
SCAN_PER_DECADE = 24

#: the scanned range of K is (SCAN_LO, SCAN_HI) * stiffness scale (:func:`scale`):
#: wider than hapstab's analysed range (1e-6 ... 1e12 times ||A0||/||A1||, about
#: sqrt(N) m/T: 1e-10 ... 1e12 m/T^2 over T = 1e-4 ... 2e-2 s), so crossings hapstab
#: cannot see are still found
SCAN_LO, SCAN_HI = 1e-11, 1e13

#: digits of the referee (:func:`robust`): the roots it refines are accurate to far
#: more than the 1e-6 relative spacing in K the campaign resolves
MP_DPS = 50


def termination(spec) -> tuple[float, float, float]:
    """(mass, damping, stiffness) of a rigidly attached termination.

    Parameters
    ----------
    spec : None, str or tuple
        ``None`` / ``"none"``; ``"spring:k"`` or ``("spring", k)``: Z = k/s;
        ``"msd:m,b,k"`` or ``("msd", m, b, k)``: Z = m s + b + k/s.
    """
    if spec is None:
        return (0.0, 0.0, 0.0)
    if isinstance(spec, str):
        kind, _, args = spec.strip().lower().partition(":")
        vals = [float(a) for a in args.split(",")] if args else []
    else:
        kind, vals = spec[0], [float(v) for v in spec[1:]]
    if kind == "none":
        return (0.0, 0.0, 0.0)
    if kind == "spring" and len(vals) == 1:
        return (0.0, 0.0, vals[0])
    if kind == "msd" and len(vals) == 3:
        return (vals[0], vals[1], vals[2])
    raise ValueError(f"termination {spec!r}: none, spring:k or msd:m,b,k")


@dataclass(frozen=True)
class Port:
    """A device with its termination: total mass, damping and stiffness to ground."""

    mass: float
    damping: float
    stiffness: float = 0.0
    term_mass: float = 0.0       # the termination's share of mass (for a measured force)
    term_damping: float = 0.0    # and of damping (its stiffness is all of ``stiffness``)


@dataclass(frozen=True)
class Control:
    """u = g K e[k] + (B/T)(e[k] - e[k-1]),  e[k] = sum sign * x_j[k - delay].

    Attributes
    ----------
    gain : float
        g, the multiplier of the swept stiffness K (1 for the master, K_s/K_m for
        the slave).
    damping : float
        B of this controller, N*s/m, any sign.
    terms : tuple of (port, sign, delay)
        The error signal; delays in whole samples.
    port : int
        The port it acts on (-1: its own index in ``Loop.controls``).
    force : bool
        The terms sample the termination forces F_t at kT^- instead of positions.
    fixed : float
        A K-independent gain on e[k] (N/m, or N/N for a force).
    filt : tuple
        The damper's velocity estimate: () the backward difference (e[k] - e[k-1])/T;
        ("lowpass", a): w[k] = a w[k-1] + (1 - a)(e[k] - e[k-1])/T (one more state,
        w[k-1]); ("average", N): (e[k] - e[k-N])/(N T).
    """

    gain: float
    damping: float
    terms: tuple[tuple[int, float, int], ...]
    port: int = -1
    force: bool = False
    fixed: float = 0.0
    filt: tuple = ()


@dataclass(frozen=True)
class Loop:
    """A sampled-data loop: one controller per port (``controls[i]`` acts on port i)."""

    ports: tuple[Port, ...]
    controls: tuple[Control, ...]
    period: float

    @property
    def rigid(self) -> bool:
        """True when equal positions of every port give zero error everywhere and no
        port is tied to ground: the K-independent rigid-body mode at z = 1."""
        return (all(p.stiffness == 0 for p in self.ports) and not self.extended
                and all(sum(s for _, s, _ in c.terms) == 0 for c in self.controls))

    @property
    def extended(self) -> bool:
        """Uses the 4-channel extension (controls on other ports, forces, fixed gains):
        :func:`matrices` and :func:`step_loop` only, not the 50-digit referee."""
        return (len(self.controls) != len(self.ports)
                or any(c.port not in (-1, i) or c.force or c.fixed
                       for i, c in enumerate(self.controls)))

    def port_of(self, i: int) -> int:
        """The port control i acts on."""
        c = self.controls[i]
        return i if c.port == -1 else c.port


def hve_loop(m: float, b: float, T: float, n: int, B: float = 0.0, operator=None,
             filt: tuple = ()) -> Loop:
    """The HVE: H(z) = K + B (z - 1)/(T z) on x[k - n]; operator per :func:`termination`;
    ``filt`` the damper's velocity filter (:class:`Control`)."""
    om, ob, ok = termination(operator)
    return Loop((Port(m + om, b + ob, ok),), (Control(1.0, B, ((0, 1.0, int(n)),),
                                                       filt=filt),), T)


def peb_loop(mm: float, bm: float, ms: float, bs: float, T: float, n_forward: int,
             n_backward: int | None = None, B: float = 0.0, B_slave: float | None = None,
             ratio: float = 1.0, operator=None, environment=None, filt: tuple = (),
             filt_slave: tuple | None = None) -> Loop:
    """PEB teleoperation (eq. 20): F_m = C_m (x_m - z^-nb x_s), F_s = C_s (x_s - z^-nf x_m).

    Parameters
    ----------
    mm, bm, ms, bs : float
        Master and slave mass (kg) and damping (N*s/m).
    T : float
        Period, s.
    n_forward, n_backward : int
        Master->slave and slave->master delays in samples (backward defaults to forward).
    B, B_slave : float
        Virtual damping of C_m and of C_s (``B_slave`` defaults to ``B``), any sign.
    ratio : float
        K_s / K_m: C_s = ratio K + B_s (z - 1)/(T z).
    operator, environment
        Terminations, see :func:`termination`.
    """
    nb = n_forward if n_backward is None else n_backward
    Bs = B if B_slave is None else B_slave
    om, ob, ok = termination(operator)
    em, eb, ek = termination(environment)
    fs = filt if filt_slave is None else filt_slave
    return Loop((Port(mm + om, bm + ob, ok), Port(ms + em, bs + eb, ek)),
                (Control(1.0, B, ((0, 1.0, 0), (1, -1.0, int(nb))), filt=filt),
                 Control(float(ratio), Bs, ((1, 1.0, 0), (0, -1.0, int(n_forward))),
                         filt=fs)), T)


def four_channel_loop(master: tuple[float, float], slave: tuple[float, float], T: float,
                      n_forward: int, n_backward: int, local_m: tuple[float, float],
                      local_s: tuple[float, float], from_master: tuple[float, float],
                      from_slave: tuple[float, float], c2: float = 0.0, c3: float = 0.0,
                      c5: float = 0.0, c6: float = 0.0, operator=None,
                      environment=None) -> Loop:
    """Lawrence's 4-channel teleoperator in the Hashtrudi-Zaad & Salcudean signs.

    The master's and slave's controller forces (what the actuators apply) are
    ``F_cm = -C_m x_m + C_4' z^-nb x_s + C_6 F_h - C_2 z^-nb F_e`` and
    ``F_cs = -C_s x_s + C_1 z^-nf x_m + C_3 z^-nf F_h - C_5 F_e``, with
    F_h = F_t,master (the operator's push on the master) and F_e = -F_t,slave (the
    slave's push on the environment), both at kT^-. Here u = -F_c.

    Parameters
    ----------
    master, slave : (mass, damping)
        The devices.
    local_m, local_s, from_master, from_slave : (gain, B)
        C_m, C_s, C_1 (on the delayed master position) and C_4' (on the delayed slave
        position) as g K + B (z - 1)/(T z).
    c2, c3, c5, c6 : float
        The force gains (N/N).
    operator, environment
        Terminations, see :func:`termination`.
    """
    om, ob, ok = termination(operator)
    em, eb, ek = termination(environment)
    ports = (Port(master[0] + om, master[1] + ob, ok, om, ob),
             Port(slave[0] + em, slave[1] + eb, ek, em, eb))
    nf, nb = int(n_forward), int(n_backward)
    controls = [Control(local_m[0], local_m[1], ((0, 1.0, 0),), port=0),
                Control(from_slave[0], from_slave[1], ((1, -1.0, nb),), port=0),
                Control(local_s[0], local_s[1], ((1, 1.0, 0),), port=1),
                Control(from_master[0], from_master[1], ((0, -1.0, nf),), port=1)]
    # u_m += -C_6 F_h + C_2 F_e = -C_6 Ft_m - C_2 Ft_s;  u_s += -C_3 Ft_m - C_5 Ft_s
    for port, g, j, d in ((0, c6, 0, 0), (0, c2, 1, nb), (1, c3, 0, nf), (1, c5, 1, 0)):
        if g:
            controls.append(Control(0.0, 0.0, ((j, -1.0, d),), port=port, force=True, fixed=g))
    return Loop(ports, tuple(controls), T)


def scale(loop: Loop) -> tuple[float, float]:
    """(smallest, largest) stiffness scale m/T^2 over the ports, N/m."""
    ms = [p.mass for p in loop.ports]
    return min(ms) / loop.period ** 2, max(ms) / loop.period ** 2


def _zoh(port: Port, T: float) -> tuple[np.ndarray, np.ndarray]:
    """ZOH of m x'' + b x' + k x = f with state [x, v] (scipy.signal.cont2discrete)."""
    A = np.array([[0.0, 1.0], [-port.stiffness / port.mass, -port.damping / port.mass]])
    Bc = np.array([[0.0], [1.0 / port.mass]])
    Ad, Bd, _, _, _ = signal.cont2discrete((A, Bc, np.eye(2), np.zeros((2, 1))), T, method="zoh")
    return Ad, Bd[:, 0]


def _depths(loop: Loop, force: bool = False) -> list[int]:
    """Registers kept for each port's position (or force): deepest delay used (+1 when B
    needs e[k-1])."""
    depth = [0] * len(loop.ports)
    for c in loop.controls:
        if c.force != force:
            continue
        for j, _, d in c.terms:
            back = c.filt[1] if c.filt and c.filt[0] == "average" else 1
            depth[j] = max(depth[j], d + (back if c.damping != 0 else 0))
    return depth


def _force_row(port: Port, j: int, N: int, u_old: int, f_old: int) -> np.ndarray:
    """F_t of port j at kT^- from the state (module docstring, item 3)."""
    M, mz = port.mass, port.term_mass
    r = np.zeros(N)
    # a = (f_old - u_old - b v - k x) / M;  F_t = f_old - mz a - b_z v - k_z x
    r[2 * j] = -port.stiffness + mz * port.stiffness / M
    r[2 * j + 1] = -port.term_damping + mz * port.damping / M
    r[u_old] = mz / M
    r[f_old] = 1.0 - mz / M
    return r


@functools.lru_cache(maxsize=64)
def matrices(loop: Loop) -> tuple[np.ndarray, np.ndarray]:
    """(A0, A1): the closed loop at the sampling instants is A(K) = A0 + K A1.

    State: [x_0, v_0, x_1, v_1, ..., registers of port 0, registers of port 1, ...,
    then for each port whose force is measured: u_old, f_old, its force registers];
    register l of port j holds x_j[k - 1 - l] (or F_t,j[k - 1 - l]). With a rigid-body
    mode (:attr:`Loop.rigid`) the returned pair is deflated: one row and column fewer,
    the eigenvalue 1 of the rigid mode removed exactly (see the module docstring).
    """
    A0, A1, _ = full_matrices(loop)
    if loop.rigid:
        N, n_pl = A0.shape[0], 2 * len(loop.ports)
        v = np.zeros(N)
        v[0:n_pl:2] = 1.0
        v[n_pl:] = 1.0
        nw = sum(1 for c in loop.controls if c.filt and c.filt[0] == "lowpass" and c.damping)
        v[N - nw:] = 0.0           # a filtered velocity of a translation is 0
        u = v / np.linalg.norm(v)
        # exact eigenvector for every K (checked, not assumed)
        assert np.abs(A0 @ u - u).max() < 1e-12 and np.abs(A1 @ u).max() < 1e-12 * np.abs(A1).max()
        w = u.copy()
        w[0] -= 1.0
        H = np.eye(N) - 2.0 * np.outer(w, w) / (w @ w)          # H u = e1, H = H^T = H^-1
        A0, A1 = (H @ A0 @ H)[1:, 1:], (H @ A1 @ H)[1:, 1:]
    return A0, A1


def full_matrices(loop: Loop) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A0, A1, G): A(K) = A0 + K A1 undeflated, and G (N, p), the exogenous force's
    input: s[k+1] = A(K) s[k] + G f[k] (:func:`matrices` for the layout)."""
    p, T = len(loop.ports), loop.period
    depth, fdepth = _depths(loop), _depths(loop, force=True)
    measured = sorted({j for c in loop.controls if c.force for j, _, _ in c.terms})
    n_pl = 2 * p
    off_r = n_pl + np.concatenate([[0], np.cumsum(depth)]).astype(int)
    N = int(off_r[-1])
    u_old, f_old, off_fr = {}, {}, {}
    for j in measured:
        u_old[j], f_old[j], off_fr[j] = N, N + 1, N + 2
        N += 2 + fdepth[j]
    ft = {j: _force_row(loop.ports[j], j, N, u_old[j], f_old[j]) for j in measured}
    w_state = {}                     # low-pass filtered velocity w[k-1] of control i
    for i, c in enumerate(loop.controls):
        if c.filt and c.filt[0] == "lowpass" and c.damping != 0:
            w_state[i] = N
            N += 1
    if w_state:
        ft = {j: np.pad(r, (0, N - r.size)) for j, r in ft.items()}

    def delayed(j: int, d: int, force: bool) -> np.ndarray:
        if force and d == 0:
            return ft[j]
        r = np.zeros(N)
        r[(off_fr[j] if force else off_r[j]) + d - 1 if d else 2 * j] = 1.0
        return r

    A0, A1, G = np.zeros((N, N)), np.zeros((N, N)), np.zeros((N, p))
    for j in range(p):
        for step in range(depth[j]):   # shift registers
            A0[off_r[j] + step, 2 * j if step == 0 else off_r[j] + step - 1] = 1.0
    for j in measured:
        for step in range(fdepth[j]):
            if step == 0:
                A0[off_fr[j]] = ft[j]
            else:
                A0[off_fr[j] + step, off_fr[j] + step - 1] = 1.0
        G[f_old[j], j] = 1.0
    u0, u1 = np.zeros((p, N)), np.zeros((p, N))
    for i, c in enumerate(loop.controls):
        pi = loop.port_of(i)
        for j, s, d in c.terms:
            u1[pi] += c.gain * s * delayed(j, d, c.force)
            u0[pi] += c.fixed * s * delayed(j, d, c.force)
            if c.damping != 0 and not c.filt:
                u0[pi] += (c.damping / T) * s * (delayed(j, d, c.force)
                                                 - delayed(j, d + 1, c.force))
            elif c.damping != 0 and c.filt[0] == "average":
                Nf = c.filt[1]
                u0[pi] += (c.damping / (Nf * T)) * s * (delayed(j, d, c.force)
                                                        - delayed(j, d + Nf, c.force))
            elif c.damping != 0:             # low-pass: w[k] = a w[k-1] + (1 - a) de / T
                a = c.filt[1]
                inc = (1.0 - a) / T * s * (delayed(j, d, c.force) - delayed(j, d + 1, c.force))
                A0[w_state[i]] += inc
                u0[pi] += c.damping * inc
        if i in w_state:
            A0[w_state[i], w_state[i]] += c.filt[1]
            u0[pi, w_state[i]] += c.damping * c.filt[1]
    for i, port in enumerate(loop.ports):
        Ad, bd = _zoh(port, T)
        sl = slice(2 * i, 2 * i + 2)
        A0[sl, sl] += Ad
        A0[sl] -= np.outer(bd, u0[i])         # the actuator force opposes u
        A1[sl] -= np.outer(bd, u1[i])
        G[sl, i] = bd
        if i in u_old:
            A0[u_old[i]], A1[u_old[i]] = u0[i], u1[i]
    return A0, A1, G


def step_loop(loop: Loop, K: float, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Step the loop sample by sample from rest at 0 under the exogenous forces f (M, p)
    held over each sample, from the physics with explicit histories (no closed-loop
    matrix; module docstring, item 3).

    Returns
    -------
    X : (M + 1, p) positions at the samples; U : (M + 1, p) controller forces u[k]
    (the actuator applies -u).
    """
    p, T, M = len(loop.ports), loop.period, f.shape[0]
    zoh = [_zoh(port, T) for port in loop.ports]
    xv = np.zeros((p, 2))
    u_old, f_old = np.zeros(p), np.zeros(p)
    hist_x, hist_f = [np.zeros(p)], [np.zeros(p)]       # newest last; before 0: at rest
    X, U = np.zeros((M + 1, p)), np.zeros((M + 1, p))

    def past(h: list, j: int, d: int) -> float:
        return float(h[-1 - d][j]) if d < len(h) else 0.0

    for k in range(M + 1):
        x, v = xv[:, 0].copy(), xv[:, 1].copy()
        ft = np.zeros(p)
        for j, pt in enumerate(loop.ports):
            a = (f_old[j] - u_old[j] - pt.damping * v[j] - pt.stiffness * x[j]) / pt.mass
            ft[j] = f_old[j] - pt.term_mass * a - pt.term_damping * v[j] - pt.stiffness * x[j]
        hist_x[-1], hist_f[-1] = x, ft
        u = np.zeros(p)
        for i, c in enumerate(loop.controls):
            h = hist_f if c.force else hist_x
            e = sum(s * past(h, j, d) for j, s, d in c.terms)
            e1 = sum(s * past(h, j, d + 1) for j, s, d in c.terms)
            u[loop.port_of(i)] += (c.gain * K + c.fixed) * e + (c.damping / T) * (e - e1)
        X[k], U[k] = x, u
        if k == M:
            break
        for j, (Ad, bd) in enumerate(zoh):
            xv[j] = Ad @ xv[j] + bd * (f[k, j] - u[j])
        u_old, f_old = u, f[k].copy()
        hist_x.append(None)
        hist_f.append(None)
    return X, U


def radius(loop: Loop, K) -> np.ndarray:
    """Spectral radius of A(K) (rigid mode excluded) for every K of an array, batched."""
    A0, A1 = matrices(loop)
    K = np.atleast_1d(np.asarray(K, float))
    out = np.empty(K.size)
    step = max(1, int(4e6 // A0.size))          # keep each stack to ~64 MB
    for s in range(0, K.size, step):
        k = K[s:s + step]
        out[s:s + step] = np.abs(np.linalg.eigvals(A0 + k[:, None, None] * A1)).max(axis=-1)
    return out


@dataclass
class Scan:
    """The stable set in K found by the scan.

    Attributes
    ----------
    intervals : list of (a, b)
        Stable intervals (a = 0: stable down to the bottom of the scan; b = inf:
        stable up to its top).
    boundaries : list of float
        Every K where rho - 1 changes sign (bisected to ``rtol``).
    K, rho : arrays
        The grid and its spectral radii.
    lo, hi : float
        The scanned range.
    """

    intervals: list
    boundaries: list
    K: np.ndarray
    rho: np.ndarray
    lo: float
    hi: float

    @property
    def kmax(self) -> float:
        """End of the interval that starts at 0, 0 when unstable at the bottom."""
        return self.intervals[0][1] if self.intervals and self.intervals[0][0] == 0 else 0.0


def stable_intervals(loop: Loop, lo: float | None = None, hi: float | None = None,
                     per_decade: int = SCAN_PER_DECADE, rtol: float = 1e-10) -> Scan:
    """Stable set in K by a geometric scan and bisection of every sign change.

    Parameters
    ----------
    loop : Loop
    lo, hi : float, optional
        Range of K; default (SCAN_LO x smallest, SCAN_HI x largest) m/T^2.
    per_decade : int
        Grid density.
    rtol : float
        Bisection stops when the bracket's ratio is within 1 + rtol.

    Returns
    -------
    Scan
    """
    s_lo, s_hi = scale(loop)
    lo = SCAN_LO * s_lo if lo is None else lo
    hi = SCAN_HI * s_hi if hi is None else hi
    Ks = np.geomspace(lo, hi, math.ceil(per_decade * math.log10(hi / lo)) + 1)
    rho = radius(loop, Ks)
    st = rho < 1.0
    idx = np.flatnonzero(st[1:] != st[:-1])
    a, b = Ks[idx].copy(), Ks[idx + 1].copy()
    sa = st[idx]
    while a.size and np.max(b / a) > 1 + rtol:   # all brackets at once
        mid = np.sqrt(a * b)
        sm = radius(loop, mid) < 1.0
        same = sm == sa
        a, b = np.where(same, mid, a), np.where(same, b, mid)
    bounds = list(np.sqrt(a * b))
    edges = [0.0, *bounds, math.inf]
    intervals = []
    stable_now = bool(st[0])
    for g in range(len(edges) - 1):
        if stable_now:
            intervals.append((edges[g], edges[g + 1]))
        stable_now = not stable_now
    return Scan(intervals, bounds, Ks, rho, lo, hi)


# ------------------------------------------------------------------ 50-digit referee
@functools.lru_cache(maxsize=64)
def _mp_plants(loop: Loop, dps: int):
    """Per port (a11, a12, a21, a22, b1, b2) of the ZOH at ``dps`` digits (mpmath.expm)."""
    out = []
    with mpmath.workdps(dps):
        T = mpmath.mpf(loop.period)
        for p in loop.ports:
            m, b, k = (mpmath.mpf(p.mass), mpmath.mpf(p.damping), mpmath.mpf(p.stiffness))
            M = mpmath.matrix([[0, 1, 0], [-k / m, -b / m, 1 / m], [0, 0, 0]]) * T
            E = mpmath.expm(M)
            out.append((E[0, 0], E[0, 1], E[1, 0], E[1, 1], E[0, 2], E[1, 2]))
    return tuple(out)


def char_fn(loop: Loop, K, z, dps: int = MP_DPS):
    """(g, g'/g) at z (g'/g None where g = 0): g(z) = det(zI - A(K)) / z^R (R registers; a factor (z - 1)
    divided out for the rigid mode), at ``dps`` digits, by the return difference
    det(zI - A_cl) = det(zI - A_ol) det(I + L(z)) with A_ol's blocks 2 x 2 plants
    and shift registers, cleared of the plants' denominators:
    M_ij = delta_ij d_j(z) + C_i(z) sum sign z^-delay n_j(z)."""
    assert not loop.extended, "the referee knows one position controller per port only"
    with mpmath.workdps(dps):
        z = mpmath.mpc(z)
        K = mpmath.mpf(K)
        T = mpmath.mpf(loop.period)
        pl = _mp_plants(loop, dps)
        d = [(z - a11) * (z - a22) - a12 * a21 for a11, a12, a21, a22, _, _ in pl]
        dd = [2 * z - a11 - a22 for a11, _, _, a22, _, _ in pl]
        nn = [(z - a22) * b1 + a12 * b2 for _, a12, _, a22, b1, b2 in pl]
        dn = [b1 for *_, b1, _ in pl]
        p = len(pl)
        M = [[d[i] if i == j else mpmath.mpc(0) for j in range(p)] for i in range(p)]
        Mp = [[dd[i] if i == j else mpmath.mpc(0) for j in range(p)] for i in range(p)]
        for i, c in enumerate(loop.controls):
            Bt = mpmath.mpf(c.damping) / T
            C = c.gain * K + Bt * (1 - 1 / z)
            Cp = Bt / z ** 2
            for j, s, dl in c.terms:
                zd = z ** (-dl)
                zdp = -dl * z ** (-dl - 1)
                M[i][j] += s * C * zd * nn[j]
                Mp[i][j] += s * (Cp * zd * nn[j] + C * zdp * nn[j] + C * zd * dn[j])
        if p == 1:
            g, gp = M[0][0], Mp[0][0]
        else:
            g = M[0][0] * M[1][1] - M[0][1] * M[1][0]
            gp = Mp[0][0] * M[1][1] + M[0][0] * Mp[1][1] - Mp[0][1] * M[1][0] - M[0][1] * Mp[1][0]
        if g == 0:
            return g, None   # z is a root exactly: no Newton ratio
        ratio = gp / g
        if loop.rigid:
            g, ratio = g / (z - 1), ratio - 1 / (z - 1)
        return g, ratio


def aberth(loop: Loop, K: float, z0, dps: int = MP_DPS, iters: int = 200):
    """Refine a set of approximate roots of det(zI - A(K)) at ``dps`` digits.

    Aberth iterations restricted to ``z0`` (nearby roots repel each other, far ones
    are in g already). Returns the refined roots, or None if they do not converge
    to distinct roots near the starting values.
    """
    with mpmath.workdps(dps + 10):
        z = [mpmath.mpc(complex(v)) for v in z0]
        tol = mpmath.mpf(10) ** (-dps)
        for _ in range(iters):
            w = []
            for i, zi in enumerate(z):
                if loop.rigid and zi == 1:   # on the divided-out rigid root: step off it
                    zi = z[i] = zi - mpmath.mpf(10) ** (-(dps // 2))
                _g, r = char_fn(loop, K, zi, dps + 10)
                if r is None:
                    w.append(mpmath.mpc(0))
                    continue
                N = 1 / r
                s = mpmath.fsum(1 / (zi - zk) for k, zk in enumerate(z) if k != i)
                w.append(N / (1 - N * s))
            z = [zi - wi for zi, wi in zip(z, w, strict=True)]
            if max(abs(wi) for wi in w) <= tol:
                break
        else:
            return None
        start = [complex(v) for v in z0]
        if any(abs(complex(zi) - s) > 1e-5 for zi, s in zip(z, start, strict=True)):
            return None
        if any(abs(z[i] - z[k]) < 1e-30 for i in range(len(z)) for k in range(i)):
            return None
        return z


@dataclass
class Verdict:
    """A refereed spectral radius.

    Attributes
    ----------
    rho : float
        Spectral radius (rigid mode excluded); refined at 50 digits where doubles
        cannot decide.
    stable : bool or None
        rho < 1, None when even the referee could not decide.
    how : str
        ``"double"`` or ``"mp"`` (which eigenvalues decided).
    rho_double : float
        The plain double-precision spectral radius.
    """

    rho: float
    stable: bool | None
    how: str
    rho_double: float


def robust(loop: Loop, K: float, dps: int = MP_DPS) -> Verdict:
    """Spectral radius at K with every eigenvalue near the circle decided for sure.

    An eigenvalue is decided in double precision when ||z| - 1| exceeds 100 times its
    rounding bound eps ||A||_F kappa (kappa = 1/|y^H x| with unit left/right
    eigenvectors; the factor 100 covers the constant of the backward error) and 1e-7
    (below that it is refined anyway: cheap, and guards against a poor kappa).
    The rest, with every eigenvalue within 1e-3 of them (so that a cluster is
    refined together), are refined by :func:`aberth` at ``dps`` digits.
    """
    A0, A1 = matrices(loop)
    A = A0 + K * A1
    ev, vl, vr = sla.eig(A, left=True, right=True)
    kappa = 1.0 / np.maximum(np.abs(np.sum(vl.conj() * vr, axis=0)), 1e-300)
    bound = 100 * _EPS * np.linalg.norm(A) * kappa
    a = np.abs(ev)
    rho_d = float(a.max())
    near = np.abs(a - 1.0) <= np.maximum(bound, 1e-7)
    if not near.any():
        return Verdict(rho_d, rho_d < 1.0, "double", rho_d)
    cl = near.copy()
    for z in ev[near]:
        cl |= np.abs(ev - z) < 1e-3
    if cl.sum() > 40:   # a huge cluster: leave it undecided rather than guess
        rest = a[~near]
        return Verdict(rho_d, False if rest.size and rest.max() > 1 else None, "undecided", rho_d)
    roots = aberth(loop, K, ev[cl], dps)
    far = a[~cl]
    if roots is None:
        if far.size and far.max() > 1.0:
            return Verdict(float(far.max()), False, "double", rho_d)
        return Verdict(rho_d, None, "undecided", rho_d)
    with mpmath.workdps(dps):
        mags = [abs(r) for r in roots]
        top = max(mags)
    rho = max(float(top), float(far.max()) if far.size else 0.0)
    # decide on the 50-digit magnitudes: float(top) can round to exactly 1.0
    if top > 1 or (far.size and far.max() > 1.0):
        stable = False
    elif top < 1:
        stable = True
    else:
        stable = None
    return Verdict(rho, stable, "mp", rho_d)


def char_poly_mp(loop: Loop, K, dps: int = 40) -> list:
    """Coefficients (highest first) of z^R g(z) = det(zI - A(K)) at ``dps`` digits
    (rigid factor (z - 1) kept), built from the 2 x 2 return difference by
    polynomial arithmetic, for an all-roots check with ``mpmath.polyroots``."""
    assert not loop.extended, "one position controller per port only"
    with mpmath.workdps(dps):
        pl = _mp_plants(loop, dps)
        T, K = mpmath.mpf(loop.period), mpmath.mpf(K)
        p = len(pl)
        # every entry times z^q, q = (max delay of its row) + 1: polynomials in z
        qs = [max(dl for _, _, dl in c.terms) + 1 for c in loop.controls]

        def padd(a, b):
            n = max(len(a), len(b))
            a = [mpmath.mpf(0)] * (n - len(a)) + list(a)
            b = [mpmath.mpf(0)] * (n - len(b)) + list(b)
            return [x + y for x, y in zip(a, b, strict=True)]

        def pmul(a, b):
            out = [mpmath.mpf(0)] * (len(a) + len(b) - 1)
            for i, x in enumerate(a):
                for j, y in enumerate(b):
                    out[i + j] += x * y
            return out

        M = [[[mpmath.mpf(0)] for _ in range(p)] for _ in range(p)]
        for i, c in enumerate(loop.controls):
            a11, a12, a21, a22, _, _ = pl[i]
            di = [mpmath.mpf(1), -(a11 + a22), a11 * a22 - a12 * a21]
            M[i][i] = padd(M[i][i], di + [mpmath.mpf(0)] * qs[i])     # d_i z^q
            Bt = mpmath.mpf(c.damping) / T
            Cz = [c.gain * K + Bt, -Bt]                              # z C(z)
            for j, s, dl in c.terms:
                _, a12j, _, a22j, b1, b2 = pl[j]
                nj = [b1, -a22j * b1 + a12j * b2]
                # C z^-dl n_j z^q = (z C) n_j z^(q - 1 - dl)
                term = pmul(pmul(Cz, nj), [mpmath.mpf(s)] + [mpmath.mpf(0)] * (qs[i] - 1 - dl))
                M[i][j] = padd(M[i][j], term)
        if p == 1:
            return M[0][0]
        return padd(pmul(M[0][0], M[1][1]), [-x for x in pmul(M[0][1], M[1][0])])
