"""The ``maglev-match`` command line. Thin: parses options, calls the library, prints/saves.

Each group of commands lives in its own module (``stability``, ``hopf``, ``cycles``,
``simulate``, ``index``, ``report``, ``design``) and registers itself on :data:`app`; the
program imports a module only when one of its commands runs (:class:`LazyGroup`, with the
table :data:`COMMANDS`), so ``--help``, ``--version``, ``presets`` and usage errors answer
without loading JAX.
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
from typer.core import TyperGroup

from maglev_match.cli.common import UserError, console_err, print_error, print_warnings
from maglev_match.core.params import ParameterError

# Where unexpected errors should be reported.
REPORT_TO = "the maglev-match issue tracker"
# What to do after a full disk: files are written atomically and checkpoints keep their
# finished tiles and chunks, so nothing already written is lost.
DISK_FULL_HINT = ("; earlier files are unchanged and finished map tiles or Monte Carlo chunks "
                  "are kept: free some space and run the same command again (with --resume "
                  "for a map or a Monte Carlo study)")

#: Every command: the module that defines it (``maglev_match.cli.<module>``) and the one
#: line shown by ``maglev-match --help``. Listing them here lets the program answer
#: ``--help``, ``--version`` and a usage error of one command without importing the
#: others (and JAX with them); ``tests/test_cli_startup.py`` checks that this table names
#: exactly the registered commands, each with the first sentence of its help.
COMMANDS: dict[str, tuple[str, str]] = {
    "stability": ("stability", "Equilibrium, eigenvalues and the stability verdict with its "
                               "margin."),
    "root-locus": ("stability", "Eigenvalues along one parameter: writes CSV and a PNG/SVG "
                                "figure."),
    "presets": ("stability", "List the shipped parameter presets: beam values, a description,"
                             " and what each changes relative to the preset it derives from."),
    "hopf": ("hopf", "Hopf points of the equilibrium along one parameter: value, frequency, "
                     "crossing speed d Re(lambda)/d param and the first Lyapunov coefficient "
                     "l1 (> 0 subcritical)."),
    "hopf-curve": ("hopf", "The Hopf curve in two parameters by continuation, with l1 along "
                           "it and the codimension-two points (GH with l2, BT, ZH, HH); "
                           "writes CSV and a Fig. 4-style figure."),
    "cycles": ("cycles", "Cycles born at Hopf points, continued in --param until a physical "
                         "limit (Fig. 5)."),
    "cycle-curve": ("cycle_curve", "The fold of cycles (LPC), period doubling (PD) or "
                                   "Neimark-Sacker bifurcation (NS) continued in two "
                                   "parameters, with its codimension-two points; writes "
                                   "CSV, netCDF and a figure."),
    "iso-curve": ("iso_curve", "The iso-chi curve: where the headline chi(P1, P2) equals the "
                               "target, continued in two parameters, with the deciding part "
                               "and the status of each point; writes CSV, netCDF and a "
                               "figure."),
    "simulate": ("simulate", "Simulate model A or B from a named or explicit initial state; "
                             "report collision (time, limit, levitation point), convergence "
                             "or neither by the horizon. With --speed V --spans N: the "
                             "vehicle at speed over N spans."),
    "index": ("index", "The headline matching index chi = min(chi_paper, chi_simulation) "
                       "(model A or the full vehicle): the paper's chi = h / w0 with the case"
                       " that decided h, the simulated critical disturbance in both "
                       "directions with what decided it, and the reading; with --scatter, the"
                       " spread of chi from parameter scatter."),
    "map": ("index", "The headline matching index chi = min(chi_paper, chi_simulation), its "
                     "two parts, h, the simulated critical disturbances and stability over a "
                     "grid of two parameters (netCDF + figure). An axis v=START:STOP:COUNT "
                     "(km/h) maps the read-outs at speed instead (see `speed`)."),
    "report": ("report", "Self-contained HTML study report of one vehicle-beam pair (figures "
                         "embedded; the PNG/SVG files are written to <out stem>_figures/ "
                         "beside it)."),
    "reproduce": ("report", "Recompute the paper's figures (Figs. 4-8, 11-13) and its claims "
                            "with the printed defaults; writes reproduce.html, claims.csv, "
                            "claims.json and figures/ into --out."),
    "sensitivity": ("design", "Exact d chi / d p of the headline index (the smaller of the "
                              "paper's chi and chi_simulation; --no-simulation: the paper's "
                              "chi), the elasticity (p / chi) d chi / d p and the margin's "
                              "sensitivity for every parameter of model A or of the vehicle "
                              "(--model vehicle), sorted by magnitude, with a tornado figure."),
    "design": ("design", "The cheapest design (or the largest chi) meeting the requirements "
                         "on the headline chi (both the paper's chi and chi_simulation; "
                         "--no-simulation: the paper's chi alone): SLSQP with exact gradients"
                         " from several grid starts, every candidate the full index."),
    "speed": ("speed", "The vehicle at speed over identical simply supported spans: the "
                       "periodic response at every speed from --from to --to (km/h), its "
                       "stability (span-map multipliers), gap deviation, current, DAF, "
                       "car-body acceleration and Sperling's Wz, the index at speed "
                       "chi(v) = h(v) / w0 (the span under the vehicle suddenly displaced; "
                       "the standstill index as v -> 0) next to the standstill headline, and "
                       "the entry disturbance; resonance speeds and stability changes marked."
                       " Writes a netCDF sweep and a figure. With --irregularity: also "
                       "runs over that irregular guideway (limits on, one per seed) at every"
                       " speed above 0, with gap, current, ride, DAF and contact-probability "
                       "read-outs (their own netCDF, CSV and figure)."),
    "explore": ("explore", "The design explorer in the browser: a local web page with the "
                           "beam, gains and delay on sliders, the stability margin live, the"
                           " headline index on release (warm-started from the previous "
                           "design), the basin-bounding cycle, the critical run and the Hopf "
                           "curve; stops with Ctrl-C."),
}


class LazyGroup(TyperGroup):
    """The program's command group, loading a command's module only when it is used.

    ``maglev-match --help`` lists :data:`COMMANDS` from the table (no command module is
    imported); ``maglev-match NAME ...`` imports ``maglev_match.cli.<module>`` of NAME alone,
    whose ``@app.command`` registrations are turned into click commands here (the same
    conversion Typer applies to commands registered before the program starts). A name not
    in the table (a command module added without a table row) falls back to importing every
    module of :data:`COMMAND_MODULES`."""

    _listing = False

    def list_commands(self, ctx):
        names = list(COMMANDS)
        return names + [n for n in self.commands if n not in COMMANDS]

    def get_command(self, ctx, cmd_name):
        if cmd_name in self.commands:
            return self.commands[cmd_name]
        if self._listing and cmd_name in COMMANDS:  # the root help: name and one line
            return _Listed(cmd_name, help=COMMANDS[cmd_name][1])
        if cmd_name not in COMMANDS:  # the table is the whole set (tested): no such command
            return None
        _import_command_module(COMMANDS[cmd_name][0])
        self._adopt_registered()
        return self.commands.get(cmd_name)

    def format_help(self, ctx, formatter):
        self._listing = True
        try:
            return super().format_help(ctx, formatter)
        finally:
            self._listing = False

    def _adopt_registered(self) -> None:
        """Click commands for the ``@app.command`` registrations not yet in the group."""
        for info in app.registered_commands:
            name = info.name or typer.main.get_command_name(info.callback.__name__)
            if name in self.commands:
                continue
            _unwrap_info(info)
            self.commands[name] = typer.main.get_command_from_info(
                info, pretty_exceptions_short=app.pretty_exceptions_short,
                rich_markup_mode=app.rich_markup_mode)


class _Listed(typer.core.TyperCommand):
    """A command as the root help lists it (name and one line), without its module."""


app = typer.Typer(
    cls=LazyGroup,
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

#: The modules that define commands (imported on demand, see :class:`LazyGroup`).
COMMAND_MODULES = tuple(dict.fromkeys(
    ("stability", "hopf", "cycles", "simulate", "index", "report", "design", "speed")
    + tuple(m for m, _ in COMMANDS.values())))
_here = Path(__file__).parent


def _import_command_module(name: str) -> None:
    if (_here / f"{name}.py").exists():
        importlib.import_module(f"maglev_match.cli.{name}")


def load_all_commands() -> None:
    """Import every command module (for the documentation's command reference and the
    tests; the program itself loads only the command it runs)."""
    for name in COMMAND_MODULES:
        _import_command_module(name)
    for info in app.registered_commands:
        _unwrap_info(info)


def all_commands() -> dict:
    """Every command of the program as a click command, by name (imports every module)."""
    load_all_commands()
    group = typer.main.get_command(app)
    for name in group.list_commands(None):  # type: ignore[arg-type]
        group.get_command(None, name)  # type: ignore[arg-type]
    return dict(group.commands)


def _unwrap_help(text: str) -> str:
    """A docstring as help text: paragraphs kept, the line breaks inside a paragraph (where
    the source was wrapped) joined, so help tables wrap at the terminal's width only."""
    paragraphs = inspect.cleandoc(text).split("\n\n")
    return "\n\n".join(" ".join(p.split()) for p in paragraphs)


