"""Hostile input (issue #11): seeded invocations of every command with hostile values
for its options, and hostile calls of every public function. A user's mistake must be
one line naming its parameter and exit code 2 (the API: a HapstabError, or a TypeError
for a wrong type); never a traceback, an "internal error", an AttributeError,
IndexError, LinAlgError, OverflowError, or a numpy warning (warnings are errors here).

``HAPSTAB_FUZZ_SEED`` draws a fresh campaign; ``-m slow`` runs a larger one."""

import contextlib
import itertools
import math
import os
import random
import warnings

import click
import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
from hapstab import budget
from hapstab.cli.main import cli
from hapstab.errors import HapstabError
from lanes import draw

SEED = int(os.environ.get("HAPSTAB_FUZZ_SEED", "20261124"))

HOSTILE = ["", " ", "nan", "inf", "-inf", "-1", "0", "-0", "1e308", "-1e308", "1e-308", "5e-324",
           "abc", "1:2:3:4", "0.001::10", "::", ":", "1,,2", "1e999", "0x10", "1_000", "µ", "½",
           "--", "-", "None", "[1]", "1 2", "9" * 400, "1e-9", "3.5", "-3.5", "1e9", "none",
           "spring:", "msd:1,2", "msd:nan,1,1", "step:", "sine:1", "pulse:1,-1", "fig7"]
#: Issue 27's shapes (drawn from their own list: the draws above stay the ones they were):
#: other scripts' digits, digit separators, tiny cutoffs, special files, extreme positions.
HOSTILE_27 = ["\U0001d7d0", "\uff11", "\u0663", "1_000", "2\u00b2", "lowpass:1e-320",
              "lowpass:5e-324", "average:\U0001d7d0", "/dev/zero", "/dev/urandom", ".", "1e308",
              "-1e308", "msd:1,\uff12,3", "1ms:2ms:\U0001d7d0", "0,1_0"]


def _commands():
    """(path, value options) of every command, found by walking the CLI."""
    out = []

    def walk(cmd, path):
        if isinstance(cmd, click.Group):
            for name, sub in cmd.commands.items():
                walk(sub, [*path, name])
        else:
            opts = [p.opts[0] for p in cmd.params if isinstance(p, click.Option)
                    and not p.is_flag and p.opts[0] not in ("--help",)]
            out.append((path, opts))

    walk(cli, [])
    return out


#: (limit-cycle's invocations are drawn in a block of their own, after the others, so that
#: the draw of every other command stays the one it was before the command existed)
#: (explore starts a server that runs until stopped: its hostile options are tested in
#: tests/explorer/test_explorer_server.py, which stops what it starts)
# identify takes a LOG argument: its hostile inputs are in tests/identification/test_identify.py
COMMANDS = [c for c in _commands()
            if c[0][0] not in ("limit-cycle", "explore", "sweep", "identify", "jitter")]
#: (jitter's invocations are drawn after every other block, so that the others' draws
#: stay the ones they were before the command existed)
JITTER = [c for c in _commands() if c[0][0] == "jitter"]
LIMIT_CYCLE = [c for c in _commands() if c[0][0] == "limit-cycle"]
SWEEP = [c for c in _commands() if c[0][0] == "sweep"]
#: (every loop kind of a command, hve, peb and 4ch, needs the same)
NEEDS = {"region": ["--K", "0:100", "--B", "0:1", "--resolution", "12"], "reproduce": ["fig5"],
         "check": ["-K", "5"], "passivity": ["-K", "5"], "simulate": ["-K", "5"],
         "run": ["study.toml"], "twoport": ["-K", "5"], "transparency": ["-K", "5"],
         "limit-cycle": ["-K", "5", "--resolution", "1e-4"],
         "zwidth": ["--K", "0:100", "--B", "0:1", "--rows", "4"],
         "robust": ["--operator-mass", "0.5", "--operator-damping", "5", "--operator-stiffness",
                    "500"],
         "sweep": ["sweep.toml", "--out", "sweep-out", "--workers", "1"],
         "jitter": ["--delay", "1:2", "--max-length", "3"]}
#: 4ch loops each command takes, one option of them then hostile: force reflection (C_m
#: a damper, C_4 = 0, C_2 = 1) for the exact K_max, a force gain for the best damping,
#: equal position controllers for the region, unequal ones for the position-only tests.
FORCE_REFLECTION = ["--master-stiffness-ratio", "0", "--c4-stiffness-ratio", "0", "--c2", "1",
                    "-B", "0.5", "--environment", "spring:1000"]
FOURCH = {"kmax": FORCE_REFLECTION, "boundary": FORCE_REFLECTION, "region": ["-n", "2"],
          "best-damping": ["--c2", "1", "--environment", "spring:1000"]}
