"""Margins at K (issue 29, item 4): the delay margin against exact K_max just inside and
outside it and against an independent brute force (a closed-loop matrix with a
fractional delay written here from the physics, no hapstab code); the stiffness margin
against the exact stable set; the damping range against the brute force; the Nyquist
view's critical point; the result protocol and ``check --json``."""

import functools
import json
import math

import matplotlib
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.linalg import expm

import hapstab
from hapstab import Device, HapticLoop, SpringDamper, mass_spring_damper
from hapstab.analysis.margins import certified_stable

M, B_DEV = 0.3, 0.5                      # device: kg, N*s/m
OP = (0.5, 5.0, 500.0)                   # operator msd: kg, N*s/m, N/m
T = 1e-3


def brute_radius(K: float, B: float, delay_samples: float) -> float:
    """Spectral radius of the HVE with an msd operator and a delay of (n + f) T, built
    from the physics: plant [x, v] with total mass, damping and spring, ZOH force -u; the
    controller acts on y_k = x((k - n - f) T) with u = K y_k + (B/T)(y_k - y_{k-1}).
    w_k = x((k - f) T) is a state: w_{k+1} = c (Phi((1-f)T) s_k + Gam((1-f)T) u_k) (the force
    held from kT covers ((k+1-f)T)); y_k = w_{k-n}."""
    Mt, bt, kt = M + OP[0], B_DEV + OP[1], OP[2]
    Ac = np.array([[0.0, 1.0], [-kt / Mt, -bt / Mt]])
    Bc = np.array([[0.0], [1.0 / Mt]])

    def zoh(tau):
        E = expm(np.block([[Ac, Bc], [np.zeros((1, 3))]]) * tau)
        return E[:2, :2], E[:2, 2:]

    n = math.floor(delay_samples + 1e-12)   # 1e-12: a whole delay written as 20.0 stays 20
    f = delay_samples - n
    Phi, Gam = zoh(T)
    Phf, Gaf = zoh((1 - f) * T)
    N = 2 + n + 2                       # s, w_k, ..., w_{k-n-1}
    iy, iy1 = 2 + n, 3 + n              # y_k = w_{k-n}, y_{k-1} = w_{k-n-1}
    u = np.zeros(N)                     # u_k as a row on the state
    u[iy] += K + B / T
    u[iy1] -= B / T
    A = np.zeros((N, N))
    A[:2, :2] = Phi
    A[:2, :] -= Gam @ u[None, :]        # force on the device is -u
    A[2, :2] = Phf[0]
    A[2, :] -= Gaf[0, 0] * u
    for i in range(3, N):               # the registers shift
        A[i, i - 1] = 1.0
    return float(np.max(np.abs(np.linalg.eigvals(A))))


def brute_delay_margin(K, B, d0, step=1 / 32, top=40.0):
    """First extra delay with brute radius >= 1 (grid of 1/32 sample, then bisection)."""
    lo = 0.0
    for x in np.arange(1, int(top / step) + 1) * step:
        if brute_radius(K, B, d0 + x) >= 1:
            hi = x
            for _ in range(30):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if brute_radius(K, B, d0 + mid) < 1 else (lo, mid)
            return lo
        lo = x
    return math.inf


def loop(K=200.0, B=0.5, n=20, f=0.0):
    return HapticLoop(Device(M, B_DEV), SpringDamper(K, B), mass_spring_damper(*OP), T, n, f)


@functools.cache
def margins_200():
    """``margins(loop(200.0), view=False)``, computed once per process: five tests read
    the same (frozen) result, ~0.6 s each time; each still compares it to its own
    reference (the brute force, the exact set, the CLI, a bounded search)."""
    return hapstab.margins(loop(200.0), view=False)


def test_brute_force_agrees_with_hapstab_at_fractional_delays():
    # the reference itself first: its radius against hapstab's at a few fractional delays
    # (1e-9: two eigenvalue solvers of ~25 x 25 matrices of norm ~1)
    for d in (0.0, 3.4, 20.0, 20.73):
        lp = loop(n=int(d), f=d - int(d))
        assert abs(brute_radius(200.0, 0.5, d) - hapstab.stability(lp).spectral_radius) < 1e-9


@pytest.mark.parametrize("K,B,n,f", [(200.0, 0.5, 20, 0.0), (400.0, 2.0, 7, 0.3)])
def test_delay_margin_brackets_exact_kmax_and_matches_brute_force(K, B, n, f):
    lp = loop(K, B, n, f)
    m = margins_200() if lp == loop() else hapstab.margins(lp, view=False)
    dm = m.delay_margin_samples
    assert m.delay_unstable_samples is not None and 0 < dm < m.delay_unstable_samples
    # the bracket is 0.25 / 2^14 samples wide
    assert m.delay_unstable_samples - dm <= 0.25 / 2**14 * (1 + 1e-9)
    # just inside: K_max above K; just outside: below (1e-3 samples is >> the bracket and
    # K_max moves by ~1e-3 |dK_max/dd| there, far beyond its certified enclosure)
    from hapstab.models.variations import extra_delay

    inside = hapstab.critical_stiffness(extra_delay(lp, dm - 1e-3))
    outside = hapstab.critical_stiffness(extra_delay(lp, dm + 1e-3))
    assert inside.critical_stiffness > K > outside.critical_stiffness
    # the independent brute force: grid of 1/32 sample, bisection to 1e-9; agreement to
    # hapstab's bracket, 1.5e-5 samples (the crossing is transversal)
    assert abs(brute_delay_margin(K, B, n + f) - dm) < 0.25 / 2**14 * (1 + 1e-6)
    assert math.isclose(m.delay_margin_s, dm * T)


