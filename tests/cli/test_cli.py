"""The CLI through its runner: exit codes, JSON on stdout, one-line errors on stderr."""

import json

import pytest
from click.testing import CliRunner

from hapstab.cli.main import cli
from reference_data import ref


def run(*args):
    return CliRunner().invoke(cli, list(args))


def test_kmax_hve_json_keys_and_value():
    r = run("kmax", "hve", "--mass", "0.15", "--damping", "0.1", "--period", "0.001", "--delay", "10",
            "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert {"critical_stiffness", "method", "stable_intervals"} <= d.keys()
    assert d["critical_stiffness"] == pytest.approx(9.5361, rel=1e-4) and d["method"] == "exact"


def test_kmax_peb_with_closed_form():
    r = run("kmax", "peb", "--delay", "4", "--method", "eq34", "--json")
    assert r.exit_code == 0
    assert json.loads(r.stdout)["critical_stiffness"] == pytest.approx(4.0)


def test_kmax_gil2004_reproducer_is_accurate():
    # issue #8: bT/m = 2e-8 gave 23.89 from cancellation; the true value (40-digit
    # evaluation of the same closed form) is 20.0000000666666666
    r = run("kmax", "hve", "--mass", "5", "--damping", "0.001", "--period", "1e-4", "--operator",
            "none", "--method", "gil2004", "--json")
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["critical_stiffness"] == pytest.approx(20.000000066666666635,
                                                                       rel=1e-12)


def test_kmax_table_without_json():
    r = run("kmax", "hve")
    assert r.exit_code == 0 and "critical stiffness" in r.stdout and "200.022" in r.stdout


def test_check_json_verdicts():
    r = run("check", "hve", "--stiffness", "250", "--json")
    d = json.loads(r.stdout)
    assert r.exit_code == 0 and d["verdict"] == "unstable" and d["spectral_radius"] > 1
    d = json.loads(run("check", "peb", "-K", "3", "--delay", "4", "--json").stdout)
    assert d["verdict"] == "stable"
    d = json.loads(run("check", "peb", "-K", "3", "--operator", "none", "--environment", "none",
                       "--json").stdout)
    assert d["verdict"] == "marginal" and d["rigid_body_modes"] == 1


def test_boundary_json_and_csv(tmp_path):
    csv = tmp_path / "b.csv"
    r = run("boundary", "hve", "--period", "0.001:0.003:3", "--delay", "0,10", "--csv", str(csv),
            "--json")
    assert r.exit_code == 0
    d = json.loads(r.stdout)
    assert len(d["critical_stiffness"]) == 2 and len(d["critical_stiffness"][0]) == 3
    assert csv.read_text().count("\n") == 7


@pytest.mark.parametrize("args", [("-B", "-0.05"), ("--virtual-damping=-0.05",)])
def test_negative_virtual_damping_is_accepted(args):
    r = run("kmax", "hve", *args, "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    # half the device damping cancelled: K_max ~ 2(b - |B|)/T = 100 N/m (exact 100.045)
    k, rel = ref("hve_negative_B_kmax")
    assert d["critical_stiffness"] == pytest.approx(k, rel=rel)


def test_negative_virtual_damping_beyond_device_damping_says_unstable_for_every_k():
    r = run("kmax", "hve", "-B", "-0.5", "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["critical_stiffness"] == 0.0 and d["stable_intervals"] == []
    assert "unstable for every K > 0" in d["reason"]
    r = run("check", "peb", "-K", "3", "-B", "-0.005", "--json")
    assert r.exit_code == 0 and json.loads(r.stdout)["verdict"] == "stable"


def test_simulate_with_negative_virtual_damping():
    r = run("simulate", "hve", "-K", "50", "-B", "-0.05", "--duration", "1", "--json")
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    # K = 50 < K_max(B = -0.05) = 100.04: bounded, and the exact analysis agrees
    assert d["linear_loop_verdict"] == "stable" and d["verdict"] == "bounded"
    d = json.loads(run("simulate", "hve", "-K", "50", "-B", "-0.2", "--duration", "1",
                       "--json").stdout)
    assert d["linear_loop_verdict"] == "unstable" and d["linear_loop_growth_rate_per_s"] > 0


def test_demo_prints_both_figures():
    r = run("demo", "--json")
    d = json.loads(r.stdout)
    assert set(d) == {"Fig. 5 (HVE)", "Fig. 6 (PEB)", "hapstab_version", "inputs"}
    assert len(d["Fig. 5 (HVE)"]) == 20


@pytest.mark.parametrize("args,needle", [
    (("kmax", "hve", "--mass", "-1"), "'--mass'"),
    (("kmax", "hve", "--mass", "0"), "must be > 0"),
    (("kmax", "hve", "--period", "nan"), "must be finite"),
    (("kmax", "hve", "--damping", "inf"), "must be finite"),
    (("kmax", "hve", "-B", "nan"), "'--virtual-damping' / '-B': 'nan': must be finite"),
    (("kmax", "hve", "--damping", "-0.1"), "'--damping' / '-b': '-0.1': must be >= 0"),
    (("kmax", "hve", "--delay", "2.5"), "whole number of samples"),
    (("kmax", "hve", "--method", "eq34"), "--method = 'eq34': unknown for hve; allowed:"),
    (("kmax", "peb", "--environment", "msd:1,2"), "--environment = 'msd:1,2'"),
    (("kmax", "hve", "--operator", "spring:abc"), "malformed number"),
    (("kmax", "hve", "--mass", "abc"), "'abc' is not a number"),
    (("boundary", "hve", "--period", "0.003:0.001:3"), "the range is empty"),
    (("boundary", "hve", "--delay", ""), "the list is empty"),
    (("check", "hve"), "Missing option '--stiffness'"),
    (("kmax", "hve", "--frobnicate"), "No such option"),
])
def test_bad_input_is_one_line_and_exit_2(args, needle):
    r = run(*args)
    assert r.exit_code == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hapstab: error: ") and needle in lines[0]
    assert "Traceback" not in r.stderr and r.stdout == ""


def test_help_exits_zero():
    r = run("kmax", "hve", "--help")
    assert r.exit_code == 0 and "--virtual-damping" in r.stdout


def test_approximation_only_with_circle():
    r = run("kmax", "hve", "--method", "exact", "--approximation", "forward")
    assert r.exit_code == 2 and "applies to --method circle or llewellyn only" in r.stderr
    assert "Traceback" not in r.stderr


def test_paper_methods_refuse_fractional_delay_in_one_line():
    r = run("kmax", "hve", "--delay-s", "0.0105", "--method", "circle")
    assert r.exit_code == 2 and "whole number of samples" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("args,needle", [
    (("boundary", "hve", "--csv", "/nonexistent/dir/x.csv"), "the folder '/nonexistent/dir' does not exist"),
    (("kmax", "hve", "--delay", "100001"), "at most 100000 samples"),
    (("kmax", "hve", "--mass", "1e-300"), "cannot"),
    (("kmax", "hve", "-B", "1e300"), "cannot"),
    (("kmax", "hve", "--period", "1e300"), "between 1e-07 s and 1000 s"),
    (("boundary", "hve", "--period", "0.001:0.002:1e12"), "from 1 to 100000"),
    # every period is checked, not only the first (these gave 0.0 and inf)
    (("boundary", "hve", "--period", "0.001,1e-9"), "period = 1e-09: must be between 1e-07 s and 1000 s"),
    (("boundary", "hve", "--period", "0.001,1e9"), "period = 1e+09: must be between 1e-07 s and 1000 s"),
    (("boundary", "peb", "--period", "0.001:3000:3"), "period = 1500: must be between"),
])
def test_extreme_input_is_one_line_and_exit_2(args, needle):
    r = run(*args)
    assert r.exit_code == 2 and needle in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_delay_with_one_side_is_refused():
    """Issue 27, 8: `-n 3 --delay-forward 2` was taken silently as forward 2, backward 3;
    a delay given two ways is refused (both sides one way, or one --delay)."""
    for args in (["--delay-forward", "2", "-n", "3"], ["--delay", "4", "--delay-backward", "4"]):
        r = run("kmax", "peb", *args)
        assert r.exit_code == 2 and "give the delay one way" in r.stderr, r.stderr
    a = json.loads(run("kmax", "peb", "--delay-forward", "4", "--delay-backward", "4",
                       "--json").stdout)
    b = json.loads(run("kmax", "peb", "--delay", "4", "--json").stdout)
    assert a["critical_stiffness"] == b["critical_stiffness"]


# ------------------------------------------------ user errors vs bugs (issue #10, 6)
def _break_stability(monkeypatch, exc):
    import hapstab.analysis.exact.core as core
    import hapstab.cli.exact as mod  # noqa: F401 - the command imports stability lazily

    def boom(*a, **k):
        raise exc
    monkeypatch.setattr(core, "stability", boom)


@pytest.mark.parametrize("exc", [ValueError("shapes (3,) and (4,) not aligned"),
                                 ZeroDivisionError("float division by zero"),
                                 RuntimeError("oops")])
def test_an_unexpected_exception_is_a_bug_exit_1_one_line(monkeypatch, exc):
    _break_stability(monkeypatch, exc)
    r = CliRunner().invoke(cli, ["check", "hve", "-K", "100"])
    assert r.exit_code == 1
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hapstab: internal error: ")
    assert type(exc).__name__ in lines[0] and "please report" in lines[0]


def test_debug_shows_the_traceback(monkeypatch):
    _break_stability(monkeypatch, RuntimeError("oops"))
    r = CliRunner().invoke(cli, ["--debug", "check", "hve", "-K", "100"])
    assert r.exit_code == 1 and isinstance(r.exception, RuntimeError)


@pytest.mark.parametrize("path", ["o.pgf", "o.xyz", "o"])
def test_a_plot_format_hapstab_does_not_write_is_a_user_error(tmp_path, path):
    r = CliRunner().invoke(cli, ["simulate", "hve", "-K", "9", "-t", "0.1",
                                 "--plot", str(tmp_path / path)])
    assert r.exit_code == 2 and "allowed: png" in r.stderr
    assert not (tmp_path / path).exists()


def test_help_summaries_are_not_cut_at_fig():
    # click ends a short help at the first ". ": "Fig. 5" cut it to "(Fig." (issue #12)
    r = CliRunner().invoke(cli, ["--help"])
    assert r.exit_code == 0 and "(Fig.\n" not in r.output and not r.output.rstrip().endswith("(Fig.")
    assert all(not line.rstrip().endswith("(Fig.") and not line.rstrip().endswith(" Fig.")
               for line in r.output.splitlines())


def test_every_subcommand_has_a_description():
    # issue #12: the hve / peb subcommands were listed with no description
    import click

    from hapstab.cli.main import cli as group

    for name, cmd in group.commands.items():
        if isinstance(cmd, click.Group):
            for sub_name, sub in cmd.commands.items():
                assert sub.help and sub.get_short_help_str(80).strip(), (name, sub_name)
                assert sub.help[:25] in run(name, "--help").stdout


@pytest.mark.parametrize("args,period", [
    (("-T", "1ms"), 1e-3), (("-T", "250 us"), 2.5e-4), (("-T", "0.002"), 2e-3),
    (("--rate", "1kHz"), 1e-3), (("--rate", "500"), 2e-3), (("--rate", "2 kHz"), 5e-4)])
def test_periods_and_rates_with_units(args, period):
    # issue #12: -T 1ms was refused and there was no --rate
    r = run("kmax", "hve", *args, "--json")
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["period_s"] == pytest.approx(period, rel=1e-15)


def test_a_delay_in_milliseconds():
    d = json.loads(run("kmax", "hve", "--delay-s", "20ms", "--json").stdout)
    assert d["delay_samples"] == 20.0


def test_a_one_second_period_warns_of_a_unit_mistake():
    r = run("kmax", "hve", "-T", "1", "--json")
    assert r.exit_code == 0 and json.loads(r.stdout)["period_s"] == 1.0
    assert r.stderr.startswith("hapstab: warning: sampling period T = 1 s") and "-T 1ms" in r.stderr
    assert run("kmax", "hve", "-T", "1ms", "--json").stderr == ""


@pytest.mark.parametrize("args,needle", [
    (("kmax", "hve", "-T", "1furlong"), "unknown unit 'furlong'; allowed: s, ms, us"),
    (("kmax", "hve", "-T", "1ms", "--rate", "1kHz"), "--period and --rate: give one"),
    (("kmax", "--mass", "0.3"), "the loop kind (hve, peb or 4ch) comes first, its options after it, "
                                "e.g. hapstab kmax hve --mass 0.3"),
])
def test_unit_and_order_mistakes_are_explained(args, needle):
    r = run(*args)
    assert r.exit_code == 2 and needle in r.stderr and r.stderr.count("\n") == 1


def test_tables_are_not_cut_when_piped():
    # issue #12: `boundary hve ... -n 0,1,2,3,5,10` printed 14021.17... at 80 columns
    r = run("boundary", "hve", "--period", "0.0001,0.001", "-n", "0,1,2,3,5,10")
    assert r.exit_code == 0 and "…" not in r.stdout and "2000.022234" in r.stdout


def test_region_explains_dash_B_against_double_dash_B():
    r = run("region", "hve", "--K", "0:900", "-B", "0:20")
    assert r.exit_code == 2 and "window of B is --B lo:hi (two dashes)" in r.stderr


def test_closed_forms_do_not_print_nan_hz():
    out = run("kmax", "hve", "--method", "eq18", "--delay", "3").stdout
    assert "nan" not in out and "not given by this method" in out


@pytest.mark.parametrize("kind", ["hve", "peb"])
def test_the_cli_defaults_are_the_apis_paper_loops(kind):
    """Issue #12: one set of defaults, stated: `hapstab <cmd> hve` with no options is
    `hapstab.paper_hve()` (and peb `paper_peb()`), the stiffness being what kmax varies."""
    import hapstab as h

    make = {"hve": h.paper_hve, "peb": h.paper_peb}[kind]
    d = json.loads(CliRunner().invoke(cli, ["kmax", kind, "--json"]).stdout)
    cli_loop, api_loop = d["inputs"]["loop"], make().to_dict()
    differ = {k for k in cli_loop if cli_loop[k] != api_loop[k]}
    assert differ <= {"controller", "master_controller", "slave_controller"}
    for k in differ:      # only the stiffness, which K_max does not depend on
        assert {**cli_loop[k], "stiffness_N_per_m": 0} == {**api_loop[k], "stiffness_N_per_m": 0}
    assert d["critical_stiffness"] == h.critical_stiffness(make()).critical_stiffness


@pytest.mark.parametrize("args,needle", [
    (["kmax", "hve", "--rate", "1mHz"], "unknown unit 'mHz'"),        # millihertz is not MHz
    (["kmax", "hve", "-T", "1Ms"], "unknown unit 'Ms'"),              # megaseconds is not ms
    (["kmax", "hve", "--mass", "1" + "0" * 5000], "must be"),
])
def test_case_sensitive_units_and_short_lines(args, needle):
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 2 and needle in r.stderr and r.stderr.count("\n") == 1
    assert len(r.stderr) < 700


@pytest.mark.parametrize("text,seconds", [("1MHz", 1e-6), ("2kHz", 5e-4), ("500 Hz", 2e-3)])
def test_rates_with_units_still_read(text, seconds):
    d = json.loads(CliRunner().invoke(cli, ["kmax", "hve", "--rate", text, "--json"]).stdout)
    assert d["period_s"] == pytest.approx(seconds, rel=1e-15)
