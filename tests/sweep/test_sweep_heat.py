"""The sweep's summary and heat map (issue 29 item 6). The heat map: not only the minimum
over the axes it does not show (with the virtual damping B as such an axis the minimum is
always B = 0's K_max) but their maximum, their median or a slice at one value, in the API
(``SweepResult.heat_map`` and ``.plot``), the study file (``[sweep.plot] reduce / at``)
and the command line (``--reduce``, ``--at``), each cell checked against the rows."""

import json
import os

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
import paths
from hapstab.cli.main import cli
from hapstab.sweep import sweep
from hapstab.sweep.axes import SweepError

pq = pytest.importorskip("pyarrow.parquet")
pa = pytest.importorskip("pyarrow")

DELAYS = [1, 3]
RATES = [500.0, 1000.0, 2000.0]
B = [0.0, 2.0, 5.0]          # N·s/m: K_max grows with B here, so min is B = 0, max B = 5

STUDY = """kind = "hve"
[loop]
mass = 0.3
damping = 0.05
operator = "msd:0.5,5,500"
[sweep]
quantities = ["kmax"]
[sweep.axes]
delay = [1, 3]
rate = ["500Hz", "1kHz", "2kHz"]
virtual-damping = [0.0, 2.0, 5.0]
[sweep.plot]
x = "rate"
y = "delay"
"""


def _hve(o):
    return h.HapticLoop(h.Device(0.3, 0.05), h.SpringDamper(1.0, o["B"]), h.spring(1.0),
                        1 / o["rate"], int(o["delay"]))


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("heat") / "out"
    res = sweep(_hve, {"delay": DELAYS, "rate": RATES, "B": B}, str(out),
                  plot=("rate", "delay"), workers=1)
    t = pa.concat_tables([pq.read_table(os.path.join(out, "chunks", c))
                          for c in sorted(os.listdir(os.path.join(out, "chunks")))])
    K = np.array(t.sort_by("point_id").column("critical_stiffness_N_per_m").to_pylist())
    return res, K.reshape(len(DELAYS), len(RATES), len(B)), out   # the grid's own order


def test_each_reduction_is_that_function_of_the_rows(swept):
    res, K, _ = swept
    assert np.all(np.diff(K, axis=2) > 0)     # the premise: min at B = 0, max at B = 5
    for reduce, f in (("min", np.min), ("max", np.max), ("median", np.median)):
        m = res.heat_map(reduce=reduce)
        got = np.array(m["critical_stiffness_N_per_m"])
        assert got.shape == (2, 3) and m["reduce"] == reduce and m["over"] == ["B"]
        assert np.array_equal(got, f(K, axis=2)), reduce       # the rows' own floats
    assert res.heat_map() is res.summary["heat_map"]           # the summary's: min
    assert not np.array_equal(res.heat_map(reduce="max")["critical_stiffness_N_per_m"],
                              res.heat_map(reduce="min")["critical_stiffness_N_per_m"])


def test_a_slice_at_a_value_and_the_others_reduced(swept):
    res, K, _ = swept
    m = res.heat_map(at={"B": 2.0})
    assert np.array_equal(m["critical_stiffness_N_per_m"], K[:, :, 1])
    assert m["over"] == [] and m["at"] == {"B": 2.0}
    m = res.heat_map(x="B", y="delay", at={"rate": 1000.0}, reduce="max")
    assert np.array_equal(m["critical_stiffness_N_per_m"], K[:, 1, :])
    m = res.heat_map(x="B", y="rate", reduce="median")     # over delay, 2 values: their mean
    assert np.array_equal(m["critical_stiffness_N_per_m"], (K[0] + K[1]) / 2)
    assert res.heat_map(at={"B": 2.0 * (1 + 1e-12)})["at"] == {"B": 2.0}   # the grid's value


def test_bad_reductions_and_slices_are_refused_naming_what_is_allowed(swept):
    res, _, out = swept
    with pytest.raises(SweepError, match=r"reduce = 'mean': allowed: min, max, median"):
        res.heat_map(reduce="mean")
    with pytest.raises(SweepError, match=r"B = 3.0: not a value of the axis; its values: 0, 2, 5"):
        res.heat_map(at={"B": 3.0})
    with pytest.raises(SweepError, match="is an axis of the heat map"):
        res.heat_map(at={"rate": 500.0})
    with pytest.raises(SweepError, match="'mass' is not an axis; axes: delay, rate, B"):
        res.heat_map(at={"mass": 1.0})
    with pytest.raises(SweepError, match="plot_reduce = 'avg'"):
        sweep(_hve, {"delay": DELAYS, "rate": RATES, "B": B}, str(out), workers=1,
                plot_reduce="avg")


def test_the_figure_says_which_reduction_or_slice(swept):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    res, _, _ = swept
    ax = res.plot(reduce="max")
    assert "maximum over B" in ax.get_title()
    ax = res.plot(at={"B": 5.0})
    assert "at B = 5" in ax.get_title() and "over" not in ax.get_title()
    assert [t.get_text() for t in ax.get_xticklabels()] == ["500", "1000", "2000"]
    assert ax.get_xlabel() == "sampling rate"     # (a Python axis "rate": no unit to name)
    plt.close("all")


def test_a_rerun_with_another_reduction_recomputes_nothing(swept):
    _res, K, out = swept
    again = sweep(_hve, {"delay": DELAYS, "rate": RATES, "B": B}, str(out),
                    plot=("rate", "delay"), workers=1, plot_reduce="max")
    assert again.computed_chunks == 0
    assert np.array_equal(again.summary["heat_map"]["critical_stiffness_N_per_m"],
                          K.max(axis=2))
    assert json.loads((out / "summary.json").read_text())["heat_map"]["reduce"] == "max"


