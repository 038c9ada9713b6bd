"""hapstab sweep (issue 16): the points and their order, the rows against the public API
called point by point, resuming, malformed study files refused before any work, and the
sweep's packages imported only when a sweep runs."""

import itertools
import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner

import hapstab as h
import paths
from hapstab.cli.main import cli
from hapstab.sweep.axes import Points, SweepError, parse_axis

pq = pytest.importorskip("pyarrow.parquet")
pa = pytest.importorskip("pyarrow")

HERE = str(paths.ROOT / "tests")
SRC = os.path.join(os.path.dirname(HERE), "src")


def rows(folder):
    """Every row of a sweep's folder, read with pyarrow, sorted by point id."""
    chunks = sorted(os.listdir(os.path.join(folder, "chunks")))
    t = pa.concat_tables([pq.read_table(os.path.join(folder, "chunks", c)) for c in chunks])
    return t.sort_by("point_id")


def invoke(args, **kw):
    return CliRunner().invoke(cli, args, **kw)


# ----------------------------------------------------------------------------- axes
def test_linear_log_list_and_units():
    a = parse_axis("mass", "0.1:0.5:5")
    assert a.values == tuple(np.linspace(0.1, 0.5, 5))
    b = parse_axis("rate", "250:4000:5:log")
    assert np.allclose(b.values, [250, 500, 1000, 2000, 4000], rtol=1e-14)  # geomspace rounding
    assert parse_axis("mass", [0.3, 1]).values == (0.3, 1.0)
    units = {"250Hz": 250.0, "4kHz": 4000.0}
    c = parse_axis("rate", "250Hz:4kHz:5:log", convert=lambda v: units.get(v, v))
    assert c.values == b.values
    d = parse_axis("delay", "0:20:5", integer=True)
    assert d.values == (0, 5, 10, 15, 20) and all(type(v) is int for v in d.values)
    assert d.dtype == "int64" and a.dtype == "float64"
    assert parse_axis("x", "2:2:1").values == (2.0,)


def test_grid_order_is_the_product_with_the_last_axis_fastest():
    axes = (parse_axis("a", [1, 2]), parse_axis("b", [10, 20, 30]), parse_axis("c", [5, 6]))
    p = Points(axes)
    assert p.count == 12
    v = p.values(0, 12)
    got = list(zip(v["a"], v["b"], v["c"], strict=True))
    assert got == list(itertools.product([1, 2], [10, 20, 30], [5, 6]))
    part = p.values(5, 9)                   # a chunk alone gives the same points
    assert list(zip(part["a"], part["b"], part["c"], strict=True)) == got[5:9]


def test_random_points_are_the_rows_of_default_rng_and_reproducible():
    axes = (parse_axis("m", "0.1:1", random=True), parse_axis("T", "1e-4:1e-2:log", random=True),
            parse_axis("n", "0:20", random=True, integer=True))
    p = Points(axes, samples=1000, seed=7)
    u = np.random.default_rng(7).random((1000, 3))
    full = p.values(0, 1000)
    assert np.array_equal(full["m"], 0.1 + u[:, 0] * 0.9)
    assert np.allclose(full["T"], np.exp(np.log(1e-4) + u[:, 1] * (np.log(1e-2) - np.log(1e-4))),
                       rtol=1e-15)  # the same formula: rounding of exp only
    assert np.array_equal(full["n"], np.floor(u[:, 2] * 21).astype(int))
    assert full["n"].min() >= 0 and full["n"].max() <= 20 and full["n"].dtype == np.int64
    for start, stop in ((0, 1), (13, 400), (999, 1000)):      # any chunk, the same rows
        part = p.values(start, stop)
        for k in full:
            assert np.array_equal(part[k], full[k][start:stop])
    assert np.array_equal(Points(axes, 1000, 7).values(0, 1000)["m"], full["m"])
    assert not np.array_equal(Points(axes, 1000, 8).values(0, 1000)["m"], full["m"])


