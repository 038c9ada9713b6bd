"""The ``hapstab`` command: parse, call the library, print. Nothing else lives here.

Every user mistake is one line on stderr (``hapstab: error: ...``) and exit code 2.
Each command lives in a module of its own and is added here, explicitly.
"""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
from typing import Any

import click
import numpy as np

from hapstab.cli.files import STDOUT_TAKEN
from hapstab.cli.options import ARGV, LOOP_KINDS, provenance
from hapstab.errors import HapstabError
from hapstab.results import dumps


# ------------------------------------------------------------------ error handling
class HapstabGroup(click.Group):
    """A click group whose user errors are one line on stderr and exit code 2.

    User errors are :class:`~hapstab.errors.HapstabError` (a value the library
    refuses, with the parameter's name), click's own usage errors and file errors.
    Anything else is a bug of hapstab's: one line asking for a report and exit
    code 1; ``--debug`` shows the traceback instead.
    """

    def main(self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
             standalone_mode: bool = True, **extra: Any) -> Any:
        argv = list(sys.argv[1:] if args is None else args)
        if args is None:                       # the real process (not a test's runner)
            _on_termination()
            # the CLI writes figures to files: matplotlib's file backend unless the user
            # chose one (the library itself never switches a backend)
            os.environ.setdefault("MPLBACKEND", "Agg")
        # --yes: run past the cost budget (anywhere on the line, like --debug)
        ARGV.set(tuple(argv))                  # echoed as given (with --yes)
        STDOUT_TAKEN.set(False)
        yes = "--yes" in argv
        argv = [a for a in argv if a != "--yes"]
        default_map = None
        if sys.stdout is None:   # started with stdout closed (>&-): the answer would be lost
            _fail([], "stdout is closed: hapstab writes its answer there; give it a file or a pipe")
        try:
            # extreme inputs overflow inside numpy: the library says so once, as an
            # error, not as warnings
            from hapstab import budget
            from hapstab.cli.study_line import take_study

            if argv[:1] not in (["run"], ["explore"]):   # --study FILE [--variant V], anywhere
                argv, default_map = take_study(argv, self)
            with np.errstate(all="ignore"), warnings.catch_warnings(), _bars(argv), \
                    (budget.unlimited() if yes else contextlib.nullcontext()):
                warnings.simplefilter("ignore", RuntimeWarning)
                rv = super().main(args=argv, prog_name=prog_name or "hapstab",
                                  complete_var=complete_var, standalone_mode=False,
                                  default_map=default_map, **extra)
            _flush_stdout(argv)
        except click.exceptions.ClickException as e:
            _fail(argv, click_message(argv, e))
        except HapstabError as e:
            _fail(argv, str(e))
        except _BrokenPipe:
            _fail(argv, "stdout: the reader closed the pipe before the answer was written "
                        "(broken pipe); the answer is incomplete")
        except OSError as e:
            _fail(argv, f"cannot use {e.filename}: {e.strerror or e}" if e.filename
                  else f"cannot write the output: {e.strerror or e}")
        except MemoryError:
            _fail(argv, "out of memory: the model is too large for this machine")
        except (_Terminated, _Interrupted, click.exceptions.Abort) as e:
            _stopped(e)
        except Exception as e:   # everything else is a bug, said as one
            _bug(e, argv)
        sys.exit(rv if isinstance(rv, int) else 0)


    def invoke(self, ctx: click.Context) -> Any:
        """Run the command; a reader that closed stdout early is reported (click would
        exit 1 silently); a Ctrl-C passes click by (which would echo an empty line to
        stderr before the CLI's one)."""
        try:
            return super().invoke(ctx)
        except BrokenPipeError:
            raise _BrokenPipe() from None
        except KeyboardInterrupt:
            raise _Interrupted() from None


def _bars(argv: list[str]) -> Any:
    """Progress bars on stderr for the library's long computations, on a terminal and
    without --json (see :mod:`hapstab.progress`); piped, a plain line at a modest rate
    (:func:`hapstab.cli.output.progress_lines`)."""
    from hapstab import progress
    from hapstab.cli.options import progress as bar
    from hapstab.cli.output import progress_lines

    if "--json" in argv:
        return progress.listening(None)
    if not sys.stderr.isatty():        # piped: a line now and then (issue 27, 5)
        return progress.listening(progress_lines)
    return progress.listening(lambda what, total: bar(total, what))


def _stopped(e: BaseException) -> None:
    """SIGTERM / SIGHUP (exit 143) or Ctrl-C (130): said, and no partial file is left."""
    if isinstance(e, _Terminated):
        click.echo("hapstab: terminated", err=True)
        sys.exit(143)
    if isinstance(e, _Interrupted) or isinstance(e.__cause__, KeyboardInterrupt):
        click.echo("hapstab: interrupted", err=True)
        _exit_interrupted()
    click.echo("hapstab: aborted", err=True)
    sys.exit(1)