def test_the_command_line_and_the_study_file(tmp_path):
    (tmp_path / "s.toml").write_text(STUDY)
    base = ["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers", "1",
            "--json"]
    r = CliRunner().invoke(cli, base)
    assert r.exit_code == 0, r.stderr
    low = np.array(json.loads(r.stdout)["summary"]["heat_map"]["critical_stiffness_N_per_m"])
    r = CliRunner().invoke(cli, [*base, "--reduce", "max"])
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    high = np.array(d["summary"]["heat_map"]["critical_stiffness_N_per_m"])
    assert d["computed_chunks"] == 0 and np.all(high > low)      # B = 5 beats B = 0
    r = CliRunner().invoke(cli, [*base, "--at", "virtual-damping=5"])
    assert r.exit_code == 0, r.stderr
    heat = json.loads(r.stdout)["summary"]["heat_map"]
    assert np.array_equal(heat["critical_stiffness_N_per_m"], high)
    assert heat["at"] == {"virtual_damping_N_s_per_m": 5.0}
    r = CliRunner().invoke(cli, [*base, "--at", "rate=2kHz"])    # units as in the study
    assert r.exit_code == 2 and "is an axis of the heat map" in r.stderr
    r = CliRunner().invoke(cli, [*base, "--at", "virtual-damping=3"])
    assert r.exit_code == 2 and "--at: virtual-damping = 3.0: not a value" in r.stderr
    r = CliRunner().invoke(cli, [*base, "--at", "damping"])
    assert r.exit_code == 2 and "give NAME=VALUE" in r.stderr
    (tmp_path / "t.toml").write_text(STUDY.replace('y = "delay"', 'y = "virtual-damping"')
                                     + 'reduce = "median"\nat = { delay = 3 }\n')
    r = CliRunner().invoke(cli, ["sweep", str(tmp_path / "t.toml"), "--out",
                                 str(tmp_path / "p"), "--workers", "1", "--json"])
    assert r.exit_code == 0, r.stderr
    heat = json.loads(r.stdout)["summary"]["heat_map"]
    t = pa.concat_tables([pq.read_table(tmp_path / "p" / "chunks" / c)
                          for c in sorted(os.listdir(tmp_path / "p" / "chunks"))])
    K = np.array(t.sort_by("point_id").column("critical_stiffness_N_per_m").to_pylist())
    assert np.array_equal(heat["critical_stiffness_N_per_m"], K.reshape(2, 3, 3)[1].T)
    assert heat["at"] == {"delay_samples": 3} and heat["over"] == []
    (tmp_path / "v.toml").write_text(STUDY + 'at = { delay = 3 }\n')
    r = CliRunner().invoke(cli, ["sweep", str(tmp_path / "v.toml"), "--out",
                                 str(tmp_path / "q"), "--workers", "1"])
    assert r.exit_code == 2 and "line 15: sweep.plot.at: 'delay' is an axis of the heat" \
        in r.stderr
    (tmp_path / "u.toml").write_text(STUDY + 'reduce = "mode"\n')
    r = CliRunner().invoke(cli, ["sweep", str(tmp_path / "u.toml"), "--out",
                                 str(tmp_path / "q"), "--workers", "1"])
    assert r.exit_code == 2 and \
        "line 15: sweep.plot.reduce = 'mode': allowed: min, max, median" in r.stderr


def test_hapstab_sweep_is_callable_after_a_submodule_import():
    """``from hapstab.sweep.axes import ...`` binds ``hapstab.sweep`` to the package; it
    must still be the function ``hapstab.sweep(...)`` the docs call (it was a module)."""
    import subprocess
    import sys

    code = ("import hapstab as h, tempfile\nfrom hapstab.sweep.axes import Points\n"
            "r = h.sweep(lambda o: h.paper_hve(1e-3, int(o['delay'])), {'delay': [0, 1]}, "
            "tempfile.mkdtemp(), workers=1)\nprint(type(r).__name__)")
    src = str(paths.SRC)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": src}, check=True)
    assert out.stdout.strip() == "SweepResult"


def test_points_where_a_quantity_does_not_apply_are_not_called_errors(tmp_path):
    """Item 6: the sampled-data passivity at a fractional delay does not apply; the table
    said "N points carry a message in the error column" although K_max was fine."""
    (tmp_path / "s.toml").write_text('kind = "hve"\n[sweep]\nquantities = ["kmax", '
                                     '"passivity"]\n[sweep.axes]\ndelay-s = [0.002, 0.0025, '
                                     '0.0035]\n')
    r = CliRunner().invoke(cli, ["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"),
                                 "--workers", "1"])
    assert r.exit_code == 0, r.stderr
    text = " ".join(r.stdout.split())
    assert "error column" not in text
    assert "2 points have a quantity that does not apply there (the not_applicable column; " \
        "not errors)" in text


def test_the_rows_read_as_the_docs_say(swept):
    """Item 6: the README said the results read with pandas, which hapstab does not
    install; the docs name pyarrow (the sweep extra) and its one call for the folder."""
    _res, K, out = swept
    docs = (paths.ROOT / "docs" / "guide" / "sweeps.md").read_text()
    assert '`pyarrow.parquet.read_table("DIR/chunks")`' in docs
    assert "pandas is not installed by hapstab" in " ".join(docs.split())
    readme = (paths.ROOT / "README.md").read_text()
    assert "pandas" not in readme
    t = pq.read_table(str(out / "chunks")).sort_by("point_id")
    assert t.num_rows == K.size
    assert np.array_equal(t.column("critical_stiffness_N_per_m").to_numpy(), K.reshape(-1))
