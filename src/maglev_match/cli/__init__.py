"""The ``maglev-match`` command line. Thin: parses options, calls the library, prints/saves.

Each group of commands lives in its own module (``stability``, ``hopf``, ``cycles``,
``simulate``, ``index``, ``report``) and registers itself on :data:`app`.
Conventions shared by every command (see :mod:`maglev_match.cli.common`):

* ``--preset NAME`` / ``--config FILE`` / ``--set NAME=VALUE`` (repeatable) choose the
  parameters, applied in that order;
* ``--model unit|vehicle`` chooses model A or B where both make sense;
* ``--json`` prints one JSON object on stdout (SI units) and nothing else there;
* ``--out PATH`` names the file or folder for CSV/netCDF/PNG/SVG outputs;
* user errors exit with code 2 and a one-line message naming the field, value and rule.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import typer

from maglev_match.cli.common import UserError, console_err
from maglev_match.params import ParameterError

app = typer.Typer(
    name="maglev-match",
    help="Stability, Hopf bifurcations, limit cycles and the vehicle-track beam matching "
    "index chi = h / w0 for EMS maglev vehicles on flexible beams.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

COMMAND_MODULES = ("stability", "hopf", "cycles", "simulate", "index", "report", "design")
_here = Path(__file__).parent
for _name in COMMAND_MODULES:
    if (_here / f"{_name}.py").exists():
        importlib.import_module(f"maglev_match.cli.{_name}")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script: user errors become a message and exit code 2."""
    try:
        app(args=argv, standalone_mode=False)
    except (ParameterError, UserError) as exc:
        console_err.print(f"[bold red]error:[/] {exc}", highlight=False)
        return 2
    except typer.Exit as exc:
        return int(exc.exit_code or 0)
    except typer.Abort:
        console_err.print("aborted")
        return 130
    except Exception as exc:  # click usage errors carry their own exit code
        import click

        if isinstance(exc, click.exceptions.ClickException):
            exc.show()
            return exc.exit_code
        raise
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
