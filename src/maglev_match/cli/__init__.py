"""The ``maglev-match`` command line. Thin: parses options, calls the library, prints/saves.

Each group of commands lives in its own module (``stability``, ``hopf``, ``cycles``,
``simulate``, ``index``, ``report``) and registers itself on :data:`app`.
Conventions shared by every command (see :mod:`maglev_match.cli.common`):

* ``--preset NAME`` / ``--config FILE`` / ``--set NAME=VALUE`` (repeatable) choose the
  parameters, applied in that order;
* ``--model unit|vehicle`` chooses model A or B where both make sense;
* ``--json`` prints one JSON object on stdout (SI units) and nothing else there;
* ``--out PATH`` names the file or folder for CSV/netCDF/PNG/SVG outputs.

Exit codes and messages (one error path, :func:`main`):

* 0 success;
* 2 a usage error (unknown command or option, a missing or malformed value, a value
  outside its rule): one line naming the option or field, the value and the rule;
* 130 interrupted (Ctrl-C); an interrupted map says how to resume;
* 1 anything else: a numerical or system failure (disk full, lost scheduler) in one line,
  or an unexpected exception in one line with where to report it; ``--debug`` (anywhere on
  the command line) shows the full traceback instead.

Messages are printed as plain text (square brackets in values are kept).
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import os
import sys
import warnings
from pathlib import Path

import typer

from maglev_match.cli.common import UserError, console_err, print_error, print_warnings
from maglev_match.params import ParameterError

# Where unexpected errors should be reported.
REPORT_TO = "the maglev-match issue tracker"

app = typer.Typer(
    name="maglev-match",
    help="Stability, Hopf bifurcations, limit cycles and the vehicle-track beam matching "
    "index chi = h / w0 for EMS maglev vehicles on flexible beams.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version_callback(value: bool) -> None:
    if value:
        from maglev_match import __version__

        typer.echo(f"maglev-match {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", is_eager=True, callback=_version_callback,
                                 help="Print the version and exit."),
    debug: bool = typer.Option(False, "--debug", help="Show the full Python traceback of an "
                               "unexpected error (may also be given after the command)."),
) -> None:
    """Stability, Hopf bifurcations, limit cycles and the matching index chi = h / w0."""


def _flags_without_type() -> None:
    """Help tables list a flag (``--json``, ``--help``, ``--limits/--no-limits``) without a
    value type: typer >= 0.26 shows ``<bool>`` beside flags, which take no value. The
    option class's type display is wrapped once to return nothing for flags."""
    try:
        from typer.core import TyperOption
    except ImportError:  # pragma: no cover - typer without its own option class
        return
    original = getattr(TyperOption, "display_type_rich", None)
    if original is None or getattr(original, "_maglev_flags", False):
        return

    def display_type_rich(self, ctx):
        if getattr(self, "is_flag", False):
            return None
        return original(self, ctx)

    display_type_rich._maglev_flags = True  # type: ignore[attr-defined]
    TyperOption.display_type_rich = display_type_rich  # type: ignore[method-assign]


_flags_without_type()

COMMAND_MODULES = ("stability", "hopf", "cycles", "simulate", "index", "report", "design",
                   "speed")
_here = Path(__file__).parent
for _name in COMMAND_MODULES:
    if (_here / f"{_name}.py").exists():
        importlib.import_module(f"maglev_match.cli.{_name}")


def _unwrap_help(text: str) -> str:
    """A docstring as help text: paragraphs kept, the line breaks inside a paragraph (where
    the source was wrapped) joined, so help tables wrap at the terminal's width only."""
    paragraphs = inspect.cleandoc(text).split("\n\n")
    return "\n\n".join(" ".join(p.split()) for p in paragraphs)


for _info in app.registered_commands:
    _doc = _info.help or (_info.callback.__doc__ if _info.callback else None)
    if _doc:
        _info.help = _unwrap_help(_doc)