def _bug(e: Exception, argv: list[str]) -> None:
    """An unexpected exception: a bug (exit 1, one line), unless a signal's unwinding set
    it off (then the signal's exit code)."""
    if SIGNALLED:
        import signal

        interrupted = SIGNALLED[0] == signal.SIGINT
        click.echo("hapstab: interrupted" if interrupted else "hapstab: terminated", err=True)
        if interrupted:
            _exit_interrupted()
        sys.exit(143)
    if "--debug" in argv:
        raise e
    click.echo(f"hapstab: internal error: {type(e).__name__}: "
               f"{' '.join(str(e).split())[:300]} -- this is a bug in hapstab; please "
               "report it with the command line (--debug shows the traceback)", err=True)
    sys.exit(1)


def _exit_interrupted() -> None:
    """``sys.exit(130)`` after a Ctrl-C, made to hold under ``python -m hapstab``.

    CPython marks a KeyboardInterrupt that ends the evaluation of a *string*
    (``exec``/``eval`` of source text, ``PyRun_String``: dataclasses and namedtuples
    create their methods that way while a module is imported) as unhandled, even when a
    caller catches it; under ``-m``, ``Py_RunMain`` then ends the process by SIGINT (exit
    status -2) whatever ``sys.exit`` said (Modules/main.c, ``exit_sigint``; seen here
    under load: a Ctrl-C during the sweep's start printed "hapstab: interrupted" and
    ended by the signal). The mark is reset at the start of every string evaluation, so
    one that ends normally clears it. A script or ``-c`` exits by ``Py_Exit`` and never
    looks at the mark.
    """
    exec("None", {})       # a constant string: clears CPython's mark (docstring)
    sys.exit(130)


class _BrokenPipe(Exception):
    """stdout's reader went away (``hapstab ... | head -c 10``)."""


#: Signals received: an exception that a signal's unwinding set off inside a library (e.g.
#: matplotlib's "Invalid bounding box" when interrupted mid-draw) is then the signal's.
SIGNALLED: list[int] = []


class _Terminated(BaseException):
    """Raised by the SIGTERM / SIGHUP handler, so that open outputs are cleaned up."""


class _Interrupted(BaseException):
    """A Ctrl-C (KeyboardInterrupt) out of a command, its outputs cleaned up already."""


