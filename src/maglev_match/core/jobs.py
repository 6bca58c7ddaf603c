"""The one runner of the package's tiled jobs: pieces computed here or on Dask, each saved
into a checkpoint folder as it finishes.

A *job* (:class:`Job`) is a list of pieces, ranges [a, b) of some index (the rows of a
design map, the speeds of a sweep, the samples of a Monte Carlo study), a top-level function
that computes a piece from its arguments, and what a saved piece must look like (its
:class:`~maglev_match.core.checkpoint.Checkpoint` in a folder: the spec's fingerprint, the
file names, the variables and their shapes). :func:`run_job` runs the pieces still to do

* in this process, one after the other (``workers == 0`` and no scheduler), or
* on Dask (:func:`run_pieces_on_dask`): a local cluster of single-threaded worker processes
  that ignore Ctrl-C (:func:`local_cluster`), or an existing scheduler,

and saves each into the checkpoint folder as it finishes (:mod:`maglev_match.core.checkpoint`:
the folder locked, every piece written atomically with the fingerprint; a resumed job reuses
the usable pieces, and damaged or foreign ones are named in a warning and recomputed),
reporting ``progress(done, total)``. While pieces run, the job's stop note counts the saved
pieces and says how to resume (:class:`TileCount`): a Ctrl-C anywhere in the job becomes
:class:`~maglev_match.core.errors.MapStopped` with exit code 130 and that note, a lost
scheduler a :class:`~maglev_match.core.errors.MapStopped` too. Dask's own messages go to a
log file (:func:`dask_log_capture`). Without a checkpoint folder the pieces are computed in
memory and their results returned (on Dask: through a temporary folder).

The runner knows nothing about what the pieces compute. Dask is imported only when a job
runs on it: the command line's start-up does not load it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import warnings as warnings_mod
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from maglev_match.core.checkpoint import LOCK_NAME, SPEC_NAME, TILE_PREFIX, Checkpoint
from maglev_match.core.errors import MapStopped
from maglev_match.core.interrupts import on_interrupt
from maglev_match.core.params import ParameterError

__all__ = ["Job", "run_job", "run_in_memory", "load_pieces", "check_workers", "TileCount",
           "run_pieces_on_dask", "local_cluster", "shared_cluster", "workers_ignore_sigint",
           "dask_log_capture",
           "remove_checkpoint", "SINGLE_THREADED_ENV", "MALLOC_TRIM_THRESHOLD",
           "MALLOC_MMAP_THRESHOLD", "SCHEDULER_TIMEOUT", "DASK_LOGGERS"]

#: a piece of a job: the range [a, b) of its index
Piece = tuple[int, int]

# One worker process per core, each single-threaded: on 2 cores a row of 100 points ran in
# 1.6 s single-threaded against 2.3 s with XLA's and BLAS's own thread pools (measured before
# the row scan of issue 14; a warm single-threaded row now takes ~0.8 s).
SINGLE_THREADED_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
}
MALLOC_TRIM_THRESHOLD = 256 * 2**20
MALLOC_MMAP_THRESHOLD = 64 * 2**20  # a fixed trim threshold disables glibc's adaptive one
SCHEDULER_TIMEOUT = "10s"  # waiting for an existing scheduler to answer
DASK_LOGGERS = ("distributed", "tornado", "asyncio", "bokeh")
# source folders of the packages whose warnings are Dask's (the port in use, ...)
_DASK_PACKAGES = ("distributed", "tornado", "dask", "bokeh")


# ---------------------------------------------------------------------------------------
# the job and its runner
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Job:
    """What a tiled job computes, for :func:`run_job`.

    pieces : the ranges [a, b), in the order of the result.
    compute : a top-level function (Dask sends it to the workers by name);
        ``compute(*args_of(piece))`` returns the piece's variables (a dict of arrays).
    args_of : the arguments of ``compute`` for a piece (called in this process).
    store : what a saved piece must look like: ``store(folder)`` is the job's
        :class:`~maglev_match.core.checkpoint.Checkpoint` in ``folder`` (fingerprint, file
        names, variables and shapes; e.g.
        :func:`~maglev_match.core.checkpoint.tile_checkpoint`).
    noun : what the stop note calls the pieces ("tiles", "Monte Carlo chunks").
    run : the kind of run the lock's message names (default: the checkpoint's ``what``).
    """

    pieces: Sequence[Piece]
    compute: Callable[..., Any]
    args_of: Callable[[Piece], tuple]
    store: Callable[[Path], Checkpoint]
    noun: str = "tiles"
    run: str | None = None

    def task(self, piece: Piece) -> tuple[Callable[..., Any], tuple]:
        """(function, arguments) of a piece."""
        return self.compute, tuple(self.args_of(piece))


def check_workers(workers: int | None) -> None:
    """``workers`` must be None (one per core), 0 (this process) or a positive count."""
    if workers is not None and workers < 0:
        raise ParameterError("--workers", workers, "must be >= 0 (0: compute in this process)")


def run_job(job: Job, folder: Path | None, *, resume: bool = False,
            scheduler: str | None = None, workers: int | None = None,
            progress: Callable[[int, int], None] | None = None, limit: int | None = None,
            log: Path | None = None, echo_dask: bool = False, capture_dask: bool = True,
            finish: Callable[[Checkpoint], Any] | None = None,
            scratch_prefix: str = "maglev-match-") -> Any:
    """Run every piece of ``job`` not yet saved in ``folder``, then return ``finish(store)``
    (default :func:`load_pieces`: the pieces' variables in order), the folder still locked.

    folder : the checkpoint folder (created and locked for the duration; with ``resume``
        its usable pieces are reused, without it old pieces are removed). None: no
        checkpoint; the pieces are computed in memory (:func:`run_in_memory`) when they run
        here, and through a temporary folder (named ``scratch_prefix...``) on Dask.
    scheduler : address of an existing Dask scheduler (tcp://host:port); else a local
        cluster of ``workers`` processes (None: one per core, :func:`local_cluster`), or no
        cluster at all when ``workers == 0`` (compute in this process).
    progress : called as ``progress(done, total)`` before the first piece and after each.
    limit : compute at most this many new pieces, then stop (for tests of resuming).
    log, echo_dask : Dask's messages go to the file ``log`` (None: dropped), with
        ``echo_dask`` to the terminal too (:func:`dask_log_capture`); ``capture_dask``
        False leaves them where Dask puts them.

    Raises :class:`~maglev_match.core.params.ParameterError` for a negative ``workers``, a
    folder of another computation under ``resume`` (option ``--resume``) or a scheduler that
    does not answer; :class:`~maglev_match.core.errors.CheckpointLocked` when another run
    holds the folder; :class:`~maglev_match.core.errors.MapStopped` (with the resume hint)
    on Ctrl-C or a lost scheduler.
    """
    check_workers(workers)
    here = workers == 0 and scheduler is None
    if folder is None:
        if here:
            return run_in_memory(job, progress)
        import tempfile

        with tempfile.TemporaryDirectory(prefix=scratch_prefix) as tmp:
            return run_job(job, Path(tmp), resume=resume, scheduler=scheduler,
                           workers=workers, progress=progress, limit=limit, log=log,
                           echo_dask=echo_dask, capture_dask=capture_dask, finish=finish)
    store = job.store(Path(folder))
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(store.locked(resume, run=job.run))
        except ValueError as exc:
            raise ParameterError("--resume", str(store.folder), str(exc)) from None
        missing = store.todo(job.pieces)
        total = len(job.pieces)
        todo = missing if limit is None else missing[:limit]
        count = TileCount(total - len(missing), total, store.folder, job.noun)
        if progress:
            progress(count.done, total)
        if todo:
            with count.stoppable():
                if here:
                    for piece in todo:
                        fn, args = job.task(piece)
                        store.save(piece, fn(*args))
                        count.done += 1
                        if progress:
                            progress(count.done, total)
                else:
                    capture = (dask_log_capture(log, echo=echo_dask) if capture_dask
                               else contextlib.nullcontext())
                    with capture:
                        run_pieces_on_dask({piece: job.task(piece) for piece in todo},
                                           store.save, scheduler, workers, progress, count)
        return finish(store) if finish is not None else load_pieces(store, job.pieces)


def run_in_memory(job: Job, progress: Callable[[int, int], None] | None = None
                  ) -> list[Any]:
    """Every piece of ``job`` computed in this process, in order, nothing saved: their
    results. ``progress(done, total)`` before the first piece and after each."""
    total = len(job.pieces)
    out: list[Any] = []
    if progress:
        progress(0, total)
    for piece in job.pieces:
        fn, args = job.task(piece)
        out.append(fn(*args))
        if progress:
            progress(len(out), total)
    return out


def load_pieces(store: Checkpoint, pieces: Sequence[Piece]) -> list[dict[str, Any]]:
    """The variables of every piece of ``store``, in order (each checked first); a missing
    or damaged piece raises RuntimeError with the resume hint."""
    out = []
    for piece in pieces:
        if not store.check(piece).ok:
            raise RuntimeError(f"{store.noun} {piece} is missing from {store.folder}; run "
                               "again with --resume")
        out.append(store.load(piece))
    return out


# ---------------------------------------------------------------------------------------
# what a stopped job says
# ---------------------------------------------------------------------------------------
def _stopped_text(what: str, done: int, total: int, checkpoint: Path,
                  noun: str = "tiles") -> str:
    return (f"{what}: {done} of {total} {noun} are saved in {checkpoint}; run the same "
            "command with --resume to continue")


@dataclass
class TileCount:
    """The finished pieces of a tiled job that keeps them in ``folder``: what an interrupt
    or a lost scheduler says (the count at that moment and how to resume)."""

    done: int
    total: int
    folder: Path
    noun: str = "tiles"

    def text(self, what: str = "interrupted") -> str:
        return _stopped_text(what, self.done, self.total, self.folder, self.noun)

    @contextlib.contextmanager
    def stoppable(self) -> Iterator[None]:
        """The job's ``with`` block: its stop note is this count (for the command line's
        interrupt guard), and a Ctrl-C anywhere inside (an import, the start of a cluster,
        a piece) becomes :class:`~maglev_match.core.checkpoint.MapStopped` with exit code 130
        and the resume hint."""
        with on_interrupt(self.text):
            try:
                yield
            except KeyboardInterrupt:
                raise MapStopped(self.text(), 130) from None


# ---------------------------------------------------------------------------------------
# Dask: the local cluster, the pieces on it, its messages
# ---------------------------------------------------------------------------------------
def _python_ignoring_sigint() -> str | None:
    """The path of a tiny launcher that starts this Python with SIGINT ignored (a POSIX shell
    script: ``trap '' INT`` then ``exec python "$@"``), kept in a per-user temporary folder;
    None where there is no POSIX shell or the file cannot be written."""
    import hashlib
    import shlex
    import sys
    import tempfile

    if os.name != "posix" or not os.path.exists("/bin/sh"):
        return None
    text = f"#!/bin/sh\ntrap '' INT\nexec {shlex.quote(sys.executable)} \"$@\"\n"
    tag = hashlib.sha256(text.encode()).hexdigest()[:16]
    folder = Path(tempfile.gettempdir()) / f"maglev-match-{os.getuid()}"
    exe = folder / f"python-{tag}"
    try:
        if exe.is_file() and exe.read_text() == text and os.access(exe, os.X_OK):
            return str(exe)
        folder.mkdir(mode=0o700, exist_ok=True)
        if folder.stat().st_uid != os.getuid():
            return None  # someone else's folder: do not run what it holds
        tmp = folder / f".{exe.name}.{os.getpid()}.tmp"
        tmp.write_text(text)
        tmp.chmod(0o755)
        os.replace(tmp, exe)
        return str(exe)
    except OSError:
        return None


@contextlib.contextmanager
def workers_ignore_sigint() -> Iterator[None]:
    """Start the worker processes created in the ``with`` block with SIGINT ignored.

    Ctrl-C in a terminal reaches the whole process group; only this (the client) process
    should react, and the workers are shut down by it. The workers are spawned (a fresh
    Python) by Dask's nannies, from a thread of their own, at a moment the client does not
    choose; so instead of ignoring SIGINT in this process while they start (a Ctrl-C in
    that window was lost, and a map went on computing), the spawned Python itself starts
    through a launcher that ignores SIGINT (:func:`multiprocessing.set_executable`). Where
    there is no launcher (no POSIX shell) SIGINT is ignored here during the start, as before.
    """
    import multiprocessing
    import multiprocessing.spawn
    import signal

    exe = _python_ignoring_sigint()
    if exe is not None:
        old = multiprocessing.spawn.get_executable()
        multiprocessing.set_executable(exe)
        try:
            yield
        finally:
            multiprocessing.set_executable(old)
        return
    try:  # pragma: no cover - not POSIX
        old_handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # pragma: no cover - not the main thread
        yield
        return
    try:  # pragma: no cover
        yield
    finally:  # pragma: no cover
        signal.signal(signal.SIGINT, old_handler)


def local_cluster(workers: int | None) -> Any:
    """A local Dask cluster for the package's tiled jobs: ``workers`` single-threaded worker
    processes (None or 0: one per core), no dashboard, one-thread BLAS and XLA in the
    workers (:data:`SINGLE_THREADED_ENV`), glibc's own malloc thresholds, and workers that
    ignore Ctrl-C (:func:`workers_ignore_sigint`): the client stops them."""
    import dask
    from dask.distributed import LocalCluster

    # Dask's nannies set MALLOC_TRIM_THRESHOLD_=65536 so that workers hand memory back
    # to the OS; for this workload that turns every large temporary array into an
    # mmap/munmap pair (measured: ~1200 per second, a third of the worker's CPU time in
    # the kernel). The tiles are small, so keep glibc's default behaviour.
    with dask.config.set({
        "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": MALLOC_TRIM_THRESHOLD,
        "distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_": MALLOC_MMAP_THRESHOLD,
    }), workers_ignore_sigint():
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, dashboard_address=None,
                               env=SINGLE_THREADED_ENV)
    _no_gc_diagnosis()
    return cluster


def _no_gc_diagnosis() -> None:
    """The scheduler of a local cluster runs in this process and times every full garbage
    collection with a gc callback (for its own diagnostic logs). A Ctrl-C that lands between
    the callback's start and stop calls leaves its timer half-started; the next collection
    then prints "Exception ignored ... AssertionError" and a traceback on the way out (seen
    once in CI: ``test_interrupts.py``, ``speed``). The package does not use those logs,
    so the callback is taken off (Dask's own switch; the scheduler's close leaves it off)."""
    with contextlib.suppress(Exception):
        from distributed.gc import disable_gc_diagnosis

        disable_gc_diagnosis(force=True)


@contextlib.contextmanager
def shared_cluster(scheduler: str | None, workers: int | None) -> Iterator[str | None]:
    """One Dask cluster for several jobs in a row (the stages of one computation): yields
    the scheduler to pass to each :func:`run_job`. An existing ``scheduler`` is yielded as
    it is and ``workers == 0`` (compute in this process) yields None; otherwise one local
    cluster (:func:`local_cluster`) is started here, its address yielded, and it is closed
    when the block ends. The workers then keep their imports and compiled kernels from one
    stage to the next instead of a new cluster starting for each."""
    check_workers(workers)
    if scheduler is not None or workers == 0:
        yield scheduler
        return
    # Dask's messages while the cluster starts and stops are dropped, as run_job drops
    # those of its own clusters
    with dask_log_capture(None):
        cluster = local_cluster(workers)
        try:
            yield cluster.scheduler_address
        except BaseException:  # Ctrl-C (or the job's MapStopped after one), an error
            _quiet_cluster(cluster=cluster)
            raise
        finally:
            with contextlib.suppress(Exception):
                cluster.close(timeout=10)


def run_pieces_on_dask(tasks: dict, save: Callable[[Any, Any], Any], scheduler: str | None,
                       workers: int | None, progress: Callable[[int, int], None] | None,
                       count: TileCount) -> None:
    """Run ``tasks`` ({key: (function, args)}) on Dask (a local cluster of ``workers``
    processes, :func:`local_cluster`, or an existing ``scheduler``) and ``save(key,
    result)`` each as it finishes, counting them in ``count`` (call inside its
    :meth:`TileCount.stoppable` block: an interrupt is re-raised here once the workers are
    quietened; a lost scheduler raises :class:`~maglev_match.core.checkpoint.MapStopped`)."""
    from dask.distributed import Client, as_completed

    cluster = client = None
    futures: dict = {}
    try:
        if scheduler is None:
            cluster = local_cluster(workers)
            client = Client(cluster)
        else:
            try:
                client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
            except (OSError, TimeoutError, ValueError, TypeError) as exc:
                raise ParameterError("--scheduler", scheduler,
                                     f"no Dask scheduler answered there ({exc})") from None
        futures = {client.submit(fn, *args, pure=False, retries=2): key
                   for key, (fn, args) in tasks.items()}
        for fut in as_completed(futures):
            key = futures[fut]
            try:
                data = fut.result()
            except KeyboardInterrupt:
                raise
            except Exception as exc:
                if _is_lost_connection(exc):
                    _quiet_logging()  # the client's reconnect attempts end in tracebacks
                    raise MapStopped(count.text(
                        f"lost the Dask scheduler ({type(exc).__name__})")) from None
                raise
            save(key, data)
            count.done += 1
            if progress:
                progress(count.done, count.total)
    except KeyboardInterrupt:
        # stop quietly: the shutdown of interrupted workers is expected, not news
        _quiet_cluster(client if cluster is not None else None)  # (local workers only)
        if cluster is None and client is not None:  # an existing scheduler: drop our tasks
            with contextlib.suppress(Exception):
                client.cancel(list(futures))
        raise
    except (OSError, TimeoutError) as exc:
        _quiet_logging()
        raise MapStopped(count.text(
            f"lost the Dask scheduler ({type(exc).__name__}: {exc})")) from None
    finally:
        if client is not None:
            with contextlib.suppress(Exception):
                client.close(timeout=10)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close(timeout=10)


@contextlib.contextmanager
def dask_log_capture(log: Path | None, echo: bool = False) -> Iterator[None]:
    """Send Dask's own messages to the file ``log`` instead of the terminal while the
    block runs: the records of the ``distributed``/``tornado``/``asyncio``/``bokeh``
    loggers (Dask's configuration prints them on stderr, e.g. "Worker process still alive
    after 4.0 seconds, killing") and Python warnings raised from those packages' files
    (e.g. "Port 8787 is already in use"). The file is created on the first message only.
    With ``echo`` they are shown as before as well. The handlers, levels and warning hook
    are restored afterwards. Messages of worker processes of an external cluster stay
    with that cluster."""
    with contextlib.suppress(ImportError):
        import distributed  # noqa: F401  (its import installs Dask's own log handlers)

    handler: logging.Handler
    if log is not None:
        handler = logging.FileHandler(log, mode="a", encoding="utf-8", delay=True)
        handler.setFormatter(logging.Formatter(
            "%(asctime)s %(name)s %(levelname)s: %(message)s"))
    else:
        handler = logging.NullHandler()
    saved = []
    for name in DASK_LOGGERS:
        lg = logging.getLogger(name)
        saved.append((lg, list(lg.handlers), lg.propagate))
        if not echo:
            for h in list(lg.handlers):
                lg.removeHandler(h)
            lg.propagate = False
        lg.addHandler(handler)
    # the warnings go to the file alone (shown on the terminal by the hook when echoing)
    warn_log = logging.getLogger("maglev_match.dask_warnings")
    warn_log.propagate = False
    warn_log.addHandler(handler)
    shown = warnings_mod.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        parts = Path(str(filename)).parts
        if any(p in parts for p in _DASK_PACKAGES):
            if log is not None:
                text = " ".join(str(message).split())
                warn_log.warning("%s: %s (%s:%s)", category.__name__, text, filename, lineno)
            if not echo:
                return
        shown(message, category, filename, lineno, file, line)

    warnings_mod.showwarning = show
    # an exception Python can only report ("Exception ignored in ...", sys.unraisablehook)
    # raised inside Dask's own code goes the same way: e.g. distributed's GC diagnosis,
    # whose callback asserts when a collection's start and stop cross its enabling in
    # another thread (seen once in the suite: a traceback in the middle of a speed sweep)
    unraisable = sys.unraisablehook

    def unraisable_hook(args) -> None:
        where = getattr(args.object, "__module__", None) or type(args.object).__module__
        if str(where).split(".")[0] in _DASK_PACKAGES:
            if log is not None:
                warn_log.warning("exception ignored in %r: %s: %s", args.object,
                                 getattr(args.exc_type, "__name__", args.exc_type),
                                 args.exc_value)
            if not echo:
                return
        unraisable(args)

    sys.unraisablehook = unraisable_hook
    try:
        yield
    finally:
        sys.unraisablehook = unraisable
        warnings_mod.showwarning = shown
        warn_log.removeHandler(handler)
        for lg, handlers, propagate in saved:
            lg.removeHandler(handler)
            for h in handlers:
                if h not in lg.handlers:
                    lg.addHandler(h)
            lg.propagate = propagate
        handler.close()


def remove_checkpoint(folder: Path, prefix: str = TILE_PREFIX) -> bool:
    """Delete a job's checkpoint folder after its result was saved: its pieces
    (``<prefix>_*``, also rejected and temporary ones), ``spec.json`` and the lock file,
    then the folder if nothing else is in it. Returns whether the folder is gone (False:
    other files were left there)."""
    folder = Path(folder)
    if not folder.is_dir():
        return True
    for pattern in (f"{prefix}_*", f".{prefix}_*", SPEC_NAME, LOCK_NAME):
        for f in folder.glob(pattern):
            with contextlib.suppress(OSError):
                f.unlink()
    try:
        folder.rmdir()
    except OSError:
        return False
    return True


def _quiet_cluster(client: Any = None, cluster: Any = None) -> None:
    """After a Ctrl-C or an error: the logging of this process silenced, then that of the
    workers of our own local cluster, whose messages reach our terminal (through ``client``,
    or a client connected to ``cluster`` for the purpose), since the shutdown of stopped
    workers is expected, not news. This process first: connecting a client may log."""
    _quiet_logging()
    if client is None and cluster is None:
        return
    with contextlib.suppress(Exception):
        if client is not None:
            client.run(_quiet_logging)
        else:
            from dask.distributed import Client

            with Client(cluster) as own:
                own.run(_quiet_logging)


def _quiet_logging() -> None:
    """Silence Dask's shutdown chatter (cancelled tasks, heartbeats to a closing scheduler)
    after an interrupt: the shutdown is expected, not news."""
    prefixes = ("distributed", "tornado", "asyncio")
    names = [n for n in list(logging.root.manager.loggerDict) if n.startswith(prefixes)]
    for name in (*prefixes, *names):  # Dask's config gives some loggers their own levels
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _is_lost_connection(exc: BaseException) -> bool:
    """Whether a task's exception means the cluster went away (not an error in the task)."""
    from concurrent.futures import CancelledError

    name = type(exc).__name__
    return isinstance(exc, CancelledError | OSError | TimeoutError) or name in (
        "FutureCancelledError", "CommClosedError", "CancelledError")