POSITION_ONLY = ["--c1-stiffness-ratio", "2", "--c4-virtual-damping", "0.3", "-n", "1"]
#: The study the fuzz's `run` invocations use (written in the test's folder).
STUDY = 'kind = "hve"\n[loop]\ndelay = 2\n[[variant]]\nname = "b"\nvirtual-damping = 1\n[run.kmax]\n'
#: ... and `sweep`'s: two points, K_max only (no heat map with one axis).
SWEEP_STUDY = 'kind = "hve"\n[loop]\ndelay = 2\n[sweep.axes]\nperiod = [0.001, 0.002]\n'



def _invocations(n, seed):
    rng = random.Random(seed)
    calls = []
    for i in range(n):
        path, opts = COMMANDS[i % len(COMMANDS)]
        base = list(path) + NEEDS.get(path[0], [])
        if path[0] == "reproduce":
            base += ["--periods", "0.003"]         # the paper's grid is slow for a fuzz run
        k = rng.choice([1, 1, 1, 2])
        chosen = rng.sample(opts, min(k, len(opts))) if opts else []
        args = list(base)
        for o in chosen:
            args += [o, rng.choice(HOSTILE)]
        calls.append((args, chosen))
    # the issue's own observations
    calls += [(["kmax", "hve", "--period", "0.001::10"], ["--period"]),
              (["kmax", "hve", "--delay-s", "1e308"], ["--delay-s"]),
              (["kmax", "hve", "--mass", "1e-308"], ["--mass"]),
              (["kmax", "hve", "--damping", "1e300"], ["--damping"]),
              (["kmax", "hve", "-B", "1e300"], ["-B"]),
              (["best-damping", "hve", "--max-damping", "0"], ["--max-damping"])]
    # 4ch: a loop each command takes, with one hostile option
    fourch = [(path, opts) for path, opts in COMMANDS if path[1:] == ["4ch"]]
    for _ in range(30):
        path, opts = rng.choice(fourch)
        o = rng.choice(opts)
        calls.append(([*path, *NEEDS.get(path[0], []), *FOURCH.get(path[0], POSITION_ONLY), o,
                       rng.choice(HOSTILE)], [o]))
    # limit-cycle hve, one or two hostile options
    for _ in range(30):
        path, opts = rng.choice(LIMIT_CYCLE)
        chosen = rng.sample(opts, rng.choice([1, 2]))
        calls.append(([*path, *NEEDS[path[0]], *[v for o in chosen for v in (o, rng.choice(HOSTILE))]],
                      chosen))
    # study files: the group-level --study / --variant, hostile values
    for _ in range(20):
        calls.append((["kmax", "hve", "--study", rng.choice(HOSTILE)], ["--study"]))
        calls.append((["kmax", "hve", "--study", "study.toml", "--variant", rng.choice(HOSTILE)],
                      ["--variant"]))
    # sweep (drawn after the others: their draws stay the ones they were), one hostile option
    for _ in range(20):
        path, opts = rng.choice(SWEEP)
        o = rng.choice(opts)
        calls.append(([*path, *NEEDS["sweep"], o, rng.choice(HOSTILE)], [o]))
    # issue 27's shapes, any command (not sweep's workers: kept fast), then as a study file
    for _ in range(40):
        path, opts = rng.choice(COMMANDS + LIMIT_CYCLE)
        if opts:
            o = rng.choice(opts)
            calls.append(([*path, *NEEDS.get(path[0], []), o, rng.choice(HOSTILE_27)], [o]))
    for f in ("/dev/zero", "/dev/urandom", "/dev/null", ".", "deep.toml", "fifo.toml"):
        calls.append((["kmax", "hve", "--study", f], ["--study"]))
        calls.append((["run", f], ["STUDY.toml"]))
    # jitter hve / peb (after everything else), one hostile option, --delay among them
    for _ in range(20):
        path, opts = rng.choice(JITTER)
        o = rng.choice(opts)
        calls.append(([*path, *NEEDS["jitter"], o, rng.choice(HOSTILE)], [o]))
    return calls


def _names(option):
    """Words a message may name the option by."""
    bare = option.lstrip("-")
    words = {option, bare, bare.replace("-", "_"), bare.replace("-", " ")}
    return words | {w[:-1] for w in words if w.endswith("s")}     # --periods: "period = ..."


