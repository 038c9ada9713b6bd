"""Robust K_max over a box of operators (issue 14, item 3): the certified lower bound
is never above the exact K_max of any operator of the box, equals the exact K_max of
the operator it names, finds minima that are not at a vertex; the ball enclosures of
the port polynomials contain the floating-point ones and 50-digit ones computed
here from scratch (mpmath), and their derivatives contain 50-digit finite differences.

References: the exact core (``exact_critical_stiffness``, itself checked against the
brute force), the independent brute-force closed loop (tests/references/brute.py:
``scipy.signal.cont2discrete``, eigenvalues), mpmath at 50 digits.
"""

from __future__ import annotations

import math
import os

import mpmath
import numpy as np
import pytest

import hapstab as h
from hapstab.analysis.exact.core import exact_critical_stiffness
from hapstab.analysis.exact.crossings import analyse
from hapstab.engine.balls import Ball, ball_expm
from hapstab.engine.frequency import loop_response, port_polynomials, stack_responses
from hapstab.engine.operator_family import box_port_polynomials
from hapstab.errors import AnalysisError, ModelError
from lanes import costly
from references import brute

DPS = 50


def _exact(loop, p, certify=True):
    return exact_critical_stiffness(loop.replace(operator=h.mass_spring_damper(*p)),
                                    certify=certify).critical_stiffness


def _exact_many(loop, P):
    """The exact core's K_max of many operators in one batch (its own responses,
    stacked; none of the robust code): the float search (certify=False), 1125 proofs
    would cost ~30 s."""
    resps = [loop_response(loop.replace(operator=h.mass_spring_damper(*p))) for p in P]
    return np.array([r.kmax for r in analyse(stack_responses(resps), full=False)])


def _samples(box, n, rng, grid=5):
    lo, hi = box.lo, box.hi
    pts = lo + rng.random((n, 3)) * (hi - lo)
    axes = [np.linspace(a, b, grid if b > a else 1) for a, b in zip(lo, hi, strict=True)]
    return np.vstack([pts, np.array(np.meshgrid(*axes, indexing="ij")).reshape(3, -1).T])


# ------------------------------------------------------------------ ball arithmetic
def test_ball_expm_contains_scipy_and_mpmath():
    from scipy.linalg import expm

    rng = np.random.default_rng(5)
    for _ in range(6):
        n = rng.integers(2, 5)
        m = rng.normal(size=(n, n)) * rng.choice([0.1, 1.0, 6.0])
        r = np.abs(m) * rng.choice([0.0, 1e-6, 1e-2])
        E = ball_expm(Ball(m[None], r[None]))
        for _ in range(4):
            A = m + r * rng.uniform(-1, 1, size=m.shape)
            ref = mpmath.expm(mpmath.matrix(A.tolist()))
            exact = np.array(ref.tolist(), dtype=float)
            assert np.all(np.abs(exact - E.m[0]) <= E.r[0])            # 50 digits: strictly in
            # scipy's own rounding (a few unit round-offs of the largest entry)
            slack = 1e-13 * np.abs(exact).max()  # tolerance: scipy's expm rounding
            assert np.all(np.abs(expm(A) - E.m[0]) <= E.r[0] + slack)
        if not r.any():        # a point: the radius is rounding only, grown by the squarings
            assert np.all(E.r[0] <= 1e-10 * np.abs(E.m[0]).max())  # tolerance: ~20 squarings


