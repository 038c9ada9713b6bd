"""Issue #13, item 4: transparency of the sampled-data teleoperator. References it is
checked against, none taken from hapstab.analysis.teleoperation.transparency: the continuous-time PEB
(Newton's law for each device, solved here), the two-port P of eq. (30) written out by
hand with the textbook h-parameter identities, the statics of the springs, and the exact
sampled-data loop in the time domain (hapstab's simulator)."""

import csv
import io
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli


def _peb(T=1e-3, n=0, Km=10.0, Bm=0.0, Ks=None, Bs=None, env=None, nb=None, bm=0.02, bs=0.03,
         mm=0.015, ms=0.02):
    return h.TeleoperationLoop(
        h.Device(mm, bm), h.Device(ms, bs), h.SpringDamper(Km, Bm),
        h.SpringDamper(Km if Ks is None else Ks, Bm if Bs is None else Bs),
        h.spring(1.0), h.spring(1.0) if env is None else env, T, n, delay_backward_samples=nb)


# ------------------------------------------------------------ continuous-time limit
def _ct_hybrid(s, bm, bs, mm, ms, C):
    """PEB in continuous time, C = K + B s acting on the position error, by Newton:
    master  mm s V_m = F_h - bm V_m - (C/s)(V_m - V_s),
    slave   ms s V_s = -F_e - bs V_s - (C/s)(V_s - V_m)   (F_e: the slave's force on the
    environment). With D = ms s + bs + C/s the slave gives V_s = ((C/s) V_m - F_e) / D, so
    [F_h; -V_s] = H [V_m; F_e] with
    h11 = mm s + bm + C/s - (C/s)^2 / D, h12 = (C/s)/D, h21 = -(C/s)/D, h22 = 1/D."""
    c, D = C / s, ms * s + bs + C / s
    return np.stack([np.stack([mm * s + bm + c - c * c / D, c / D], -1),
                     np.stack([-c / D, 1 / D], -1)], -2)


@pytest.mark.parametrize("K,B,ke", [(50.0, 0.0, 200.0), (200.0, 0.3, 5.0), (5.0, 1.0, 0.0)])
def test_as_T_goes_to_0_it_is_the_continuous_time_teleoperator(K, B, ke):
    bm, bs, mm, ms, T = 0.4, 1.5, 0.2, 1.0, 1e-6
    loop = _peb(T, 0, K, B, env=h.spring(ke) if ke else h.NO_IMPEDANCE, bm=bm, bs=bs, mm=mm,
                ms=ms)
    f = np.geomspace(0.01, 200.0, 40)                   # Hz; theta = w T <= 1.3e-3
    res = h.transparency(loop, frequencies_hz=f)
    s, C = 2j * np.pi * f, K + B * 2j * np.pi * f
    Hct = _ct_hybrid(s, bm, bs, mm, ms, C)
    # the two-port of the continuous-time loop: P = [[bm + C/s, -C/s], [-C/s, bs + C/s]]
    Pct = np.stack([np.stack([bm + C / s, -C / s], -1), np.stack([-C / s, bs + C / s], -1)], -2)
    ct_free, ct_rigid = Hct[:, 0, 0], mm * s + bm + C / s
    c, D = C / s, ms * s + bs + C / s
    ct_env, ct_track = mm * s + bm + c - c * c / (D + ke / s), c / (D + ke / s)
    # the sampled loop differs by the hold's half-sample lag e^{-j theta/2} in X and by
    # B's backward difference: each term C/s is off by at most theta (relative); the felt
    # impedance subtracts two terms of size |C|/w, so its error is within a few theta
    # times |C|/w (3x: the terms and the rounding of their difference), plus theta |ref|
    theta = (2 * np.pi * f * T)[:, None, None]
    scale = np.abs(C / s)[:, None, None]
    for got, ref in [(res.impedance, Pct), (res.hybrid, Hct)]:
        assert np.all(np.abs(got - ref) <= 3 * theta * (scale + np.abs(ref)))
    for got, ref in [(res.felt_free, ct_free), (res.felt_rigid, ct_rigid),
                     (res.felt_environment, ct_env), (res.tracking, ct_track)]:
        assert np.all(np.abs(got - ref) <= 3 * theta[:, 0, 0] * (scale[:, 0, 0] + np.abs(ref)))
    # and the comparison can fail: a different B is caught
    assert not np.allclose(res.felt_free, mm * s + bm + (C + 0.1 * s) / s
                           - ((C + 0.1 * s) / s) ** 2 / (D + 0.1), rtol=1e-2)


