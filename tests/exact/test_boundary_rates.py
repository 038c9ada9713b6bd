"""Issue #12: K_max against the sampling rate at a fixed delay in seconds (the first
question about one's own device), `boundary --plot`, and one range syntax everywhere."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli


def run(*args):
    return CliRunner().invoke(cli, list(args))


def _kmax_by_eigenvalues(loop, hi):
    """Independent reference: bisection on the closed loop's spectral radius (the exact
    model's eigenvalues) between a stable K and an unstable one."""
    from hapstab.engine.system import build

    def stable(K):
        return np.max(np.abs(np.linalg.eigvals(build(loop.with_stiffness(K)).closed_loop()[0]))) < 1
    lo = 1e-3
    assert stable(lo) and not stable(hi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


@pytest.mark.parametrize("make,T,delay_s", [
    (h.paper_hve, 3e-4, 1e-3),            # 3.33 samples: a fractional delay
    (h.paper_hve, 2.5e-4, 2e-2),          # 80 whole samples
    (h.paper_peb, 7e-4, 2e-3),            # 2.86 samples each way
])
def test_fixed_delays_in_seconds_match_an_independent_eigenvalue_bisection(make, T, delay_s):
    res = h.boundary(make(), [T], delays_s=[delay_s])
    K = res.critical_stiffness[0, 0]
    ref = _kmax_by_eigenvalues(make().replace(period=T).with_delay_s(delay_s), 10 * K)
    assert K == pytest.approx(ref, rel=1e-7)   # bisection to 2^-60; the exact core to ~1e-12


def test_whole_sample_delays_in_seconds_agree_with_delays_in_samples():
    T = np.array([5e-4, 1e-3, 2e-3])
    by_s = h.boundary(h.paper_hve(), T, delays_s=[0.0, 0.01])
    # 10 ms is 20, 10 and 5 samples at these periods
    for j, (t, n) in enumerate(zip(T, (20, 10, 5), strict=True)):
        by_n = h.boundary(h.paper_hve(), [t], [0, n])
        np.testing.assert_allclose(by_s.critical_stiffness[:, j], by_n.critical_stiffness[:, 0],
                                   rtol=1e-12)   # the same loops, two paths to them
    assert by_s.to_dict()["delay_s"] == [0.0, 0.01] and "delay_samples" not in by_s.to_dict()
    assert by_s.rows()[1] == {"period_s": 1e-3, "delay_s": 0.0, "delay_samples": 0.0,
                              "critical_stiffness": by_s.critical_stiffness[0, 1]}


def test_boundary_over_rates_at_a_fixed_delay_through_the_cli(tmp_path):
    png, csv = tmp_path / "b.png", tmp_path / "b.csv"
    r = run("boundary", "hve", "--rate", "250Hz:4kHz:4", "--delay-s", "0,20ms", "--plot", str(png),
            "--csv", str(csv), "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["delay_s"] == [0.0, 0.02]
    np.testing.assert_allclose(d["period_s"], sorted(1 / np.array([250, 1500, 2750, 4000])))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert csv.read_text().splitlines()[0] == "period_s,delay_s,delay_samples,critical_stiffness"
    # the API gives the same numbers
    api = h.boundary(h.paper_hve(), d["period_s"], delays_s=[0.0, 0.02])
    np.testing.assert_allclose(d["critical_stiffness"], api.critical_stiffness, rtol=0)


@pytest.mark.parametrize("args,needle", [
    (("boundary", "hve", "--rate", "1kHz", "--period", "1ms"), "--period and --rate: give one"),
    (("boundary", "hve", "--delay", "3", "--delay-s", "5ms"), "--delay and --delay-s: give one"),
    (("boundary", "hve", "--rate", "1e9"), "--rate = '1e9': 1e+09 Hz gives T = 1e-09 s"),
    (("boundary", "hve", "--delay-s", "-1ms"), "every value must be finite and >= 0"),
    (("boundary", "hve", "--period", "1ms:2ms:x"), "count 'x' is not a number"),
    (("boundary", "hve", "--period", "1ms::10"), "expected start:stop[:count]"),
    (("region", "hve", "--K", "0:900:5", "--B", "0:1"), "the grid's size is --resolution"),
    (("region", "hve", "--K", "a:9", "--B", "0:1"), "'a' is not a number"),
])
def test_range_mistakes_are_one_line_naming_the_option(args, needle):
    r = run(*args)
    assert r.exit_code == 2 and needle in r.stderr and r.stderr.count("\n") == 1, r.stderr


@pytest.mark.parametrize("spec", ["1ms:10ms", "0.001:0.01:10", "1ms:10ms:10"])
def test_one_range_syntax_count_optional_units_allowed(spec):
    from hapstab.cli.ranges import parse_range

    np.testing.assert_allclose(parse_range(spec, "--period", "s"), np.linspace(1e-3, 1e-2, 10),
                               rtol=1e-12)


def test_boundary_plot_over_periods_labels_delays_in_samples(tmp_path):
    res = h.boundary(h.paper_hve(), np.linspace(1e-3, 1e-2, 4), [0, 10])
    ax = res.plot()
    assert ax.get_xlabel() == "sampling period T (ms)"
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["n = 0", "n = 10"]
    ax = h.boundary(h.paper_hve(), [1e-3, 2e-3], delays_s=[0.02], axis="rate").plot()
    assert ax.get_xlabel() == "sampling rate 1/T (Hz)"
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["t_d = 20 ms"]