def test_no_margin_when_unstable_and_stiffness_margin_from_exact_set():
    lp = loop(200.0)
    kmax = hapstab.critical_stiffness(lp)
    m = margins_200()
    lo, hi = m.stiffness_interval
    assert (lo, hi) == tuple(kmax.stable_intervals[0])
    assert math.isclose(m.stiffness_margin, kmax.critical_stiffness / 200.0)
    bad = hapstab.margins(loop(1.01 * kmax.critical_stiffness), view=False)
    assert bad.verdict == "unstable" and bad.delay_margin_samples == 0.0
    assert "not stable at its own parameters" in bad.reason


def test_damping_range_against_brute_force():
    m = margins_200()                                    # loop(200.0, 0.5, 20)
    lo, hi = m.damping_interval
    # the ends are stable, a little beyond is not (brute force; 1e-3 N*s/m is wider than
    # the bisection's bracket: 2^k 1e-3 m/T / 8 / 2^10 ~ 1e-4 N*s/m here)
    for b, sign in ((lo, -1), (hi, 1)):
        assert brute_radius(200.0, b - sign * 1e-3, 20.0) < 1
        assert brute_radius(200.0, b + sign * 1e-3, 20.0) > 1


def test_nyquist_view_crosses_minus_one_over_the_stiffness_margin():
    lp = loop(200.0)
    v = hapstab.frequency_view(lp)
    kmax = hapstab.critical_stiffness(lp).critical_stiffness
    # L = -K G: at K_max the closed loop has a pole on the circle, so L reaches -K/K_max
    # on the negative real axis at the crossing frequency
    f_c = hapstab.critical_stiffness(lp).crossing_frequency_hz
    Lc = hapstab.frequency_view(lp, [f_c]).loop[0]
    assert abs(Lc - (-200.0 / kmax)) < 1e-6
    assert v.open_loop_outside == 0 and v.circle_bound


def test_margin_result_protocol(tmp_path):
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = hapstab.margins(loop(200.0))
    d = m.to_dict()
    json.dumps(d, allow_nan=False)
    assert {"delay_margin_s", "delay_margin_samples", "stiffness_max_N_per_m",
            "damping_min_N_s_per_m"} <= set(d)
    html = m._repr_html_()
    assert " s<" in html and "N/m" in html and "N*s/m" in html and "samples" in html
    m.to_csv(tmp_path / "m.csv")
    m.view.to_csv(tmp_path / "v.csv")
    assert (tmp_path / "v.csv").read_text().startswith("frequency_hz,loop_re")
    axs = m.plot()
    assert len(axs) == 3
    _fig, ax = plt.subplots()
    assert m.view.plot(ax=ax, kind="nyquist") is ax
    plt.close("all")


def test_check_json_has_the_delay_margin():
    from hapstab.cli import cli

    r = CliRunner().invoke(cli, ["check", "hve", "-m", "0.3", "-b", "0.5", "--operator",
                                 "msd:0.5,5,500", "--period", "1ms", "--delay", "20", "-K",
                                 "200", "-B", "0.5", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    m = margins_200()
    assert d["delay_margin_s"] == pytest.approx(m.delay_margin_s, rel=1e-12)
    assert d["verdict"] == "stable" and "spectral_radius" in d
    assert certified_stable(hapstab.stability(loop(200.0)))


def test_a_time_bound_cuts_the_delay_search_and_says_so():
    # the paper's PEB with a massive environment is stable past +100 samples: the search
    # is cut after max_seconds at the delay it reached, which the margin then is
    import dataclasses
    slow = dataclasses.replace(hapstab.paper_peb(delay_samples=3, stiffness=1.0),
                               environment="msd:0.1,1,300",
                               master_controller=SpringDamper(1.0, 0.01),
                               slave_controller=SpringDamper(1.0, 0.01))
    m = hapstab.margins(slow, view=False, max_seconds=0.3)
    assert m.delay_unstable_samples is None
    assert 0 <= m.delay_margin_samples == m.delay_searched_samples < 100
    assert "stopped at" in m.reason and "max_seconds = 0.3 s" in m.reason
    # what it says holds: stable at the delay it reached (certified, as each grid point)
    from hapstab.models.variations import extra_delay
    assert certified_stable(hapstab.stability(extra_delay(slow, m.delay_margin_samples)))
    # a search that ends before the bound is the whole search, unchanged
    whole = margins_200()
    bounded = hapstab.margins(loop(200.0), view=False, max_seconds=600)
    assert bounded.delay_margin_samples == whole.delay_margin_samples
    assert "stopped" not in bounded.reason


def test_check_cuts_the_delay_search_it_was_not_asked_for():
    from hapstab.cli import cli
    from hapstab.cli.exact import AUTO_MARGIN_SECONDS

    args = ["check", "peb", "-n", "3", "-B", "0.01", "--environment", "msd:0.1,1,300", "-K", "1",
            "--json"]
    r = CliRunner().invoke(cli, [*args, "--margin-seconds", "0.2"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    assert "max_seconds = 0.2 s" in d["margins_reason"] and d["delay_unstable_s"] is None
    assert d["delay_searched_s"] == d["delay_margin_s"] < 0.1
    r = CliRunner().invoke(cli, [*args, "--margin-seconds", "0"])
    assert r.exit_code == 2 and "--margin-seconds" in r.output
    assert f"{AUTO_MARGIN_SECONDS:g} s unasked" in CliRunner().invoke(cli, ["check", "peb",
                                                                          "--help"]).output
