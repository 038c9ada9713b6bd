"""Limit cycles from quantisation and Coulomb friction (describing function refined by
harmonic balance) against the hybrid simulator, and the describing functions against
brute-force Fourier integrals.

Campaigns (seeded; ``-m slow`` runs the full sets):

* quantisation-driven: random HVE loops (masses 0.05-1 kg, dampings 0.01-2 N*s/m, no
  operator / a spring / a mass-spring-damper, T 0.25-2 ms, 3-29 samples of delay, K from
  0.75 to 1.2 K_max, floor and nearest encoders): every trusted stable cycle is simulated
  from its peak; the run must settle into a cycle whose amplitude and frequency are within
  10 % of the prediction;
* no cycle: K from 0.3 to 0.75 K_max, the operator's spring relaxed inside an encoder
  step: where no cycle is predicted the simulation must settle;
* friction-driven: the predicted threshold (an unstable cycle) of a linearly unstable loop
  separates runs that stop from runs that grow (started 10 % below and above it);
  friction and quantisation together give stable cycles, checked as the first set.
"""

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.analysis.nonlinear.harmonic import (
    Balance,
    quantize,
    quantizer_describing_function,
    staircase_harmonics,
)
from hapstab.analysis.nonlinear.limit_cycles import limit_cycles
from hapstab.cli.main import cli
from hapstab.errors import AnalysisError, ModelError
from lanes import costly

D = 1e-4          # the encoder step of the campaigns (quantisation scales with it)
TOL = 0.10        # the acceptance: amplitude and frequency within 10 % of the simulation


# ------------------------------------------------------------ describing functions
@pytest.mark.parametrize("quantizer", ["floor", "nearest"])
def test_dual_input_describing_function_against_a_fourier_integral(quantizer):
    rng = np.random.default_rng(7)
    phi = np.linspace(0, 2 * math.pi, 2_000_001)[:-1]
    # sin and cos of the 2e6 points once, not three times per draw (the same arrays)
    sin, cos = np.sin(phi), np.cos(phi)
    for _ in range(12):
        x0, A = rng.uniform(-3, 3), 10 ** rng.uniform(-1, 1)
        q = quantize(x0 + A * sin, 1.0, quantizer)
        n1, mean = quantizer_describing_function(A, x0, 1.0, quantizer)
        # a Riemann sum on 2e6 points: each jump costs <= 1 cell, ~1e-6 per threshold
        assert abs(n1 - 2 * np.mean(q * sin) / A) < 1e-5 * (1 + 2 * A)
        assert abs(mean - np.mean(q)) < 1e-5 * (1 + 2 * A)
        assert abs(np.mean(q * cos)) < 1e-5 * (1 + 2 * A)   # memoryless: no phase


def test_the_sum_in_python_is_the_sum_in_numpy(monkeypatch):
    """Below FEW thresholds the describing function is summed in Python: the same terms,
    equal to numpy's sums up to libm's arcsin (1 ulp)."""
    from hapstab.analysis.nonlinear import harmonic

    rng = np.random.default_rng(11)
    draws = [(10 ** rng.uniform(-1, 0.6), rng.uniform(-3, 3), q)
             for _ in range(300) for q in ("floor", "nearest")]
    fast = [quantizer_describing_function(A, x0, 1.0, q) for A, x0, q in draws]
    few = harmonic.FEW
    monkeypatch.setattr(harmonic, "FEW", 0)                  # every sum through numpy
    for (A, x0, q), (n1, mean) in zip(draws, fast, strict=True):
        m1, m2 = quantizer_describing_function(A, x0, 1.0, q)
        # a few roundings of terms of size <= 1 (the step), relative to the sums
        assert abs(n1 - m1) <= 1e-14 * max(1.0, m1) and abs(mean - m2) <= 1e-14 * (1 + abs(m2))
    assert sum(2 * A < few - 1 for A, _, _ in draws) > 100     # the Python sums ran