@pytest.mark.parametrize("a", ["forward", "backward", "tustin"])
@pytest.mark.parametrize("nf,nb", [(0, 0), (2, 5)])
def test_in_free_motion_the_delay_is_felt_as_damping(a, nf, nb):
    """As w -> 0 in free motion, with c_i = X C_i and c_i -> K_i / s,
    Z_t = b_m + c_m - c_m c_s z^-(nf+nb) / (b_s + m_s s + c_s)
        = b_m + c_m [1 - (1 - s (nf + nb) T)(1 - (b_s + m_s s) / c_s)] + O(s)
        -> b_m + (K_m / K_s) b_s + K_m (nf + nb) T:
    the operator feels the master's damping, the slave's scaled, and the round trip's
    delay as a damper K_m t_rt (X's half-sample lead or lag cancels between p11 and the
    coupling term, and B's difference is O(s))."""
    loop = _peb(1e-3, nf, 30.0, 0.05, 20.0, 0.02, env=h.NO_IMPEDANCE, nb=nb)
    res = h.transparency(loop, a, frequencies_hz=[1e-3, 1.0])
    expected = 0.02 + 30.0 / 20.0 * 0.03 + 30.0 * (nf + nb) * 1e-3
    # the next term is O(w^2): measured 4e-8 relative at 1e-3 Hz, 1e-6 leaves room
    assert res.felt_free[0].real == pytest.approx(expected, rel=1e-6)
    assert abs(res.felt_free[1].real - expected) > 1e-4 * expected    # 1 Hz is not DC


# -------------------------------------------------------------- eq. (30) by hand
def _x_hand(a, z, T):
    return {"forward": T / (z - 1), "backward": T * z / (z - 1),
            "tustin": T / 2 * (z + 1) / (z - 1)}[a]


def _p_hand(loop, a, f):
    """P = diag(bm, bs) + X(z) [[C_m, -z^-nb C_m], [-z^-nf C_s, C_s]] (eq. 30, with the
    slave -> master delay nb in the master's channel), C(z) = K + B (1 - z^-1) / T."""
    T = loop.period
    z = np.exp(2j * np.pi * f * T)
    X = _x_hand(a, z, T)
    cm, cs = loop.master_controller, loop.slave_controller
    Cm = cm.stiffness + cm.damping * (1 - 1 / z) / T
    Cs = cs.stiffness + cs.damping * (1 - 1 / z) / T
    nf, nb = round(loop.forward_delay_in_samples), round(loop.backward_delay_in_samples)
    return np.stack([np.stack([loop.master.damping + X * Cm, -X * z ** -nb * Cm], -1),
                     np.stack([-X * z ** -nf * Cs, loop.slave.damping + X * Cs], -1)], -2)


@pytest.mark.parametrize("a", ["forward", "backward", "tustin"])
@pytest.mark.parametrize("nf,nb", [(0, 0), (3, 3), (2, 5)])
def test_the_two_port_hybrid_matrix_and_felt_impedances_match_eq_30_by_hand(a, nf, nb):
    env = h.mass_spring_damper(0.05, 0.4, 300.0)
    loop = _peb(1e-3, nf, 40.0, 0.05, 25.0, 0.1, env=env, nb=nb)
    res = h.transparency(loop, a)
    f = res.frequencies_hz
    P, s = _p_hand(loop, a, f), 2j * np.pi * f
    mm, ms = loop.master.mass, loop.slave.mass
    # z - 1 computed naively loses eps / theta (3e-13 at the grid's first angle): 1e-9 is
    # far above that and far below any modelling difference
    assert res.impedance == pytest.approx(P, rel=1e-9)
    # textbook identities in the orientation [F_h; F_e] = Z' [V_m; -V_s]: z'12 = -p12,
    # z'21 = -p21, and the masses on the diagonal
    z11, z12, z21, z22 = mm * s + P[:, 0, 0], -P[:, 0, 1], -P[:, 1, 0], ms * s + P[:, 1, 1]
    Hh = np.stack([np.stack([z11 - z12 * z21 / z22, z12 / z22], -1),
                   np.stack([-z21 / z22, 1 / z22], -1)], -2)
    assert res.hybrid == pytest.approx(Hh, rel=1e-9)
    Ze = 0.05 * s + 0.4 + 300.0 / s
    assert res.felt_rigid == pytest.approx(mm * s + P[:, 0, 0], rel=1e-9)
    assert res.felt_free == pytest.approx(
        mm * s + P[:, 0, 0] - P[:, 0, 1] * P[:, 1, 0] / (P[:, 1, 1] + ms * s), rel=1e-9)
    assert res.felt_environment == pytest.approx(
        mm * s + P[:, 0, 0] - P[:, 0, 1] * P[:, 1, 0] / (P[:, 1, 1] + ms * s + Ze), rel=1e-9)
    assert res.tracking == pytest.approx(-P[:, 1, 0] / (P[:, 1, 1] + ms * s + Ze), rel=1e-9)
    assert res.tracking_error == pytest.approx(1 - res.tracking, rel=1e-12)
    # Hannaford's terminated two-port, from the result's own H: the same numbers
    H = res.hybrid
    assert res.felt_environment == pytest.approx(
        H[:, 0, 0] - H[:, 0, 1] * H[:, 1, 0] * Ze / (1 + H[:, 1, 1] * Ze), rel=1e-7)