@pytest.mark.parametrize("spec, kw, words", [
    ([], {}, "empty"), ("1:0:3", {}, "lo = 1 > hi = 0"), ("0:1:0", {}, "count = 0"),
    ("0:1", {}, "a range is"), ("0:1:2.5", {}, "whole number"), ("0:1:4:log", {}, "lo > 0"),
    ("0:3:10", {"integer": True}, "repeat"), ("0:1:3", {"random": True}, "a range is"),
    ([1, 2], {"random": True}, "not a list"), (5, {}, "must be a list"),
    ("a:b:3", {}, "value 'a'"), ([1.5], {"integer": True}, "whole number"),
    ([10 ** 20], {"integer": True}, "at most 9007199254740992"),    # was an OverflowError
    ([10 ** 400], {"integer": True}, "beyond double precision"), ([10 ** 400], {}, "beyond"),
])
def test_bad_axes_are_refused_naming_the_key(spec, kw, words):
    with pytest.raises(SweepError, match=r"^mass") as e:
        parse_axis("mass", spec, **kw)
    assert words in str(e.value)


# ------------------------------------------------------------------- rows vs the API
STUDY = '''kind = "hve"
title = "a test sweep"

[loop]
damping = 0.5
operator = "msd:0.5,5,500"

[sweep]
quantities = ["kmax", "passivity", "closed-form", "check"]
chunk = 7

[sweep.axes]
mass = [0.1, 1.0]
rate = "500Hz:4kHz:4:log"
delay = "0:8:3"

[sweep.check]
stiffness = 300

[sweep.plot]
x = "rate"
y = "delay"
'''


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    (d / "s.toml").write_text(STUDY)
    r = invoke(["sweep", str(d / "s.toml"), "--out", str(d / "out"), "--workers", "1",
                "--json"])
    assert r.exit_code == 0, r.stderr
    return d, json.loads(r.stdout)


def test_rows_equal_the_public_api_point_by_point(swept):
    d, _ = swept
    t = rows(d / "out").to_pylist()
    assert [r["point_id"] for r in t] == list(range(24))
    order = list(itertools.product([0.1, 1.0], np.geomspace(500, 4000, 4), [0, 4, 8]))
    for r, (m, rate, n) in zip(t, order, strict=True):
        assert (r["mass_kg"], r["delay_samples"]) == (m, n) and r["rate_hz"] == pytest.approx(rate)
        loop = h.HapticLoop(h.Device(m, 0.5), h.SpringDamper(1.0, 0.0),
                            operator=h.mass_spring_damper(0.5, 5, 500), period=1 / r["rate_hz"],
                            delay_samples=n)
        exact = h.critical_stiffness(loop)
        # the batched core may order its arithmetic otherwise; K_max is certified to ~1e-12
        assert r["critical_stiffness_N_per_m"] == pytest.approx(exact.critical_stiffness,
                                                                rel=1e-9)  # see above
        assert r["reason"] == exact.reason
        assert r["passivity_kmax_N_per_m"] == h.critical_stiffness(
            loop, method="passivity").critical_stiffness
        eq = "colgate" if n == 0 else "eq18"          # the paper's condition: (13) or (18)
        cf = h.critical_stiffness(loop, method=eq).critical_stiffness
        assert r["closed_form_equation"] == ("(13)" if n == 0 else "(18)")
        assert r["closed_form_N_per_m"] == cf
        assert r["closed_form_over_promises"] == (cf > exact.critical_stiffness * (1 + 1e-6))
        assert r["verdict_at_K"] == h.stability(loop.with_stiffness(300.0)).verdict
        assert r["error"] is None


