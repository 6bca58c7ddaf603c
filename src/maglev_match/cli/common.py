"""Options and helpers shared by every command of the command line."""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import sys
import tempfile
import warnings
from collections.abc import Callable
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.text import Text

from maglev_match.core.options import (
    MC_SAMPLES_MAX,
    NCOL_MAX,
    NCOL_MIN,
    NTST_MAX,
    NTST_MIN,
    SEED_MAX,
    STEPS_MAX,
    TOL_MAX,
    WORKERS_MAX,
)
from maglev_match.core.params import (
    DEFAULT_PRESET,
    PARAMETER_DOCS,
    ParameterError,
    ParameterWarning,
    Params,
    load_params,
)

# Text lines are not hard-wrapped (pipes, logs); off a terminal, tables get 160 columns
# instead of Rich's 80 so their numbers are not folded (a terminal keeps its own width).
console = Console(soft_wrap=True, width=None if sys.stdout.isatty() else 160)
console_err = Console(stderr=True)


class UserError(Exception):
    """A mistake in the command line that is not about a parameter value."""


PresetOpt = Annotated[
    str, typer.Option("--preset", help="Shipped parameter preset (see `maglev-match presets`).")
]
ConfigOpt = Annotated[
    Path | None, typer.Option("--config", help="User TOML file applied on top of the preset.")
]
SetOpt = Annotated[
    list[str] | None,
    typer.Option("--set", metavar="NAME=VALUE",
                 help="Override one value (repeatable), e.g. --set kD=120 or --set L=20 "
                 "(beam and vehicle data L, EI, mbar, l, k, s, s0 re-derive omega1 and sigma "
                 "unless those are set explicitly)."),
]
ModelOpt = Annotated[
    str, typer.Option("--model", help="'unit' (model A, 9 states), 'vehicle' (model B) or a "
                      "user model file FILE.py (see docs/user-models.md).")
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object (SI units).")]
OutOpt = Annotated[Path | None, typer.Option("--out", help="Output file or folder.")]

DEFAULT_PRESET_NAME = DEFAULT_PRESET

#: Help text of a ``--param`` option that accepts beam and vehicle data (the list of those
#: names is :data:`maglev_match.analyses.engineering.ENGINEERING_PARAMS`; kept here so that help
#: texts need no numerical module).
PARAM_HELP = ("Parameter to vary: a model parameter (omega1, sigma, kD ...) or beam/vehicle "
              "data L, EI, mbar, l, k, s, s0 (omega1 and sigma follow).")


def params_from_options(preset: str, config: Path | None, sets: list[str] | None) -> Params:
    """Preset, then --config, then --set overrides. Warnings about values that an explicit
    omega1 or sigma makes irrelevant are printed on stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ParameterWarning)
        params = load_params(preset, config, sets or [])
    print_warnings([str(w.message) for w in caught if issubclass(w.category, ParameterWarning)])
    for w in caught:
        if not issubclass(w.category, ParameterWarning):
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    return params


def preload(*modules: str) -> None:
    """Import ``modules`` in a background (daemon) thread while the command computes.

    A command that ends by writing figures and netCDF files needs matplotlib, xarray and
    h5netcdf only at its end; importing them costs ~0.8 s of CPU (measured 2026-11-25).
    Started at the beginning, the imports run on the second core while the main thread is
    inside compiled code (XLA, LAPACK) and has released the GIL. An import that fails here
    is left to fail again, with its message, where the module is really used.

    JAX is imported here, in the calling thread, before the thread starts: JAX's own
    modules import each other in circles, and two threads importing them at once can each
    hold a module the other waits for, which Python breaks by handing one thread a
    partially initialised module ("ImportError: ... partially initialized module 'jax'",
    seen as an internal error of `cycles`). The command needs JAX next anyway."""
    import importlib
    import threading

    importlib.import_module("maglev_match.dynamics.system")  # JAX, configured

    def work() -> None:
        import importlib

        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 - reported by the real import later
                return

    threading.Thread(target=work, name="maglev-match-preload", daemon=True).start()


#: The commands that accept a user model file (``--model FILE.py``).
USER_MODEL_COMMANDS = "stability, root-locus, hopf, hopf-curve, cycles and simulate"


def check_model(model: str) -> str:
    """``--model`` of a command that works on the maglev models: 'unit' or 'vehicle' (a
    command that accepts a model file branches off before calling this)."""
    if str(model).endswith(".py"):
        raise ParameterError("--model", model, "this command works on the maglev models "
                             "'unit' and 'vehicle' only; user model files are accepted by "
                             f"{USER_MODEL_COMMANDS}")
    from maglev_match.maglev.catalog import MODEL_NAMES, names_text

    if model not in MODEL_NAMES:
        raise ParameterError("--model", model,
                             f"must be {names_text().replace(' or ', ', ')} or a model file "
                             "ending in .py")
    return model


def print_warnings(items) -> None:
    """Warnings of a computation on stderr, one line each (stdout stays clean for --json).
    The text is printed literally (no Rich markup: brackets in values are kept)."""
    for w in items:
        console_err.print(Text.assemble(("warning: ", "yellow"), str(w)), highlight=False,
                          soft_wrap=True)


def print_error(message: str, prefix: str = "error") -> None:
    """One error line on stderr, printed literally (no Rich markup)."""
    line = " ".join(str(message).split())
    console_err.print(Text.assemble((f"{prefix}: ", "bold red"), line), highlight=False,
                      soft_wrap=True)


def check_param(system, model: str, name: str, option: str) -> None:
    """``name`` must be a parameter of the chosen model."""
    if name not in system.param_names:
        raise ParameterError(
            option, name,
            f"model '{model}' has no such parameter; choose one of {', '.join(system.param_names)}",
        )


def validate_value(params: Params, name: str, value: float) -> None:
    """A parameter value outside its rule (e.g. omega1 <= 0) is a user error."""
    if name in PARAMETER_DOCS:
        params.replace(**{name: value})


def unit_of(name: str) -> str:
    """The SI unit of a parameter, '' if unknown."""
    return PARAMETER_DOCS.get(name, ("", ""))[0]


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays, complex numbers and dataclasses for json.dumps.
    Complex numbers become [re, im]; non-finite floats become null."""
    import numpy as np  # (here: `--help` and usage errors need no NumPy)

    if is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable(asdict(obj))
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, complex | np.complexfloating):
        return [to_jsonable(float(obj.real)), to_jsonable(float(obj.imag))]
    if isinstance(obj, np.bool_ | bool):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def emit_json(obj: Any) -> None:
    """Print one JSON object on stdout."""
    typer.echo(json.dumps(to_jsonable(obj), indent=2))


