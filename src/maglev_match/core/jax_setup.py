"""JAX configuration shared by the whole package: float64 everywhere, a persistent
compilation cache for every compilation, and one thread for the small problems of a
command-line process.

Imported first by ``maglev_match/__init__.py``, so the settings below are in place before
JAX (and, through it, NumPy's BLAS) is loaded, unless the caller imported them earlier.

* **Compilation cache.** Every compiled kernel is written to the cache (no minimum compile
  time, no minimum size), so a second process loads its executables instead of compiling
  them. Set ``MAGLEV_MATCH_CACHE`` to choose the folder (default
  ``~/.cache/maglev-match/jax``), or to an empty string to switch the cache off. The key is
  JAX's: the lowered program, the argument shapes/dtypes and the compiler version. Model
  parameters are traced arguments of the kernels, so a new parameter value finds the same
  entry; only a new shape, a new model function or a new option that is a compile-time
  constant compiles again. The package's kernels are also exported ahead of time into the
  ``aot`` subfolder (:mod:`maglev_match.core.aot`), so a new process does not trace them again
  to find their executables; ``MAGLEV_MATCH_AOT=0`` switches that off.
* **Threads.** The models are small (9 to 39 states): XLA's and BLAS's thread pools cost
  more than they give on them, and the handing-over between cores of a compiled while loop
  dominates a simulation (model B, 5 s: 0.22 s on two cores, 0.11 s pinned to one, measured
  2026-11-25 on the 2-core test machine). So, unless ``MAGLEV_MATCH_THREADS`` says
  otherwise, the thread pools are set to one thread (``OMP_NUM_THREADS``,
  ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS``, ``XLA_FLAGS``; values the user set are
  kept; the pools of a BLAS that NumPy loaded before this module are limited to one
  thread the same way). The two cores of a small machine are used by running independent
  parts of one computation in two threads instead (the index's paper and simulated parts,
  :mod:`maglev_match.core.beside`), or by the worker processes of a map.
  ``MAGLEV_MATCH_THREADS=auto`` leaves the thread pools to the libraries;
  ``MAGLEV_MATCH_THREADS=1`` also pins the process to the core it started on, which halves a
  model-B simulation on a quiet machine but is NOT the default: a pinned process cannot move
  to the free core when the machine is busy (an empty-cache ``index`` took 62.6 s pinned
  against 11.0 s unpinned at load ~7, 2026-11-25). Child processes of a pinned process
  (Dask workers of a map) get their parent's full CPU set back.
* **Environment problems** are named in one line on stderr, never left to surface as a JAX
  traceback, and the run goes on: a ``JAX_PLATFORMS`` naming a platform this machine cannot
  start (``gpu`` without a GPU) falls back to the CPU (where the package computes anyway),
  and a cache folder that cannot be written is left out. Each line names the variable and
  what to set instead. (A line on stderr rather than a Python warning: this module is
  imported before any caller can arrange how warnings look, and a warning's two-line form
  with a source line is noise here.)
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_XLA_SINGLE = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
_PINNED_ENV = "_MAGLEV_MATCH_PINNED_FROM"  # the CPU set before pinning, for child processes
PINNED_CPU: int | None = None  # the core this process was pinned to (None: not pinned)


def _is_cli_process() -> bool:
    """True for the ``maglev-match`` console script and ``python -m maglev_match.cli``,
    never for a child process (multiprocessing copies the parent's ``sys.argv``)."""
    import multiprocessing

    if (multiprocessing.parent_process() is not None
            or "--multiprocessing-fork" in getattr(sys, "orig_argv", ())):
        return False  # (a spawned child imports this before its parent_process is set)
    argv = list(getattr(sys, "orig_argv", sys.argv))
    if "-m" in argv[:-1]:  # python -m maglev_match.cli: sys.argv[0] is still "-m" here
        return argv[argv.index("-m") + 1] in ("maglev_match", "maglev_match.cli")
    return bool(sys.argv) and Path(sys.argv[0]).name in ("maglev-match", "maglev-match.exe")


def _current_cpu() -> int | None:
    """The core this process is running on now (field 39 of /proc/self/stat), or None."""
    try:
        stat = Path("/proc/self/stat").read_text()
        return int(stat[stat.rindex(")") + 2:].split()[36])
    except (OSError, ValueError, IndexError):
        return None


def _configure_threads() -> None:
    global PINNED_CPU
    mode = os.environ.get("MAGLEV_MATCH_THREADS", "").strip().lower()
    if mode == "auto":
        return
    chosen = [name for name in _THREAD_ENV if name in os.environ]
    for name in _THREAD_ENV:
        os.environ.setdefault(name, "1")
    if not chosen and "numpy" in sys.modules:
        # NumPy came first (a notebook, a test module): its BLAS started its thread pool
        # before the variables above were set, one thread per core. Two such processes on
        # two cores (the test suite's two workers) then run four BLAS threads that wait on
        # each other: the suite used 9 % more CPU (2660 against 2434 s, 2026-12-05). Limit
        # the pools already loaded as the variables would have.
        try:
            from threadpoolctl import threadpool_limits

            threadpool_limits(limits=1)
        except Exception:  # noqa: BLE001  (a library threadpoolctl cannot handle: left as is)
            pass
    flags = os.environ.get("XLA_FLAGS", "")
    if "intra_op_parallelism_threads" not in flags and "multi_thread_eigen" not in flags:
        os.environ["XLA_FLAGS"] = (flags + " " + _XLA_SINGLE).strip()
    if not hasattr(os, "sched_setaffinity"):
        return
    inherited = os.environ.get(_PINNED_ENV)
    try:
        if inherited and not _is_cli_process():
            # a child of a pinned command (e.g. a Dask worker): give it the full set back
            os.sched_setaffinity(0, {int(c) for c in inherited.split(",")})
            return
        allowed = os.sched_getaffinity(0)
        if len(allowed) > 1 and mode == "1":  # pinning only on request (see above)
            cpu = _current_cpu()
            cpu = cpu if cpu in allowed else min(allowed)
            os.environ[_PINNED_ENV] = ",".join(str(c) for c in sorted(allowed))
            os.sched_setaffinity(0, {cpu})
            PINNED_CPU = cpu
    except (OSError, ValueError):  # affinity not permitted here: threads stay as they are
        pass


_configure_threads()

import jax  # noqa: E402  (after the thread settings above)

jax.config.update("jax_enable_x64", True)
_PLATFORMS = os.environ.get("JAX_PLATFORMS", "cpu") or "cpu"
jax.config.update("jax_platforms", _PLATFORMS)
#: environment problems met while this module was imported (each already reported)
ENVIRONMENT_PROBLEMS: list[str] = []


def _environment_warning(message: str) -> None:
    """One line on stderr (see the module docstring), remembered for callers."""
    ENVIRONMENT_PROBLEMS.append(message)
    try:
        sys.stderr.write(f"warning: {message}\n")
        sys.stderr.flush()
    except (OSError, ValueError, UnicodeError):  # no usable stderr: the list keeps it
        pass


def _check_platforms(platforms: str) -> None:
    """A platform other than the CPU is started now; one this machine cannot start is
    reported in one line and replaced by the CPU, instead of a RuntimeError deep inside the
    first computation (the CPU always exists and is started lazily, as before)."""
    if {p.strip().lower() for p in platforms.split(",") if p.strip()} <= {"cpu"}:
        return
    try:
        jax.devices()
    except RuntimeError as exc:
        detail = " ".join(str(exc).split("(set JAX_PLATFORMS")[0].split())
        jax.config.update("jax_platforms", "cpu")
        _environment_warning(
            f"JAX_PLATFORMS={platforms}: JAX cannot start that platform on this machine "
            f"({detail}); computing on the CPU instead: unset JAX_PLATFORMS or set "
            "JAX_PLATFORMS=cpu to silence this")


_check_platforms(_PLATFORMS)

# the folder of the persistent caches (XLA executables, and the exported kernels of
# maglev_match.core.aot in its "aot" subfolder); None when the cache is switched off or unusable
CACHE_DIR: Path | None = None

def _cache_problem(folder: Path) -> str | None:
    """Why ``folder`` cannot hold the cache (created if needed), or None if it can: a file
    is created and removed there, since a folder can exist and still refuse writes."""
    import tempfile

    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=".probe-", dir=folder)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def _cache_setting() -> tuple[str, bool]:
    """The cache folder and whether MAGLEV_MATCH_CACHE chose it."""
    if "MAGLEV_MATCH_CACHE" in os.environ:
        return os.environ["MAGLEV_MATCH_CACHE"], True
    try:
        return str(Path.home() / ".cache" / "maglev-match" / "jax"), False
    except RuntimeError:  # no home folder can be determined
        return "", False


