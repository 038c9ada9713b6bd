"""Benchmark (issue 26): hapstab's certified K_max against the peers, side by side in one run.

For the paper's HVE (``hapstab.paper_hve(delay_samples=n)``) and PEB
(``hapstab.paper_peb(delay_samples=n)``), n in {0, 4, 10, 100, 1000, 10000}, medians of
CPU time (``time.process_time``: the machine is shared) over repeats:

- **naive**: the closed-loop matrix (written here: ZOH by ``scipy.linalg.expm``, shift
  registers), ``numpy.linalg.eigvals`` on a geometric scan of K (400 points, 1e-3...1e7
  N/m) up to the first unstable one, then bisection to 1e-10 relative. Skipped above
  250 states (each of its ~100 solves is O(N^3): minutes at n = 1000).
- **python-control** (``control``, the ``bench`` extra): ``c2d`` (ZOH) of each device,
  the delay as ``z^-n``, ``feedback``, ``poles()``, the same scan and bisection. The PEB
  is closed as a user would with transfer functions: the slave loop first, then the
  master's. Its K_max is compared with the truth and marked WRONG when off by > 1e-6.
- **expert** (uncertified, written here from scratch, not hapstab code): the delay as an
  exact phase e^{-j n theta}; on a vectorised theta grid (32 points per turn of the
  phase, and 40 geometric points below its first: the low-frequency crossings of
  fast-sampled loops) the characteristic function of the low-order ZOH plant polynomials and the
  controller K + B (1 - z^-1)/T; K real where Im(...) = 0 (HVE: linear in K; PEB: the
  resultant of the real and imaginary parts of a quadratic in K); sign changes, Newton
  refinement (derivative by central difference, kept in the bracket), the lowest
  positive crossing K. Checked against the naive method where both run.
- **hapstab**: ``critical_stiffness(loop)`` (whatever the core is today).

Also: ``critical_stiffness_many`` over 200 HVE loops (n = 10) against the expert
method vectorised over the loops; the explorer's verdict + K_max for PEB n = 4 (the
API in-process, starlette's TestClient, as the page asks); ``hapstab --version`` as a
process. Run: ``python benchmarks/bench_core.py`` (``--quick``: fewer repeats).
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import math
import resource
import statistics
import subprocess
import sys
import time
import warnings

import numpy as np
from scipy.linalg import expm

import hapstab as h

DELAYS = (0, 4, 10, 100, 1000, 10_000)
QUICK = "--quick" in sys.argv
NAIVE_MAX_STATES = 250
SCAN = np.geomspace(1e-3, 1e7, 400)
PAPER = {"hve": [(0.15, 0.1, 1.0)], "peb": [(0.015, 0.02, 1.0), (0.015, 0.02, 1.0)]}
T = 1e-3


def cpu(f, reps: int) -> tuple[float, object]:
    """(median CPU seconds, last value) of ``reps`` calls."""
    ts, v = [], None
    for _ in range(reps):
        t = time.process_time()
        v = f()
        ts.append(time.process_time() - t)
    return statistics.median(ts), v


# --------------------------------------------------------------------- the plant
def zoh(m: float, b: float, k: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    """(Ad, bd) of m x'' + b x' + k x = f, state [x, v], zero-order hold."""
    M = np.zeros((3, 3))
    M[:2, :2] = [[0.0, 1.0], [-k / m, -b / m]]
    M[1, 2] = 1.0 / m
    E = expm(M * T)
    return E[:2, :2], E[:2, 2]


def polys(m: float, b: float, k: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    """(d, n): x/f = n(z)/d(z) of the ZOH plant (coefficients, highest power first)."""
    A, bd = zoh(m, b, k, T)
    d = np.array([1.0, -(A[0, 0] + A[1, 1]), A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]])
    n = np.array([bd[0], -A[1, 1] * bd[0] + A[0, 1] * bd[1]])
    return d, n