def parse_range(text: str, name: str = "range") -> tuple[float, float]:
    """'a:b' -> (a, b), with a clear error."""
    try:
        a, b = (float(t) for t in text.split(":"))
    except ValueError:
        raise UserError(f"{name} '{text}': expected FROM:TO, e.g. 1e-4:8e-4") from None
    return a, b


#: The one folder every command writes to by default, one subfolder per command
#: (``maglev-match-out/root-locus/``, ``maglev-match-out/map/`` ...); ignored by git.
OUTPUT_ROOT = "maglev-match-out"


def default_output(command: str) -> Path:
    """The default output folder of ``command``: ``maglev-match-out/<command>``."""
    return Path(OUTPUT_ROOT) / command


def is_file_name(path: Path | str) -> bool:
    """True when ``path`` names a file: its last part has a suffix that begins with a letter
    (``run.csv``, ``map.nc``, ``report.html``). A name without one, or whose "suffix" is a
    number (``tau_0.001``, ``v1.5``), is a folder."""
    suffix = Path(path).suffix
    return len(suffix) > 1 and suffix[1].isalpha()


def output_target(out: Path | None, command: str, stem: str) -> tuple[Path, str]:
    """Where a command writes, the same way in every command: ``(folder, stem)``.

    ``--out`` absent: the folder ``maglev-match-out/<command>/`` and the command's own
    ``stem``. A name without a file suffix (:func:`is_file_name`) is a folder (created)
    holding ``stem.*``. A name with one is a file: its folder (created) and its stem name
    the outputs, so ``--out results/rl.csv`` writes ``results/rl.csv`` beside
    ``results/rl.png``.
    """
    path = output_path(out, str(default_output(command)))
    if not is_file_name(path):
        return path, stem + (parameter_suffix() if out is None else "")
    return path.parent, path.stem