def test_a_discrete_controller_gives_what_its_spring_damper_gives():
    loop = _peb(1e-3, 2, 30.0, 0.05, 20.0, 0.02)
    T = loop.period
    dc = [h.DiscreteController(*c.transfer(T)) for c in loop.controllers]
    a = h.transparency(loop)
    b = h.transparency(loop.replace(master_controller=dc[0], slave_controller=dc[1]))
    assert b.felt_environment == pytest.approx(a.felt_environment, rel=1e-9)
    assert b.felt_stiffness_environment == pytest.approx(a.felt_stiffness_environment, rel=1e-12)


# ------------------------------------------------------------------------- statics
@pytest.mark.parametrize("Km,Ks,ke", [(10.0, 10.0, 30.0), (10.0, 40.0, 5.0), (7.0, 2.0, 0.0)])
def test_the_static_felt_stiffness_and_tracking(Km, Ks, ke):
    """Statics by hand (w -> 0: no velocities, delayed positions equal the current ones):
    master F = K_m (x_m - x_s); slave 0 = K_s (x_s - x_m) + k_e x_s. So
    x_s / x_m = K_s / (K_s + k_e) and F / x_m = K_m k_e / (K_s + k_e): against a rigid
    environment (k_e -> inf) the operator feels K_m alone, not the series
    K_m K_s / (K_m + K_s) -- the slave is held, only the master's spring stretches; with
    equal controllers and a spring k_e it is the series K k_e / (K + k_e); free (k_e = 0)
    nothing, and the slave tracks exactly."""
    loop = _peb(1e-3, 4, Km, 0.02, Ks, 0.02, env=h.spring(ke) if ke else h.NO_IMPEDANCE)
    f = np.array([1e-4, 1.0])
    res = h.transparency(loop, frequencies_hz=f)
    assert res.felt_stiffness_rigid == pytest.approx(Km, rel=1e-12)
    assert res.felt_stiffness_free == pytest.approx(0.0, abs=1e-12 * Km)
    assert res.felt_stiffness_environment == pytest.approx(Km * ke / (Ks + ke), rel=1e-12,
                                                           abs=1e-12 * Km)
    assert res.static_tracking == pytest.approx(Ks / (Ks + ke), rel=1e-12)
    # the curves agree at 1e-4 Hz: Re(jw Z) = k - w^2 m + O(w^2), w^2 m ~ 1e-8 N/m
    jw = 2j * np.pi * f[0]
    assert (jw * res.felt_rigid[0]).real == pytest.approx(Km, rel=1e-6)
    assert (jw * res.felt_environment[0]).real == pytest.approx(Km * ke / (Ks + ke), abs=1e-6)
    # tracking lags at first order in w: w (nT + T/2 + (bs + Bs) / Ks) <= 1.9e-5 rad here
    assert res.tracking[0] == pytest.approx(Ks / (Ks + ke), abs=3e-5)
    if ke == 0:
        assert abs(res.tracking_error[0]) < 3e-5          # (the same lag)
        assert abs(res.tracking_error[1]) > 1e-3          # and it grows: 1 Hz is not DC


def test_the_static_stiffness_agrees_with_the_exact_sampled_loop_in_time():
    """A constant force F on the master, no operator, a spring environment: the exact
    sampled-data simulation settles at x_m = F / K_felt."""
    loop = _peb(1e-3, 3, 20.0, 0.05, 20.0, 0.05, env=h.spring(60.0), bm=0.5, bs=0.5)
    loop = loop.replace(operator=h.NO_IMPEDANCE)
    K_felt = h.transparency(loop).felt_stiffness_environment
    assert K_felt == pytest.approx(20.0 * 60.0 / 80.0, rel=1e-12)
    sim = h.simulate(loop, 5.0, force=1.0)
    x_m, x_s = sim.position[-1]
    # settled: the slowest pole decays within a second here; 1e-6 relative is far above
    # what is left after 5 s and far below a wrong stiffness
    assert 1.0 / x_m == pytest.approx(K_felt, rel=1e-6)
    assert x_s / x_m == pytest.approx(h.transparency(loop).static_tracking, rel=1e-6)