def test_a_newton_step_to_zero_amplitude_is_stepped_back():
    """MINPACK's first steps in log A went far enough that exp(log A) was 0, and the
    describing function divided by it: an internal error (ZeroDivisionError) for this
    command. Such a step is now outside the model and pushed back."""
    r = CliRunner().invoke(cli, ["limit-cycle", "hve", "-K", "40", "-n", "10",
                                 "--resolution", "1e-4", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert d["linear_verdict"] == "unstable" and d["cycles"]


def test_a_newton_step_far_above_the_scan_is_stepped_back():
    """A step to A ~ 1e10 encoder steps made the quantiser's describing function ask for
    arrays of 200 GB ("out of memory", exit 2, for a small loop; found by a seeded fuzz of
    616 loops). Steps above 4x the scan's top are now pushed back."""
    loop = h.HapticLoop(h.Device(0.5139198729622363, 0.007872339101800595),
                        h.SpringDamper(83.52725179285821, 0.09499035328041933),
                        operator=h.mass_spring_damper(2.75229, 0.00819811, 0.0297012),
                        period=0.0001235532355303883, delay_samples=25)
    r = limit_cycles(loop, resolution_m=2.993222390396244e-07, quantizer="nearest",
                     rest_position_m=7.487021560902917e-07, harmonics=1)
    assert r.searched_m[1] == pytest.approx(64 * 2.993222390396244e-07)
    assert all(c.amplitude_m <= 4 * r.searched_m[1] for c in r.cycles)


def test_textbook_quantiser_and_relay():
    # centred nearest quantiser: 4/pi at A = 1/sqrt 2, (4/(pi A)) sqrt(1 - 1/(4 A^2)) on (1/2, 3/2)
    assert math.isclose(quantizer_describing_function(2 ** -0.5, 0.0, 1.0, "nearest")[0],
                        4 / math.pi, rel_tol=1e-14)
    for A in (0.6, 1.0, 1.4):
        assert math.isclose(quantizer_describing_function(A, 0.0, 1.0, "nearest")[0],
                            4 / (math.pi * A) * math.sqrt(1 - 1 / (4 * A * A)), rel_tol=1e-14)
    # floor is nearest shifted by a half step at its input
    assert quantizer_describing_function(1.3, 0.2, 1.0, "floor")[0] == \
        pytest.approx(quantizer_describing_function(1.3, -0.3, 1.0, "nearest")[0], rel=1e-14)
    # the relay f_c sign(v): x = sin, v ~ cos; 2 sign(cos) = (8/pi)(cos - cos 3phi / 3 + ...),
    # in phase with the velocity
    bal = Balance(lambda t: t, lambda t: t, 0.0, 1.0, 0.0, "floor", 2.0)
    f0, F = bal.friction(np.array([-1j, 0, 0], complex))     # x = Re(-j e^{j phi}) = sin
    assert abs(f0) < 1e-14 and abs(F[0] - 8 / math.pi) < 1e-12   # exact sums, to rounding
    assert abs(F[1]) < 1e-12 and abs(F[2] + 8 / (3 * math.pi)) < 1e-12


def test_staircase_harmonics_against_an_fft():
    rng = np.random.default_rng(3)
    M = 1 << 20
    for _ in range(6):
        X = (rng.normal(size=7) + 1j * rng.normal(size=7)) / np.arange(1, 8) ** 2
        x0 = rng.uniform(-1, 1)
        # x = x0 + Re sum_k X_k e^{jk phi} on the M-point grid phi = 2 pi i / M, by the
        # inverse FFT (the same samples to 3e-15, measured; the input, not what is tested)
        # rather than an M x 7 matrix of exponentials (0.5 s a draw)
        spec = np.zeros(M // 2 + 1, complex)
        spec[0], spec[1:8] = x0 * M, X * (M / 2)
        x = np.fft.irfft(spec, M)
        levels = np.arange(math.floor(x.min() / 0.37) - 1, math.ceil(x.max() / 0.37) + 2) * 0.37
        q0, Q = staircase_harmonics(x0, X, levels,
                                    lambda v: 0.37 * np.floor(np.asarray(v) / 0.37))
        ref = np.fft.rfft(0.37 * np.floor(x / 0.37)) / M
        assert abs(q0 - ref[0].real) < 1e-5                 # ~1/M per jump on the FFT's grid
        assert np.max(np.abs(Q - 2 * ref[1:8])) < 1e-5       # Q_k = (1/pi) int y e^{-jk phi}


# ------------------------------------------------------------------- campaigns
def _draw(rng):
    op = rng.choice(["none", "spring", "msd"])
    o = (None if op == "none" else h.spring(10 ** rng.uniform(-0.5, 1.5)) if op == "spring"
         else h.mass_spring_damper(10 ** rng.uniform(-1.5, -0.5), 10 ** rng.uniform(-1, 0.5),
                                   10 ** rng.uniform(0, 2)))
    return h.HapticLoop(h.Device(10 ** rng.uniform(-1.3, 0), 10 ** rng.uniform(-2, 0.3)),
                        h.SpringDamper(1.0, 0.0), operator=o, period=10 ** rng.uniform(-3.6, -2.7),
                        delay_samples=int(rng.integers(3, 30)))


def simulated_cycle(res, periods=8):
    """(amplitude, frequency, how): the simulator's verdict when it names a limit cycle, else
    the trajectory's own envelope when it is flat (2 %) over its last quarters (the
    verdict also asks for growth at the linearised rate to have shown, which a slowly
    unstable linear loop cannot give); None when neither."""
    v = res.verdict
    if v.behaviour == "limit cycle":
        return v.amplitude_m, 1 / v.period_s, "verdict"
    x = res.position[:, 0]
    q = np.array_split(x[x.size // 2:], 4)
    amps = [np.ptp(p) / 2 for p in q]
    if min(amps) <= 0 or max(amps) > 1.02 * min(amps):
        return None
    y = x[x.size // 2:] - x[x.size // 2:].mean()
    up = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))
    if up.size < periods:
        return None
    return amps[-1], (up.size - 1) / ((up[-1] - up[0]) * res.period), "envelope"


def _quantised_case(seed, ratio_range):
    rng = np.random.default_rng(seed)
    loop = _draw(rng)
    km = h.critical_stiffness(loop)
    ratio, q = rng.uniform(*ratio_range), str(rng.choice(["floor", "nearest"]))
    return loop.with_stiffness(ratio * km.critical_stiffness), km.crossing_frequency_hz, q, rng


def _check_cycles(loop, pred, f_x, q, rest=0.0, friction=False, duration=None):
    """Every trusted stable cycle, simulated from its peak (for ``duration`` s, by default
    100 of its periods, 60 s at least): (errors in A and f, how)."""
    out = []
    for c in [c for c in pred.cycles if c.stable and c.trusted][:3]:
        dur = duration or max(60.0, 100 / c.frequency_hz)
        res = h.simulate(loop, dur, initial_position=c.offset_m + c.amplitude_m,
                         rest_position=rest, resolution=D if pred.resolution_m else None,
                         quantizer=q)
        got = simulated_cycle(res)
        assert got is not None, (loop, c, res.verdict.reason)
        A, f, how = got
        out.append((A / c.amplitude_m - 1, f / c.frequency_hz - 1, how))
        assert abs(A / c.amplitude_m - 1) <= TOL and abs(f / c.frequency_hz - 1) <= TOL, \
            (loop, q, c, got)
    return out


FAST_CYCLES = [1, 4, 7]
SLOW_CYCLES = list(range(100, 140))


#: seed 4 (a nearest-step encoder) in the default lane; 1 and 7 (floor encoders, their
#: cycles simulated longer) in `make test-campaign`
@pytest.mark.parametrize("seed", [s if s == 4 else costly(s, id=str(s)) for s in FAST_CYCLES]
                         + [pytest.param(s, marks=pytest.mark.slow) for s in SLOW_CYCLES])
def test_quantisation_cycles_match_the_simulator(seed):
    loop, f_x, q, _ = _quantised_case(seed, (0.75, 1.2))
    pred = limit_cycles(loop, resolution_m=D, quantizer=q)
    _check_cycles(loop, pred, f_x, q)


#: seed 209 (nearest encoder) is a draw of the slow lane's whose verdict is "no limit
#: cycle predicted": the default lane's case that simulates the claim (2 predicts chatter
#: and 5 a cycle, so neither reaches it)
FAST_NONE = [2, 5, 209]
SLOW_NONE = [s for s in range(200, 230) if s not in FAST_NONE]


def no_cycle(res):
    """The run shows no limit cycle: it settles, has stopped, or its envelope still falls
    over its last eighths (a slow decay the verdict will not yet call settled)."""
    if res.verdict.behaviour == "settles":
        return True
    x = res.position[:, 0]
    e = [np.ptp(p) for p in np.array_split(x, 8)]
    return e[-1] <= 1e-9 * max(e) or (e[-1] < 0.95 * e[-2] < 0.95 ** 2 * e[-3])


#: seed 5 (K = 0.6 K_max, a floor encoder: a cycle is predicted and simulated, with the
#: dual-input offset the nearest encoder of test_quantisation_cycles_match_the_simulator's
#: default seed 4 does not have) stays in the default lane
@pytest.mark.parametrize("seed", FAST_NONE + [pytest.param(s, marks=pytest.mark.slow)
                                              for s in SLOW_NONE])
def test_no_cycle_predicted_means_none_simulated(seed):
    loop, f_x, q, rng = _quantised_case(seed, (0.3, 0.75))
    rest = D * (round(rng.uniform(-3, 3)) + rng.uniform(0.2, 0.8))    # inside a step
    pred = limit_cycles(loop, resolution_m=D, quantizer=q, rest_position_m=rest)
    if pred.verdict == "limit cycle":
        _check_cycles(loop, pred, f_x, q, rest)
    if pred.verdict != "no limit cycle predicted":
        return
    for x0 in (rest + 3 * D, rest + 0.6 * D):
        res = h.simulate(loop, max(60.0, 100 / f_x), initial_position=x0, rest_position=rest,
                         resolution=D, quantizer=q)
        assert no_cycle(res), (loop, q, rest, x0, res.verdict.reason)


def test_the_paper_loop_documented_cases():
    # the paper's delayed HVE (n = 10, K_max = 9.5361 N/m): the describing function alone
    # is 14 % off at 0.8 K_max, the refined balance within 1.5 % (the README's table)
    base = h.paper_hve(1e-3, 10)
    kmax = h.critical_stiffness(base).critical_stiffness
    loop = base.with_stiffness(0.8 * kmax)
    pred = limit_cycles(loop, resolution_m=D, quantizer="nearest")
    c = next(c for c in pred.cycles if c.stable)
    assert c.describing_function_amplitude_m == pytest.approx(0.786 * D, rel=2e-3)
    assert c.amplitude_m == pytest.approx(0.912 * D, rel=2e-3)
    errs = _check_cycles(loop, pred, 1.33, "nearest")
    assert all(abs(a) < 0.02 and abs(f) < 0.01 for a, f, _ in errs)
    # a linearly unstable loop (1.1 K_max) held by quantisation in a 1.36-step cycle
    loop = base.with_stiffness(1.1 * kmax)
    pred = limit_cycles(loop, resolution_m=D, quantizer="nearest")
    assert pred.verdict == "limit cycle" and pred.linear_verdict == "unstable"
    _check_cycles(loop, pred, 1.33, "nearest")
    # far below: no cycle (gain margin 2 > 4/pi) and none simulated
    pred = limit_cycles(base.with_stiffness(0.5 * kmax), resolution_m=D, quantizer="nearest")
    assert pred.verdict == "no limit cycle predicted" and "gain margin" in pred.conditions


#: relaxed 0.05 steps below the line in `make test-campaign`: 0.2 steps below asks the same
#: (no rest anywhere: chatter predicted, a sub-step cycle simulated), its cycle in a
#: period of 1.8 s against 3.0 s
@pytest.mark.parametrize("rest", [pytest.param(-0.2 * D, id="-0.2D"),
                                  costly(-0.05 * D, id="-0.05D")])
def test_chatter_where_the_device_cannot_rest(rest):
    # a floor encoder, the operator's spring relaxed just below a line: no rest anywhere
    loop = _quantised_case(2, (0.3, 0.78))[0]      # msd operator, K = 0.39 K_max
    pred = limit_cycles(loop, resolution_m=D, quantizer="floor", rest_position_m=rest)
    assert pred.verdict == "chatter" and pred.rests == "nowhere"
    # 45 s for -0.2 steps (its cycle's period 1.8 s; the verdict's limit cycle, 0.175
    # steps, is the same to rounding at 36, 40, 45, 50 and 60 s, measured), 60 s for -0.05
    # (3.0 s: 8 periods in the judged half need it)
    res = h.simulate(loop, 45.0 if rest == -0.2 * D else 60.0, initial_position=3 * D,
                     rest_position=rest, resolution=D)
    assert res.verdict.behaviour == "limit cycle" and res.verdict.amplitude_m < D / 2


def test_no_chatter_where_the_device_can_rest():
    loop = _quantised_case(2, (0.3, 0.78))[0]      # the loop above
    # relaxed on the line: it may rest there (this overdamped loop does), not predicted
    pred = limit_cycles(loop, resolution_m=D, quantizer="floor", rest_position_m=0.0)
    assert pred.verdict == "undecided" and pred.rests == "on a line"
    pred = limit_cycles(loop, resolution_m=D, quantizer="floor", rest_position_m=0.3 * D)
    assert pred.rests == "inside a step"


def _stops(res, A):
    """Settled, or its last tenth below 0.7 of the threshold (started at 0.9) and still
    shrinking (a run that starts near an unstable cycle leaves it slowly)."""
    x = res.position[:, 0]
    tail, before = x[-x.size // 10:], x[-x.size // 5:-x.size // 10]
    return res.verdict.behaviour == "settles" or (
        np.ptp(tail) / 2 < 0.7 * A and np.ptp(tail) < np.ptp(before))


def _grows(res, A):
    """Overflowed, grows, or past 1.4 times the threshold (started at 1.1) at the end."""
    x = res.position[:, 0]
    return res.verdict.behaviour == "grows" or not np.all(np.isfinite(x)) or \
        np.abs(x[-x.size // 10:]).max() > 1.4 * A


def _leaving_time(loop):
    """A run long enough to leave the threshold's neighbourhood: 8 e-foldings of the linear
    loop's growth (the motion 10 % off the threshold leaves it at about that rate), 30 s
    at least, 400 s at most."""
    rate = math.log(h.stability(loop).spectral_radius) / loop.period
    return float(np.clip(8 / rate, 30.0, 400.0))


def test_friction_threshold_separates_stopping_from_growing():
    base = h.paper_hve(1e-3, 10)
    kmax = h.critical_stiffness(base).critical_stiffness
    loop = base.replace(device=h.Device(0.15, 0.1, coulomb_friction=0.01)).with_stiffness(1.2 * kmax)
    pred = limit_cycles(loop)
    assert pred.verdict == "threshold"
    c = pred.cycles[0]
    assert not c.stable and c.trusted
    assert c.amplitude_m == pytest.approx(0.0701, rel=2e-3)     # 4 f_c / (pi c_eq w)
    # 45 s: the run below stops exactly at t = 34.6 s (measured), and a 45 s run still
    # sees it stopped and at rest for its last 10 s ("settles", as a 60 s run)
    below = h.simulate(loop, 45.0, initial_position=0.9 * c.amplitude_m, rest_position=0.0)
    above = h.simulate(loop, 30.0, initial_position=1.1 * c.amplitude_m, rest_position=0.0)
    assert _stops(below, c.amplitude_m) and _grows(above, c.amplitude_m)
    # a stable linear loop: friction adds no cycle, and the run stops
    pred = limit_cycles(loop.with_stiffness(0.9 * kmax))
    assert pred.verdict == "no limit cycle predicted"


@pytest.mark.parametrize("seed", [pytest.param(s, marks=pytest.mark.slow) for s in range(300, 312)])
def test_friction_thresholds_seeded(seed):
    rng = np.random.default_rng(seed)
    loop = _draw(rng)
    km = h.critical_stiffness(loop).critical_stiffness
    fc = 10 ** rng.uniform(-3, -1)
    dev = h.Device(loop.device.mass, loop.device.damping, coulomb_friction=fc)
    loop = loop.replace(device=dev).with_stiffness(rng.uniform(1.05, 1.5) * km)
    pred = limit_cycles(loop)
    thr = [c for c in pred.cycles if c.trusted and not c.stable]
    assert pred.linear_verdict == "unstable" and thr, pred.reason
    c = thr[0]
    dur = max(_leaving_time(loop), 40 / c.frequency_hz)
    below = h.simulate(loop, dur, initial_position=0.9 * c.amplitude_m, rest_position=0.0)
    above = h.simulate(loop, dur, initial_position=1.1 * c.amplitude_m, rest_position=0.0)
    assert _stops(below, c.amplitude_m), below.verdict.reason
    assert _grows(above, c.amplitude_m), above.verdict.reason


@pytest.mark.parametrize("ratio, fc", [(0.9, 1e-5),
                                       pytest.param(1.1, 1e-4, marks=pytest.mark.slow),
                                       pytest.param(0.9, 1e-6, marks=pytest.mark.slow)])
def test_friction_and_quantisation_cycles(ratio, fc):
    # f_c = 1e-5 N at 0.9 K_max: the describing function has no root (|F| = 0.009 at its
    # closest), harmonic balance finds the 0.86-step cycle the simulator shows (0.89)
    base = h.paper_hve(1e-3, 10)
    kmax = h.critical_stiffness(base).critical_stiffness
    loop = base.replace(device=h.Device(0.15, 0.1, coulomb_friction=fc)).with_stiffness(ratio * kmax)
    pred = limit_cycles(loop, resolution_m=D, quantizer="nearest")
    assert pred.verdict == "limit cycle"
    # the default lane's case for 40 s (55 periods) instead of 100 periods (73 s; a
    # stick-slip step costs 5 times a quantised one): started on the predicted cycle, the
    # run is on it within 15 s (A and f within 0.06 % of the prediction at every length
    # from 15 s to 73 s, measured, against the 10 % asked)
    dur = 40.0 if (ratio, fc) == (0.9, 1e-5) else None
    _check_cycles(loop, pred, 1.33, "nearest", friction=True, duration=dur)


# ----------------------------------------------------------------- the interface
def test_refusals():
    with pytest.raises(AnalysisError, match="resolution_m > 0 or a Coulomb friction"):
        limit_cycles(h.paper_hve(1e-3, 10).with_stiffness(5.0))
    with pytest.raises(AnalysisError, match="hve"):
        limit_cycles(h.paper_peb(), resolution_m=D)
    with pytest.raises(AnalysisError, match="whole samples"):
        limit_cycles(h.paper_hve().with_stiffness(5.0).with_delay_s(0.0105), resolution_m=D)
    with pytest.raises(AnalysisError, match="K > 0"):
        limit_cycles(h.paper_hve().with_stiffness(0.0), resolution_m=D)
    with pytest.raises(ModelError, match="quantizer"):
        limit_cycles(h.paper_hve().with_stiffness(5.0), resolution_m=D, quantizer="round")
    with pytest.raises(ModelError, match="harmonics"):
        limit_cycles(h.paper_hve().with_stiffness(5.0), resolution_m=D, harmonics=0)


def test_few_samples_per_period_is_not_predicted():
    # a light, well damped device without delay: K_max's crossing at 292 Hz, 3.4 samples a
    # period at 1 kHz: outside the describing function's range (the quantiser sees samples)
    loop = h.HapticLoop(h.Device(0.0005, 1.0), h.SpringDamper(0.95 * 2911.36, 0.0))
    pred = limit_cycles(loop, resolution_m=D, quantizer="nearest")
    assert pred.verdict in ("undecided", "no limit cycle predicted")
    assert pred.cycles and all(not c.trusted and "samples per period" in c.notes
                               for c in pred.cycles)


def test_result_protocol_and_cli(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    loop = h.paper_hve(1e-3, 10).with_stiffness(8.0)
    pred = limit_cycles(loop, resolution_m=D, quantizer="nearest")
    d = pred.to_dict()
    json.dumps(d, allow_nan=False)
    assert pred._repr_html_().count("<tr>") == len(d)
    assert pred.plot().has_data()
    pred.to_csv(str(tmp_path / "c.csv"))
    assert (tmp_path / "c.csv").read_text().count("\n") == len(pred.cycles) + 1
    r = CliRunner().invoke(cli, ["limit-cycle", "hve", "-K", "8", "-n", "10", "--resolution",
                                 "1e-4", "--quantizer", "nearest", "--json", "--plot",
                                 str(tmp_path / "p.png")])
    assert r.exit_code == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["verdict"] == pred.verdict and out["files"] == [str(tmp_path / "p.png")]
    assert "friction_note" not in out
    r = CliRunner().invoke(cli, ["limit-cycle", "hve", "-K", "8"])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1