def test_the_summary_and_manifest(swept):
    d, out = swept
    t = rows(d / "out")
    K = np.array(t.column("critical_stiffness_N_per_m").to_pylist())
    s = json.loads((d / "out" / "summary.json").read_text())
    assert s == json.loads(json.dumps(out["summary"]))
    q = s["quantities"]["critical_stiffness_N_per_m"]
    assert q["min"] == K.min() and q["where_min"]["point_id"] == int(np.argmin(K))
    assert q["max"] == K.max() and q["where_max"]["point_id"] == int(np.argmax(K))
    over = t.column("closed_form_over_promises").to_pylist()
    assert s["closed_form"]["over_promises"] == sum(over) and s["closed_form"]["compared"] == 24
    m = json.loads((d / "out" / "manifest.json").read_text())
    import hashlib

    assert m["study_sha256"] == hashlib.sha256(STUDY.encode()).hexdigest()
    assert m["points"] == 24 and m["chunk"] == 7 and m["chunks"] == 4
    for e in m["finished"]:
        data = (d / "out" / "chunks" / f"chunk-{e['chunk']:06d}.parquet").read_bytes()
        assert hashlib.sha256(data).hexdigest() == e["sha256"]
    assert sum(e["rows"] for e in m["finished"]) == 24
    heat = np.array(s["heat_map"]["critical_stiffness_N_per_m"], dtype=float)
    assert heat.shape == (3, 4) and s["heat_map"]["min_over"] == ["mass"]
    assert heat[0, 0] == min(K[0], K[12])     # rate 500 Hz, n = 0: the lower of both masses
    assert (d / "out" / "kmax.png").stat().st_size > 1000


def test_a_rerun_computes_nothing_and_a_lost_chunk_is_computed_again(swept, tmp_path):
    d, _ = swept
    import shutil

    shutil.copytree(d / "out", tmp_path / "out")
    before = rows(tmp_path / "out")
    args = ["sweep", str(d / "s.toml"), "--out", str(tmp_path / "out"), "--workers", "1",
            "--json"]
    r = invoke(args)
    assert r.exit_code == 0 and json.loads(r.stdout)["computed_chunks"] == 0
    os.remove(tmp_path / "out" / "chunks" / "chunk-000002.parquet")          # lost
    (tmp_path / "out" / "chunks" / "chunk-000001.parquet").write_bytes(b"garbage")   # damaged
    (tmp_path / "out" / "chunks" / ".chunk-000003.parquet.abc.part").write_bytes(b"x")
    r = invoke(args)
    assert r.exit_code == 0 and json.loads(r.stdout)["computed_chunks"] == 2
    assert rows(tmp_path / "out").equals(before)
    assert not [f for f in os.listdir(tmp_path / "out" / "chunks") if f.endswith(".part")]


def test_the_same_study_in_python(tmp_path):
    def build(o):
        return h.paper_hve(o["period"], o["delay"])

    res = h.sweep(build, {"period": [1e-3, 2e-3], "delay": [0, 3]}, str(tmp_path / "o"),
                  workers=1, quantities=["kmax", "closed-form"])
    t = res.table().to_pylist()
    for r in t:
        lp = h.paper_hve(r["period"], int(r["delay"]))
        assert r["critical_stiffness_N_per_m"] == pytest.approx(
            h.critical_stiffness(lp).critical_stiffness, rel=1e-9)  # as above
    assert res.to_dict()["summary"]["points"] == 4
    page, d = res._repr_html_(), res.to_dict()
    assert "SweepResult" in page and page.count("<tr>") == len(d)
    json.dumps(d, allow_nan=False)
    ax = res.plot()
    assert "minimum over" not in ax.get_title()
    import matplotlib.pyplot as plt

    plt.close(ax.figure)


def test_a_refused_point_is_a_row_with_its_message(tmp_path):
    def build(o):
        return h.paper_hve(1e-3, 0).replace(device=h.Device(o["mass"], 0.1))

    res = h.sweep(build, {"mass": [0.15, -1.0, 0.3]}, str(tmp_path / "o"), workers=1)
    t = res.table().to_pylist()
    assert [r["error"] is None for r in t] == [True, False, True]
    assert t[1]["critical_stiffness_N_per_m"] is None and "\n" not in t[1]["error"]
    assert res.summary["errors"] == 1


# ------------------------------------------------------------------ malformed studies
GOOD = 'kind = "hve"\n[loop]\nmass = 0.2\n[sweep]\nquantities = ["kmax"]\n[sweep.axes]\n' \
       'delay = [0, 2]\n'
