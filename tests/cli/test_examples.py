"""Issue #12: the examples run (as a user would run them) and say what they find; their
numbers agree with an independent check, and their figures are written."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest

import hapstab as h
import paths

ROOT = str(paths.ROOT)


def _run(script, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.path.join(ROOT, "src"), "MPLBACKEND": "Agg"}
    r = subprocess.run([sys.executable, os.path.join(ROOT, "examples", script), str(tmp_path)],
                       env=env, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    return r.stdout


def _png(path):
    return path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _first_unstable(loop, hi, n=4000):
    """Independent: the first K of a fine geometric scan whose closed loop has a pole
    outside the unit circle. The closed-loop matrix is affine in K (the controllers'
    forces are), A(K) = A(1) + (K - 1) (A(2) - A(1)): checked against the matrix built at
    the scan's top, then the scan's eigenvalues are solved in batches."""
    from hapstab.engine.system import build

    def closed(K):
        return build(loop.with_stiffness(K)).closed_loop()[0]

    a1, a2 = closed(1.0), closed(2.0)
    step = a2 - a1
    top = closed(hi)
    # the affine form's rounding: ~hi * eps of the matrix's largest entry
    assert np.allclose(a1 + (hi - 1.0) * step, top, rtol=0,
                       atol=1e-10 * max(1.0, np.abs(top).max()))
    Ks = np.geomspace(1.0, hi, n)
    for at in range(0, n, 500):
        chunk = Ks[at:at + 500]
        rho = np.abs(np.linalg.eigvals(a1 + (chunk - 1.0)[:, None, None] * step)).max(axis=1)
        if (rho >= 1).any():
            return float(chunk[np.argmax(rho >= 1)])
    return np.inf


def test_your_device(tmp_path):
    out = _run("your_device.py", tmp_path)
    kmax = float(re.search(r"1\. K_max = ([\d.]+) N/m", out).group(1))
    loop = h.HapticLoop(h.Device(0.3, 0.5), operator=h.mass_spring_damper(0.5, 5, 500),
                        period=1e-3).with_delay_s(0.02)
    scan = _first_unstable(loop, 2000.0)
    assert kmax <= scan <= kmax * 1.003   # the scan's step is 0.25 %
    assert "the delay, not the rate, limits this wall" in out
    assert "4. wall contact at 0.8 K_max: bounded" in out
    assert "4. spring held at 1.2 K_max: unbounded (grows)" in out
    for f in ("kmax_vs_rate", "region", "wall_inside", "spring_beyond"):
        assert _png(tmp_path / f"{f}.png"), f


def test_teleoperation(tmp_path):
    out = _run("teleoperation.py", tmp_path)
    values = [float(v) for v in re.search(r"2\. K_max \(N/m\) at .*: ([\d, ]+)\n", out)
              .group(1).split(",")]
    loop = h.TeleoperationLoop(h.Device(0.3, 2.0), h.Device(1.0, 5.0),
                               operator=h.mass_spring_damper(0.5, 5.0, 500.0),
                               environment=h.spring(20000.0), period=1e-3)
    for d, k in zip((0.0, 0.002, 0.005, 0.010, 0.020), values, strict=True):
        scan = _first_unstable(loop.with_delay_s(d), 20000.0, 3000)
        assert k <= scan * 1.0005 and scan <= k * 1.004 + 1    # printed to 1 N/m; step 0.33 %
    assert "grid cross-check: 0 of" in out and "4. contact at 0.7 K_max: bounded" in out
    for f in ("teleoperation_kmax_vs_rate", "teleoperation_region", "teleoperation_contact"):
        assert _png(tmp_path / f"{f}.png"), f


@pytest.mark.parametrize("study", ["my_device.toml"])
def test_the_example_study_runs(study, tmp_path):
    from click.testing import CliRunner

    from hapstab.cli.main import cli

    r = CliRunner().invoke(cli, ["run", os.path.join(ROOT, "examples", study), "--out",
                                 str(tmp_path / "results")])
    assert r.exit_code == 0, r.stderr
    assert (tmp_path / "results" / "manifest.json").exists()
    assert _png(tmp_path / "results" / "damped" / "region.png")