# -------------------------------------------------------------------- the naive way
def closed_loop(ports, n: int, B: float, T: float):
    """A0, A1 with A(K) = A0 + K A1: plants [x, v] per port, then n + 1 registers of
    each position (x[k-1] ... x[k-n-1]); u_i = K e_i[k] + B/T (e_i[k] - e_i[k-1]) with
    e = x (HVE) or e_m = x_m - x_s[k-n], e_s = x_s - x_m[k-n] (PEB)."""
    p, R = len(ports), n + 1
    N = 2 * p + p * R
    A0, A1 = np.zeros((N, N)), np.zeros((N, N))
    reg = lambda j, d: 2 * p + j * R + d - 1   # noqa: E731  x_j[k-d], d >= 1

    def x(j: int, d: int) -> np.ndarray:
        r = np.zeros(N)
        r[2 * j if d == 0 else reg(j, d)] = 1.0
        return r

    for j in range(p):
        A0[reg(j, 1), 2 * j] = 1.0
        for d in range(2, R + 1):
            A0[reg(j, d), reg(j, d - 1)] = 1.0
    for i, (m, b, k) in enumerate(ports):
        Ad, bd = zoh(m, b, k, T)
        terms = [(i, 1.0, 0)] if p == 1 and n == 0 else [(i, 1.0, n)] if p == 1 else \
            [(i, 1.0, 0), (1 - i, -1.0, n)]
        e0 = sum(s * x(j, d) for j, s, d in terms)
        e1 = sum(s * x(j, d + 1) for j, s, d in terms)
        A0[2 * i:2 * i + 2, 2 * i:2 * i + 2] += Ad
        A0[2 * i:2 * i + 2] -= np.outer(bd, B / T * (e0 - e1))
        A1[2 * i:2 * i + 2] -= np.outer(bd, e0)
    return A0, A1


def bisect_scan(stable, rtol: float = 1e-10) -> float:
    """First K of the scan where ``stable`` fails, bisected (0 / inf at the ends)."""
    prev = 0.0
    for K in SCAN:
        if not stable(K):
            lo, hi = prev, K
            if lo == 0:
                return 0.0
            while hi / lo - 1 > rtol:
                mid = math.sqrt(lo * hi)
                lo, hi = (mid, hi) if stable(mid) else (lo, mid)
            return lo
        prev = K
    return math.inf


def naive_kmax(ports, n: int, B: float, T: float) -> float:
    A0, A1 = closed_loop(ports, n, B, T)
    return bisect_scan(lambda K: np.abs(np.linalg.eigvals(A0 + K * A1)).max() < 1.0)


# ---------------------------------------------------------------- python-control
def control_kmax(ports, n: int, B: float, T: float) -> float:
    import control as ct

    G = [ct.c2d(ct.tf([1.0], [m, b, k]), T, "zoh") for m, b, k in ports]
    D = ct.tf([1.0], [1.0] + [0.0] * n, T)

    def rho(K: float) -> float:
        C = ct.tf([K + B / T, -B / T], [1.0, 0.0], T)
        if len(G) == 1:
            cl = ct.feedback(G[0], C * D)
        else:      # slave loop closed first, seen by the master through both delays
            slave = ct.feedback(G[1] * C, 1)            # x_s / x_m[k-n]
            cl = ct.feedback(G[0], C * (1 - D * D * slave))
        return float(np.abs(cl.poles()).max())

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return bisect_scan(lambda K: rho(K) < 1.0)


# ------------------------------------------------------------ the expert's method
def _char(ports, n: int, B: float, T: float, th: np.ndarray):
    """(c0, c1, c2) of the characteristic function c0 + c1 K + c2 K^2 on z = e^{j th}
    (divided by the plants' n(z)): HVE d/n + e^{-jn th} beta + K e^{-jn th};
    PEB (P_m + C)(P_s + C) - C^2 e^{-2jn th}, C = K + beta, beta = B (1 - 1/z)/T."""
    z = np.exp(1j * th)
    ph = np.exp(-1j * n * th)
    beta = B * (1.0 - 1.0 / z) / T
    P = [np.polyval(d, z) / np.polyval(nn, z) for d, nn in (polys(*pt, T) for pt in ports)]
    if len(P) == 1:
        return P[0] + ph * beta, ph, 0 * z
    w = ph * ph
    p, q = P[0] + beta, P[1] + beta
    return p * q - w * beta * beta, p + q - 2 * w * beta, 1 - w