BAD = [
    ('kind = "hve"\nsweeps = 1\n', "sweeps"),
    (GOOD + "[sweep.random]\nsamples = 10\nbar = 1\n", "sweep.random.bar"),
    (GOOD.replace("[sweep]\n", "[sweep]\nfoo = 1\n"), "sweep.foo"),
    (GOOD + '[sweep.plot]\nx = "delay"\nz = "delay"\n', "sweep.plot.z"),
    (GOOD + "[sweep.check]\nK = 1\n", "sweep.check.K"),
    (GOOD + "[sweep.best-damping]\nB = 1\n", "sweep.best-damping.B"),
    (GOOD.replace("mass = 0.2", "massa = 0.2"), "massa"),
    (GOOD.replace("mass = 0.2", "method = 'circle'"), "method"),
    (GOOD.replace("delay = [0, 2]", "massa = [1, 2]"), "sweep.axes.massa"),
    (GOOD.replace("delay = [0, 2]", "method = ['exact']"), "sweep.axes.method"),
    # a helper's fuzz (seed 20261207): kmax's proof options are not loop options of a sweep
    (GOOD.replace("delay = [0, 2]", "certificate = ['a.json']"), "sweep.axes.certificate"),
    (GOOD.replace("delay = [0, 2]", "certify = ['true', 'false']"), "sweep.axes.certify"),
    (GOOD.replace("mass = 0.2", "mass = 0.2\nmass-kg = 1"), "mass-kg"),
    (GOOD.replace("mass = 0.2", "virtual-damping = 1\nvirtual_damping = 2"),
     "virtual-damping and virtual_damping"),
    (GOOD.replace("delay = [0, 2]", 'damping = "0.1:1:20000000"'), "at most 10000000 values"),
    (GOOD + "[sweep.best-damping]\nmin-damping = 5\n", "sweep.best-damping.min-damping = 5.0"),
    (GOOD.replace("delay = [0, 2]", "m = [0.1]\nmass = [0.2]"),
     "s.toml line 8: sweep.axes.mass: the option of sweep.axes.m again"),
    (GOOD + "[sweep.best-damping]\nmax-damping = 0\n", "sweep.best-damping.max-damping = 0.0"),
    (GOOD + "[sweep.best-damping]\nresolution = 100000000\n", "sweep.best-damping.resolution"),
    (GOOD.replace("delay = [0, 2]", "delay = []"), "sweep.axes.delay"),
    (GOOD.replace("delay = [0, 2]", 'mass = "1:0.1:5"'), "sweep.axes.mass"),
    (GOOD.replace("delay = [0, 2]", 'mass = "0.1:1:0"'), "sweep.axes.mass"),
    (GOOD.replace("delay = [0, 2]", "mass = 5"), "sweep.axes.mass"),
    (GOOD.replace("delay = [0, 2]", 'rate = "1kHz:4kXz:4"'), "sweep.axes.rate"),
    (GOOD.replace("delay = [0, 2]", 'delay-s = "0:20ms:4:log"'), "sweep.axes.delay-s"),
    (GOOD.replace("delay = [0, 2]", "delay = [0.5]"), "sweep.axes.delay"),
    (GOOD.replace("delay = [0, 2]", "mass = [-1]"), "sweep.axes.mass"),
    (GOOD.replace('quantities = ["kmax"]', 'quantities = "kmax"'), "sweep.quantities"),
    (GOOD.replace('quantities = ["kmax"]', 'quantities = ["kmaxx"]'), "sweep.quantities"),
    (GOOD.replace('quantities = ["kmax"]', 'quantities = ["check"]'), "sweep.quantities"),
    (GOOD.replace('quantities = ["kmax"]', "chunk = 0"), "sweep.chunk"),
    (GOOD.replace('quantities = ["kmax"]', 'chunk = "big"'), "sweep.chunk"),
    (GOOD + "[sweep.random]\nsamples = -1\n", "sweep.random.samples"),
    (GOOD + '[sweep.plot]\nx = "delay"\ny = "mass"\n', "sweep.plot.y"),
    (GOOD + "[sweep.check]\nstiffness = 'stiff'\n", "sweep.check.stiffness"),
    (GOOD.replace("[sweep.axes]\ndelay = [0, 2]\n", "axes = 3\n"), "sweep.axes"),
    (GOOD.replace("mass = 0.2", 'operator = "msd:1,2"'), "--operator"),     # the first point
    ('kind = "hve"\n[loop]\nmass = 0.2\n', "[sweep]"),
]


