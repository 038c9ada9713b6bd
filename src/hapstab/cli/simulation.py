"""CLI commands of the simulation feature: ``hapstab simulate hve|peb`` and
``hapstab reproduce fig5|fig6|all`` (the main job). Parse, call the library, print."""

from __future__ import annotations

import math
import sys
from typing import Any

import click

from hapstab.cli.files import check_files, write_files
from hapstab.cli.options import (
    LENGTH,
    LOOP_KINDS,
    NONNEG,
    POS,
    STATE_SPACE_KINDS,
    IntRange,
    Number,
    emit,
    loop_options,
    progress,
    provenance,
    rich_table,
)
from hapstab.cli.ranges import parse_periods
from hapstab.outputs import write_folder
from hapstab.results import dumps

# ------------------------------------------------------------------ simulate
#: What ``stability`` describes beside a run: the loop itself, or its linearisation.
LINEAR_LOOP = {False: "this loop",
               True: "linearised loop (wall always in contact, no saturation, quantisation, "
                     "friction or TDPA)"}

@click.group("simulate")
def simulate_cmd() -> None:
    """Time-domain simulation of the sampled-data loop (exact between samples)."""


def _simulate_command(kind: str) -> None:
    make = LOOP_KINDS[kind]
    extra = [click.option("--environment-force", default=None,
                          help="Exogenous environment force on the slave (same forms as --force).")
             ] if kind != "hve" else [
        click.option("--wall", type=Number(), default=None,
                     help="Unilateral virtual wall at x = WALL m: force only while x > WALL."),
        click.option("--wall-pulls", is_flag=True,
                     help="Let the wall's damper pull the device in (default: a wall only pushes).")]

    @simulate_cmd.command(kind)
    @loop_options(kind)
    @click.option("--stiffness", "-K", type=NONNEG, required=True, help="K in N/m.")
    @click.option("--duration", "-t", type=POS, default=5.0, show_default=True, help="Seconds.")
    @click.option("--force", default="step:1", show_default=True,
                  help="Operator force: none | step:F[,t0] | pulse:F,width[,t0] | sine:F,Hz (N, s, Hz).")
    @click.option("--x0", type=Number(), default=0.0, show_default=True,
                  help="Initial position of the device / master in m (history at rest there).")
    @click.option("--saturation", type=POS, default=None, help="Actuator force limit in N.")
    @click.option("--resolution", type=LENGTH, default=None,
                  help="Encoder resolution: m, or with a unit (2um).")
    @click.option("--quantizer", type=click.Choice(["floor", "nearest"]), default="floor",
                  show_default=True,
                  help="Encoder reading: floor (count of lines passed) or nearest step.")
    @click.option("--rest", type=Number(), default=None,
                  help="Rest position of the operator's spring in m (default: --x0).")
    @click.option("--dense", type=IntRange(0, 1000), default=0, show_default=True,
                  help="Also compute the exact trajectory at this many points per sample (plot).")
    @click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None,
                  help="Write the sampled time series as CSV.")
    @click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
                  help="Write a plot of position, force and port energy (PNG, SVG, PDF).")
    @_tdpa_and_series
    @_network_options
    def _cmd(stiffness: float, duration: float, force: str, x0: float, saturation: float | None,
             resolution: float | None, quantizer: str, rest: float | None, dense: int,
             csv_path: str | None, plot_path: str | None, as_json: bool, tdpa: bool,
             tdpa_observer: str | None, tdpa_velocity: str | None,
             tdpa_max_damping: float | None, series_points: int, delay_trace: str | None,
             jitter: str | None, loss: float | None, seed: int,
             environment_force: str | None = None, wall: float | None = None,
             wall_pulls: bool = False, **kw: Any) -> None:
        check_files(csv_path, plot_path, as_json)
        loop = make(kw, stiffness)
        pc = _tdpa(tdpa, tdpa_observer, tdpa_velocity, tdpa_max_damping)
        net = _network(loop, delay_trace, jitter, loss, seed)
        res = _run(kind, loop, duration, force, x0, rest, environment_force, wall, wall_pulls,
                   saturation=saturation, resolution=resolution, quantizer=quantizer,
                   dense=dense, tdpa=pc, network=net)
        files = write_files(res, csv_path, plot_path)
        d = _summary(res, loop, files, series_points)
        emit(d, as_json, lambda: _table(kind, stiffness, loop, res, d, files), loop)

    for deco in reversed(extra):
        _cmd = deco(_cmd)
    _cmd.__doc__ = (f"Simulate the {kind.upper()} loop at stiffness K: verdict, growth rate, "
                    "CSV and plot of position, force and port energy.")