def _F(c0, c1, c2, quad: bool):
    """(F(theta), K): F = 0 where a real K solves the characteristic equation."""
    if not quad:
        r = -c0 / c1
        return r.imag, r.real
    Ar, Ai, Br, Bi, Cr, Ci = c2.real, c2.imag, c1.real, c1.imag, c0.real, c0.imag
    u, v, w = Ar * Ci - Ai * Cr, Ar * Bi - Ai * Br, Br * Ci - Bi * Cr
    with np.errstate(all="ignore"):
        return u * u - v * w, -u / v


def theta_grid(m: int) -> np.ndarray:
    """m midpoints of [0, pi] and 40 geometric points below the first (down to 1e-12 of
    it): a fast-sampled loop's lowest crossing can lie far below pi / m (theta = 2 pi f T:
    1.5 Hz at T = 0.19 ms is theta = 1.8e-3, under the first midpoint at n = 10)."""
    first = 0.5 * math.pi / m
    return np.concatenate([np.geomspace(1e-12 * first, first, 41)[:-1],
                           (np.arange(m) + 0.5) * (math.pi / m)])


def expert_kmax(ports, n: int, B: float, T: float) -> float:
    quad = len(ports) == 2 and n > 0
    m = 32 * 2 * (n + 2) * (2 if quad else 1)
    th = theta_grid(m)
    F, _ = _F(*_char(ports, n, B, T, th), quad)
    i = np.flatnonzero(np.sign(F[1:]) * np.sign(F[:-1]) < 0)
    a, b = th[i], th[i + 1]
    fa = F[i]
    x = 0.5 * (a + b)
    for _ in range(30):                      # Newton, kept in the bracket
        hstep = 1e-7 * (b - a) + 1e-13
        f, _ = _F(*_char(ports, n, B, T, x), quad)
        df = (_F(*_char(ports, n, B, T, x + hstep), quad)[0]
              - _F(*_char(ports, n, B, T, x - hstep), quad)[0]) / (2 * hstep)
        left = np.sign(f) == np.sign(fa)
        a, b, fa = np.where(left, x, a), np.where(left, b, x), np.where(left, f, fa)
        with np.errstate(all="ignore"):
            nx = x - f / df
        bad = ~((nx > a) & (nx < b))
        nx[bad] = 0.5 * (a[bad] + b[bad])
        if np.all(np.abs(nx - x) <= 1e-15 * np.maximum(np.abs(x), 1e-300)):
            x = nx
            break
        x = nx
    c0, c1, c2 = _char(ports, n, B, T, x)
    _, K = _F(c0, c1, c2, quad)
    # the resultant also vanishes where c2 = 1 - w = 0 (theta = k pi / n) with no common
    # root: keep only sign changes where the characteristic function itself vanishes
    # (a refined root leaves ~1e-12 of its terms; a spurious one is of their order)
    with np.errstate(all="ignore"):
        res = np.abs(c0 + c1 * K + c2 * K * K) / (np.abs(c0) + np.abs(c1 * K)
                                                  + np.abs(c2) * K * K)
    K = K[np.isfinite(res) & (res < 1e-6)]
    ends = []
    for t in (0.0, math.pi):                 # z = +-1: real polynomials in K
        c0, c1, c2 = (complex(c).real for c in _char(ports, n, B, T, np.array(t)))
        ends += [r.real for r in np.roots([c2, c1, c0] if c2 else [c1, c0]) if r.imag == 0]
    Ks = [k for k in [*K, *ends] if k > 0 and math.isfinite(k)]
    return min(Ks) if Ks else math.inf


