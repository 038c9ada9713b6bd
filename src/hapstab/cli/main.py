"""The ``hapstab`` command: parse, call the library, print. Nothing else lives here.

Every user mistake is one line on stderr (``hapstab: error: ...``) and exit code 2.
Each command lives in a module of its own and is added here, explicitly.
"""

from __future__ import annotations

import sys
import warnings
from typing import Any

import click
import numpy as np

from hapstab.errors import HapstabError


# ------------------------------------------------------------------ error handling
class HapstabGroup(click.Group):
    """A click group whose errors are one line on stderr and exit code 2."""

    def main(self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
             standalone_mode: bool = True, **extra: Any) -> Any:
        try:
            # extreme inputs overflow inside numpy: say so once, as an error, not as warnings
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                rv = super().main(args=args, prog_name=prog_name or "hapstab",
                                  complete_var=complete_var, standalone_mode=False, **extra)
        except click.exceptions.ClickException as e:
            _fail(e.format_message())
        except HapstabError as e:
            _fail(str(e))
        except OSError as e:
            _fail(f"cannot use {e.filename or 'the file'}: {e.strerror or e}")
        except MemoryError:
            _fail("out of memory: the model is too large for this machine")
        except ValueError as e:          # a plot format matplotlib does not know, NaN from overflow
            _fail(f"cannot do this: {e}")
        except (ArithmeticError, np.linalg.LinAlgError) as e:
            # parameters so extreme that the matrices overflow: the user's input, in one line
            _fail(f"cannot compute this: {type(e).__name__}: {e} (check the values: they may be "
                  "outside the range the model can represent)")
        except click.exceptions.Abort:
            click.echo("hapstab: aborted", err=True)
            sys.exit(1)
        sys.exit(rv if isinstance(rv, int) else 0)


def _fail(msg: str) -> None:
    click.echo("hapstab: error: " + " ".join(str(msg).split()), err=True)
    sys.exit(2)



# ------------------------------------------------------------------------- commands
@click.group(cls=HapstabGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="hapstab")
def cli() -> None:
    """Exact stability and critical stiffness of sampled-data, delayed haptic (hve) and
    PEB teleoperation (peb) loops. Defaults are the paper's simulation study."""



def _register() -> None:
    """Add every command to :data:`cli` (one place, in the order of ``--help``)."""
    from hapstab.cli import analysis, paper, regions, simulation

    for cmd in (analysis.kmax, analysis.check, analysis.boundary_cmd, analysis.demo,
                paper.passivity_cmd, paper.audit_cmd, regions.region,
                regions.best, simulation.simulate_cmd, simulation.reproduce_cmd):
        cli.add_command(cmd)


_register()


def main(argv: list[str] | None = None) -> None:
    """Console entry point."""
    cli.main(args=argv)