def _files(tmp_path):
    """The studies the campaign reads: a good one, a sweep's, one nested 3000 deep (tomllib
    recursed past Python's limit) and a FIFO with no writer (an open would block)."""
    (tmp_path / "study.toml").write_text(STUDY)
    (tmp_path / "sweep.toml").write_text(SWEEP_STUDY)
    (tmp_path / "deep.toml").write_text('kind = "hve"\nx = ' + "[" * 3000 + "]" * 3000 + "\n")
    os.mkfifo(tmp_path / "fifo.toml")


def _check_cli(args, chosen, runner):
    with budget.limits(seconds=2.0):          # a fuzz run must stay fast: bigger work is refused
        r = runner.invoke(cli, args)
    err = r.stderr
    assert r.exit_code in (0, 2), (args, r.exit_code, err, r.exception)
    assert "Traceback" not in err and "internal error" not in err, (args, err)
    lines = err.splitlines()
    warnings = [ln for ln in lines if ln.startswith("hapstab: warning: ")]
    csv_on_stdout = any(a == "--csv" and b == "-" for a, b in itertools.pairwise(args))
    if r.exit_code == 0 and not csv_on_stdout:            # (--csv -: the table is on stderr)
        assert lines == warnings, (args, err)             # nothing but plausibility warnings
    if r.exit_code == 2:
        err = lines[-1] + "\n"
        assert lines[:-1] == warnings and err.startswith("hapstab: error: "), (args, lines)
        msg = err.lower()
        named = any(w.lower() in msg for o in chosen for w in _names(o))
        assert named or "would need about" in msg or not chosen, (args, err)


# 4 of the 10 chunks (286 of the 716 command lines) in the default lane, the rest -m campaign
@pytest.mark.parametrize("chunk", draw(range(10), 4))
def test_hostile_command_lines(chunk, tmp_path):
    runner = CliRunner()
    calls = _invocations(520, SEED)
    os.chdir(tmp_path)                       # reproduce writes ./out
    _files(tmp_path)
    # A command line drawn again within the chunk (``demo`` and ``verify`` have no value
    # option: the cycle draws them bare 15 times each; a few values repeat) is checked
    # where the chunk first draws it, once: the CLI is deterministic, and a repeat in the
    # chunk's folder asks nothing new (it cost 5 bare ``demo`` runs, ~4 s, in the default
    # lane's chunks). Each chunk still runs every command line it draws at least once.
    first: dict[tuple, int] = {}
    for i in range(chunk, len(calls), 10):
        first.setdefault(tuple(calls[i][0]), i)
    for i in range(chunk, len(calls), 10):
        args, chosen = calls[i]
        if first[tuple(args)] == i:
            _check_cli(args, chosen, runner)


@pytest.mark.slow
def test_more_hostile_command_lines(tmp_path):
    runner = CliRunner()
    os.chdir(tmp_path)
    _files(tmp_path)
    for args, chosen in _invocations(3000, SEED + 1):
        _check_cli(args, chosen, runner)


# ------------------------------------------------------------------------------ API
LOOP = h.paper_hve(1e-3, 2).with_stiffness(5.0)
with warnings.catch_warnings():
    warnings.simplefilter("ignore")        # (numpy warns making it: it underflows)
    TINY_LONGDOUBLE = np.longdouble("1e-4940")
PEB = h.paper_peb(1e-3, 2).with_stiffness(2.0)
NOT_LOOPS = [None, 1, "x", [], {}, 1.5, object(), math.nan, np.zeros(3), PEB.master]

TAKES_A_LOOP = {
    "stability": lambda L: h.stability(L),
    "critical_stiffness": lambda L: h.critical_stiffness(L),
    "boundary": lambda L: h.boundary(L, [1e-3], [0]),
    "stability_region": lambda L: h.stability_region(L, (0, 10), (0, 1), 5),
    "best_damping": lambda L: h.best_damping(L, resolution=4),
    "simulate": lambda L: h.simulate(L, 0.05),
    "audit": lambda L: h.audit(L),
    "sampled_passivity": lambda L: h.sampled_passivity(L),
    "circle_test": lambda L: h.circle_test(L),
    "loop_inverse": lambda L: h.loop_inverse(L),
    "build": lambda L: h.build(L),
    "critical_stiffness_simulation": lambda L: h.critical_stiffness_simulation(L),
    "positive_real": lambda G: h.positive_real(G, 1e-3),
    "circle_criterion": lambda G: h.circle_criterion(G, 1.0, 1e-3),
    "transparency": lambda L: h.transparency(L),
    "abbott_okamura": lambda L: h.abbott_okamura(L, resolution_m=1e-4),
    "nonlinear_passivity": lambda L: h.nonlinear_passivity(L, coulomb_friction_N=0.01),
    "limit_cycles": lambda L: h.limit_cycles(L, resolution_m=1e-4),
}