def parameter_suffix() -> str:
    """What a default file name adds for the parameter set of the running command: a
    preset other than the default, a --config file's stem and every --set item, e.g.
    ``_turnout-stiff_tau-0.001`` for ``--preset turnout-stiff --set tau=0.001``, so that a
    run with other values does not overwrite the standstill answer in
    ``maglev-match-out/``. Empty outside a command or without those options."""
    ctx = _current_context()
    if ctx is None:
        return ""
    parts = []
    preset = ctx.params.get("preset")
    if preset and given("preset") and preset != DEFAULT_PRESET_NAME:
        parts.append(str(preset))
    config = ctx.params.get("config")
    if config:
        parts.append(Path(str(config)).stem)
    for item in ctx.params.get("set_") or []:
        name, _, value = str(item).partition("=")
        parts.append(f"{name.strip()}-{value.strip()}")
    text = "".join(f"_{p}" for p in parts)
    return re.sub(r"[^A-Za-z0-9._+-]", "_", text)[:120]


def write_result_json(out: Path | None, command: str, stem: str, data: Any,
                      json_out: bool) -> list[Path]:
    """Save a command's JSON result as ``<folder>/<stem>.json`` (the folder of
    :func:`output_target`); with ``--json`` and no ``--out`` nothing is written (stdout
    holds the same object). Returns the written files."""
    if json_out and out is None:
        return []
    from maglev_match.core.io import atomic_write_text

    folder, name = output_target(out, command, stem)
    path = folder / f"{name}.json"
    atomic_write_text(path, json.dumps(to_jsonable(data), indent=2) + "\n")
    return [path]


def output_path(out: Path | None, default: str) -> Path:
    """The output path (creating its folder): ``out`` if given, else ``default``."""
    path = Path(out) if out is not None else Path(default)
    if not is_file_name(path):
        path.mkdir(parents=True, exist_ok=True)
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
    return path


# ----- validation of typed options -------------------------------------------------------
# Bounds of the numerical options. Each is enforced while the command line is parsed
# (before any computation) and reported as "Invalid value for '--opt': ..." with exit code 2.

# NTST_MIN: the smallest mesh that resolves a cycle (measured; see maglev_match.core.options).
SCAN_MAX = 20_000  # values of an eigenvalue scan (each one an eigenvalue problem)
GRID_MAX = 400  # stability-grid points per axis (GRID_MAX^2 eigenvalue problems)
N_SAVE_MAX = 1_000_000  # saved time points of a simulation
HORIZON_MAX = 1e5  # s, simulation horizon
ROWS_PER_TILE_MAX = 10_000


