"""hapstab.identify: a device's m, b (and f_c) from a log, with confidence intervals.

The logs are made by two simulators that share no code with the identification's model
(hapstab.analysis.identification.identify_model): hapstab's own simulator (hapstab.simulate, its exact
stick-slip in simulation/friction.py) and an independent one written here (the ZOH step
from scipy's matrix exponential of the augmented matrix, friction's stop found by root
finding, not the closed form). The truth is known; the campaign counts how often the
stated intervals contain it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.linalg import expm
from scipy.optimize import brentq
from scipy.stats import binom

import hapstab
from hapstab.cli.main import cli
from hapstab.errors import AnalysisError, ModelError
from hapstab.models.parts import quantize
from lanes import PARTS, costly, part


# ------------------------------------------------------------ an independent simulator
def _zoh(m, b, t):
    """(Phi, Gamma) of x' = [[0, 1], [0, -b/m]] x + [0, 1/m] F over t (Van Loan's block
    matrix exponential)."""
    M = np.zeros((3, 3))
    M[0, 1], M[1, 1], M[1, 2] = 1.0, -b / m, 1.0 / m
    E = expm(M * t)
    return E[:2, :2], E[:2, 2]


def independent_log(m, b, fc, F, T, x0=0.0, v0=0.0):
    """Exact positions at the samples under the held force F, Coulomb friction's stop
    located by Brent's method on the velocity (not the identification's closed form)."""
    Phi, Gam = _zoh(m, b, T)
    s = np.array([x0, v0])
    out = [s[0]]
    for f in F[:-1]:
        left = T
        while left > 0:
            v = s[1]
            if v == 0 and abs(f) <= fc:
                break                              # sticks for the rest of the sample
            d = np.sign(v) if v != 0 else np.sign(f)
            g = f - fc * d
            P, G = (Phi, Gam) if left == T else _zoh(m, b, left)
            nxt = P @ s + G * g
            if np.sign(nxt[1]) == d or fc == 0:
                s = nxt
                break
            # the velocity reaches 0 inside: find when, and stop there
            ts = brentq(lambda tau, s=s, g=g: (_zoh(m, b, tau)[0] @ s
                                               + _zoh(m, b, tau)[1] * g)[1], 0.0, left,
                        xtol=1e-15, rtol=1e-14)
            P, G = _zoh(m, b, ts)
            s = P @ s + G * g
            s[1] = 0.0
            left -= ts
        out.append(s[0])
    return np.array(out)


def hapstab_log(m, b, fc, F, T):
    """True positions from hapstab's simulator (no controller: K = B = 0, no operator)."""
    loop = hapstab.HapticLoop(hapstab.Device(m, b, fc), operator=None, period=T)
    r = hapstab.simulate(loop, (F.size - 1) * T, force=F[:-1])
    return np.asarray(r.position)[:, 0] if np.ndim(r.position) == 2 else np.asarray(r.position)


def excitation(rng, N, T, amp):
    """A random multisine (1-25 Hz) plus white noise: a usual identification force."""
    t = np.arange(N) * T
    f = rng.uniform(1, 25, 6)
    F = sum(np.sin(2 * np.pi * fi * t + rng.uniform(0, 2 * np.pi)) for fi in f) / 3
    return amp * (F + 0.3 * rng.standard_normal(N))


def draw(seed, simulator):
    """One synthetic log with its truth: device, rate, encoder, noise, friction."""
    rng = np.random.default_rng(seed)
    m, b = rng.uniform(0.05, 1.0), rng.uniform(0.1, 3.0)
    fc = rng.uniform(0.02, 0.2) if rng.random() < 0.5 else 0.0
    T = 1 / rng.choice([1000, 2000, 4000])
    res = rng.choice([1e-6, 2e-6, 5e-6])
    sigma = rng.choice([0.0, 0.5, 2.0]) * res
    N = 1500
    F = excitation(rng, N, T, amp=rng.uniform(1, 3) * (fc + 0.2))
    x = (independent_log if simulator == "independent" else hapstab_log)(m, b, fc, F, T)
    y = quantize(x + sigma * rng.standard_normal(N), res, "floor")
    log = {"time_s": np.arange(N) * T + 0.37, "force_N": F, "position_m": y}
    return log, (m, b, fc), res


# ------------------------------------------------------------------ the two simulators
def test_the_independent_simulator_matches_hapstabs():
    """The two log makers agree (they share no code), with and without friction; the
    tolerance is 1e-12 of the travel: both are exact up to rounding over 1500 samples."""
    rng = np.random.default_rng(3)
    for fc in (0.0, 0.08):
        F = excitation(rng, 1500, 5e-4, 0.5)
        a = independent_log(0.3, 0.7, fc, F, 5e-4)
        h = hapstab_log(0.3, 0.7, fc, F, 5e-4)
        assert np.max(np.abs(a - h)) <= 1e-9 * np.ptp(a)