def _felt_in_time(loop, f_hz, periods=10):
    """F / V_m at f_hz of the exact sampled-data loop (hapstab's simulator, no operator):
    a sinusoidal force held over each sample, the steady state's fundamental (least
    squares over whole periods, after 4 s of settling) of the force and of the master's
    velocity at the samples; the held force's fundamental is its samples' times
    sinc(w T / 2) e^{-j w T / 2}."""
    w, T = 2 * np.pi * f_hz, loop.period
    sim = h.simulate(loop, 4.0 + periods / f_hz, force=lambda t: np.sin(w * t))
    last = slice(len(sim.time) - round(periods / f_hz / T), None)
    t = sim.time[last]
    A = np.stack([np.cos(w * t), np.sin(w * t)], 1)

    def phasor(y):
        c = np.linalg.lstsq(A, y[last], rcond=None)[0]
        return c[0] - 1j * c[1]

    held = np.sinc(w * T / 2 / np.pi) * np.exp(-0.5j * w * T)
    return phasor(np.ravel(sim.exogenous_force[:, 0])) * held / phasor(sim.velocity[:, 0])


def test_the_felt_impedance_against_the_exact_sampled_loop_at_5_and_20_hz():
    """The fundamental-frequency picture ignores aliasing; with the forward approximation
    it is close to the sampled loop below a tenth of the Nyquist frequency (measured, T = 1
    ms, n = 2: 1e-4 at 5 Hz, 1.2e-3 at 20 Hz, 8e-3 at 50 Hz, 3.5e-2 at 100 Hz); backward
    differs by 1.8e-2 already at 5 Hz."""
    loop = h.TeleoperationLoop(h.Device(0.015, 0.5), h.Device(0.015, 0.5),
                               h.SpringDamper(20.0, 0.05), h.SpringDamper(20.0, 0.05),
                               h.NO_IMPEDANCE, h.spring(60.0), 1e-3, 2)
    for f_hz, rel in [(5.0, 1e-3), (20.0, 5e-3)]:      # 10x and 4x the measured differences
        exact = _felt_in_time(loop, f_hz)
        got = h.transparency(loop, frequencies_hz=[f_hz]).felt_environment[0]
        assert got == pytest.approx(exact, rel=rel)
    backward = h.transparency(loop, "backward", frequencies_hz=[5.0]).felt_environment[0]
    assert backward != pytest.approx(_felt_in_time(loop, 5.0), rel=1e-2)


# --------------------------------------------------------------------- errors, API
def test_named_errors():
    peb = _peb()
    with pytest.raises(h.AnalysisError, match="kind 'hve'; allowed: 'peb'"):
        h.transparency(h.paper_hve())
    with pytest.raises(h.ArgumentTypeError, match="loop = 3"):
        h.transparency(3)
    with pytest.raises(h.AnalysisError, match="approximation = 'bilinear'"):
        h.transparency(peb, "bilinear")
    with pytest.raises(h.AnalysisError, match=r"above the Nyquist frequency 1/\(2T\) = 500 Hz"):
        h.transparency(peb, frequencies_hz=[1.0, 501.0])
    with pytest.raises(h.ModelError, match="frequencies_hz"):
        h.transparency(peb, frequencies_hz=[])
    with pytest.raises(h.ModelError, match="frequencies_hz"):
        h.transparency(peb, frequencies_hz=[1.0, -1.0])
    with pytest.raises(h.ArgumentTypeError, match="frequencies_hz"):
        h.transparency(peb, frequencies_hz="fast")
    with pytest.raises(h.AnalysisError, match=r"whole-sample delays.*delay forward 1\.5"):
        h.transparency(peb.with_delays_s(1.5e-3))
    with pytest.raises(h.ModelError, match="environment"):
        h.transparency(peb, environment="bogus")