def _series(res: Any, points: int) -> dict[str, Any]:
    """The run's sampled columns (as ``to_dict(series=True)``), every k-th sample with the
    smallest k that leaves at most ``points`` rows (the first sample always kept)."""
    full = res.to_dict(series=True)["series"]
    n = len(full["time_s"])
    k = max(1, -(-n // points))
    return {name: column[::k] for name, column in full.items()}


_TDPA_AND_SERIES = [
    click.option("--tdpa", is_flag=True,
                 help="Time-domain passivity observer and controller at every device port "
                      "(Hannaford & Ryu 2002; PEB: Ryu, Artigas & Preusche 2010)."),
    click.option("--tdpa-observer", type=click.Choice(["paper", "held"]), default=None,
                 help="TDPA observer: paper (f[k] v[k] T, default) or held (the energy each "
                      "held force delivered, plus the coming sample). Implies --tdpa."),
    click.option("--tdpa-velocity", type=click.Choice(["backward", "sensor"]), default=None,
                 help="TDPA velocity: backward difference of the encoder (default) or a "
                      "velocity sensor. Implies --tdpa."),
    click.option("--tdpa-max-damping", type=POS, default=None,
                 help="Cap on the TDPA controller's damping in N*s/m (default none). "
                      "Implies --tdpa."),
    click.option("--series", "series_points", type=IntRange(0, 1_000_000), default=0,
                 show_default=True,
                 help="With --json: add the sampled time series (the --csv columns) as "
                      "\"series\", every k-th sample so that at most this many rows (0: none)."),
]


def _tdpa_and_series(f: Any) -> Any:
    """simulate's --tdpa options and --series."""
    for d in reversed(_TDPA_AND_SERIES):
        f = d(f)
    return f


_NETWORK = [
    click.option("--delay-trace", "delay_trace", type=click.Path(dir_okay=False), default=None,
                 help="Network trace CSV: sample (or time_s), delay_samples (each packet's "
                      "transport delay) and arrived (1/0); PEB optionally "
                      "delay_backward_samples, arrived_backward. Replaces the loop's delay."),
    click.option("--jitter", default=None,
                 help="Random network: each packet's delay uniform in LO:HI whole samples "
                      "(or seconds with a unit, 5ms:15ms). Replaces the loop's delay."),
    click.option("--loss", type=NONNEG, default=None,
                 help="Random network: each packet lost with probability P (the receiver "
                      "holds the last value it used). Without --jitter: at the loop's delay."),
    click.option("--seed", type=IntRange(0, 2 ** 63 - 1), default=0, show_default=True,
                 help="Seed of the random network (same seed, same run)."),
]


def _network_options(f: Any) -> Any:
    """simulate's network options."""
    for d in reversed(_NETWORK):
        f = d(f)
    return f


def _network(loop: Any, trace: str | None, jitter: str | None, loss: float | None,
             seed: int) -> Any:
    """The network the options ask for: a trace file, random delays and losses, or None."""
    from hapstab.cli.network import parse_delay_range
    from hapstab.errors import HapstabError
    from hapstab.models.delays import whole_delays
    from hapstab.simulation.network_trace import read_trace

    if trace is not None:
        if jitter is not None or loss is not None:
            raise HapstabError("--delay-trace: a trace gives every packet's delay and arrival; "
                               "not with --jitter / --loss")
        return read_trace(trace, loop.period)
    if jitter is None and loss is None:
        return None
    if jitter is None:
        d = float(loop.delay_in_samples)
        if d != int(d):
            raise HapstabError(f"--loss: the loop's delay {d:g} samples is not whole; give "
                               "--jitter LO:HI (whole samples)")
        lo = hi = int(d)
    else:
        a, b, seconds = parse_delay_range(jitter, "--jitter")
        lo, hi = whole_delays(a, b, loop.period) if seconds else (int(a), int(b))
    return {"jitter": (lo, hi), "loss": 0.0 if loss is None else loss, "seed": seed}


def _tdpa(on: bool, observer: str | None, velocity: str | None,
          max_damping: float | None) -> dict[str, Any] | None:
    """The TDPA options of the command line (any --tdpa-* option turns it on)."""
    given = {k: v for k, v in (("observer", observer), ("velocity", velocity),
                               ("max_damping", max_damping)) if v is not None}
    return given if on or given else None


def _run(kind: str, loop: Any, duration: float, force: str, x0: float, rest: float | None,
         environment_force: str | None, wall: float | None, wall_pulls: bool,
         **options: Any) -> Any:
    """The simulation the options ask for: the force on the device / master, the
    environment force (PEB) or the wall (HVE), initial and rest positions."""
    from hapstab.simulation.run import simulate

    opts: dict[str, Any] = dict(options)
    if kind != "hve":
        opts["environment_force"] = None if environment_force in (None, "none") else environment_force
        x_init: Any = [x0, 0.0]
        rest_pos: Any = None if rest is None else [rest, 0.0]
    else:
        opts.update(wall=wall, wall_pulls=wall_pulls)
        x_init, rest_pos = x0, rest
    return simulate(loop, duration, force=None if force == "none" else force,
                    initial_position=x_init, rest_position=rest_pos, **opts)


def _summary(res: Any, loop: Any, files: list[str], series_points: int = 0) -> dict[str, Any]:
    """The run's summary beside the exact verdict of the linear loop: this one, or
    with nonlinear elements the linearised one (wall always in contact, no
    saturation, quantisation or friction)."""
    from hapstab.analysis.exact.core import stability

    what = LINEAR_LOOP[bool(res.nonlinear)]
    if "network" in res.nonlinear:       # the network replaced the loop's delay
        from hapstab.simulation.network import Network, network_loop

        n = int(res.delay_samples)
        loop = network_loop(Network(jitter=(n, n)), loop)
        what = (f"this loop at the constant delay {n} samples (the network's largest), no "
                "packet lost" + (", " + what.split("(", 1)[1].rstrip(")")
                                 if set(res.nonlinear) != {"network"} else ""))
    ex = stability(loop)
    d = res.summary()
    d.update(linear_loop=what, linear_loop_verdict=ex.verdict,
             linear_loop_spectral_radius=ex.spectral_radius,
             linear_loop_growth_rate_per_s=(math.log(ex.spectral_radius) / loop.period
                                            if ex.spectral_radius > 0 else -math.inf),
             files=files)
    if series_points:
        d["series"] = _series(res, series_points)
    return d


def _g(x: Any, spec: str = ".6g") -> str:
    """A summary value: a number, or "inf/NaN" where the run overflowed (null in JSON)."""
    return format(x, spec) if isinstance(x, (int, float)) else "inf/NaN (overflow)"


def _table(kind: str, stiffness: float, loop: Any, res: Any, d: dict[str, Any],
           files: list[str]) -> None:
    """The readable table of a run."""
    v = res.verdict
    rate = (v.rate_words() if v.growth_rate == -math.inf else
            f"{_g(v.growth_rate)} 1/s (+- {_g(v.growth_rate_uncertainty, '.2g')})"
            f"{_doubling(v.growth_rate)}")
    rows = [("simulated", v.words()), ("growth rate", rate)]
    for lab in res.labels:       # what the plot shows: the swing at the start and at the end
        rows.append((f"swing of x, {lab}", f"{_g(d[f'swing_start_m_{lab}'])} m in the first "
                                           f"tenth of the run, {_g(d[f'swing_end_m_{lab}'])} m "
                                           "in the last"))
    if v.amplitude_m is not None:
        rows.append(("limit cycle", f"amplitude {v.amplitude_m:.4g} m, period {v.period_s:.4g} s"))
    if v.duration_hint_s is not None:
        rows.append(("to decide", f"run about {v.duration_hint_s:.3g} s"))
    rows += [(f"exact, {d['linear_loop']}",
              f"{d['linear_loop_verdict']} (rate {_g(d['linear_loop_growth_rate_per_s'])} 1/s)"),
             ("samples", f"{d['samples']} x {loop.period:g} s")]
    for lab in res.labels:
        rows.append((f"max |x| {lab}", f"{_g(d[f'max_abs_position_{lab}'])} m"))
        rows.append((f"max |u| {lab}", f"{_g(d[f'max_abs_force_{lab}'])} N"))
        rows.append((f"energy into controller from {lab}", f"{_g(d[f'final_port_energy_{lab}'])} J"))
        if res.tdpa is not None:
            rows.append((f"TDPA at {lab}", _tdpa_row(d, lab)))
    rows.extend([("why", v.reason)] + [("wrote", f) for f in files])
    rich_table(f"simulation, {kind}, K = {stiffness:g} N/m", rows, loop)


def _tdpa_row(d: dict[str, Any], lab: str) -> str:
    """One port's TDPA in a line: lowest observed energy, dissipated energy, peak damping
    and how often the controller acted."""
    return (f"observed energy >= {_g(d[f'tdpa_min_observed_energy_J_{lab}'], '.3g')} J, "
            f"dissipated {_g(d[f'tdpa_dissipated_J_{lab}'], '.4g')} J, peak damping "
            f"{_g(d[f'tdpa_peak_damping_N_s_per_m_{lab}'], '.4g')} N s/m, active in "
            f"{_g(100 * d[f'tdpa_active_fraction_{lab}'], '.3g')} % of samples")


def _doubling(rate: float) -> str:
    """``: doubles every 8.3 s`` / ``: halves every ...`` for a rate in 1/s."""
    if not math.isfinite(rate) or abs(rate) < 1e-12:   # (below 1e-12 1/s: never, in practice)
        return ""
    return f": {'doubles' if rate > 0 else 'halves'} every {math.log(2) / abs(rate):.3g} s"


for _kind in STATE_SPACE_KINDS:
    _simulate_command(_kind)


# ------------------------------------------------------------------ reproduce
@click.command("reproduce", short_help="Reproduce the paper's Fig. 5 / Fig. 6 (PNG, SVG, CSV).")
@click.argument("figure", type=click.Choice(["fig5", "fig6", "all"]))
@click.option("--out", "out_dir", default="out", show_default=True, type=click.Path(file_okay=False),
              help="Directory for figN.png, figN.svg and figN.csv.")
@click.option("--periods", default=None,
              help="Sampling periods in s (start:stop:count or a comma list); default the "
                   "paper's 1..10 ms.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def reproduce_cmd(figure: str, out_dir: str, periods: str | None, as_json: bool) -> None:
    """Reproduce the paper's Fig. 5 (HVE) and/or Fig. 6 (PEB): theory lines, simulation
    stars, exact and circle-criterion boundaries; PNG, SVG and CSV files."""
    from hapstab import __version__
    from hapstab.paper.reproduce import FIGURES, PAPER_PERIODS, reproduce_figure

    T = parse_periods(periods, "--periods") if periods else list(PAPER_PERIODS)
    names = list(FIGURES) if figure == "all" else [figure]
    total = sum(len(FIGURES[n].delays) for n in names) * len(T)
    reps = []
    with progress(total, "K_max by simulation", as_json) as tick:
        for n in names:
            reps.append(reproduce_figure(n, T, progress=tick))
    manifest = {"command": "reproduce", "figure": figure, "periods_s": T,
                "hapstab_version": __version__}
    files = write_folder(out_dir, [(r.figure.name, r) for r in reps], manifest, "--out")
    if as_json:
        click.echo(dumps({**provenance(), "figures": [r.to_dict() for r in reps], "files": files,
                               "worst_simulation_error": max(r.worst_simulation_error()
                                                             for r in reps)}))
        return
    _reproduce_table(reps)
    click.echo("wrote:")
    for f in files:
        click.echo(f"  {f}")


def _reproduce_table(reps: list[Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    con = Console(width=None if sys.stdout.isatty() else 110)   # piped: do not truncate to 80
    for rep in reps:
        has_circle = "circle" in rep.columns
        t = Table(title=f"{rep.figure.title}\nK_max (N/m): paper's condition vs exact vs simulation")
        cols = ["T (ms)", "n", "eq.", "paper", "exact", "simulation", "sim vs exact", "exact/paper"]
        if has_circle:
            cols.insert(6, "circle")
        for c in cols:
            t.add_column(c, justify="right")
        for r in rep.rows:
            cells = [f"{r['period_s'] * 1e3:.4g}", str(r["delay_samples"]), r["equation"],
                     f"{r['theory']:.6g}", f"{r['exact']:.6g}", f"{r['simulation']:.6g}",
                     f"{100 * (r['simulation'] / r['exact'] - 1):+.4f} %" if r["exact"] else "-",
                     f"{r['exact'] / r['theory']:.4f}" if r["theory"] else "-"]
            if has_circle:
                cells.insert(6, f"{r['circle']:.6g}" if math.isfinite(r["circle"]) else "n/a")
            t.add_row(*cells)
        con.print(t)
        con.print(f"worst |simulation/exact - 1| = {rep.worst_simulation_error():.2e}")