def test_the_model_matches_the_independent_simulator():
    rng = np.random.default_rng(4)
    from hapstab.analysis.identification.identify_model import predict
    for fc, b in ((0.0, 0.0), (0.0, 2.0), (0.1, 0.5), (0.1, 0.0)):
        F = excitation(rng, 800, 1e-3, 0.6)
        a = independent_log(0.2, b, fc, F, 1e-3, 0.001, 0.02)
        p = predict(0.2, b, fc, 0.001, 0.02, F, 1e-3)
        assert np.max(np.abs(a - p)) <= 1e-9 * np.ptp(a)


def test_the_models_runs_are_its_one_sample_steps_bit_for_bit():
    """predict steps a sliding run (and a stuck one) at once; each sample's position is
    the one-sample step's, bit for bit: seeded forces that stick-slip often (a force
    switching around the friction band), rarely (a slow sine, runs past MAX_RUN) and in
    between, with and without damping, from rest and moving."""
    from hapstab.analysis.identification import identify_model as im
    rng = np.random.default_rng(20261207)
    for case in range(24):
        n = int(rng.integers(2, 3 * im.MAX_RUN))
        m, fc, T = float(10 ** rng.uniform(-2, 0)), float(10 ** rng.uniform(-2, 0)), 1e-4
        b = 0.0 if case % 3 == 0 else float(10 ** rng.uniform(-2, 1))
        t = np.arange(n) * T
        F = [fc * rng.uniform(-3, 3, n), 2 * fc * np.sin(2 * np.pi * rng.uniform(0.5, 5) * t),
             np.where(rng.uniform(size=n) < 0.5, 0.9, -0.9) * fc * rng.uniform(0, 2)][case % 3]
        x0, v0 = float(rng.normal()), (0.0 if case % 2 else float(rng.normal()))
        got = im.predict(m, b, fc, x0, v0, F, T)
        assert np.array_equal(got, im._predict_stepwise(m, b, fc, x0, v0, F, T)), case


# ------------------------------------------------------------------ the campaign
def _campaign(seeds, simulator):
    """For each log: whether each parameter's interval holds the truth."""
    inside, friction_ok = [], []
    for seed in seeds:
        log, truth, res = draw(seed, simulator)
        r = hapstab.identify(log, resolution_m=res)
        inside += [r.low[i] <= truth[i] <= r.high[i] for i in (0, 1)]
        if truth[2] > 0:
            inside.append(r.friction_fitted and r.low[2] <= truth[2] <= r.high[2])
        friction_ok.append((truth[2] > 0, r.friction_fitted))
    return np.array(inside), friction_ok


def _check_detection(found):
    """Friction is found in every log that has it (f_c >= 0.02 N, the draws' smallest, is
    far above the intervals' widths); in a log without it, auto keeps a friction whose
    interval excludes 0: a false find at the rate (1 - 0.95) / 2 per log, so at most 2
    of ~12 (P(>= 3) = 0.3 %) and at most 6 % over the full draw."""
    assert all(fit for has, fit in found if has)
    false = [fit for has, fit in found if not has]
    assert sum(false) <= max(2, 0.06 * len(false))


def _check_rate(inside, level=0.95):
    """The intervals hold the truth at about their nominal rate: the count is inside the
    central 99.9 % of Binomial(n, 0.95) (a false alarm once in 1000 campaigns; a rate of
    0.85 or of 1.0 on 250 checks fails it)."""
    n, k = inside.size, int(inside.sum())
    lo, hi = binom.ppf(0.0005, n, level), binom.ppf(0.9995, n, level)
    assert lo <= k <= hi, f"{k}/{n} = {k / n:.3f} inside the 95 % intervals"


#: hapstab's simulator's logs in `make test-campaign`: the default lane's independent
#: simulator asks the same question, and the two agree to 1e-9 of the travel (above).
#: Of the independent simulator's 25 logs the default lane checks 12 evenly spaced ones
#: (0.5 s of identification each; its rate and false-find bounds are those of 12 logs, a
#: weaker check), `make test-campaign` all 25 at the whole draw's bounds (PARTS); the rate
#: is asked at full strength by the 200-log draws below (-m slow, in that lane too)
@pytest.mark.parametrize("simulator, rest", [
    pytest.param("independent", *p.values, marks=p.marks, id=f"independent-{p.id}")
    for p in PARTS] + [costly("hapstab", False, id="hapstab")])
