"""Position-error-based teleoperation over a network, step by step
===============================================================

A light master and a heavier slave (0.3 kg / 1 kg), a hand on the master (0.5 kg,
5 N*s/m, 500 N/m) and a stiff object at the slave (20,000 N/m), coupled by
C_m = C_s = K + B(z-1)/(Tz) at 1 kHz:

1. K_max of the coupling with 5 samples of delay each way, and why;
2. how K_max falls with the round-trip delay (fixed in milliseconds, at 1 kHz);
3. the K-B region, with the circle criterion and passivity drawn for comparison;
4. a contact simulated at a K the analysis allows.

Run: ``python examples/teleoperation.py [OUT_DIR]`` (default ``out/examples``).
"""

from __future__ import annotations

import os
import sys

import hapstab as h
from hapstab.plotting import save_plot

out = sys.argv[1] if len(sys.argv) > 1 else os.path.join("out", "examples")
os.makedirs(out, exist_ok=True)

# %%
# **1. the teleoperator and its K_max**
loop = h.TeleoperationLoop(
    master=h.Device(0.3, 2.0), slave=h.Device(1.0, 5.0),
    operator=h.mass_spring_damper(0.5, 5.0, 500.0), environment=h.spring(20000.0),
    period=1e-3, delay_samples=5)
kmax = h.critical_stiffness(loop)
print(f"1. K_max = {kmax.critical_stiffness:.1f} N/m with 5 ms each way: {kmax.reason}")

# %%
# **2. against the one-way delay (milliseconds, fixed while T stays 1 ms)**
delays_s = [0.0, 0.002, 0.005, 0.010, 0.020]
by_delay = h.boundary(loop, [1e-3], delays_s=delays_s)
print("2. K_max (N/m) at one-way delays of " + ", ".join(f"{d * 1e3:g} ms" for d in delays_s)
      + ": " + ", ".join(f"{k:.0f}" for k in by_delay.critical_stiffness[:, 0]))
print("   not monotone: a longer delay can move the crossing past the environment's "
      "resonance (each value checked against a scan of the closed loop's eigenvalues in "
      "tests/cli/test_examples.py)")
rates = h.boundary(loop, [2.5e-4, 5e-4, 1e-3, 2e-3], delays_s=[0.005], axis="rate")
save_plot(rates, os.path.join(out, "teleoperation_kmax_vs_rate.png"))

# %%
# **3. the K-B region**
region = h.stability_region(loop, (0.0, 8000.0), (0.0, 60.0), resolution=80,
                            overlays=("passivity", "circle"))
print(f"3. K_max at B = 0: {region.kmax()[0]:.0f} N/m; the largest in the window: "
      f"{region.kmax().max():.0f} N/m at B = {region.B_rows[region.kmax().argmax()]:.3g} N*s/m; "
      f"grid cross-check: {region.agreement['disagree']} of {region.agreement['compared']} "
      "points differ")
save_plot(region, os.path.join(out, "teleoperation_region.png"))

# %%
# **4. a contact at 70 % of K_max**
run = h.simulate(loop.with_stiffness(0.7 * kmax.critical_stiffness), 4.0, force="step:1")
v = run.verdict
print(f"4. contact at 0.7 K_max: {v.verdict} ({v.behaviour}) -- {v.reason}")
save_plot(run, os.path.join(out, "teleoperation_contact.png"))
print(f"figures in {out}")