@pytest.mark.parametrize("text, key", BAD, ids=[k for _, k in BAD])
def test_a_malformed_study_is_one_line_naming_the_key(text, key, tmp_path, monkeypatch):
    from hapstab.sweep import run

    def never(*a, **k):
        raise AssertionError("evaluated")

    monkeypatch.setattr(run, "evaluate_chunk", never)
    (tmp_path / "s.toml").write_text(text)
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers",
                "1"])
    assert r.exit_code == 2, (r.stdout, r.stderr, r.exception)
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hapstab: error: "), r.stderr
    assert key in lines[0], lines[0]
    assert not (tmp_path / "o" / "chunks").exists() or not os.listdir(tmp_path / "o" / "chunks")


def test_a_line_number_is_given(tmp_path):
    (tmp_path / "s.toml").write_text(GOOD.replace("delay = [0, 2]", "delay = []"))
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and "s.toml line 7: sweep.axes.delay" in r.stderr


def test_a_trillion_points_are_refused_at_once_without_building_anything(tmp_path, monkeypatch):
    import hapstab.cli.sweep as cs
    from hapstab.sweep import run

    def never(*a, **k):
        raise AssertionError("built or evaluated")

    monkeypatch.setattr(run, "evaluate_chunk", never)
    monkeypatch.setattr(cs, "build_loop", never)
    axes = "\n".join(f'{k} = "1:2:1000"' for k in ("mass", "damping", "virtual-damping"))
    (tmp_path / "s.toml").write_text(GOOD.replace("delay = [0, 2]", axes + '\nrate = "1kHz:2kHz:1000"'))
    t0 = time.perf_counter()
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o")])
    assert time.perf_counter() - t0 < 3.0          # counted, never built
    assert r.exit_code == 2 and "1e+12 points" in r.stderr and "--yes" in r.stderr
    assert not (tmp_path / "o").exists()


def test_another_study_in_the_folder_is_refused_unless_forced(tmp_path):
    (tmp_path / "a.toml").write_text(GOOD)
    (tmp_path / "b.toml").write_text(GOOD.replace("[0, 2]", "[0, 3]"))
    out = str(tmp_path / "o")
    assert invoke(["sweep", str(tmp_path / "a.toml"), "--out", out, "--workers", "1"]).exit_code == 0
    r = invoke(["sweep", str(tmp_path / "b.toml"), "--out", out, "--workers", "1"])
    assert r.exit_code == 2 and "--out" in r.stderr and "another sweep" in r.stderr
    assert len(r.stderr.splitlines()) == 1
    r = invoke(["sweep", str(tmp_path / "b.toml"), "--out", out, "--workers", "1", "--force",
                "--json"])
    assert r.exit_code == 0
    assert rows(out).column("delay_samples").to_pylist() == [0, 3]


def test_without_pyarrow_one_line_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    (tmp_path / "s.toml").write_text(GOOD)
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers", "1"])
    assert r.exit_code == 2 and "pip install 'hapstab[sweep]'" in r.stderr
    assert len(r.stderr.splitlines()) == 1


def test_importing_hapstab_imports_neither_dask_nor_pyarrow():
    code = ("import sys, hapstab, hapstab.cli.main; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('dask', 'distributed', 'pyarrow')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": SRC}, check=True)
    assert out.stdout.strip() == "[]"


def test_budget_and_scheduler_messages(tmp_path):
    (tmp_path / "s.toml").write_text(GOOD)
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"),
                "--scheduler", "not an address"])
    assert r.exit_code == 2 and "--scheduler" in r.stderr
    with pytest.raises(h.BudgetError, match="points"):
        h.sweep(lambda o: h.paper_hve(), {"period": [1e-3] * 3}, str(tmp_path / "p"),
                max_points=2)
    assert math.isinf(float("inf"))