def _click_exception_types() -> tuple[type[BaseException], ...]:
    """The click exception classes typer may raise: its bundled copy (typer >= 0.25,
    ``typer._click``) and, for older typer, the click package itself."""
    types: list[type[BaseException]] = []
    try:
        from typer._click.exceptions import ClickException as bundled

        types.append(bundled)
    except ImportError:  # pragma: no cover - typer without a bundled click
        pass
    try:
        from click.exceptions import ClickException as standalone

        types.append(standalone)
    except ImportError:  # pragma: no cover - click not installed
        pass
    return tuple(types)


CLICK_EXCEPTIONS = _click_exception_types()


def _usage_message(exc: BaseException) -> tuple[str, int]:
    """One-line text and exit code of a click exception."""
    fmt = getattr(exc, "format_message", None)
    text = fmt() if callable(fmt) else str(exc)
    code = int(getattr(exc, "exit_code", 2) or 2)
    if type(exc).__name__ == "NoArgsIsHelpError":
        return "", 2  # the help text itself is printed by the caller
    cmd = getattr(getattr(exc, "ctx", None), "command_path", None)
    one_line = " ".join(text.split())
    if cmd and type(exc).__name__ in ("NoSuchOption", "BadOptionUsage", "MissingParameter",
                                      "BadParameter", "UsageError", "BadArgumentUsage"):
        one_line = f"{cmd}: {one_line} (see '{cmd} --help')"
    return one_line, code


def _where(exc: BaseException) -> str:
    tb = exc.__traceback__
    last = None
    while tb is not None:
        last = tb
        tb = tb.tb_next
    if last is None:
        return ""
    code = last.tb_frame.f_code
    return f" (in {Path(code.co_filename).name}:{last.tb_lineno}, {code.co_name})"


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings of this package as 'warning: ...' lines; others as Python prints them."""
    if category.__module__.startswith("maglev_match"):
        print_warnings([str(message)])
    else:
        _default_showwarning(message, category, filename, lineno, file, line)


_default_showwarning = warnings.showwarning


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code (see the module docstring).

    Run as a program (``argv`` None) and interrupted, the process ends at once with code 130
    after flushing its output: tearing down an interpreter whose XLA computation was
    interrupted midway can crash (SIGSEGV seen), which would hide the exit code."""
    code = _main(argv)
    if code == 130 and argv is None:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(130)
    return code


def _main(argv: list[str] | None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    if debug:
        args = [a for a in args if a != "--debug"]
        args = ["--debug", *args]
    from maglev_match.checkpoint import CheckpointLocked, MapStopped

    old_show = warnings.showwarning
    warnings.showwarning = _show_warning
    try:
        rv = app(args=args, standalone_mode=False, prog_name="maglev-match")
    except (ParameterError, UserError, CheckpointLocked) as exc:
        print_error(str(exc))
        return 2
    except MapStopped as exc:
        print_error(str(exc), prefix="stopped" if exc.exit_code == 130 else "error")
        return exc.exit_code
    except typer.Exit as exc:
        return int(exc.exit_code or 0)
    except (typer.Abort, KeyboardInterrupt):
        print_error("interrupted", prefix="stopped")
        return 130
    except CLICK_EXCEPTIONS as exc:
        text, code = _usage_message(exc)
        if type(exc).__name__ == "NoArgsIsHelpError":
            ctx = getattr(exc, "ctx", None)
            console_err.print(ctx.get_help() if ctx is not None else str(exc), markup=False,
                              highlight=False)
        else:
            print_error(text)
        return code
    except MemoryError:
        if debug:
            raise
        print_error("out of memory: the requested computation does not fit; use fewer "
                    "points, steps or saved samples")
        return 1
    except OSError as exc:
        if debug:
            raise
        where = f" {exc.filename}" if getattr(exc, "filename", None) else ""
        print_error(f"system error{where}: {exc.strerror or exc}")
        return 1
    except Exception as exc:
        if debug:
            raise
        print_error(f"internal error: {type(exc).__name__}: {' '.join(str(exc).split())}"
                    f"{_where(exc)}. This is a bug: please report it to {REPORT_TO} with the "
                    "command line and the output of the same command with --debug")
        return 1
    finally:
        warnings.showwarning = old_show
    if isinstance(rv, int) and not isinstance(rv, bool):
        if rv == 130:
            print_error("interrupted", prefix="stopped")
        return rv
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