def _mp_port(md, bd, m, b, k, T, f):
    """d, N, Nt^f, D^f of the port (state [x, v]) at 50 digits, from the definitions:
    E = e^(AT) - I, Gamma = int_0^T e^(As) ds B, d(y) = det(yI - E),
    N(y) = [adj(yI - E) Gamma]_0, Nt(y) = C Gamma_(1-f) d(y) + C Phi_(1-f) adj(yI - E) Gamma,
    D = (Nt - (1 + y) N) / y. Ascending in y."""
    mp = mpmath.mp
    M = mp.mpf(md) + mp.mpf(m)
    A = mpmath.matrix([[0, 1], [-mp.mpf(k) / M, -(mp.mpf(bd) + mp.mpf(b)) / M]])
    B = mpmath.matrix([[0], [1 / M]])

    def zoh(t):
        aug = mpmath.matrix(4, 4)
        for i in range(2):
            for j in range(2):
                aug[i, j] = A[i, j] * t
            aug[i, i + 2] = t
        X = mpmath.expm(aug)
        Phi = mpmath.matrix([[X[0, 0], X[0, 1]], [X[1, 0], X[1, 1]]])
        S = mpmath.matrix([[X[0, 2], X[0, 3]], [X[1, 2], X[1, 3]]])
        return Phi, S

    Phi, S = zoh(mp.mpf(T))
    E = Phi - mpmath.eye(2)
    G = S * B
    d = [E[0, 0] * E[1, 1] - E[0, 1] * E[1, 0], -(E[0, 0] + E[1, 1]), 1]
    # adj(yI - E) = [[y - E11, E01], [E10, y - E00]]: row 0 times Gamma
    N = [E[0, 1] * G[1] - E[1, 1] * G[0], G[0]]
    Phf, Sf = zoh((1 - mp.mpf(f)) * mp.mpf(T))
    Gf = (Sf * B)[0]
    c0, c1 = Phf[0, 0], Phf[0, 1]
    # c_phi adj(yI - E) Gamma = y (c0 G0 + c1 G1) + c0 (E01 G1 - E11 G0) + c1 (E10 G0 - E00 G1)
    part = [c0 * (E[0, 1] * G[1] - E[1, 1] * G[0]) + c1 * (E[1, 0] * G[0] - E[0, 0] * G[1]),
            c0 * G[0] + c1 * G[1]]
    Nt = [Gf * d[0] + part[0], Gf * d[1] + part[1], Gf * d[2]]
    onepy = [N[0], N[0] + N[1], N[1]]
    D = [Nt[1] - onepy[1], Nt[2] - onepy[2]]
    return {"d": d, "N": N, f"Nt{f}": Nt, f"D{f}": D}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_port_enclosures_contain_float_and_50_digits(seed):
    rng = np.random.default_rng(seed)
    md, bd = rng.uniform(0.01, 1.0), rng.uniform(0.0, 2.0)
    T = rng.choice([1e-4, 1e-3, 4e-3])
    f = float(rng.choice([0.25, 0.5]))
    c = np.array([rng.uniform(0.05, 2.0), rng.uniform(0.5, 20.0), rng.uniform(10.0, 2000.0)])
    w = rng.uniform(0.01, 0.3)
    lo, hi = c * (1 - w), c * (1 + w)
    bp = box_port_polynomials(md, bd, lo[None], hi[None], T, [f])
    mpmath.mp.dps = DPS
    for _ in range(6):
        p = lo + rng.random(3) * (hi - lo)
        ref = _mp_port(md, bd, *p, T, f)
        M = md + p[0]
        A = np.array([[0.0, 1.0], [-p[2] / M, -(bd + p[1]) / M]])
        flo = port_polynomials(A, np.array([[0.0], [1.0 / M]]), False, np.array([T]), [f])
        fl = {"d": flo.d, "N": flo.N, f"Nt{f}": flo.Nt[f], f"D{f}": flo.D[f]}
        for name, coefs in ref.items():
            exact = np.array([float(x) for x in coefs])
            mid, rad = bp.mid[name][0], bp.rad[name][0]
            assert np.all(np.abs(exact - mid) <= rad), (name, exact, mid, rad)
            # the float pipeline's own coefficients, within the ball plus their error bound
            err = flo.err[name][0]
            assert np.all(np.abs(fl[name][0] - mid) <= rad + err), name
    # derivatives: central differences at 50 digits lie in the derivative balls
    p = lo + rng.random(3) * (hi - lo)
    for j in range(3):
        step = [0.0, 0.0, 0.0]
        step[j] = mpmath.mpf(10) ** -20 * max(1.0, p[j])
        plus = _mp_port(md, bd, *[mpmath.mpf(x) + s for x, s in zip(p, step, strict=True)], T, f)
        minus = _mp_port(md, bd, *[mpmath.mpf(x) - s for x, s in zip(p, step, strict=True)], T, f)
        for name in plus:
            fd = np.array([float((a - b) / (2 * step[j])) for a, b in
                           zip(plus[name], minus[name], strict=True)])
            mid, rad = bp.dmid[name][j, 0], bp.drad[name][j, 0]
            # the difference quotient's error (h^2 third derivatives, 1e-40 relative)
            assert np.all(np.abs(fd - mid) <= rad + 1e-25 * np.abs(fd)), (name, j)  # tolerance: h^2