def test_the_example_sweep_runs(tmp_path):
    path = os.path.join(os.path.dirname(HERE), "examples", "sweep_device.toml")
    r = invoke(["sweep", path, "--out", str(tmp_path / "o"), "--workers", "1", "--json"])
    assert r.exit_code == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["manifest"]["points"] == 120 and d["summary"]["errors"] == 0
    assert d["summary"]["heat_map"]["min_over"] == ["mass"]
    assert (tmp_path / "o" / "kmax.png").read_bytes()[:4] == b"\x89PNG"


def _hve_b(o):
    return h.paper_hve(1e-3, o["delay"], damping=o["B"])


def test_over_promises_are_counted_and_each_is_a_broken_promise(tmp_path):
    # n = 4, B = 0.08: eq. (18) promises 40 N/m where the exact limit is 39.976 (test_audit)
    res = h.sweep(_hve_b, {"B": [0.0, 0.04, 0.08], "delay": [2, 4]}, str(tmp_path / "o"),
                  quantities=["closed-form"], workers=1)
    t = res.table().to_pylist()
    for r in t:
        loop = _hve_b({"B": r["B"], "delay": r["delay"]})
        # independent of the flag's rule: the exact loop just below the promise
        broken = not h.stability(loop.with_stiffness(r["closed_form_N_per_m"] * (1 - 1e-6))).stable
        assert r["closed_form_over_promises"] == broken, r
    flagged = [r for r in t if r["closed_form_over_promises"]]
    assert any(r["B"] == 0.08 and r["delay"] == 4 for r in flagged)
    cf = res.summary["closed_form"]
    assert cf["over_promises"] == len(flagged) and cf["compared"] == 6
    assert {w["point_id"] for w in cf["worst"]} == {r["point_id"] for r in flagged}
    ratios = [w["ratio"] for w in cf["worst"]]
    assert ratios == sorted(ratios, reverse=True) and min(ratios) > 1


RANDOM = '''kind = "peb"
[loop]
environment = "spring:1000"
[sweep]
quantities = ["kmax", "closed-form"]
chunk = CHUNK
[sweep.axes]
master-mass = "0.01:1:log"
rate = "250Hz:4kHz:log"
delay = "0:6"
[sweep.random]
samples = 15
seed = 11
[sweep.plot]
x = "rate"
y = "master-mass"
'''


def test_random_points_from_a_study_do_not_depend_on_the_chunks(tmp_path):
    # 15 points (was 30): in chunks of 7 they are still a first, a middle and a short last
    # chunk against one chunk of all, and the draw is still checked whole against the seed
    tables = []
    for chunk in (7, 30):
        (tmp_path / f"{chunk}.toml").write_text(RANDOM.replace("CHUNK", str(chunk)))
        r = invoke(["sweep", str(tmp_path / f"{chunk}.toml"), "--out", str(tmp_path / str(chunk)),
                    "--workers", "1", "--json"])
        assert r.exit_code == 0, r.stderr
        tables.append(rows(tmp_path / str(chunk)))
    assert tables[0].equals(tables[1])
    t = tables[0].to_pylist()
    u = np.random.default_rng(11).random((15, 3))
    assert [r["delay_samples"] for r in t] == np.floor(u[:, 2] * 7).astype(int).tolist()
    assert np.allclose([r["rate_hz"] for r in t], 250 * 16 ** u[:, 1], rtol=1e-12)  # exp/log
    for r in t[:5]:
        loop = h.TeleoperationLoop(h.Device(r["master_mass_kg"], 0.02), h.Device(0.015, 0.02),
                                   h.SpringDamper(1.0, 0), h.SpringDamper(1.0, 0),
                                   operator=h.spring(1.0), environment=h.spring(1000.0),
                                   period=1 / r["rate_hz"], delay_samples=r["delay_samples"])
        assert r["critical_stiffness_N_per_m"] == pytest.approx(
            h.critical_stiffness(loop).critical_stiffness, rel=1e-9)   # as above
        eq = "eq29" if r["delay_samples"] == 0 else "eq34"
        assert r["closed_form_N_per_m"] == h.critical_stiffness(loop, method=eq).critical_stiffness
    heat = json.loads((tmp_path / "7" / "summary.json").read_text())["heat_map"]
    assert heat["x_log"] and heat["min_over"] == ["delay"]
    assert (tmp_path / "7" / "kmax.png").exists()