def test_intervals_hold_the_truth_at_their_rate(simulator, rest):
    """>= 50 seeded logs in all (25 per simulator; measured over 80 logs: m 97.5 %,
    b 92.5 %, f_c 90 % of 95 % intervals); friction found where there is some."""
    seeds = (range(25) if rest else part(range(25), 12, False)) if simulator == "independent" \
        else range(100, 125)
    inside, found = _campaign(seeds, simulator)
    _check_rate(inside)
    _check_detection(found)


@pytest.mark.slow
@pytest.mark.parametrize("simulator", ["independent", "hapstab"])
def test_intervals_hold_the_truth_full_draw(simulator):
    """200 logs per simulator. Before the Newey-West sandwich (identify._covariance) the
    95 % intervals held m 91 %, b 90 %, f_c 87 % here (seeds 1000-1199: b 86 % on the
    noise-free logs); with it m 94.5 %, b 93.5 % (independent simulator, measured)."""
    seeds = range(1000, 1200) if simulator == "independent" else range(2000, 2200)
    inside, found = _campaign(seeds, simulator)
    _check_rate(inside)
    _check_detection(found)


# ------------------------------------------------------------------ refusals
def _good(N=600, T=5e-4, fc=0.0, seed=0):
    rng = np.random.default_rng(seed)
    F = excitation(rng, N, T, 0.4)
    y = quantize(independent_log(0.25, 0.8, fc, F, T), 2e-6, "floor")
    return {"time_s": np.arange(N) * T, "force_N": F, "position_m": y}


@pytest.mark.parametrize("spoil, error, words", [
    (lambda d: {k: v[:60] for k, v in d.items()}, ModelError, "60 samples: too short"),
    (lambda d: {**d, "force_N": 0 * d["force_N"]}, AnalysisError, "no excitation"),
    (lambda d: {**d, "force_N": 0 * d["force_N"] + 0.3}, AnalysisError, "constant"),
    (lambda d: {**d, "time_s": d["time_s"] ** 1.01}, ModelError, "non-uniform time"),
    (lambda d: {**d, "time_s": np.r_[d["time_s"][:9], d["time_s"][8:-1]]}, ModelError,
     "does not increase at sample 9"),
    (lambda d: {**d, "position_m": np.r_[d["position_m"][:5], np.nan, d["position_m"][6:]]},
     ModelError, "position at sample 5 is nan"),
    (lambda d: {**d, "position_m": 2e-6 * np.round(10 * d["position_m"] / np.ptp(d["position_m"]))},
     AnalysisError, "10 encoder steps"),
])
def test_data_that_cannot_identify_is_refused_with_the_reason(spoil, error, words):
    with pytest.raises(error, match=words):
        hapstab.identify(spoil(_good()), resolution_m=2e-6)


def test_parameters_the_run_cannot_tell_apart_are_refused():
    """A force that only ever pushes one way at one speed (after a transient of a few
    samples): mass and damping and friction merge; refused, not given wide intervals."""
    N, T = 2000, 5e-4
    F = np.full(N, 0.3)
    F[:3] = 0.0
    x = independent_log(0.25, 0.8, 0.1, F, T)
    log = {"time_s": np.arange(N) * T, "force_N": F, "position_m": quantize(x, 2e-6)}
    with pytest.raises(AnalysisError, match="cannot tell the parameters apart"):
        hapstab.identify(log, resolution_m=2e-6, friction="yes")


def test_options_are_checked():
    with pytest.raises(ModelError, match="friction = 'maybe'"):
        hapstab.identify(_good(), friction="maybe")
    with pytest.raises(ModelError, match="confidence = 2"):
        hapstab.identify(_good(), confidence=2)
    with pytest.raises(ModelError, match="quantizer"):
        hapstab.identify(_good(), resolution_m=2e-6, quantizer="round")
    with pytest.raises(ModelError, match="no force column"):
        hapstab.identify({"t": [0, 1], "pos": [0, 1], "x": [0, 1]})