def _fmt(v: float) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def check_number(value: Any, lo: float | None = None, hi: float | None = None, *,
                 lo_open: bool = False, hi_open: bool = False, integer: bool = False,
                 unit: str = "", why: str = "") -> str | None:
    """The rule ``value`` breaks, or None. Non-finite numbers always break it."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        return "must be a number"
    if isinstance(value, float) and not math.isfinite(value):
        return "must be a finite number"
    if integer and isinstance(value, float) and not value.is_integer():
        return "must be a whole number"
    bad = ((lo is not None and (value <= lo if lo_open else value < lo))
           or (hi is not None and (value >= hi if hi_open else value > hi)))
    if not bad:
        return None
    left = ("(" if lo_open else "[") + (_fmt(lo) if lo is not None else "-inf")
    right = (_fmt(hi) if hi is not None else "inf") + (")" if hi_open else "]")
    kind = "a whole number" if integer else "a number"
    rule = f"must be {kind} in {left}, {right}" + (f" {unit}" if unit else "")
    return rule + (f" ({why})" if why else "")


def bounded(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
            hi_open: bool = False, integer: bool = False, unit: str = "",
            why: str = "") -> Callable[[Any], Any]:
    """A typer option callback enforcing a finite range (see :func:`check_number`); use as
    ``typer.Option("--ntst", callback=bounded(NTST_MIN, NTST_MAX, integer=True))``."""

    def callback(value: Any) -> Any:
        values = value if isinstance(value, list | tuple) else [value]
        for v in values:
            rule = check_number(v, lo, hi, lo_open=lo_open, hi_open=hi_open,
                                integer=integer, unit=unit, why=why)
            if rule is not None:
                raise typer.BadParameter(f"{v!r}: {rule}")
        return value

    return callback


def finite(value: Any) -> Any:
    """Option callback: any finite number (or None)."""
    return bounded()(value)


ntst_option = bounded(NTST_MIN, NTST_MAX, integer=True,
                      why=f"fewer than {NTST_MIN} mesh intervals do not resolve a cycle")
ncol_option = bounded(NCOL_MIN, NCOL_MAX, integer=True)
tolerance_option = bounded(0.0, TOL_MAX, lo_open=True)
scan_option = bounded(2, SCAN_MAX, integer=True)
steps_option = bounded(1, STEPS_MAX, integer=True)
grid_option = bounded(0, GRID_MAX, integer=True, why="0: no grid")
n_save_option = bounded(2, N_SAVE_MAX, integer=True)
horizon_option = bounded(0.0, HORIZON_MAX, lo_open=True, unit="s")
workers_option = bounded(0, WORKERS_MAX, integer=True, why="0: compute in this process")
monte_carlo_option = bounded(2, MC_SAMPLES_MAX, integer=True,
                             why="samples; each one is an index computation")
seed_option = bounded(0, SEED_MAX, integer=True)
rows_per_tile_option = bounded(1, ROWS_PER_TILE_MAX, integer=True)
fraction_option = bounded(0.0, 1.0, lo_open=True)
# initial displacements (x5, q1): finite and at most 1 m (gaps are millimetres)
displacement_option = bounded(-1.0, 1.0, unit="m")


def check_index_params(params: Params) -> None:
    """The index chi = h / w0 needs w0 > 0: sigma = 0 (no force on the beam) leaves the
    beam undeflected and chi undefined."""
    if not params.w0 > 0:
        raise ParameterError("sigma", params.sigma, "must be > 0 for the index: chi = h / w0 "
                             f"needs a beam deflection w0 > 0 (w0 = {params.w0:g} m)")


SCHEDULER_RE = re.compile(r"^(tcp|tls|ucx|ws|wss)://(\[[0-9a-fA-F:]+\]|[A-Za-z0-9_.-]+):"
                          r"(\d{1,5})/?$")


def scheduler_option(value: str | None) -> str | None:
    """Option callback: a Dask scheduler address PROTOCOL://HOST:PORT."""
    if value is None:
        return value
    m = SCHEDULER_RE.match(value.strip())
    if m is None or not 1 <= int(m.group(3)) <= 65535:
        raise typer.BadParameter(f"{value!r}: expected a Dask scheduler address "
                                 "PROTOCOL://HOST:PORT, e.g. tcp://127.0.0.1:8786")
    return value.strip()


# ----- output paths ----------------------------------------------------------------------
SYSTEM_FOLDERS = ("/proc", "/sys", "/dev")


