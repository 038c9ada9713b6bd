"""Seeded random loops of many structures in one list, for the batched exact core
(``critical_stiffness_many``) and its campaign: HVE, PEB (equal and unequal
controllers, asymmetric delays, scaled), 4-channel, free masses, filtered velocity,
fractional delays, delays 0-30 samples, masses and dampings over decades, B of both
signs, operators none / spring / msd, stiff environments, rates 100 Hz - 10 kHz.

Only hapstab's model classes are used (the answers are checked elsewhere: against
``critical_stiffness`` one loop at a time, and against :mod:`references.brute`).
"""

from __future__ import annotations

import math

import numpy as np

import hapstab as h
from hapstab.models.controllers import FilteredSpringDamper
from hapstab.models.fourchannel import FourChannelLoop
from references.campaign import spring_damper

SEED = 16_0002


def _logu(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(math.log(lo), math.log(hi))))


def _term(rng: np.random.Generator, env: bool) -> str:
    u = rng.uniform()
    if u < 0.3:
        return "none"
    k = _logu(rng, 1.0, 1e6) if env else _logu(rng, 0.01, 3e3)      # stiff walls up to 1e6 N/m
    if u < 0.65:
        return f"spring:{k:.6g}"
    return f"msd:{_logu(rng, 1e-3, 2.0):.6g},{_logu(rng, 1e-4, 20.0):.6g},{k:.6g}"


def _B(rng: np.random.Generator, b: float) -> float:
    """Virtual damping from -0.95 b (negative) through 0 to 5 b."""
    u = rng.uniform()
    if u < 0.2:
        return float(-rng.uniform(0.01, 0.95) * b)
    if u < 0.35:
        return 0.0
    return _logu(rng, 1e-2, 5.0) * b


def _delay(rng: np.random.Generator, most: int) -> int:
    return int(rng.integers(0, 5)) if rng.uniform() < 0.6 else int(rng.integers(5, most + 1))


def _controller(rng: np.random.Generator, K: float, B: float):
    """A spring-damper, sometimes with a filtered velocity (only with B >= 0)."""
    u = rng.uniform()
    if B > 0 and u < 0.15:
        return FilteredSpringDamper(K, B, f"lowpass:{_logu(rng, 20.0, 2000.0):.5g}")
    if B > 0 and u < 0.22:
        return FilteredSpringDamper(K, B, f"average:{int(rng.integers(2, 6))}")
    return spring_damper(K, B)


def random_loop(rng: np.random.Generator, most_delay: int = 30):
    """One loop of a random kind and structure (see the module docstring)."""
    kind = rng.uniform()
    m, b = _logu(rng, 1e-3, 10.0), _logu(rng, 1e-4, 5.0)
    T = 1.0 / _logu(rng, 100.0, 1e4)
    n = _delay(rng, most_delay)
    if kind < 0.4:
        frac = float(rng.uniform(0.05, 0.95)) if rng.uniform() < 0.15 else 0.0
        return h.HapticLoop(h.Device(m, b), _controller(rng, 1.0, _B(rng, b)),
                            _term(rng, False), T, n, fractional_delay=frac)
    ms, bs = _logu(rng, 1e-3, 10.0), _logu(rng, 1e-4, 5.0)
    nb = n if rng.uniform() < 0.6 else _delay(rng, most_delay)
    B = _B(rng, min(b, bs))
    free = rng.uniform() < 0.15
    op, env = ("none", "none") if free else (_term(rng, False), _term(rng, True))
    ratio = 1.0 if rng.uniform() < 0.6 else _logu(rng, 0.1, 10.0)
    Bs = B if ratio == 1.0 else _B(rng, min(b, bs))
    kw = dict(master=h.Device(m, b), slave=h.Device(ms, bs), operator=op, environment=env,
              period=T, delay_samples=n, delay_backward_samples=nb)
    if kind < 0.85:
        extra = {}
        u = rng.uniform()
        if u < 0.15:
            extra = dict(fractional_delay=float(rng.uniform(0.05, 0.95)),
                         fractional_delay_backward=float(rng.uniform(0, 0.95)))
        elif u < 0.25:
            extra = dict(position_scale=_logu(rng, 0.2, 5.0), force_scale=_logu(rng, 0.2, 5.0))
        return h.TeleoperationLoop(master_controller=_controller(rng, 1.0, B),
                                   slave_controller=spring_damper(ratio, Bs), **kw, **extra)
    return FourChannelLoop(master_controller=spring_damper(1.0, B),
                           slave_controller=spring_damper(ratio, Bs), **kw,
                           force_to_slave=float(rng.choice([0.0, rng.uniform(0, 1)])),
                           force_to_master=float(rng.choice([0.0, rng.uniform(0, 1)])))


def mixed_loops(count: int, seed: int = SEED, most_delay: int = 30) -> list:
    """``count`` random loops (deterministic in ``seed``), with a few repeated and a
    few of the paper's own among them."""
    rng = np.random.default_rng(seed)
    out = [random_loop(rng, most_delay) for _ in range(count)]
    for k in range(0, count, 17):           # the paper's loops over their rate range
        T = 1.0 / _logu(rng, 100.0, 1e4)
        out[k] = h.paper_hve(T, int(rng.integers(0, 11))) if k % 2 == 0 else \
            h.paper_peb(T, int(rng.integers(0, 11)))
    for k in range(5, count, 23):           # duplicates
        out[k] = out[k - 3]
    return out


def undamped_loops(count: int, seed: int = SEED + 1) -> list:
    """Loops with (nearly) no damping anywhere: poles within rounding of the unit
    circle, where the exact core answers "marginal" or leaves K-intervals uncertain."""
    rng = np.random.default_rng(seed)

    def z() -> str:
        return str(rng.choice(["none", "spring:50", "msd:0.05,0,200", "msd:0.1,0.01,1000"]))

    def dev() -> h.Device:
        return h.Device(float(rng.uniform(0.01, 1)), float(rng.choice([0.0, 1e-6, 0.01])))

    out = []
    for _ in range(count):
        T = float(rng.choice([1e-4, 1e-3, 5e-3]))
        n = int(rng.integers(0, 4))
        if rng.uniform() < 0.3:
            out.append(h.HapticLoop(dev(), h.SpringDamper(1, float(rng.choice([0.0, 1e-5]))), z(), T, n))
        else:
            out.append(h.TeleoperationLoop(dev(), dev(), h.SpringDamper(1, float(rng.choice([0.0, 1e-5]))),
                                           h.SpringDamper(1, float(rng.choice([0.0, 1e-5]))), z(), z(),
                                           T, n))
    return out


def batch_keys(loops: list) -> list:
    """Each loop's batch in one ``critical_stiffness_many`` call: its structure's key (the
    loops sharing one are one batch), a refused loop alone in its own. The split of a
    batched draw between the test lanes (``lanes.part_groups``) reads it."""
    from hapstab.engine.frequency import plan_response
    from hapstab.errors import HapstabError

    out: list = []
    for i, lp in enumerate(loops):
        try:
            out.append(plan_response(lp).key())
        except HapstabError:
            out.append(("refused", i))
    return out