BAD_VALUES = {
    "with_delay_s(1e308)": lambda: LOOP.with_delay_s(1e308),
    "with_delay_s(-1)": lambda: LOOP.with_delay_s(-1),
    "with_delays_s(inf)": lambda: PEB.with_delays_s(math.inf),
    "device mass 1e-300": lambda: h.critical_stiffness(LOOP.replace(device=h.Device(1e-300, 0.1))),
    "device mass 1e300": lambda: h.critical_stiffness(LOOP.replace(device=h.Device(1e300, 0.1))),
    "device damping 1e300": lambda: h.critical_stiffness(LOOP.replace(device=h.Device(0.1, 1e300))),
    "stability mass 1e-300": lambda: h.stability(LOOP.replace(device=h.Device(1e-300, 0.1))),
    "simulate mass 1e-300": lambda: h.simulate(LOOP.replace(device=h.Device(1e-300, 0.1)), 0.1),
    "region (0,)": lambda: h.stability_region(LOOP, (0,), (0, 1), 5),
    "region ()": lambda: h.stability_region(LOOP, (), (0, 1), 5),
    "region 'ab'": lambda: h.stability_region(LOOP, "ab", (0, 1), 5),
    "region (nan, 1)": lambda: h.stability_region(LOOP, (math.nan, 1), (0, 1), 5),
    "region resolution 'x'": lambda: h.stability_region(LOOP, (0, 1), (0, 1), "x"),
    "region resolution 1.5": lambda: h.stability_region(LOOP, (0, 1), (0, 1), 1.5),
    "region resolution 1e9": lambda: h.stability_region(LOOP, (0, 1), (0, 1), 10 ** 9),
    "simulate nan force": lambda: h.simulate(LOOP, 0.1, force=lambda t: math.nan),
    "simulate inf force": lambda: h.simulate(LOOP, 0.1, force=lambda t: math.inf),
    "simulate force raises": lambda: h.simulate(LOOP, 0.1, force=lambda t: 1 / 0),
    "simulate force string": lambda: h.simulate(LOOP, 0.1, force="nonsense"),
    "simulate force array": lambda: h.simulate(LOOP, 0.1, force=[1.0, 2.0]),
    "simulate duration nan": lambda: h.simulate(LOOP, math.nan),
    "simulate duration '1'": lambda: h.simulate(LOOP, "1"),
    "simulate duration 1e12": lambda: h.simulate(LOOP, 1e12),
    "simulate x0 3 values": lambda: h.simulate(LOOP, 0.1, initial_position=[1, 2, 3]),
    "simulate initial_state short": lambda: h.simulate(LOOP, 0.1, initial_state=[1, 2]),
    "simulate dense 1": lambda: h.simulate(LOOP, 0.1, dense=1),
    "simulate wall nan": lambda: h.simulate(LOOP, 0.1, wall=math.nan),
    "simulate saturation -1": lambda: h.simulate(LOOP, 0.1, saturation=-1),
    "simulate quantizer x": lambda: h.simulate(LOOP, 0.1, resolution=1e-3, quantizer="x"),
    "build periods [-1]": lambda: h.build(LOOP, periods=[-1]),
    "build periods [nan]": lambda: h.build(LOOP, periods=[math.nan]),
    "build periods []": lambda: h.build(LOOP, periods=[]),
    "build periods 'x'": lambda: h.build(LOOP, periods="x"),
    "boundary periods []": lambda: h.boundary(LOOP, [], [0]),
    "boundary delays [-1]": lambda: h.boundary(LOOP, [1e-3], [-1]),
    "boundary delays [1.5]": lambda: h.boundary(LOOP, [1e-3], [1.5]),
    "boundary method x": lambda: h.boundary(LOOP, [1e-3], [0], method="x"),
    "critical_stiffness method x": lambda: h.critical_stiffness(LOOP, method="x"),
    "critical_stiffness method None": lambda: h.critical_stiffness(LOOP, method=None),
    "eq18 of a PEB": lambda: h.eq18(PEB),
    "eq34 of an HVE": lambda: h.eq34(LOOP),
    "SpringDamper('a')": lambda: h.SpringDamper("a"),
    "SpringDamper(-1)": lambda: h.SpringDamper(-1.0),
    "Device(-1, 0)": lambda: h.Device(-1, 0),
    "Device(nan, 0)": lambda: h.Device(math.nan, 0),
    "HapticLoop(None, None)": lambda: h.HapticLoop(None, None),
    "period 0": lambda: LOOP.replace(period=0),
    "period nan": lambda: LOOP.replace(period=math.nan),
    "delay -1": lambda: LOOP.replace(delay_samples=-1),
    "paper_hve(-1)": lambda: h.paper_hve(-1),
    "paper_hve(1e-3, 1e9)": lambda: h.paper_hve(1e-3, 10 ** 9),
    "DiscreteController([], [])": lambda: h.DiscreteController([], []),
    "DiscreteController([1], [0])": lambda: h.DiscreteController([1], [0]),
    "RationalMatrix zero den": lambda: h.RationalMatrix([[1]], [[0]]),
    "RationalMatrix ragged": lambda: h.RationalMatrix([[1, 2]], [[1]]),
    "parse_impedance('msd:1,2')": lambda: h.parse_impedance("msd:1,2"),
    "parse_impedance(None)": lambda: h.parse_impedance(None),
    "mass_spring_damper(nan)": lambda: h.mass_spring_damper(math.nan, 1, 1),
    "spring(-1)": lambda: h.spring(-1),
    "methods_for('x')": lambda: h.methods_for("x"),
    "circle approximation x": lambda: h.critical_stiffness(LOOP, method="circle",
                                                           approximation="x"),
    "circle sector -1": lambda: h.critical_stiffness(LOOP, method="circle", sector=-1),
    "stability max_memory 1": lambda: h.stability(LOOP, max_memory=1),
    "best_damping resolution 'x'": lambda: h.best_damping(LOOP, resolution="x"),
    "best_damping resolution 10**7": lambda: h.best_damping(LOOP, resolution=10 ** 7),
    "boundary 10**6 periods": lambda: h.boundary(LOOP, np.linspace(1e-3, 2e-3, 10 ** 6), [0]),
    "transparency of an HVE": lambda: h.transparency(LOOP),
    "transparency frequencies nan": lambda: h.transparency(PEB, frequencies_hz=[math.nan]),
    "transparency frequencies 1e308": lambda: h.transparency(PEB, frequencies_hz=1e308),
    "transparency frequencies 'x'": lambda: h.transparency(PEB, frequencies_hz="x"),
    "transparency frequencies []": lambda: h.transparency(PEB, frequencies_hz=[]),
    "transparency environment 'x'": lambda: h.transparency(PEB, environment="x"),
    "transparency approximation 3": lambda: h.transparency(PEB, approximation=3),
    # issue 27: huge arrays, tiny cutoffs, extreme rests, exotic numbers
    "build 10**7 periods": lambda: h.build(LOOP, periods=np.full(10 ** 7, 1e-3)),
    "boundary 10**6 periods x 100 delays": lambda: h.boundary(
        LOOP, np.linspace(1e-4, 1e-2, 10 ** 6), range(100)),
    "boundary 10**7 delays": lambda: h.boundary(LOOP, [1e-3], np.arange(10 ** 7)),
    "VelocityFilter lowpass 1e-320": lambda: h.stability(LOOP.replace(
        controller=h.FilteredSpringDamper(5.0, 0.1, velocity_filter="lowpass:1e-320"))),
    "VelocityFilter average:\U0001d7d0": lambda: h.VelocityFilter.parse("average:\U0001d7d0"),
    "parse_impedance unicode": lambda: h.parse_impedance("msd:1,\uff12,3"),
    "limit_cycles rest 1e308": lambda: h.limit_cycles(LOOP, resolution_m=1e-4,
                                                      rest_position_m=1e308),
    "limit_cycles rest -1e300 friction": lambda: h.limit_cycles(
        LOOP, coulomb_friction_N=0.1, rest_position_m=-1e300),
    "delay longdouble 1e-4940": lambda: h.paper_hve(delay_samples=TINY_LONGDOUBLE),
    "NO_IMPEDANCE(None)": lambda: h.NO_IMPEDANCE(None),
    "NO_IMPEDANCE('x')": lambda: h.NO_IMPEDANCE("x"),
    "NO_IMPEDANCE([None])": lambda: h.NO_IMPEDANCE([None]),
}