def test_the_grid_the_environment_argument_and_a_pole_of_the_environment():
    peb = _peb(1e-3, 6)
    res = h.transparency(peb)
    f = res.frequencies_hz
    assert f[-1] == pytest.approx(500.0, rel=1e-12) and f[0] == pytest.approx(0.05, rel=1e-12)
    assert np.all(np.diff(np.log(f)) > 0) and f.size == 40 * (6 + 6 + 2)
    assert h.transparency(peb, frequencies_hz=[3.0, 1.0, 3.0]).frequencies_hz.tolist() == [1, 3]
    # an LC environment s / (s^2 + w0^2) has a pole at w0: there it clamps the slave
    w0 = 2 * np.pi * 10.0
    res = h.transparency(peb, frequencies_hz=[5.0, 10.0], environment=([1.0, 0.0], [1.0, 0.0, w0**2]))
    assert res.felt_environment[1] == res.felt_rigid[1] and res.tracking[1] == 0
    assert res.felt_environment[0] != res.felt_rigid[0]
    assert res.environment.label == "custom" and peb.environment.label.startswith("spring")


def test_the_result_protocol(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # K_s = 0 in free motion: the static limits are undefined (NaN, null in JSON)
    loop = _peb(1e-3, 2, 5.0, 0.01, 0.0, 0.01, env=h.NO_IMPEDANCE)
    res = h.transparency(loop, frequencies_hz=np.geomspace(0.1, 500, 30))
    assert math.isnan(res.felt_stiffness_free) and math.isnan(res.static_tracking)
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert d["felt_stiffness_N_per_m"]["free"] is None and d["static_tracking"] is None
    assert len(d["tracking"]) == 30 and set(d["tracking"][0]) == {"re", "im"}
    assert d["hybrid"]["h21"][4]["re"] == pytest.approx(res.hybrid[4, 1, 0].real, rel=1e-15)
    assert set(d["impedance_N_s_per_m"]) == {"p11", "p12", "p21", "p22"}
    buf = io.StringIO()
    res.to_csv(buf)
    rows = list(csv.reader(io.StringIO(buf.getvalue())))
    assert rows[0][:3] == ["frequency_hz", "felt_free_N_s_per_m_re", "felt_free_N_s_per_m_im"]
    assert len(rows) == 31 and len(rows[0]) == 17
    assert float(rows[5][7]) == pytest.approx(res.tracking[4].real)
    axes = res.plot()
    assert len(axes) == 3 and all(a.has_data() for a in axes)
    _fig, given = plt.subplots(3, 1)
    assert list(res.plot(given)) == list(given)
    plt.close("all")
    page = res._repr_html_()
    assert page.startswith("<table>") and "TransparencyResult" in page


# ----------------------------------------------------------------------------- CLI
def test_the_cli(tmp_path):
    args = ["transparency", "peb", "-K", "8", "-n", "2", "--environment", "spring:50",
            "--frequencies", "0.5:200:25", "--csv", str(tmp_path / "t.csv"),
            "--plot", str(tmp_path / "t.png"), "--json"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["felt_stiffness_N_per_m"] == pytest.approx(
        {"free": 0.0, "environment": 8 * 50 / 58, "rigid": 8.0}, abs=1e-12)
    f = np.array(d["frequencies_hz"])
    assert f.size == 25 and f[0] == pytest.approx(0.5) and f[-1] == pytest.approx(200.0)
    assert np.diff(np.log(f)) == pytest.approx(np.full(24, np.log(400) / 24))   # log-spaced
    loop = h.paper_peb(1e-3, 2, 8.0).replace(environment=h.spring(50.0))
    ref = h.transparency(loop, frequencies_hz=f)
    got = np.array([c["re"] + 1j * c["im"] for c in d["felt_impedance_N_s_per_m"]["environment"]])
    assert got == pytest.approx(ref.felt_environment, rel=1e-12)
    assert (tmp_path / "t.png").read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "t.csv").read_text().startswith("frequency_hz,")
    r = CliRunner().invoke(cli, ["transparency", "peb", "-K", "8"])
    assert r.exit_code == 0 and "felt stiffness" in r.stdout
    for bad, word in [(["--frequencies", "1:600"], "--frequencies"),
                      (["--frequencies", "x"], "--frequencies"),
                      (["--approximation", "bilinear"], "approximation")]:
        r = CliRunner().invoke(cli, ["transparency", "peb", "-K", "8", *bad])
        assert r.exit_code == 2 and len(r.stderr.splitlines()) == 1, r.stderr
        assert r.stderr.startswith("hapstab: error: ") and word in r.stderr
    r = CliRunner().invoke(cli, ["transparency", "peb"])
    assert r.exit_code == 2 and "--stiffness" in r.stderr