def test_a_4ch_sweep_says_no_closed_form_applies(tmp_path):
    (tmp_path / "s.toml").write_text('kind = "4ch"\n[sweep]\nquantities = ["closed-form"]\n'
                                     '[sweep.axes]\ndelay = [0, 1]\n')
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers",
                "1", "--json"])
    assert r.exit_code == 0, r.stderr
    for row in rows(tmp_path / "o").to_pylist():
        assert row["closed_form_equation"] == "" and math.isnan(row["closed_form_N_per_m"])
        assert row["closed_form_over_promises"] is None
        assert row["not_applicable"].startswith("closed-form: ") and row["error"] is None
        assert row["critical_stiffness_N_per_m"] > 0


def test_passivity_at_a_fractional_delay_is_not_applicable_not_an_error(tmp_path):
    """Issue 29 item 6: the sampled-data passivity is derived for whole samples of delay; at
    t_d = 2.5 T it does not apply, which is not an error (K_max is fine there)."""
    (tmp_path / "s.toml").write_text('kind = "hve"\n[sweep]\nquantities = ["kmax", '
                                     '"passivity"]\n[sweep.axes]\ndelay-s = [0.002, 0.0025]\n')
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers",
                "1", "--json"])
    assert r.exit_code == 0, r.stderr
    whole, frac = sorted(rows(tmp_path / "o").to_pylist(), key=lambda row: row["point_id"])
    assert whole["not_applicable"] is None and whole["error"] is None
    assert whole["passivity_kmax_N_per_m"] > 0
    assert frac["error"] is None and frac["critical_stiffness_N_per_m"] > 0
    assert frac["not_applicable"] == ("passivity: derived for whole samples of delay; this "
                                      "point has t_d = 2.5 T")
    assert math.isnan(frac["passivity_kmax_N_per_m"])
    s = json.loads(r.stdout)["summary"]
    assert s["errors"] == 0 and s["not_applicable"] == 1