# ------------------------------------------------------------------ the acceptance
HVE = h.HapticLoop(h.Device(0.3, 0.5), h.SpringDamper(0.0, 0.0), period=1e-3, delay_samples=20)
BOX = h.operator_box(mass=(0.45, 0.55), damping=(4.5, 5.5), stiffness=(450.0, 550.0))


#: the tests that share `hve_result` run on one xdist worker (--dist loadgroup), so the
#: module fixture (3 s) is computed once, not once per worker
SHARES_HVE_RESULT = pytest.mark.xdist_group("robust-hve-result")


@pytest.fixture(scope="module")
def hve_result():
    return h.robust_critical_stiffness(HVE, BOX)


@SHARES_HVE_RESULT
def test_robust_kmax_is_below_every_operator_and_equals_the_named_one(hve_result):
    r = hve_result
    assert r.converged and r.rtol == 1e-6
    rng = np.random.default_rng(14)
    pts = _samples(BOX, 1000, rng)                         # 1000 random and a 5^3 grid
    K = _exact_many(HVE, pts)
    assert K[0] == _exact(HVE, pts[0], certify=False)       # the batch is the float core's
    assert r.critical_stiffness <= _exact(HVE, pts[0])      # and below the proved one
    assert np.all(r.critical_stiffness <= K), K.min()
    named = _exact(HVE, r.operator)
    assert r.operator_critical_stiffness == named
    assert r.critical_stiffness <= named <= r.upper_bound
    assert named - r.critical_stiffness <= 1e-6 * named           # rtol, the default
    assert K.min() >= named * (1 - 1e-6)                           # no sample below it
    # the independent brute force: every sampled operator is stable just below the
    # bound, and the named one is unstable just above its K_max
    for p in pts[:: 40]:
        loop = brute.hve_loop(0.3, 0.5, 1e-3, 20, 0.0, ("msd", *p))
        assert brute.radius(loop, r.critical_stiffness * (1 - 1e-6))[0] < 1
    loop = brute.hve_loop(0.3, 0.5, 1e-3, 20, 0.0, ("msd", *r.operator))
    assert brute.radius(loop, named * (1 + 1e-5))[0] > 1 > brute.radius(loop, named * (1 - 1e-5))[0]


# the default lane: a +-4 % box (51 sub-boxes, 2.7 s of CPU), the same question (all three
# parameters varied, the worst at a vertex, sampled and named against the exact core) as
# the +-10 % BOX (214 sub-boxes, 7.8 s), which runs -m campaign
NARROW = h.operator_box(mass=(0.48, 0.52), damping=(4.8, 5.2), stiffness=(480.0, 520.0))


@pytest.mark.parametrize("box", [pytest.param(NARROW, id="narrow"), costly(BOX, id="box")])
def test_peb_operator_box_at_the_master(box):
    loop = h.TeleoperationLoop(h.Device(0.3, 0.5), h.Device(0.3, 0.5), h.SpringDamper(0, 0),
                               h.SpringDamper(0, 0), operator=h.spring(1.0),
                               environment=h.spring(1000.0), period=1e-3, delay_samples=2)
    r = h.robust_critical_stiffness(loop, box)
    assert r.converged
    rng = np.random.default_rng(3)
    K = _exact_many(loop, _samples(box, 300, rng, grid=3))
    assert np.all(r.critical_stiffness <= K)
    assert abs(_exact(loop, r.operator) - r.critical_stiffness) <= 1e-6 * r.critical_stiffness


