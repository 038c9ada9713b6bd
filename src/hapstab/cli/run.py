"""``hapstab run STUDY.toml``: every analysis of a study file, for every variant, into
one folder of results (JSON, CSV, figures, the study itself and a manifest written last).

Each analysis is the loop command of the same name run with ``--study FILE --variant V
--json`` (and ``--csv`` / ``--plot`` where it writes them): the same code and the same
numbers as typing it. Everything is written to a staging folder first and committed
together (see :mod:`hapstab.outputs`): an error or an interrupt leaves the previous
results, never a mix.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import shutil
import tempfile
from typing import Any

import click

from hapstab.cli.options import ARGV, console, progress, provenance
from hapstab.cli.study import BASE, Study, StudyError, load_study, study_defaults
from hapstab.cli.study_line import kind_command, loop_commands
from hapstab.errors import HapstabError
from hapstab.outputs import OutputError, Outputs, signals_held
from hapstab.results import dumps

#: What each analysis writes besides its JSON (the command's own --csv / --plot).
FILES = {"boundary": ("csv", "png"), "region": ("csv", "png"), "simulate": ("csv", "png")}


@click.command("run", short_help="Run a study file's analyses into a folder of results.")
@click.argument("study_path", metavar="STUDY.toml")
@click.option("--out", "out_dir", default=None, type=click.Path(file_okay=False),
              help="Folder of results (default: out/<study file name>).")
@click.option("--only", "only", multiple=True,
              help="Run only this variant (repeatable; default: every variant).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (the manifest).")
def run_cmd(study_path: str, out_dir: str | None, only: tuple[str, ...], as_json: bool) -> None:
    """Run every analysis of a study file ([run.<command>] tables) for the base loop and
    every [[variant]], into a folder: <variant>/<command>.json (+ .csv, .png), the study
    file and manifest.json, written together."""
    study = load_study(study_path, "STUDY.toml")
    root = click.get_current_context().find_root().command
    assert isinstance(root, click.Group)
    plan = _plan(study, root, only)
    _charge(plan)
    if out_dir is None:
        out_dir = os.path.join("out", os.path.splitext(os.path.basename(study.path))[0])
    _refuse_links(out_dir, plan)
    stage = _stage_folder(out_dir)
    try:
        with progress(len(plan), f"study {os.path.basename(study.path)}", as_json) as tick:
            results = []
            for variant, command, defaults in plan:
                results.append(_one(root, study, variant, command, defaults, stage))
                if tick:
                    tick(1)
        written = _commit(study, stage, out_dir, results)
    finally:
        with signals_held():               # a second Ctrl-C must not leave it behind
            shutil.rmtree(stage, ignore_errors=True)
    manifest = _manifest(study, results, written)
    if as_json:
        click.echo(dumps({**manifest, **provenance()}))
    else:
        _table(study, results, written, out_dir)


#: The least one analysis of a study costs: 43 ms of CPU each for the cheapest (K_max of
#: an HVE with 2 samples of delay: 201 of them in 8.7 s, 24 s of wall time on the
#: project's busy machine), 8.5 kB of files each (1.7 MB) and its result kept in memory
#: until the folder is written together: taken as 40 ms and 64 kB.
ANALYSIS_SECONDS, ANALYSIS_BYTES = 0.04, 64 * 1024.0


def _charge(plan: list[tuple[str, str, dict[str, Any]]]) -> None:
    """The whole run's budget (:mod:`hapstab.budget`), before any work: each analysis at
    least :data:`ANALYSIS_SECONDS` (its own, larger cost is charged when it runs)."""
    from hapstab import budget

    variants = len({v for v, _, _ in plan})
    budget.check(budget.Cost(f"run: {len(plan)} analyses ({variants} variant(s) x "
                             f"{len(plan) // max(variants, 1)} command(s))",
                             len(plan) * ANALYSIS_BYTES, len(plan) * ANALYSIS_SECONDS))


def _plan(study: Study, root: click.Group, only: tuple[str, ...]
          ) -> list[tuple[str, str, dict[str, Any]]]:
    """(variant, command, defaults) for every run, all checked before any work."""
    if not study.run:
        raise StudyError(f"{study.path}: no [run.<command>] table: nothing to run; e.g. "
                         "[run.kmax] (commands: " + ", ".join(loop_commands(root)) + ")")
    for v in only:
        if v not in study.variants:
            raise StudyError(f"--only = {v!r}: {study.path} has "
                             f"{', '.join(map(repr, study.variants))}")
    for command in study.run:
        if not isinstance(root.commands.get(command), click.Group):
            raise StudyError(f"{study.where(command, 'run')}run.{command}: not a loop command; "
                             f"allowed: {', '.join(loop_commands(root))}")
    kinds = {command: kind_command(study, root.commands[command], command,  # type: ignore[arg-type]
                                   study.where(command) + "run.")
             for command in study.run}
    return [(variant, command, study_defaults(study, kinds[command], command, variant, []))
            for variant in study.variants if not only or variant in only
            for command in study.run]


def _refuse_links(out_dir: str, plan: list[tuple[str, str, dict[str, Any]]]) -> None:
    """Refuse a symbolic link where the run writes in its folder (a variant's folder, a
    result, study.toml, manifest.json): the run never makes one, so it is someone else's,
    and writing through it replaced files outside the folder (a linked variant folder's
    target got the run's kmax.json; issue 27, the class of a sweep's linked chunks/).
    The folder itself (``--out``) may be a link: the user named it."""
    names = ["study.toml", "manifest.json"]
    for variant, command, _ in plan:
        names += [variant, *(os.path.join(variant, f"{command}.{ext}")
                             for ext in ("json", *FILES.get(command, ())))]
    for rel in names:
        if os.path.islink(os.path.join(out_dir, rel)):
            raise OutputError(f"--out = {out_dir!r:.80}: {rel} is a symbolic link (a run "
                              "never makes one, and never writes through one); remove it, "
                              "or choose another folder")


def _stage_folder(out_dir: str) -> str:
    """The results folder (created now, so that a folder it cannot be fails before any
    work) and a hidden staging folder inside it (its parent may not be writable)."""
    if not out_dir.strip() or "\0" in out_dir:
        raise OutputError(f"--out = {out_dir!r:.80}: must be a folder path (it is empty)")
    try:
        os.makedirs(out_dir, exist_ok=True)
        return tempfile.mkdtemp(prefix=".hapstab-run.", dir=out_dir)
    except OSError as e:
        raise OutputError(f"--out = {out_dir!r:.80}: cannot create the folder "
                          f"({e.strerror or e})") from None


def _one(root: click.Group, study: Study, variant: str, command: str,
         defaults: dict[str, Any], stage: str) -> dict[str, Any]:
    """Run one analysis of one variant: its JSON answer and the files it wrote."""
    folder = os.path.join(stage, variant)
    os.makedirs(folder, exist_ok=True)
    files = {f"{command}.json": "json"}
    argv = [command, study.kind, "--json"]
    for ext in FILES.get(command, ()):
        opt = "--csv" if ext == "csv" else "--plot"
        argv += [opt, os.path.join(folder, f"{command}.{ext}")]
        files[f"{command}.{ext}"] = ext
    shown = [command, study.kind, "--study", study.path, "--variant", variant, "--json"]
    token = ARGV.set(tuple(shown))
    buf = io.StringIO()
    try:
        with root.make_context("hapstab", argv,
                               default_map={command: {study.kind: defaults}}) as ctx, \
                contextlib.redirect_stdout(buf):
            root.invoke(ctx)
    except HapstabError as e:
        raise HapstabError(f"{study.path}: variant {variant!r}, {command}: {e}") from None
    except click.ClickException as e:
        raise HapstabError(f"{study.path}: variant {variant!r}, {command}: "
                           f"{e.format_message()}") from None
    finally:
        ARGV.reset(token)
    answer = json.loads(buf.getvalue())
    if "files" in answer:          # where they end up, not the staging folder
        answer["files"] = [os.path.join(variant, os.path.basename(f)) for f in answer["files"]]
    with open(os.path.join(folder, f"{command}.json"), "w") as fh:
        fh.write(dumps(answer) + "\n")
    return {"variant": variant, "command": command, "answer": answer,
            "files": [os.path.join(variant, f) for f in files]}


def _commit(study: Study, stage: str, out_dir: str, results: list[dict[str, Any]]) -> list[str]:
    """Every staged file, the study file and the manifest (last), written together."""
    for variant in {r["variant"] for r in results}:
        try:
            os.makedirs(os.path.join(out_dir, variant), exist_ok=True)
        except OSError as e:
            raise OutputError(f"--out = {out_dir!r:.80}: cannot create {variant}/ in it "
                              f"({e.strerror or e})") from None
    with Outputs() as out:
        for r in results:
            for rel in r["files"]:
                with open(os.path.join(stage, rel), "rb") as src, \
                        out.open(os.path.join(out_dir, rel), "--out", "wb") as dst:
                    shutil.copyfileobj(src, dst)
        with out.open(os.path.join(out_dir, "study.toml"), "--out") as fh:
            fh.write(study.text)           # the file's own bytes (UTF-8, checked on reading)
        names = [rel for r in results for rel in r["files"]] + ["study.toml"]
        with out.open(os.path.join(out_dir, "manifest.json"), "--out") as fh:
            json.dump(json.loads(dumps({**_manifest(study, results, names), **provenance()})),
                      fh, indent=2)
            fh.write("\n")
    return out.written


def _manifest(study: Study, results: list[dict[str, Any]], files: list[str]) -> dict[str, Any]:
    return {"study": study.path, "study_sha256": hashlib.sha256(study.text.encode()).hexdigest(),
            "title": study.title, "kind": study.kind, "variants": list(study.variants),
            "analyses": list(study.run),
            "runs": [{"variant": r["variant"], "command": r["command"], "files": r["files"]}
                     for r in results],
            "files": files}


#: The headline of each command's answer: (JSON key, unit).
HEADLINE = {"kmax": ("critical_stiffness", "N/m"), "check": ("verdict", ""),
            "passivity": ("verdict", ""), "simulate": ("verdict", ""),
            "best-damping": ("critical_stiffness", "N/m"),
            "jitter": ("stable_up_to_N_per_m", "N/m")}


def _table(study: Study, results: list[dict[str, Any]], written: list[str], out_dir: str) -> None:
    from rich.markup import escape
    from rich.table import Table

    from hapstab.cli.options import fmt

    t = Table(title=escape(f"{study.title or study.path} ({study.kind})"))
    for c in ("variant", "analysis", "answer", "files"):
        t.add_column(c)
    for r in results:
        key, unit = HEADLINE.get(r["command"], (None, ""))
        value = r["answer"].get(key) if key else None
        if value is None and key in r["answer"].get("infinite", {}):
            value = float("inf") * r["answer"]["infinite"][key]
        shown = (fmt(value) + (f" {unit}" if unit else "")) if isinstance(value, (int, float)) \
            else (str(value) if value is not None else "see files")
        t.add_row(escape(r["variant"] if r["variant"] != BASE else "base (the [loop] table)"),
                  r["command"], escape(shown),
                  ", ".join(os.path.basename(f) for f in r["files"]))
    con = console()
    con.print(t)
    con.print(escape(f"wrote {len(written)} files to {out_dir}"))