API_CALLS = ([(f"{name}({bad!r:.20})", (lambda f=f, b=bad: f(b)))
              for name, f in TAKES_A_LOOP.items() for bad in NOT_LOOPS]
             + list(BAD_VALUES.items()))


def test_the_api_campaign_has_300_calls():
    rng = random.Random(SEED)
    assert len(API_CALLS) + len(_api_combinations(rng)) >= 300


def _field_call(field, v):
    """A call that puts the hostile value ``v`` into one field of the models."""
    if field in ("mass", "damping"):
        kw = {"mass": 0.1, "damping": 0.1, field: v}
        return lambda: h.critical_stiffness(LOOP.replace(device=h.Device(**kw)))
    if field in ("stiffness", "virtual"):
        kw = {"stiffness": 5.0, "damping": 0.0, ("damping" if field == "virtual" else field): v}
        return lambda: h.stability(LOOP.replace(controller=h.SpringDamper(**kw)))
    if field == "period":
        return lambda: h.stability(LOOP.replace(period=v))
    return lambda: h.critical_stiffness(LOOP.replace(delay_samples=v))


def _api_combinations(rng):
    """Seeded random hostile values for the loop models' fields."""
    vals = [-1.0, 0.0, math.nan, math.inf, 1e-300, 1e300, "x", None, True, [1.0]]
    fields = ["mass", "damping", "stiffness", "virtual", "period", "delay"]
    out = []
    for _ in range(120):
        field, v = rng.choice(fields), rng.choice(vals)
        out.append((f"{field} = {v!r}", _field_call(field, v)))
    return out