# ------------------------------------------------------------------ not at a vertex
def test_minimum_inside_the_box_not_at_a_vertex():
    # the README's non-monotone case: a 10 g device on a stiff operator, n = 6; K_max
    # over the operator's stiffness dips where the resonance meets the delay's phase
    loop = h.HapticLoop(h.Device(0.01, 0.0251), h.SpringDamper(0.0, 0.0), period=4.52e-3,
                        delay_samples=6)
    box = h.operator_box(mass=0.0, damping=(0.15, 0.25), stiffness=(600.0, 760.0))
    r = h.robust_critical_stiffness(loop, box)
    assert r.converged
    _, b, k_star = r.operator
    assert b == 0.15 and 610 < k_star < 750               # on an edge, inside it: no vertex
    assert r.vertex_minimum > 1.05 * r.critical_stiffness          # vertices alone: 5 % high
    assert "not at a vertex" in r.reason
    rng = np.random.default_rng(6)
    pts = _samples(box, 400, rng, grid=9)
    K = _exact_many(loop, pts)
    assert np.all(r.critical_stiffness <= K)
    assert K.min() >= r.operator_critical_stiffness * (1 - 1e-6)
    ref = brute.kmax(brute.hve(0.01, 0.0251 + b, (k_star,), (1, 0), 6, 0.0, 4.52e-3))
    assert ref == pytest.approx(r.critical_stiffness, rel=1e-6)


# ------------------------------------------------------------------ edges
def test_a_zero_width_box_is_the_exact_kmax():
    p = (0.5, 5.0, 500.0)
    r = h.robust_critical_stiffness(HVE, h.operator_box(mass=p[0], damping=p[1], stiffness=p[2]))
    exact = _exact(HVE, p)
    assert r.converged and r.boxes == 1 and r.operator == p
    assert r.critical_stiffness <= exact <= r.upper_bound
    assert r.critical_stiffness == pytest.approx(exact, rel=1e-10)   # tolerance: the enclosure


def test_unstable_and_budget_cases():
    # a budget of one sub-box: not converged, the gap reported, still a lower bound
    box = h.operator_box(mass=(0.3, 0.7), damping=(3.0, 7.0), stiffness=(300.0, 700.0))
    r = h.robust_critical_stiffness(HVE, box, max_boxes=1)
    assert not r.converged and r.boxes == 1 and "budget" in r.reason
    assert r.critical_stiffness <= _exact(HVE, r.operator) <= r.upper_bound
    # negative virtual damping beyond what the device has: K_max = 0 for every operator
    neg = HVE.replace(controller=h.SpringDamper(0.0, -5.0))
    r0 = h.robust_critical_stiffness(neg, h.operator_box(mass=0.5, damping=(0.0, 0.1),
                                                         stiffness=500.0))
    assert r0.critical_stiffness == 0.0 and r0.upper_bound == 0.0 and r0.converged


def test_errors_name_the_parameter():
    with pytest.raises(ModelError, match=r"operator mass = \(2, 1\) kg: the lower end"):
        h.operator_box(mass=(2.0, 1.0), damping=1.0, stiffness=1.0)
    with pytest.raises(ModelError, match="operator stiffness"):
        h.operator_box(mass=1.0, damping=1.0, stiffness=(-1.0, 1.0))
    with pytest.raises(ModelError, match="unknown preset; allowed: arm-grasp"):
        h.operator_box("hand")
    with pytest.raises(ModelError, match="damping not given"):
        h.operator_box(mass=1.0, stiffness=1.0)
    with pytest.raises(h.HapstabError, match=r"rtol = 0\.0: must be > 0"):
        h.robust_critical_stiffness(HVE, BOX, rtol=0.0)
    with pytest.raises(AnalysisError, match="max_boxes"):
        h.robust_critical_stiffness(HVE, BOX, max_boxes=0)
    fc = h.FourChannelLoop(h.Device(0.3, 0.5), h.Device(0.3, 0.5), h.SpringDamper(0, 0),
                           h.SpringDamper(0, 0), h.spring(1), h.spring(100))
    with pytest.raises(AnalysisError, match="HVE and PEB"):
        h.robust_critical_stiffness(fc, BOX)
    free = h.TeleoperationLoop(h.Device(0.3, 0.5), h.Device(0.3, 0.5), h.SpringDamper(0, 0),
                               h.SpringDamper(0, 0))
    with pytest.raises(AnalysisError, match="free slave"):
        h.robust_critical_stiffness(free, h.operator_box(mass=0.5, damping=5.0,
                                                         stiffness=(0.0, 100.0)))
    with pytest.raises(ModelError, match="outside the box"):
        BOX.operator(1.0, 5.0, 500.0)