def _unwrap_info(info) -> None:
    if getattr(info, "_maglev_unwrapped", False):
        return
    doc = info.help or (info.callback.__doc__ if info.callback else None)
    if doc:
        info.help = _unwrap_help(doc)
    info._maglev_unwrapped = True


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
    global _GUARDED
    if argv is None:  # a program: Ctrl-C ends it within seconds in every phase
        from maglev_match.cli import interrupts

        interrupts.install(lambda text: print_error(text, prefix="stopped"))
        _GUARDED = True
    code = _main(argv)
    if code == 130 and argv is None:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(130)
    return code


#: Whether :func:`main` runs as the program (the interrupt guard is installed).
_GUARDED = False


def _stopped(text: str) -> None:
    """The one 'stopped: ...' line of an interrupted command. As a program the interrupt
    guard prints it and ends the process (exit 130), so that its watchdog, racing to end
    a process that does not stop, never prints a second line."""
    if _GUARDED:
        from maglev_match.cli import interrupts

        interrupts.finish(text)
    print_error(text, prefix="stopped")


def _main(argv: list[str] | None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    if debug:
        args = [a for a in args if a != "--debug"]
        args = ["--debug", *args]
    from maglev_match.cli.terminal import encoding_note, guard_output
    from maglev_match.core.errors import CheckpointLocked, MapStopped, ModelFileError
    from maglev_match.core.io import DiskFull, is_disk_full

    guard_output()  # a non-UTF-8 terminal: ASCII stand-ins, never a lost result
    old_show = warnings.showwarning
    warnings.showwarning = _show_warning
    try:
        rv = app(args=args, standalone_mode=False, prog_name="maglev-match")
    except (ParameterError, UserError, CheckpointLocked, ModelFileError) as exc:
        print_error(str(exc))
        return 2
    except DiskFull as exc:
        print_error(f"{exc}{DISK_FULL_HINT}")
        return 1
    except MapStopped as exc:
        if exc.exit_code == 130:
            _stopped(str(exc))
        else:
            print_error(str(exc))
        return exc.exit_code
    except typer.Exit as exc:
        return int(exc.exit_code or 0)
    except (typer.Abort, KeyboardInterrupt):
        from maglev_match.core.interrupts import stop_note

        _stopped(stop_note())
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
    except RuntimeError as exc:  # a map's checkpoint errors (their module loads with maps)
        cp = sys.modules.get("maglev_match.core.checkpoint")
        if cp is not None and isinstance(exc, cp.CheckpointLocked):
            print_error(str(exc))
            return 2
        if cp is not None and isinstance(exc, cp.MapStopped):
            if exc.exit_code == 130:
                _stopped(str(exc))
            else:
                print_error(str(exc))
            return exc.exit_code
        if debug:
            raise
        print_error(f"internal error: {type(exc).__name__}: {' '.join(str(exc).split())}"
                    f"{_where(exc)}. This is a bug: please report it to {REPORT_TO} with the "
                    "command line and the output of the same command with --debug")
        return 1
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
        if is_disk_full(exc):
            print_error(f"disk full: cannot write{where} ({exc.strerror or exc})"
                        f"{DISK_FULL_HINT}")
            return 1
        print_error(f"system error{where}: {exc.strerror or exc}")
        return 1
    except Exception as exc:
        if debug:
            raise
        if is_disk_full(exc):  # raised from a full disk through a library's own error
            print_error(f"disk full: {type(exc).__name__}: {' '.join(str(exc).split())}"
                        f"{DISK_FULL_HINT}")
            return 1
        print_error(f"internal error: {type(exc).__name__}: {' '.join(str(exc).split())}"
                    f"{_where(exc)}. This is a bug: please report it to {REPORT_TO} with the "
                    "command line and the output of the same command with --debug")
        return 1
    finally:
        warnings.showwarning = old_show
        note = encoding_note()
        if note:
            print_warnings([note])
    if isinstance(rv, int) and not isinstance(rv, bool):
        if rv == 130:
            _stopped("interrupted")
        return rv
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