class _Opaque:
    """An arbitrary object whose repr is the same in every process: the draw's test ids
    must not depend on an address (pytest-xdist's workers collect them separately)."""

    def __repr__(self) -> str:
        return "<opaque object>"


def _exotic_values():
    """Issue 27's kinds of values: numbers of every numeric type at the edges of their
    range, unicode digits and separators, and containers where numbers belong."""
    from fractions import Fraction

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ld = [np.longdouble("1e-4940"), np.longdouble("1e4931"), np.longdouble("-1e-4940")]
    return [*ld, np.float16(65504), np.float32(1e-45), np.float32(math.nan), np.int64(-1),
            np.int8(127), np.uint64(2 ** 64 - 1), 2 ** 70, -0.0, 5e-324, 1e-320, 1e308, 1j,
            complex(math.nan, 0), Fraction(1, 3), Fraction(10 ** 400, 3), True, b"1",
            "\U0001d7d0", "\uff11", "1_000", "0x10", " 2 ", [[1.0]], [], (), {}, set(),
            np.array([]), np.array([1e-3] * 3), np.array([[1e-3]]), np.array(["x"]),
            np.array([1e-3, math.nan]), range(0), _Opaque(), None]


def _exotic_call(field, v):
    """A call of the library that puts ``v`` where ``field`` goes."""
    calls = {
        "cutoff": lambda: h.stability(LOOP.replace(controller=h.FilteredSpringDamper(
            5.0, 0.1, velocity_filter=h.VelocityFilter("lowpass", cutoff_hz=v)))),
        "rest": lambda: h.limit_cycles(LOOP, resolution_m=1e-4, rest_position_m=v),
        "resolution": lambda: h.limit_cycles(LOOP, resolution_m=v),
        "friction": lambda: h.nonlinear_passivity(LOOP, coulomb_friction_N=v),
        "duration": lambda: h.simulate(LOOP, v),
        "frequencies": lambda: h.transparency(PEB, frequencies_hz=v),
        "impedance": lambda: h.NO_IMPEDANCE(v),
        "periods": lambda: h.build(LOOP, periods=v),
        "delays": lambda: h.boundary(LOOP, [1e-3], v),
        "region K": lambda: h.stability_region(LOOP, (0, v), (0, 1), 5),
        "resolution of a region": lambda: h.stability_region(LOOP, (0, 10), (0, 1), v),
        "paper delay": lambda: h.paper_hve(delay_samples=v),
        "paper period": lambda: h.paper_hve(period=v),
        "with_stiffness": lambda: h.stability(LOOP.with_stiffness(v)),
        "with_delay_s": lambda: h.critical_stiffness(LOOP.with_delay_s(v)),
        "max_seconds": lambda: h.critical_stiffness(LOOP, max_seconds=v),
        "max_memory": lambda: h.stability(LOOP, max_memory=v),
    }
    return calls[field]


#: The fields of the issue-27 draw, in a fixed order (the draw is by index).
EXOTIC_FIELDS = ["cutoff", "rest", "resolution", "friction", "duration", "frequencies",
                 "impedance", "periods", "delays", "region K", "resolution of a region",
                 "paper delay", "paper period", "with_stiffness", "with_delay_s",
                 "max_seconds", "max_memory"]


def _api_combinations_27(rng):
    """Seeded draws of issue 27's values into the library's numeric arguments (their own
    generator: the draws of :func:`_api_combinations` stay the ones they were)."""
    vals = _exotic_values()
    out = []
    for _ in range(160):
        field, i = rng.choice(EXOTIC_FIELDS), rng.randrange(len(vals))
        out.append((f"{field} = {vals[i]!r:.40}", _exotic_call(field, vals[i])))
    return out


@pytest.mark.parametrize("name,call", API_CALLS + _api_combinations(random.Random(SEED))
                         + _api_combinations_27(random.Random(SEED + 27)),
                         ids=lambda x: x if isinstance(x, str) else "")