def test_the_heat_map_axes_have_names_units_and_a_tick_per_value():
    """Issue 29 item 6: not the raw column names (rate_hz) and one tick on a log axis."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hapstab.sweep.result import draw_heat_map

    h = {"x": "rate_hz", "y": "virtual_damping_N_s_per_m", "x_values": [500.0, 1000.0, 2000.0],
         "y_values": [0.0, 1.0], "x_log": True, "y_log": False, "min_over": [],
         "critical_stiffness_N_per_m": [[10.0, 20.0, 40.0], [15.0, 30.0, 60.0]]}
    _fig, ax = plt.subplots()
    draw_heat_map(h, ax)
    assert ax.get_xlabel() == "sampling rate (Hz)"
    assert ax.get_ylabel() == "virtual damping B (N·s/m)"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["500", "1000", "2000"]
    plt.close("all")


def test_loss_jitter_width_and_delay_range_are_axes_and_quantities(tmp_path):
    """Issue 30 item 5: loss, jitter-width and delay-range-width as axes ([sweep.network]
    for a fixed burst), the three network quantities; every row equals the public API at
    that point (the same floating-point computation: equal), and a bad value is refused."""
    from hapstab.analysis.network import (
        delay_range_critical_stiffness,
        jitter,
        loss_critical_stiffness,
    )

    (tmp_path / "s.toml").write_text(
        'kind = "hve"\n[loop]\nvirtual-damping = 0.5\n[sweep]\nquantities = ["kmax", '
        '"loss-kmax", "delay-range-kmax", "jitter"]\n[sweep.network]\nburst = 2\n'
        '[sweep.axes]\ndelay = [0, 3]\nloss = [0.0, 0.1]\njitter-width = [1]\n'
        'delay-range-width = [2]\n')
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers",
                "1", "--json"])
    assert r.exit_code == 0, r.stderr
    got = rows(tmp_path / "o").to_pylist()
    assert len(got) == 4
    for row in got:
        assert row["error"] is None and row["not_applicable"] is None
        n, P = row["delay_samples"], row["loss"]
        loop = h.paper_hve(1e-3, n).with_controllers(h.SpringDamper(1.0, 0.5))
        assert row["loss_kmax_N_per_m"] == loss_critical_stiffness(loop, P, 2.0).critical_stiffness
        d = delay_range_critical_stiffness(loop, n, n + 2, seconds=False)
        assert row["delay_range_kmax_N_per_m"] == d.critical_stiffness
        assert row["worst_delay_samples"] == d.worst_delay_samples
        j = jitter(loop, (n, n + 1))
        assert (row["jitter_stable_up_to_N_per_m"], row["jitter_unstable_from_N_per_m"]) == (
            j.stable_up_to, j.unstable_from)
        assert row["delay_range_kmax_N_per_m"] <= row["critical_stiffness_N_per_m"]
    (tmp_path / "s.toml").write_text('kind = "hve"\n[sweep]\nquantities = ["loss-kmax"]\n'
                                     '[sweep.axes]\nloss = [0.5, 1.0]\n')
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "p")])
    assert r.exit_code == 2 and "loss = 1.0: allowed: a number in [0, 1)" in r.stderr, r.stderr
    (tmp_path / "s.toml").write_text('kind = "hve"\n[sweep]\nquantities = ["jitter"]\n'
                                     '[sweep.network]\njitter-width = 1.5\n[sweep.axes]\n'
                                     'delay = [0]\n')
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "p")])
    assert r.exit_code == 2 and "line 5" in r.stderr and \
        "jitter-width = 1.5: allowed: a whole number of samples >= 0" in r.stderr, r.stderr


def test_the_sweep_reads_the_loop_not_the_kmax_runs_table(tmp_path):
    """[run.kmax] is hapstab run's table: its mass = 5 gave the sweep's loop its mass (a
    helper's fuzz); the sweep's loop is [loop] with the axes."""
    (tmp_path / "s.toml").write_text(GOOD.replace("delay = [0, 2]", "delay = [2]")
                                     + "[run.kmax]\nmass = 5\n")
    r = invoke(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers",
                "1", "--json"])
    assert r.exit_code == 0, r.stderr
    got = rows(tmp_path / "o")["critical_stiffness_N_per_m"][0].as_py()
    loop = h.HapticLoop(h.Device(0.2, 0.1), h.SpringDamper(1.0, 0.0), operator=h.spring(1.0),
                        period=1e-3, delay_samples=2)
    assert got == h.critical_stiffness(loop).critical_stiffness


def test_random_axes_log_integers_and_a_range_wider_than_doubles():
    """A random integer axis "1:1000:log" was drawn uniformly (median ~500, the manifest
    saying log); a range -1e308:1e308 drew every point at its top (hi - lo is inf)."""
    u = np.random.default_rng(20261207).uniform(size=4000)
    whole = parse_axis("delay", "1:1000:log", integer=True, random=True).from_uniform(u)
    assert whole.dtype == np.int64 and whole.min() >= 1 and whole.max() <= 1000
    assert 20 <= np.median(whole) <= 45           # log-uniform: ~sqrt(1000)
    wide = parse_axis("b", "-1e308:1e308", random=True).from_uniform(u)
    assert np.all(np.isfinite(wide)) and wide.min() < -1e307 and wide.max() > 1e307


def test_a_slice_at_a_network_axis_value(tmp_path):
    """--at loss=0.1 on a sweep with a loss axis was an internal error (KeyError): a
    network axis has no loop option to read its value."""
    (tmp_path / "s.toml").write_text('kind = "hve"\n[loop]\nmass = 0.2\n[sweep]\n'
                                     'quantities = ["kmax"]\n[sweep.axes]\n'
                                     'damping = [0.1, 0.5]\nmass = [0.1, 0.3]\nloss = [0, 0.1]\n')
    args = ["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers", "1"]
    r = invoke([*args, "--at", "loss=0", "--at", "loss=0.1"])
    assert r.exit_code == 2 and "--at loss: given twice" in r.stderr, r.stderr
    r = invoke([*args, "--at", "loss=abc"])
    assert r.exit_code == 2 and "--at loss = 'abc'" in r.stderr, r.stderr
    r = invoke([*args, "--at", "loss=0.1", "--json"])
    assert r.exit_code == 0, r.stderr
