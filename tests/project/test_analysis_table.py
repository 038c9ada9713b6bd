"""The one table of analyses (hapstab.analysis.table) names things that exist, and each
row agrees with them: the function returns the result, the result draws with the plot
named, the command takes the loop kinds and the option named, the sweep's quantity has
the row's columns, the explorer runs the row's endpoint."""

import importlib
import inspect
import pathlib

import click
import pytest

import paths
from hapstab.analysis import table
from hapstab.analysis.table import TABLE
from hapstab.cli.main import cli
from hapstab.results import Result
from hapstab.sweep.evaluate import QUANTITIES

ROWS = {r.name: r for r in TABLE}
ROOMS = {p.name for p in (pathlib.Path(table.__file__).parent).iterdir() if p.is_dir()
         and (p / "__init__.py").exists()} | {"simulation"}

#: analysis/'s top-level modules: the front door (critical_stiffness, boundary) and margins
TOP = {"hapstab.analysis.methods", "hapstab.analysis.margins"}


def _resolve(path):
    module, _, name = path.partition(":")
    obj = importlib.import_module(module)
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def test_rows_have_one_name_each():
    assert len(ROWS) == len(TABLE)
    assert table.row("kmax") is ROWS["kmax"]
    with pytest.raises(KeyError):
        table.row("kmaxx")


@pytest.mark.parametrize("name", ROWS)
def test_the_function_returns_the_result_and_lives_in_its_room(name):
    r = ROWS[name]
    assert r.room in ROOMS, r.room
    f, cls = _resolve(r.function), _resolve(r.result)
    assert callable(f) and inspect.isclass(cls)
    home = {"simulation": "hapstab.simulation."}.get(r.room, f"hapstab.analysis.{r.room}.")
    assert f.__module__.startswith(home) or f.__module__ in TOP, (r.room, f.__module__)
    ret = inspect.signature(f).return_annotation
    assert ret == cls.__name__ or ret is cls, (ret, cls)


@pytest.mark.parametrize("name", ROWS)
def test_the_result_draws_with_the_plot_named(name):
    r = ROWS[name]
    cls = _resolve(r.result)
    if r.plot is None:
        assert not hasattr(cls, "plot"), f"{cls.__name__} draws: name its plot in the table"
        return
    assert issubclass(cls, Result)
    draw = _resolve(r.plot)
    assert callable(draw) and hasattr(cls, "plot")
    if draw is not cls.plot:            # a plotting function the result's plot calls
        assert draw.__name__ in inspect.getsource(cls.plot), (r.plot, cls.__name__)


@pytest.mark.parametrize("name", [n for n, r in ROWS.items() if r.command])
def test_the_command_takes_the_kinds_and_the_option_named(name):
    r = ROWS[name]
    cmd = cli.commands[r.command]
    kinds = tuple(cmd.commands) if isinstance(cmd, click.Group) else ()
    assert sorted(kinds) == sorted(r.kinds), (r.command, kinds)
    if r.option:
        sub = cmd.commands[r.kinds[0]] if r.kinds else cmd
        opts = {o for p in sub.params for o in (*p.opts, *p.secondary_opts)}
        assert r.option in opts, (r.command, r.option)


def test_the_cli_registers_every_command_of_the_table_and_no_other_analysis():
    from hapstab.cli import conditions, design, exact, network

    assert set(table.commands()) <= set(cli.commands)
    # the commands found by name are the modules' own objects
    assert cli.commands["kmax"] is exact.kmax and cli.commands["audit"] is conditions.audit_cmd
    assert cli.commands["best-damping"] is design.best
    assert cli.commands["jitter"] is network.jitter_cmd
    loop_commands = {n for n, c in cli.commands.items() if isinstance(c, click.Group)}
    assert loop_commands <= set(table.commands()), loop_commands - set(table.commands())


def test_the_sweeps_quantities_are_the_tables():
    assert QUANTITIES == table.quantities()
    assert list(QUANTITIES) == [r.quantity for r in TABLE if r.quantity]
    for r in TABLE:
        assert bool(r.quantity) == bool(r.columns), r.name
        if r.quantity:
            assert all(t in ("float64", "string", "bool") for _, t in r.columns)


def test_the_explorers_commands_are_the_tables_endpoints():
    from hapstab.explorer.api import COMMANDS

    assert COMMANDS == table.endpoints()     # the explorer reads the table
    assert len(set(COMMANDS)) == len(COMMANDS)
    for r in TABLE:
        if r.endpoint:
            assert r.endpoint == r.command, r.name   # the explorer runs the CLI's command


def test_the_tests_are_laid_out_by_the_same_rooms():
    """Each room's tests live in tests/<room>/ (the analyses' rooms, and the layers
    around them); nothing is left at the top of tests/ but the shared references."""
    tests = paths.ROOT / "tests"
    for room in {r.room for r in TABLE}:
        assert sorted((tests / room).glob("test_*.py")), f"no tests/{room}/"
    assert not sorted(tests.glob("test_*.py")), "a test outside its room's folder"
    names = [p.name for p in tests.glob("*/test_*.py")]
    assert len(names) == len(set(names)), "two rooms hold a test module of one name"


@pytest.mark.parametrize("name", [n for n, r in ROWS.items() if r.command and not r.option])
def test_the_command_lives_in_the_cli_module_of_its_room(name):
    """cli/<room>.py answers the room's questions: the module is named as the analysis's
    room (an analysis asked through another command's option lives with that command)."""
    r = ROWS[name]
    cmd = cli.commands[r.command]
    subs = list(cmd.commands.values()) if isinstance(cmd, click.Group) else [cmd]
    for sub in subs:
        assert sub.callback.__module__ == f"hapstab.cli.{r.room}", (name, sub.callback.__module__)