def expert_many_hve(params, n: int) -> np.ndarray:
    """The expert's K_max of many HVE loops at once: one (loops x theta) array."""
    m = 32 * 2 * (n + 2)
    th = theta_grid(m)
    z = np.exp(1j * th)[None, :]
    ph = np.exp(-1j * n * th)[None, :]
    dn = [polys(mm, b, k, T_) for mm, b, k, T_, _ in params]
    d = np.array([x[0] for x in dn])[:, :, None]
    nn = np.array([x[1] for x in dn])[:, :, None]
    B = np.array([p[4] for p in params])[:, None]
    Ts = np.array([p[3] for p in params])[:, None]

    def F(zz, pp):
        P = (zz * zz + d[:, 1] * zz + d[:, 2]) / (nn[:, 0] * zz + nn[:, 1])
        r = -(P + pp * B * (1 - 1 / zz) / Ts) / pp
        return r.imag, r.real

    f, _ = F(z, ph)
    out = np.full(len(params), math.inf)
    rows, cols = np.nonzero(np.sign(f[:, 1:]) * np.sign(f[:, :-1]) < 0)
    a, b = th[cols], th[cols + 1]
    fa = f[rows, cols]
    sub = lambda t: (np.exp(1j * t)[:, None], np.exp(-1j * n * t)[:, None])  # noqa: E731
    for _ in range(60):                      # bisection of every bracket of every loop
        mid = 0.5 * (a + b)
        zz, pp = sub(mid)
        P = (zz * zz + d[rows, 1] * zz + d[rows, 2]) / (nn[rows, 0] * zz + nn[rows, 1])
        fm = (-(P + pp * B[rows] * (1 - 1 / zz) / Ts[rows]) / pp).imag[:, 0]
        left = np.sign(fm) == np.sign(fa)
        a, b, fa = np.where(left, mid, a), np.where(left, b, mid), np.where(left, fm, fa)
    zz, pp = sub(0.5 * (a + b))
    P = (zz * zz + d[rows, 1] * zz + d[rows, 2]) / (nn[rows, 0] * zz + nn[rows, 1])
    K = (-(P + pp * B[rows] * (1 - 1 / zz) / Ts[rows]) / pp).real[:, 0]
    ok = K > 0
    np.minimum.at(out, rows[ok], K[ok])
    return out


# ----------------------------------------------------------------------- the rows
def row(kind: str, n: int) -> dict:
    ports = PAPER[kind]
    make = h.paper_hve if kind == "hve" else h.paper_peb
    reps = 3 if QUICK or n >= 1000 else 7
    r: dict = {"kind": kind, "n": n}
    r["t_expert"], r["K_expert"] = cpu(lambda: expert_kmax(ports, n, 0.0, T), reps)
    try:
        r["t_hapstab"], res = cpu(lambda: h.critical_stiffness(make(delay_samples=n)), reps)
        r["K_hapstab"] = res.critical_stiffness
    except h.HapstabError as e:
        r["t_hapstab"], r["K_hapstab"], r["hapstab_note"] = math.nan, math.nan, str(e)[:60]
    states = len(ports) * (n + 3)
    if states <= NAIVE_MAX_STATES:
        r["t_naive"], r["K_naive"] = cpu(lambda: naive_kmax(ports, n, 0.0, T),
                                         1 if n >= 100 else 3)
    else:
        r["t_naive"], r["K_naive"] = math.nan, math.nan
        r["naive_note"] = f"skipped: {states} states"
    try:
        if n > 1000:
            raise RuntimeError("skipped: a degree-10^4 polynomial per K")
        r["t_control"], r["K_control"] = cpu(lambda: control_kmax(ports, n, 0.0, T), 1)
    except (ImportError, RuntimeError) as e:
        r["t_control"], r["K_control"], r["control_note"] = math.nan, math.nan, str(e)[:40]
    except Exception as e:     # python-control fails on the loop: say how (WRONG too)
        r["t_control"], r["K_control"] = math.nan, math.nan
        r["control_note"] = f"control FAILED: {type(e).__name__}: {str(e)[:40]}"
    return r


def fmt_t(t: float) -> str:
    return "   -    " if not math.isfinite(t) else f"{t * 1e3:8.1f}"