# ------------------------------------------------------------ result and command line
def test_the_result_protocol(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = hapstab.identify(_good(fc=0.05), resolution_m=2e-6)
    assert r.friction_fitted and r.low[2] <= 0.05 <= r.high[2]
    d = json.loads(hapstab.results.dumps(r.to_dict()))
    assert d["mass_kg_interval"][0] <= d["mass_kg"] <= d["mass_kg_interval"][1]
    assert "white" in d["noise_model"] and d["samples"] == 600
    dev = r.device()
    assert (dev.mass, dev.damping, dev.coulomb_friction) == pytest.approx(r.estimate[:3])
    _fig, ax = plt.subplots()
    assert r.plot(ax)[0] is ax and len(ax.lines) == 2
    plt.close("all")
    r.to_csv(tmp_path / "fit.csv")
    rows = (tmp_path / "fit.csv").read_text().splitlines()
    assert rows[0] == "time_s,force_N,position_m,fitted_position_m,residual_m"
    assert len(rows) == 601
    assert "mass_kg (95 % interval)" in r._repr_html_()
    # the residuals are the reading's centred error: mean ~0 (not -Delta/2), spread ~
    # Delta / sqrt(12) (quantisation only)
    assert abs(r.residuals_m.mean()) < 0.2e-6
    assert r.residual_std_m == pytest.approx(2e-6 / 12 ** 0.5, rel=0.2)


def test_the_command_line_for_the_identified_device_runs():
    """identify's kmax line is a valid command whose device is the estimate; the cautious
    line's damping is at or below the interval's lower end (rounded down)."""
    r = hapstab.identify(_good(fc=0.05), resolution_m=2e-6)
    low = r.commands()["low_damping"].split()
    b_low = float(low[low.index("--damping") + 1])
    assert b_low <= r.low[1] and b_low >= 0.999 * r.low[1]
    out = CliRunner().invoke(cli, [*r.commands()["estimate"].split()[1:], "--json"])
    assert out.exit_code == 0, out.stderr
    dev = json.loads(out.stdout)["inputs"]["loop"]["device"]
    assert dev["mass_kg"] == pytest.approx(r.mass, rel=1e-3)
    assert dev["coulomb_friction_N"] == pytest.approx(r.coulomb_friction, rel=1e-3)


def test_hapstab_identify_on_a_csv(tmp_path):
    d = _good(fc=0.05)
    path = tmp_path / "run.csv"
    path.write_text("# a comment line\ntime,commanded_force_N,x\n" + "".join(
        f"{a:.9g},{b:.17g},{c:.17g}\n" for a, b, c in zip(*d.values(), strict=True)))
    out = CliRunner().invoke(cli, ["identify", str(path), "--resolution", "2um",
                                            "--json"])
    assert out.exit_code == 0, out.stderr
    j = json.loads(out.stdout)
    api = hapstab.identify(d, resolution_m=2e-6)
    assert j["mass_kg"] == pytest.approx(api.mass, rel=1e-6)   # times to 9 digits: ~1e-9
    assert j["coulomb_friction_fitted"] and j["resolution_m"] == 2e-6
    table = CliRunner().invoke(cli, ["identify", str(path), "--resolution", "2um",
                                              "--plot", str(tmp_path / "fit.png")])
    assert table.exit_code == 0 and "hapstab kmax hve" in table.stdout
    assert (tmp_path / "fit.png").stat().st_size > 10_000
    bad = CliRunner().invoke(cli, ["identify", str(path), "--columns", "a,b"])
    assert bad.exit_code == 2 and "--columns" in bad.stderr


def test_a_log_with_a_byte_order_mark_is_read(tmp_path):
    """A spreadsheet's "CSV UTF-8" starts with a byte-order mark: it was read as part of
    the first column's name ("no time column (... '\\ufefftime_s' ...)", a helper's fuzz)."""
    d = _good()
    text = "time_s,force_N,position_m\n" + "".join(
        f"{a:.17g},{b:.17g},{c:.17g}\n" for a, b, c in zip(*d.values(), strict=True))
    plain, marked = tmp_path / "plain.csv", tmp_path / "marked.csv"
    plain.write_text(text, encoding="utf-8")
    marked.write_text(text, encoding="utf-8-sig")
    assert marked.read_bytes()[:3] == b"\xef\xbb\xbf"
    assert hapstab.identify(str(marked)).mass == hapstab.identify(str(plain)).mass


@pytest.mark.parametrize("scale, words", [
    ({"force_N": 1e300}, "force up to"), ({"position_m": 1e-300}, "position up to"),
    ({"time_s": 1e-310}, "period"), ({"time_s": 1e305}, "period"),
])
def test_a_log_outside_the_models_range_is_refused_by_name(scale, words):
    """Values scaled by 1e+-300 and subnormal or huge time steps were internal errors
    (scipy's least_squares refused its scale, LAPACK's SVD did not converge) or a hang
    (a subnormal period: inf columns), in a helper's fuzz; now a ModelError naming them."""
    d = _good()
    with pytest.raises(ModelError, match=words):
        hapstab.identify({k: v * scale.get(k, 1.0) for k, v in d.items()})


def test_a_log_too_long_for_the_time_budget_is_refused_before_the_fit():
    from hapstab import budget

    d = _good()
    with budget.limits(seconds=0.1), pytest.raises(budget.BudgetError, match="600 samples"):
        hapstab.identify(d)