def test_preset_is_the_cited_measurement():
    box = h.operator_box("arm-grasp")
    # van Beek et al. 2015, Fig. 3: M = 0.554 kg, B = 6.45 N s/m, K = 135 N/m; the
    # preset spans a factor of 2 either side
    assert box.mass == (0.554 / 2, 0.554 * 2) and box.damping == (6.45 / 2, 6.45 * 2)
    assert box.stiffness == (67.5, 270.0)
    for words in ("van Beek", "18004", "M = 0.554 kg", "B = 6.45 N s/m", "K = 135 N/m",
                  "not a published range"):
        assert words in box.source
    doc = h.operator_box.__doc__
    assert "van Beek" in doc and "0.554" in doc
    assert h.operator_box("arm-grasp", stiffness=(100, 200)).stiffness == (100.0, 200.0)


# ------------------------------------------------------------------ best damping
def test_robust_best_damping_names_an_operator_it_fails():
    loop = h.HapticLoop(h.Device(0.3, 0.5), h.SpringDamper(0.0, 0.0),
                        operator=h.mass_spring_damper(0.5, 5.0, 500.0), period=1e-3,
                        delay_samples=4)
    box = h.operator_box(mass=(0.45, 0.55), damping=(4.0, 5.0), stiffness=(450.0, 550.0))
    r = h.robust_best_damping(loop, box, resolution=12, B_min=0.0)
    n = r.nominal
    assert n.damping > 0 and n.critical_stiffness > 0
    if not r.stable_for_all:
        assert "loses stability for other operators" in r.reason
        worst = r.robust.operator
        K = _exact(with_B(loop, n.damping), worst)
        assert K < n.critical_stiffness and K == pytest.approx(r.robust.operator_critical_stiffness)
    d = r.to_dict()
    assert d["robust_critical_stiffness"] <= n.critical_stiffness or r.stable_for_all
    assert d["stable_for_every_operator"] == r.stable_for_all


def with_B(loop, B):
    return loop.replace(controller=h.SpringDamper(0.0, B))


# ------------------------------------------------------------------ the result
@SHARES_HVE_RESULT
def test_result_protocol(hve_result, tmp_path):
    import json

    r = hve_result
    d = r.to_dict()
    json.dumps(d, allow_nan=False)
    assert d["operator"]["stiffness_N_per_m"] == r.operator[2]
    assert d["operator_box"]["label"] == "custom" and d["converged"] is True
    assert "<table>" in r._repr_html_()
    r.to_csv(tmp_path / "r.csv")
    lines = (tmp_path / "r.csv").read_text().splitlines()
    assert lines[0].startswith("mass_kg,damping_N_s_per_m,stiffness_N_per_m,critical_stiffness")
    import matplotlib
    matplotlib.use("Agg")
    ax = r.plot(resolution=3)
    assert ax.get_xlabel().startswith("operator")


# ------------------------------------------------------------------ campaign
def _campaign(n, seed):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        md, bd = rng.uniform(0.05, 1.0), rng.uniform(0.05, 2.0)
        T = float(rng.choice([5e-4, 1e-3, 2e-3]))
        delay = float(rng.choice([0, 1, 3, 7.5, 15]))
        c = np.array([rng.uniform(0.1, 1.5), rng.uniform(1.0, 15.0), rng.uniform(50.0, 800.0)])
        w = rng.uniform(0.01, 0.08, 3) * (rng.random(3) < 0.8)
        box = h.operator_box(mass=(c[0] * (1 - w[0]), c[0] * (1 + w[0])),
                             damping=(c[1] * (1 - w[1]), c[1] * (1 + w[1])),
                             stiffness=(c[2] * (1 - w[2]), c[2] * (1 + w[2])))
        n_, frac = int(delay), delay - int(delay)
        loop = h.HapticLoop(h.Device(md, bd), h.SpringDamper(0.0, 0.0), period=T,
                            delay_samples=n_, fractional_delay=frac)
        yield loop, box, rng