def check_output_path(path: Path | str | None, option: str = "--out", *,
                      kind: str = "auto", suffixes: tuple[str, ...] | None = None) -> None:
    """Check before any computation that an output can be written at ``path``.

    ``kind`` is 'file', 'folder' or 'auto' (a name without a suffix is a folder, as in
    :func:`output_path`). The path must not lie in a system folder (/proc, /sys, /dev), a
    file must not be an existing folder (nor a folder an existing file), no part of the
    path above it may be a plain file, and the nearest existing folder must accept a new
    file (tested by creating and removing one). Raises :class:`ParameterError` naming
    ``option``.
    """
    if path is None:
        return
    p = Path(path)
    text = str(path)
    if text.strip() == "" or "\x00" in text:
        raise ParameterError(option, text, "must be a file or folder name")
    if kind == "auto":
        kind = "file" if is_file_name(p) else "folder"
    if suffixes is not None and kind == "file" and p.suffix.lower() not in suffixes:
        raise ParameterError(option, text, f"must end in {' or '.join(suffixes)}")
    absolute = Path(os.path.abspath(p))
    for system in SYSTEM_FOLDERS:
        if absolute == Path(system) or Path(system) in absolute.parents:
            raise ParameterError(option, text, f"lies in the system folder {system}; choose "
                                 "a folder of your own")
    if absolute.exists():
        if kind == "file" and absolute.is_dir():
            raise ParameterError(option, text, "is an existing folder; give a file name")
        if kind == "folder" and not absolute.is_dir():
            raise ParameterError(option, text, "is an existing file; give a folder name")
    # the nearest existing ancestor must be a folder we can write to
    probe = absolute if (kind == "folder" and absolute.is_dir()) else absolute.parent
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise ParameterError(option, text, f"lies under {probe}, which is a file, not a folder")
    try:
        fd, name = tempfile.mkstemp(prefix=".maglev-match-probe-", dir=probe)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        raise ParameterError(option, text, f"cannot write in {probe}: "
                             f"{exc.strerror or exc}") from None
    if len(absolute.name.encode()) > 255:
        raise ParameterError(option, text, "the file name is longer than 255 bytes")


# ----- progress --------------------------------------------------------------------------
#: Seconds without news after which a plain-line progress report repeats its current stage
#: ("still ..."), so a log of a long command never falls silent for longer.
HEARTBEAT_S = 5.0


def _duration(seconds: float) -> str:
    """A time span for people: '42 s', '3 min 05 s', '1 h 02 min'."""
    seconds = max(0.0, float(seconds))
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