def test_hostile_api_calls(name, call):
    with budget.limits(seconds=10.0), contextlib.suppress(HapstabError):
        call()                                # a ValueError (or TypeError) naming the argument


# ----------------------------------------------------------- issue 27: linked output folders
#: Where a sweep or a run writes or deletes in its folder, and the links the fuzz plants
#: there: a symbolic link to someone else's folder or file (relative or absolute), a
#: dangling one, or a hard link to someone else's file. The rule for each: nothing of
#: theirs is written, deleted or created through it (the folder itself, --out, may be a
#: link: the user named it, and that is drawn too).
SWEEP_SPOTS = ["chunks", "manifest.json", "summary.json", "kmax.png",
               "chunks/chunk-000000.parquet", "chunks/chunk-000001.parquet",
               "chunks/.chunk-000000.parquet.part", ".manifest.json.part", "."]
RUN_SPOTS = ["base", "b", "base/kmax.json", "b/kmax.json", "study.toml", "manifest.json", "."]
LINKS = ["dir", "file", "dangling", "hard", "dir-absolute"]


def _link_cases(n, seed):
    rng = random.Random(seed)
    out = []
    for _ in range(n):
        command = rng.choice(["sweep", "run"])
        spot = rng.choice(SWEEP_SPOTS if command == "sweep" else RUN_SPOTS)
        link = "dir" if spot == "." else rng.choice(LINKS)
        out.append((command, spot, link, rng.random() < 0.5, rng.random() < 0.5))
    return out


def _snapshot(root):
    """Every path under ``root`` (links not followed) and each file's bytes."""
    seen = {}
    for d, dirs, files in os.walk(root):
        for f in dirs + files:
            p = os.path.join(d, f)
            if os.path.isdir(p) or os.path.islink(p):
                seen[os.path.relpath(p, root)] = None
            else:
                with open(p, "rb") as fh:
                    seen[os.path.relpath(p, root)] = fh.read()
    return seen


def _plant(out, spot, link, theirs):
    """Make ``out/spot`` a link into ``theirs`` (someone else's folder, with files named as
    the run's own)."""
    path = os.path.normpath(os.path.join(out, spot))
    if spot != ".":
        os.makedirs(os.path.dirname(path), exist_ok=True)
    if os.path.isdir(path) and not os.path.islink(path):
        import shutil

        shutil.rmtree(path)
    elif os.path.lexists(path):
        os.remove(path)
    folder, file = os.path.join(theirs, "folder"), os.path.join(theirs, "file")
    if link == "hard":
        if spot in ("chunks", "base", "b"):          # (no hard links to folders)
            link = "dir"
        else:
            os.link(file, path)
            return
    target = {"dir": folder, "dir-absolute": os.path.abspath(folder), "file": file,
              "dangling": os.path.join(theirs, "nothing-here")}[link]
    os.symlink(target if link == "dir-absolute" else os.path.relpath(target, os.path.dirname(
        os.path.abspath(path))), path)


@pytest.mark.parametrize("command,spot,link,force,prior",
                         draw(_link_cases(60, SEED + 27), 16, ids=lambda c: "-".join(map(str, c))))
def test_linked_output_folders(command, spot, link, force, prior, tmp_path):
    """Issue 27 (9): a sweep's linked chunks/ was written through and --force deleted
    chunk files in its target; the same class: any link in a sweep's or a run's folder
    that the run did not make, with or without --force, in a fresh or a finished folder."""
    case = (command, spot, link, force, prior)
    (tmp_path / "study.toml").write_text(STUDY)
    (tmp_path / "sweep.toml").write_text(SWEEP_STUDY)
    theirs = tmp_path / "theirs"
    (theirs / "folder").mkdir(parents=True)
    for name in ("chunk-000000.parquet", "chunk-000001.parquet", "kmax.json",
                 "manifest.json", "summary.json", "study.toml"):
        (theirs / "folder" / name).write_bytes(b"someone else's " + name.encode())
    (theirs / "file").write_bytes(b"someone else's file")
    out = tmp_path / "out"
    args = (["sweep", str(tmp_path / "sweep.toml"), "--out", str(out), "--workers", "1",
             *(["--force"] if force else [])] if command == "sweep"
            else ["run", str(tmp_path / "study.toml"), "--out", str(out)])
    runner = CliRunner()
    if prior:                                       # a finished folder, then the link
        assert runner.invoke(cli, args).exit_code == 0
    else:
        out.mkdir()
    if spot == ".":
        import shutil

        shutil.rmtree(out)
    _plant(str(out), spot, link, str(theirs))
    before = _snapshot(theirs)
    with budget.limits(seconds=5.0):
        r = runner.invoke(cli, args)
    err = r.stderr
    assert r.exit_code in (0, 2), (case, r.exit_code, err, r.exception)
    assert "Traceback" not in err and "internal error" not in err, (case, err)
    if spot == ".":                                  # --out itself: the user's link
        assert r.exit_code == 0, (case, err)
        return
    assert _snapshot(theirs) == before, case        # nothing of theirs touched or made
    if link != "hard":
        assert r.exit_code == 2 and "symbolic link" in err.splitlines()[-1], (case, err)
        assert len(err.strip().splitlines()) == 1, (case, err)