@pytest.mark.parametrize("seed", [21, costly(22, id="22")])   # 22: 6.6 s of CPU, -m campaign
def test_campaign_fast(seed):
    _check_campaign(1, seed, max_boxes=150)


@pytest.mark.slow
def test_campaign_full():
    _check_campaign(int(os.environ.get("HAPSTAB_ROBUST_CAMPAIGN", "30")), 2026)


def _check_campaign(n, seed, max_boxes=400):
    """Soundness on every scenario (the bound is below every sampled operator's exact
    K_max, converged or not); equality with the named operator where converged."""
    for loop, box, rng in _campaign(n, seed):
        r = h.robust_critical_stiffness(loop, box, rtol=1e-4, max_boxes=max_boxes)
        pts = _samples(box, 200, rng, grid=3)
        K = _exact_many(loop, pts)
        assert np.all(r.critical_stiffness <= K), (loop, box, r.critical_stiffness, K.min())
        if r.converged and math.isfinite(r.critical_stiffness):
            named = _exact(loop, r.operator)
            assert r.critical_stiffness <= named <= r.upper_bound * (1 + 1e-12)
            assert named - r.critical_stiffness <= 1e-4 * named


# ------------------------------------------------------------------ command line
def _run(*args):
    from click.testing import CliRunner

    from hapstab.cli.main import cli

    return CliRunner().invoke(cli, list(args))


def test_cli_robust_json_plot_and_csv(tmp_path):
    import json

    png, csv_path = tmp_path / "box.png", tmp_path / "box.csv"
    r = _run("robust", "hve", "-n", "2", "--operator-mass", "0.5", "--operator-damping", "4.5:5",
             "--operator-stiffness", "490:510", "--json", "--plot", str(png), "--csv",
             str(csv_path))
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    loop = h.HapticLoop(h.Device(0.15, 0.1), h.SpringDamper(0.0, 0.0), period=1e-3,
                        delay_samples=2)
    exact = _exact(loop, (d["operator"]["mass_kg"], d["operator"]["damping_N_s_per_m"],
                          d["operator"]["stiffness_N_per_m"]))
    assert d["converged"] and d["critical_stiffness"] <= exact
    assert exact - d["critical_stiffness"] <= 1e-6 * exact
    assert d["inputs"]["loop"]["operator"]["mass_kg"] == 0.5      # the worst operator shown
    assert png.stat().st_size > 0 and csv_path.read_text().count("\n") == 3
    table = _run("robust", "hve", "-n", "2", "--operator-box", "arm-grasp", "--operator-mass",
                 "0.5", "--operator-damping", "6", "--operator-stiffness", "100")
    assert table.exit_code == 0 and "robust K_max (certified)" in table.stdout


@pytest.mark.parametrize("args, words", [
    (["robust", "hve"], "operator box: not given"),
    (["robust", "hve", "--operator", "spring:5", "--operator-box", "arm-grasp"],
     "--operator = 'spring:5': the operator is varied over the box"),
    (["robust", "hve", "--operator-mass", "2:1", "--operator-damping", "1",
      "--operator-stiffness", "1"], "--operator-mass = '2:1': the lower end must not exceed"),
    (["robust", "hve", "--operator-box", "hand"], "unknown preset; allowed: arm-grasp"),
    (["robust", "hve", "--operator-mass", "x", "--operator-damping", "1",
      "--operator-stiffness", "1"], "--operator-mass = 'x'"),
    (["robust", "peb", "--operator-box", "arm-grasp", "--rtol", "0"], "--rtol"),
])
def test_cli_robust_refusals_are_one_line(args, words):
    r = _run(*args)
    assert r.exit_code == 2 and words in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_cli_best_damping_with_an_operator_box():
    r = _run("best-damping", "hve", "-n", "2", "--operator", "msd:0.5,5,500", "--min-damping",
             "0", "--operator-mass", "0.5", "--operator-damping", "4.5:5", "--operator-stiffness",
             "500")
    assert r.exit_code == 0, r.stderr
    assert "robust K_max at B*" in r.stdout and "Over the operator box" in r.stdout