class ProgressReport:
    """Progress of a long command on stderr (stdout stays clean for ``--json``).

    On a terminal a Rich spinner (stages) or bar (tiles, with the time left) is shown and
    replaced as work advances; off a terminal (a log file, a pipe, CI) each stage or finished
    tile is one plain line ``maglev-match <command> [  12.3 s] <message>``, flushed at once,
    so a log shows what a long run is doing. A stage that runs longer than
    :data:`HEARTBEAT_S` seconds repeats itself (``still <stage> (<latest detail>)``), so a
    log never stays silent for longer; countable work (tiles, chunks, stages numbered
    ``k/n``) adds an estimate of the time left. Use as a context manager::

        with progress_report("cycles") as prog:
            prog.stage("searching Hopf points ...")
            prog.tiles(done, total)

    Parameters
    ----------
    command : the command name printed at the start of each plain line.
    tty : force terminal (True) or plain-line (False) output; None detects stderr.
    heartbeat : seconds of silence before the current stage is repeated (plain lines only;
        0 or None: never).
    """

    def __init__(self, command: str, tty: bool | None = None,
                 heartbeat: float | None = HEARTBEAT_S) -> None:
        import threading

        self.command = command
        self.tty = console_err.is_terminal if tty is None else tty
        self.heartbeat = heartbeat
        self.t0 = 0.0
        self._rich: Any = None
        self._task: Any = None
        self._last_done = -1
        self._stage = ""
        self._detail = ""
        self._last_line = 0.0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: Any = None
        self._finished: list[tuple[int, float]] = []  # (units done, when), as they grew
        self._what = ""  # what the units are (tiles, speeds, ...)

    def __enter__(self) -> ProgressReport:
        import threading
        import time

        self.t0 = time.perf_counter()
        self._last_line = self.t0
        if self.tty:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                SpinnerColumn,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._rich = Progress(SpinnerColumn(), TextColumn("{task.description}"),
                                  BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                                  TimeRemainingColumn(), console=console_err, transient=True)
            self._rich.__enter__()
            self._task = self._rich.add_task(self.command, total=None)
        elif self.heartbeat:
            self._thread = threading.Thread(target=self._beat, name="maglev-match-progress",
                                            daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None
        if self._rich is not None:
            self._rich.__exit__(*exc)
            self._rich = None

    @property
    def elapsed(self) -> float:
        """Seconds since the report started."""
        import time

        return time.perf_counter() - self.t0

    def _beat(self) -> None:
        """The heartbeat thread: repeat the stage after ``heartbeat`` seconds of silence.
        It writes while the main thread computes in compiled code (XLA, LAPACK release the
        interpreter lock)."""
        import time

        tick = min(0.5, self.heartbeat / 4)
        while not self._stop.wait(tick):
            if self._stage and time.perf_counter() - self._last_line >= self.heartbeat:
                stage = self._stage.rstrip(". ")
                detail = f" ({self._detail})" if self._detail else ""
                self._line(f"still {stage}{detail}")

    def _line(self, message: str) -> None:
        import sys
        import time

        with self._lock:
            sys.stderr.write(f"maglev-match {self.command} [{self.elapsed:7.1f} s] {message}\n")
            sys.stderr.flush()
            self._last_line = time.perf_counter()

    def stage(self, message: str, done: int | None = None, total: int | None = None) -> None:
        """A new stage of the work (one line off a terminal). With ``done`` of ``total``
        stages finished before this one, the line counts them (``[k/n]``)."""
        self._detail = ""
        if done is not None and total:
            message = f"[{done + 1}/{total}] {message}"
        self._stage = message
        if self._rich is not None:
            if done is not None and total:
                self._rich.update(self._task, description=message, completed=done,
                                  total=total)
            else:
                self._rich.update(self._task, description=message)
        else:
            self._line(message)

    def update(self, message: str) -> None:
        """Fine-grained news (e.g. each continuation step): shown on a terminal at once;
        off a terminal it is the detail of the next heartbeat line, so a log gets a line
        per stage and one every few seconds, not one per step."""
        self._detail = message
        if self._rich is not None:
            self._rich.update(self._task, description=message)

    def eta(self, done: int, total: int) -> float | None:
        """Estimated seconds left when ``done`` of ``total`` equal units are finished
        (:func:`time_left` of the finishing times seen so far)."""
        import time

        now = time.perf_counter()
        if done > 0 and (not self._finished or done > self._finished[-1][0]):
            self._finished.append((done, now))
        return time_left(self._finished, done, total, now)

    def tiles(self, done: int, total: int, what: str = "tiles") -> None:
        """``done`` of ``total`` units finished (one line per finished unit off a
        terminal, with the estimated time left). Units of another ``what`` (the runs
        over an irregular guideway after a sweep's speeds) start their own count: the
        estimate of the time left is made from their finishing times alone."""
        if what != self._what:
            self._what = what
            self._finished = []
            self._last_done = -1
        left = self.eta(done, total)
        self._stage = f"computing {what} ({done}/{total} done)"
        self._detail = ""
        if self._rich is not None:
            self._rich.update(self._task, completed=done, total=total,
                              description=f"{self.command}: {what}")
        elif done != self._last_done:
            tail = f", about {_duration(left)} left" if left is not None and done < total else ""
            self._line(f"{done}/{total} {what} done{tail}")
        self._last_done = done


def time_left(finished: list[tuple[int, float]], done: int, total: int,
              now: float) -> float | None:
    """Seconds left of ``total`` equal units, ``done`` finished, from ``finished`` (units
    done and the time, each time the count grew). The first finishing times say nothing
    of the rate: the first unit of every worker also loads and compiles kernels, so with
    two workers the second unit ends almost as late as the first. The rate is therefore
    that of the latest half of the units finished after the first, and there is no
    estimate until two units have finished after the first (none beats a wrong one)."""
    if done <= 0:
        return None
    if done >= total:
        return 0.0
    if not finished:
        return None
    d_first = finished[0][0]
    after = done - d_first
    if after < 2:
        return None
    k = max(1, after // 2)
    ref = [(d, t) for d, t in finished if d_first <= d <= done - k]
    d_ref, t_ref = ref[-1] if ref else finished[0]
    if done <= d_ref or now <= t_ref:
        return None
    return (now - t_ref) / (done - d_ref) * (total - done)


def progress_report(command: str, tty: bool | None = None) -> ProgressReport:
    """A :class:`ProgressReport` for ``command`` (see there)."""
    return ProgressReport(command, tty)


# ----- options that do not apply -----------------------------------------------------------
def _current_context() -> Any:
    """The click context of the running command (typer's bundled click, or click)."""
    for module in ("typer._click.globals", "click.globals"):
        try:
            mod = __import__(module, fromlist=["get_current_context"])
        except ImportError:
            continue
        ctx = mod.get_current_context(silent=True)
        if ctx is not None:
            return ctx
    return None


def given(name: str) -> bool:
    """Whether the option with parameter name ``name`` (the Python name, e.g. ``set_``) was
    given on the command line, as opposed to left at its default. False outside a command."""
    ctx = _current_context()
    if ctx is None:
        return False
    source = ctx.get_parameter_source(name)
    return source is not None and getattr(source, "name", "") in ("COMMANDLINE", "ENVIRONMENT")


def refuse_given(options: dict[str, str], why: str) -> None:
    """Refuse (exit code 2) the first of ``options`` (parameter name -> option as typed,
    e.g. {"x5": "--x5"}) given on the command line: ``why`` says why it does not apply."""
    for name, option in options.items():
        if given(name):
            raise UserError(f"{option}: {why}")


# ----- from the command line to the API ---------------------------------------------------
def set_items(sets: list[str] | None, option: str = "--set") -> dict[str, str]:
    """``NAME=VALUE`` items as {name: value text} (a user model file's parameters; the API
    checks the names and the numbers)."""
    out: dict[str, str] = {}
    for item in sets or []:
        if "=" not in item:
            raise UserError(f"{option} '{item}': expected NAME=VALUE, e.g. a=1.5")
        name, text = (t.strip() for t in item.split("=", 1))
        out[name] = text
    return out


#: Options that choose a maglev parameter set (python name -> option as typed).
PARAMETER_SET_OPTIONS = {"preset": "--preset", "config": "--config", "set_": "--set"}


def model_inputs(model: str, preset: str, config: Path | None, sets: list[str] | None,
                 *, default_params: bool = True) -> tuple[Any, dict[str, Any]]:
    """``(params, overrides)`` for an API call from ``--model``, ``--preset``, ``--config``
    and ``--set``: for the maglev models the parameter set (preset, then config, then the
    overrides; its warnings printed), for a user model file ``FILE.py`` no parameter set
    and the ``--set`` items as the file's own values (a preset or config does not apply to
    it). With ``default_params`` False and none of those options given, params is None
    (the API then takes, for a restart, the saved values)."""
    if str(model).endswith(".py"):
        if config is not None:
            raise UserError(f"--config {config}: maglev parameter files do not apply to a "
                            f"user model ({model}); use --set NAME=VALUE")
        refuse_given({"preset": "--preset"}, f"maglev parameter presets do not apply to a "
                     f"user model ({model}); use --set NAME=VALUE")
        return None, set_items(sets)
    if not default_params and not any(given(n) for n in PARAMETER_SET_OPTIONS):
        return None, {}
    return params_from_options(preset, config, sets), {}


@contextlib.contextmanager
def api_options(fields: dict[str, str]):
    """Errors of an API call name the command's options: a
    :class:`~maglev_match.core.params.ParameterError` whose field is an API keyword of
    ``fields`` (API keyword -> option as typed, e.g. {"start": "--from"}) is raised again
    with the option's name."""
    try:
        yield
    except ParameterError as exc:
        option = fields.get(exc.field)
        if option is None:
            raise
        raise ParameterError(option, exc.value, exc.rule) from None