_cache, _chosen = _cache_setting()
if _cache:
    _problem = _cache_problem(Path(_cache))
    if _problem is not None:
        _shown = _cache if _chosen else f"{_cache} (the default)"
        _environment_warning(
            f"MAGLEV_MATCH_CACHE={_shown}: the compilation cache folder cannot be written "
            f"({_problem}); running without it (every process compiles again, slower "
            "start): set MAGLEV_MATCH_CACHE to a writable folder, or to an empty value to "
            "switch the cache off")
        _cache = ""
if _cache:
    try:
        jax.config.update("jax_compilation_cache_dir", _cache)
        # cache every compilation: most of the package's kernels compile in 0.01-0.2 s,
        # which a threshold would leave to be redone in every process
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
        CACHE_DIR = Path(_cache)
    except OSError:  # read-only home: run without the persistent cache
        pass


def to_device(x, dtype=None):  # noqa: ANN001, ANN201  (any array-like in, a jax.Array out)
    """``jnp.asarray(x, dtype)`` without compiling anything: host data (a NumPy array, a
    Python or NumPy scalar, a list) is copied to the device with :func:`jax.device_put`.

    Why. ``jnp.asarray`` of host data runs a small jitted staging program, one per new
    shape and dtype; in a fresh process each costs a lowering and a cache look-up (~10 ms),
    and one ``maglev-match index`` met about 25 of them (measured 2026-12-04). The result is
    the same array: same values, dtype and weak type (a Python scalar stays weakly typed,
    as with ``jnp.asarray``); a ``jax.Array`` (or a tracer) goes through ``jnp.asarray``."""
    import numpy as np

    if isinstance(x, jax.Array):
        return jax.numpy.asarray(x, dtype)
    if dtype is None and isinstance(x, (bool, int, float, complex)):
        return jax.device_put(x)
    return jax.device_put(np.asarray(x, dtype))


def kernel_arg(x, dtype=None):  # noqa: ANN001, ANN201
    """An argument for a jitted kernel, standing for ``jnp.asarray(x, dtype)``: host data as
    a NumPy array (a Python scalar without ``dtype`` as it is, weakly typed as with
    ``jnp.asarray``), a ``jax.Array`` as it is. The kernel's call moves it to the device
    on its fast path: no staging program compiled per shape (see :func:`to_device`) and
    none of ``jax.device_put``'s Python overhead (~15 us an argument) on every call."""
    import numpy as np

    if isinstance(x, jax.Array):
        return x if dtype is None else jax.numpy.asarray(x, dtype)
    if dtype is None and isinstance(x, (bool, int, float, complex)):
        return x
    return np.asarray(x, dtype)
