"""The Z-width (issue 14, item 5): passive and stable virtual walls over B and the
impedance a wall displays, against references derived here."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from scipy import signal

import hapstab as h
from hapstab.analysis.design.zwidth import displayed_impedance, zwidth
from hapstab.cli.main import cli
from hapstab.errors import HapstabError


def _paper(B=0.5, n=0, c=None):
    return h.HapticLoop(h.Device(0.15, 0.1), c or h.SpringDamper(100.0, B), h.spring(1.0),
                        period=1e-3, delay_samples=n)


def _first_harmonic(loop, f_hz, periods=400):
    """F/X at f_hz from the sampled, held force itself: x(kT) = sin(w kT) through H
    (scipy's lfilter) and n samples of delay, the ZOH's staircase integrated exactly
    against e^{-jwt} over the last whole periods (transients long gone)."""
    T, n = loop.period, loop.delay_samples
    w = 2 * np.pi * f_hz
    N = round(periods / (f_hz * T))
    k = np.arange(N)
    x = np.sin(w * k * T)
    num, den = loop.controller.transfer(T)
    u = signal.lfilter(num, den, x)
    u = np.concatenate([np.zeros(n), u[:N - n]])
    last = k >= N // 2
    # int_{kT}^{(k+1)T} e^{-jwt} dt = e^{-jwkT} (1 - e^{-jwT}) / (jw)
    seg = np.exp(-1j * w * k * T) * (1 - np.exp(-1j * w * T)) / (1j * w)
    U = np.sum(u[last] * seg[last])
    # x(t) = sin(wt) has the coefficient 1/(2j) on e^{jwt}: over the span, span/(2j)
    span = last.sum() * T
    return U / (span / 2j)


@pytest.mark.parametrize("c,n", [(h.SpringDamper(100.0, 0.5), 0), (h.SpringDamper(50.0, 1.0), 4),
                                 (h.FilteredSpringDamper(80.0, 0.8, "lowpass:60"), 2),
                                 (h.FilteredSpringDamper(80.0, 0.8, "average:5"), 0)])
def test_displayed_impedance_is_the_held_forces_first_harmonic(c, n):
    loop = _paper(n=n, c=c)
    for f in (1.0, 8.0, 40.0, 125.0):       # 1/(fT) whole: whole periods in whole samples
        ks, bs = displayed_impedance(loop, [f])
        fx = _first_harmonic(loop, f)
        # the same quantity computed two ways; the sum over whole periods leaves only
        # the rounding of ~1e5 terms (and a low-pass transient e^{-2 pi f_c t}, gone)
        assert ks[0] == pytest.approx(fx.real, rel=1e-7, abs=1e-7 * abs(fx))
        assert bs[0] * 2 * np.pi * f == pytest.approx(fx.imag, rel=1e-7, abs=1e-7 * abs(fx))


def test_displayed_impedance_at_low_frequency():
    # K and B - K (n + 1/2) T: the delay and the hold take damping away
    T, K, B, n = 1e-3, 200.0, 0.6, 3
    ks, bs = displayed_impedance(_paper(n=n, c=h.SpringDamper(K, B)), [0.01])
    assert ks[0] == pytest.approx(K, rel=1e-6)
    assert bs[0] == pytest.approx(B - K * (n + 0.5) * T, rel=1e-6)


def test_rows_are_the_passivity_and_exact_limits():
    loop = _paper(n=0)
    res = zwidth(loop, K=(0, 400), B=(0.0, 0.09), resolution=4)
    # eq. (1) of the paper: 2 (b - B) / T for 0 <= B < b, n = 0
    assert np.allclose(res.K_passive, 2 * (0.1 - res.B_rows) / 1e-3, rtol=1e-9)
    for B, ks in zip(res.B_rows, res.K_stable, strict=True):
        want = h.critical_stiffness(loop.with_controllers(h.SpringDamper(0, float(B))))
        assert ks == pytest.approx(want.critical_stiffness, rel=1e-12)   # batched: last digits
    assert np.all(res.K_passive <= res.K_stable)   # passive => stable with a passive operator


def test_filtered_rows_keep_the_filter():
    c = h.FilteredSpringDamper(0, 0.5, "lowpass:80")
    loop = _paper(n=2, c=c)
    res = zwidth(loop, K=(0, 400), B=(0.2, 0.6), resolution=3)
    for B, kp, ks in zip(res.B_rows, res.K_passive, res.K_stable, strict=True):
        lb = loop.with_controllers(h.FilteredSpringDamper(0, float(B), "lowpass:80"))
        assert kp == h.critical_stiffness(lb, method="passivity").critical_stiffness
        assert ks == pytest.approx(h.critical_stiffness(lb).critical_stiffness, rel=1e-12)


def test_refusals():
    peb = h.paper_peb(1e-3, 2)
    with pytest.raises(HapstabError, match="hve"):
        zwidth(peb, K=(0, 10), B=(0, 1))
    with pytest.raises(HapstabError, match="resolution"):
        zwidth(_paper(), K=(0, 10), B=(0, 1), resolution=1)
    with pytest.raises(HapstabError, match="Nyquist"):
        displayed_impedance(_paper(), [600.0])


def test_cli_zwidth(tmp_path):
    out = tmp_path / "zw.png"
    r = CliRunner().invoke(cli, ["zwidth", "hve", "--K", "0:400", "--B", "0:1", "--rows", "5",
                                 "--plot", str(out), "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert len(d["rows"]["virtual_damping_N_s_per_m"]) == 5 and out.stat().st_size > 0


def test_friction_and_encoder_point_at_zero_damping():
    # Abbott and Okamura: K <= min(2 b/T, 2 f_c/Delta), worked by hand: min(200, 100)
    loop = h.HapticLoop(h.Device(0.15, 0.1, coulomb_friction=0.005), h.SpringDamper(0, 0),
                        h.spring(1.0), period=1e-3)
    res = zwidth(loop, K=(0, 400), B=(0, 1), resolution=3, resolution_m=1e-4)
    assert res.K_quantised == pytest.approx(100.0, rel=1e-12)
    # its assumptions exclude a delay: no point, and the reason says why
    res = zwidth(loop.replace(delay_samples=2), K=(0, 400), B=(0, 1), resolution=3,
                 resolution_m=1e-4)
    assert res.K_quantised is None and "does not apply" in res.nonlinear_reason
