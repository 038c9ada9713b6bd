"""Your own haptic device, step by step
====================================

A 0.3 kg handle with 0.5 N*s/m of friction, held by a hand (0.5 kg, 5 N*s/m, 500 N/m),
rendering a virtual wall at 1 kHz behind 20 ms of network delay:

1. how stiff may the wall be (K_max, and why)?
2. does sampling faster help, with that delay (K_max against the rate)?
3. which K and B go together (the K-B region), and the best virtual damping;
4. a wall contact simulated at a stiffness the analysis allows, and the hand on a
   virtual spring just beyond K_max.

Run: ``python examples/your_device.py [OUT_DIR]`` (default ``out/examples``); it prints
what it finds and writes four figures. The same study on the command line is
``hapstab run examples/my_device.toml``.
"""

from __future__ import annotations

import os
import sys

import numpy as np

import hapstab as h
from hapstab.plotting import save_plot

out = sys.argv[1] if len(sys.argv) > 1 else os.path.join("out", "examples")
os.makedirs(out, exist_ok=True)

# %%
# **1. the loop and its K_max**
device = h.Device(mass=0.3, damping=0.5)                    # kg, N*s/m
hand = h.mass_spring_damper(0.5, 5.0, 500.0)                # kg, N*s/m, N/m
loop = h.HapticLoop(device, operator=hand, period=1e-3).with_delay_s(0.020)
kmax = h.critical_stiffness(loop)
print(f"1. K_max = {kmax.critical_stiffness:.1f} N/m at 1 kHz with 20 ms of delay "
      f"({loop.delay_in_samples:g} samples): {kmax.reason}")

# %%
# **2. K_max against the sampling rate, without and with the delay**
rates_hz = np.array([250.0, 500.0, 1000.0, 2000.0, 4000.0])
by_rate = h.boundary(loop, 1.0 / rates_hz, delays_s=[0.0, 0.020], axis="rate")
no_delay, delayed = by_rate.critical_stiffness[:, np.argsort(1.0 / by_rate.periods)]
print("2. K_max (N/m) at " + ", ".join(f"{r:g} Hz" for r in rates_hz))
print("   without delay: " + ", ".join(f"{k:.0f}" for k in no_delay))
print("   with 20 ms:    " + ", ".join(f"{k:.0f}" for k in delayed))
print(f"   sampling 16x faster multiplies K_max by {no_delay[-1] / no_delay[0]:.1f} without "
      f"delay but by {delayed[-1] / delayed[0]:.2f} with it: the delay, not the rate, limits "
      "this wall")
save_plot(by_rate, os.path.join(out, "kmax_vs_rate.png"))

# %%
# **3. the K-B region and the best virtual damping**
region = h.stability_region(loop, (0.0, 2000.0), (0.0, 20.0), resolution=80,
                            overlays=("passivity",))
best = h.best_damping(loop, B_max=20.0)
print(f"3. the largest K_max in the window: {region.kmax().max():.0f} N/m; best damping: "
      f"{best.reason}")
save_plot(region, os.path.join(out, "region.png"))

# %%
# **4. a wall contact inside the stable range; the hand on a spring just beyond it**
inside = h.simulate(loop.with_stiffness(0.8 * kmax.critical_stiffness), 8.0, force="step:2",
                    wall=0.0)
beyond = h.simulate(loop.with_stiffness(1.2 * kmax.critical_stiffness), 8.0, force="step:2")
for what, run in (("wall contact at 0.8 K_max", inside), ("spring held at 1.2 K_max", beyond)):
    v = run.verdict
    print(f"4. {what}: {v.verdict} ({v.behaviour}) -- {v.reason}")
save_plot(inside, os.path.join(out, "wall_inside.png"))
save_plot(beyond, os.path.join(out, "spring_beyond.png"))
print(f"figures in {out}")