# ------------------------------------------------- issue 27: the explorer's client hangs up
#: Requests whose client goes away: mid-body (at a drawn byte, the declared length the
#: body's or more), before any body, after the body while the answer is computed, or on a
#: GET. The rule: never an internal error or a traceback on the server's stderr, never a
#: 5xx, and a hung-up computation stops (the slow region: in about a second, not its 8 s).
HANGUP_BODIES = {
    "kmax": {"kind": "hve", "options": {"delay": 2}},
    "boundary": {"kind": "hve", "options": {"period": "1ms:2ms:3", "delay": "0,1"}},
    "region": {"kind": "hve", "options": {"K": "0:100", "B": "0:5", "delay": 40,
                                          "resolution": 600}},
    "simulate": {"kind": "hve", "options": {"stiffness": 5, "duration": 0.2, "series": 30}},
    "code": {"command": "kmax", "kind": "hve", "options": {"delay": 2}},
    "nonsense": {"kind": "hve"},
}
HANGUPS = ["mid-body", "before-body", "after-body", "get"]


def _hangup_cases(n, seed):
    rng = random.Random(seed)
    return [(rng.choice(list(HANGUP_BODIES)), rng.choice(HANGUPS), rng.random(),
             rng.choice(["exact", "more", "none"]), rng.choice([0.0, 0.3, 1.0]))
            for _ in range(n)]


def _hang_up(app, command, shape, cut, length, after_s):
    """One request to ``app`` whose client hangs up as drawn: (response statuses, s)."""
    import json as _json
    import time

    import anyio

    body = _json.dumps(HANGUP_BODIES[command]).encode()
    sent = []
    path = "/" if shape == "get" else f"/api/v1/{command}"
    headers = [(b"host", b"127.0.0.1"), (b"content-type", b"application/json")]
    if length != "none" and shape != "get":
        headers.append((b"content-length", str(len(body) + (40 if length == "more" else 0))
                        .encode()))
    if shape == "mid-body":
        msgs = [{"type": "http.request", "body": body[:int(cut * len(body))], "more_body": True}]
    elif shape == "after-body":
        msgs = [{"type": "http.request", "body": body, "more_body": False}]
    else:
        msgs = []

    async def main():
        t0 = time.monotonic()

        async def receive():
            if msgs:
                return msgs.pop(0)
            if shape == "after-body" and time.monotonic() - t0 < after_s:
                await anyio.sleep(after_s)          # (is_disconnected cancels this at once)
            return {"type": "http.disconnect"}

        async def send(m):
            sent.append(m)

        scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1",
                 "method": "GET" if shape == "get" else "POST", "scheme": "http",
                 "path": path, "raw_path": path.encode(), "query_string": b"", "root_path": "",
                 "headers": headers, "client": ("127.0.0.1", 5555),
                 "server": ("127.0.0.1", 8765)}
        with anyio.fail_after(60):
            await app(scope, receive, send)
        return time.monotonic() - t0

    took = anyio.run(main)
    return [m["status"] for m in sent if m["type"] == "http.response.start"], took


@pytest.fixture(scope="module")
def explorer_app():
    pytest.importorskip("starlette")
    from hapstab.explorer.app import create_app

    return create_app()


@pytest.mark.parametrize("command,shape,cut,length,after_s", draw(
    _hangup_cases(40, SEED + 10), 12, ids=lambda c: f"{c[0]}-{c[1]}-{c[2]:.2f}-{c[3]}-{c[4]}"))
def test_the_explorer_client_hangs_up(command, shape, cut, length, after_s, explorer_app,
                                      capfd):
    case = (command, shape, cut, length, after_s)
    statuses, took = _hang_up(explorer_app, command, shape, cut, length, after_s)
    err = capfd.readouterr().err
    assert "internal error" not in err and "Traceback" not in err, (case, err)
    assert all(s < 500 for s in statuses), (case, statuses)
    if shape == "after-body" and command == "region":    # ~8 s of work, abandoned
        assert took < after_s + 3, (case, took)