def batched() -> str:
    rng = np.random.default_rng(26)
    params = [(float(10 ** rng.uniform(-1.3, -0.3)), float(10 ** rng.uniform(-2, 0)),
               float(10 ** rng.uniform(-1, 2)), float(1 / 10 ** rng.uniform(2.7, 4)), 0.0)
              for _ in range(200)]
    loops = [h.HapticLoop(h.Device(m, b), h.SpringDamper(1.0, B), h.spring(k), T_, 10)
             for m, b, k, T_, B in params]
    t_h, res = cpu(lambda: h.critical_stiffness_many(loops), 1 if QUICK else 3)
    t_e, Ke = cpu(lambda: expert_many_hve(params, 10), 3)
    Kh = np.array([r.critical_stiffness for r in res])
    err = float(np.nanmax(np.abs(Kh / Ke - 1)))
    return (f"critical_stiffness_many, 200 HVE loops (n = 10): {t_h * 1e3:.0f} ms; expert "
            f"vectorised over loops {t_e * 1e3:.0f} ms; ratio {t_h / t_e:.1f}x "
            f"(largest K difference {err:.1e})")


def explorer() -> str:
    try:
        from starlette.testclient import TestClient

        from hapstab.explorer.app import create_app
    except ImportError as e:
        return f"explorer: skipped ({e})"
    model = {"delay": 4, "virtual-damping": 0.5}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with TestClient(create_app(), base_url="http://127.0.0.1") as c:
            def change() -> None:
                for cmd, opts in (("check", {**model, "stiffness": 5.0}), ("kmax", model)):
                    assert c.post(f"/api/v1/{cmd}", json={"kind": "peb", "options": opts}
                                  ).status_code == 200
            change()
            wall = []
            for _ in range(5 if QUICK else 15):
                t = time.perf_counter()
                change()
                wall.append(time.perf_counter() - t)
    return (f"explorer, PEB n = 4: verdict + K_max per change {statistics.median(wall) * 1e3:.0f}"
            " ms wall (the API in-process, computing in its worker processes; target < 50 ms)")


def version() -> str:
    wall, cpu_t = [], []
    for _ in range(5):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        subprocess.run([sys.executable, "-m", "hapstab", "--version"], check=True,
                       capture_output=True)
        wall.append(time.perf_counter() - t)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu_t.append(r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime)
    return (f"`python -m hapstab --version`: {statistics.median(wall) * 1e3:.0f} ms wall, "
            f"{statistics.median(cpu_t) * 1e3:.0f} ms CPU (target < 300 ms)")


def main() -> None:
    print("K_max of the paper's loops, T = 1 ms, B = 0: CPU ms (medians); ratios to the expert")
    print(f"{'loop':>4} {'n':>6} {'expert':>8} {'hapstab':>8} {'x exp':>6} {'naive':>8} "
          f"{'x exp':>6} {'control':>8}  K hapstab / expert / naive / control")
    for kind in ("hve", "peb"):
        for n in DELAYS:
            r = row(kind, n)
            te = r["t_expert"]
            Kc = r["K_control"]
            ref = r["K_naive"] if math.isfinite(r["K_naive"]) else r["K_expert"]
            wrong = math.isfinite(Kc) and abs(Kc / ref - 1) > 1e-6
            notes = "; ".join(r[k] for k in ("hapstab_note", "naive_note", "control_note") if k in r)
            print(f"{kind:>4} {n:>6} {fmt_t(te)} {fmt_t(r['t_hapstab'])} "
                  f"{r['t_hapstab'] / te:6.1f} {fmt_t(r['t_naive'])} {r['t_naive'] / te:6.1f} "
                  f"{fmt_t(r['t_control'])}  {r['K_hapstab']:.12g} / {r['K_expert']:.12g} / "
                  f"{r['K_naive']:.12g} / {Kc:.6g}{' WRONG' if wrong else ''}"
                  f"{'  (' + notes + ')' if notes else ''}", flush=True)
    print(batched(), flush=True)
    print(explorer(), flush=True)
    print(version())


if __name__ == "__main__":
    main()