def _on_termination() -> None:
    """SIGTERM and SIGHUP unwind like Ctrl-C (temporary files removed), in the main thread."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def stop(signum: int, frame: Any) -> None:
        SIGNALLED.append(signum)
        raise _Terminated()

    def interrupt(signum: int, frame: Any) -> None:
        SIGNALLED.append(signum)
        raise KeyboardInterrupt()

    signal.signal(signal.SIGINT, interrupt)

    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, stop)


def _kind_hint(argv: list[str], message: str = "") -> str:
    """For options given before the loop kind (``kmax --mass 0.3``): where they go; for
    ``region ... -B 0:20``: the window is ``--B`` (two dashes)."""
    if argv and argv[0] == "region" and "'--virtual-damping' / '-B'" in message:
        return "; the region's window of B is --B lo:hi (two dashes); -B is the virtual damping"
    if argv[1:2] == ["4ch"] and "No such option" in message and "--scaling-" in message:
        return ("; a 4ch loop has no scaling factors: scale the channels' gains instead "
                "(--c1-/--c4-stiffness-ratio, --c2, --c3)")
    group = cli.commands.get(argv[0]) if argv else None
    if not isinstance(group, click.Group) or len(argv) < 2 or argv[1] in group.commands:
        return ""
    names = list(group.commands)
    kinds = f"{', '.join(names[:-1])} or {names[-1]}" if len(names) > 1 else names[0]
    if argv[1] in LOOP_KINDS:                       # a kind this command does not take
        return f"; {argv[0]} takes {kinds} loops, not {argv[1]}"
    if not argv[1].startswith("-") or argv[1] in ("-h", "--help"):
        return ""
    opt = argv[1].split("=")[0]
    kind = next((k for k, c in group.commands.items()
                 if any(opt in p.opts for p in c.params)), next(iter(group.commands)))
    return (f"; the loop kind ({kinds}) comes first, its options after it, e.g. "
            f"hapstab {argv[0]} {kind} {' '.join(argv[1:])}")


def _flush_stdout(argv: list[str]) -> None:
    """Make a failed write of the answer an error (e.g. stdout on a full disk), not a
    silent exit 0."""
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        _fail(argv, "stdout: the reader closed the pipe before the answer was written "
                    "(broken pipe); the answer is incomplete")
    except OSError as e:
        _fail(argv, f"cannot write to stdout ({e.strerror or e})")


def click_message(argv: list[str], e: click.exceptions.ClickException) -> str:
    """What the command line says of click's usage error ``e`` on ``argv`` (with a better
    hint than click's guess where there is one).

    Parameters
    ----------
    argv : list of str
        The command line after ``hapstab``.
    e : click.ClickException

    Returns
    -------
    str
    """
    msg = e.format_message()
    hint = _kind_hint(argv, msg)
    if "No such option" in msg and "'--encoder" in msg:
        hint += ("; the encoder's step is --resolution (m, or with a unit: --resolution 2um; "
                 "simulate, limit-cycle, zwidth, passivity, audit, identify)")
    return (msg.split(" Did you mean")[0].rstrip(".") + hint) if hint else msg


def one_line(msg: object) -> str:
    """An error message as the one line the command line prints (whitespace folded, a
    value of thousands of digits shortened).

    Parameters
    ----------
    msg : object
        The message.

    Returns
    -------
    str
    """
    line = " ".join(str(msg).split())
    return f"{line[:400]} ... {line[-150:]}" if len(line) > 600 else line


def _fail(argv: list[str], msg: str) -> None:
    """A user error: one line on stderr, exit code 2; with ``--json`` also a JSON object
    ``{"error": ..., "exit_code": 2}`` on stdout, so that a tool reading it sees why."""
    line = one_line(msg)
    click.echo("hapstab: error: " + line, err=True)
    if "--json" in argv:
        with contextlib.suppress(OSError):
            click.echo(dumps({"error": line, "exit_code": 2, **provenance()}))
    _quiet_stdout()
    sys.exit(2)


def _quiet_stdout() -> None:
    """If stdout cannot take what is buffered (a closed pipe, a full disk), send it to
    /dev/null, so that Python's flush at exit does not print a second error."""
    if sys.stdout is None:
        return
    try:
        sys.stdout.flush()
    except OSError:
        with contextlib.suppress(OSError, AttributeError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


# ------------------------------------------------------------------------- commands
@click.group(cls=HapstabGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="hapstab")
@click.option("--debug", is_flag=True, expose_value=False,
              help="On an internal error, show the traceback.")
@click.option("--yes", is_flag=True, expose_value=False,
              help="Run even when the estimated memory or time exceeds the budget "
                   "(2 GiB, 1 min); may be given anywhere on the line.")
@click.option("--study", metavar="FILE", expose_value=False,
              help="Take a loop command's options from a TOML study file (the command line "
                   "overrides them); anywhere on the line. See hapstab run.")
@click.option("--variant", metavar="NAME", expose_value=False,
              help="With --study: use this [[variant]] of the study (default: its [loop]).")
def cli() -> None:
    """Exact stability and critical stiffness of sampled-data, delayed haptic (hve), PEB
    teleoperation (peb) and Lawrence's 4-channel teleoperation (4ch) loops. Defaults are
    the paper's simulation study (the API's hapstab.paper_hve() / paper_peb(); 4ch's
    defaults are PEB's, with no force channel)."""



def _register() -> None:
    """Add every command to :data:`cli` (one place): the analyses' commands as the one table
    of analyses lists them (:data:`hapstab.analysis.table.TABLE`), then the others."""
    from hapstab.analysis.table import commands
    from hapstab.cli import (
        conditions,
        design,
        exact,
        explore,
        identification,
        network,
        nonlinear,
        robust,
        run,
        simulation,
        sweep,
        teleoperation,
    )

    # the rooms' modules (cli/<room>.py, named as hapstab.analysis's rooms) and the others
    modules = (exact, conditions, teleoperation, design, robust, nonlinear, network,
               identification, simulation, explore, run, sweep)
    found = {c.name: c for m in modules for c in vars(m).values()
             if isinstance(c, click.Command)}
    # the analyses' commands, by the one table of analyses; then the others
    others = (exact.demo, exact.verify_cmd, simulation.reproduce_cmd, run.run_cmd,
              explore.explore_cmd, sweep.sweep_cmd)
    for cmd in (*(found[name] for name in commands()), *others):
        cli.add_command(cmd)
        _describe(cmd)


def _describe(cmd: click.Command) -> None:
    """Give every loop-kind subcommand (hve, peb, 4ch) the description its builder wrote as
    ``_cmd.__doc__``, after click had built the command (and read no help)."""
    if isinstance(cmd, click.Group):
        for sub in cmd.commands.values():
            _describe(sub)
    elif not cmd.help and cmd.__dict__.get("__doc__"):
        cmd.help = cmd.__dict__["__doc__"]


_register()


def main(argv: list[str] | None = None) -> None:
    """Console entry point."""
    cli.main(args=argv)

