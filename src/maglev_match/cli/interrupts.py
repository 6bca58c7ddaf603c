"""Ctrl-C ends the command within seconds, whatever the process is doing.

Python raises :class:`KeyboardInterrupt` only in the main thread and only between two
bytecodes. That is prompt while the program runs Python code, but not always:

* the Python-level signal handler itself waits while the main thread sits inside a long C
  call that does not look for signals;
* the exit of a process whose main thread was interrupted while XLA compiled a kernel waits
  for that compilation to finish (measured: the interrupt is raised within 0.1 s, the
  process ends only when the compile is done; a cold cache on a busy machine makes that a
  minute or more);
* an interrupt that arrives while Python runs a garbage-collection callback (JAX registers
  one) is printed as "Exception ignored" and swallowed, and the work goes on;
* the shutdown of a local Dask cluster waits for its workers to finish their task.

So the guard listens for the signal twice. The Python handler raises
:class:`KeyboardInterrupt` as usual: the normal path stops the job, keeps what is finished
and prints how to resume. A watcher thread learns of the signal at once, from the byte the
C-level handler writes to a pipe (:func:`signal.set_wakeup_fd`), whatever the main thread is
doing (a compile releases the GIL, so the watcher runs while it goes on). If the process is
still alive :data:`GRACE_S` seconds after the signal, the watcher prints the running job's
stop note (:func:`maglev_match.core.interrupts.stop_note`: the pieces kept and the ``--resume``
hint), ends the worker processes this process started and ends the process with exit code
130 (:func:`os._exit`: no interpreter teardown that could wait for a compile or crash in the
middle of one). Finished pieces are on disk already (written atomically, each as it
finished), so nothing that was done is lost; a piece half-written at that moment is a
temporary file that the next run ignores. A second Ctrl-C ends the process at once.

Exactly one "stopped: ..." line is printed, by whichever path gets there first.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable

__all__ = ["GRACE_S", "install", "finish"]

#: Seconds the normal path gets to stop (0.1 s in this process, about 4 s to shut down a
#: local Dask cluster, measured 2026-12-03) before the watchdog ends the process.
GRACE_S = 8.0

_say: Callable[[str], None] | None = None
_finishing = threading.Lock()
_state = threading.Lock()
_interrupted_at: float | None = None
_watching = False


def _kill_children() -> None:
    """End the worker processes this process started (a local Dask cluster's nannies and
    workers): they compute pieces whose results nobody will collect."""
    try:
        import psutil
    except ImportError:  # pragma: no cover - psutil comes with dask.distributed
        return
    with contextlib.suppress(Exception):
        children = psutil.Process().children(recursive=True)
        for child in children:
            with contextlib.suppress(Exception):
                child.kill()


def finish(text: str | None = None, code: int = 130) -> None:
    """Print the one 'stopped: ...' line (``text``, default the running job's stop note),
    end the worker processes and end this process with ``code``. Whoever calls this second
    waits for the first to end the process."""
    from maglev_match.core.interrupts import stop_note

    if not _finishing.acquire(blocking=False):
        time.sleep(GRACE_S)  # the other path is printing and exiting; a last resort below
        os._exit(code)
    with contextlib.suppress(Exception):
        line = stop_note() if text is None else text
        if _say is not None:
            _say(line)
        else:
            sys.stderr.write(f"stopped: {line}\n")
    with contextlib.suppress(Exception):
        sys.stdout.flush()
        sys.stderr.flush()
    _kill_children()
    os._exit(code)


def _interrupted() -> None:
    """Called at every SIGINT (from the watcher thread, or from the Python handler when no
    watcher runs): the first arms the watchdog, a second ends the process now."""
    global _interrupted_at
    with _state:
        first = _interrupted_at is None
        if first:
            _interrupted_at = time.monotonic()
    if first:
        threading.Thread(target=_watchdog, name="maglev-match-interrupt-watchdog",
                         daemon=True).start()
    else:
        threading.Thread(target=finish, name="maglev-match-stop", daemon=True).start()


def _watchdog() -> None:
    time.sleep(GRACE_S)
    finish()


def _watch(fd: int) -> None:
    """Read the signal numbers the C-level handler writes to the wake-up pipe: SIGINT is
    seen here at once even while the main thread cannot run Python code."""
    while True:
        try:
            data = os.read(fd, 64)
        except InterruptedError:  # pragma: no cover - PEP 475 retries for us
            continue
        except OSError:
            return
        if not data:
            return
        for _ in range(data.count(bytes([signal.SIGINT]))):
            _interrupted()


def _on_sigint(signum, frame) -> None:
    if not _watching:  # no wake-up pipe (taken by someone else): arm the watchdog here
        _interrupted()
    raise KeyboardInterrupt


def _unraisable(hook):
    """An interrupt swallowed inside a callback (a garbage-collection callback, a
    finaliser) is not news: the watchdog ends the process. Everything else as before."""

    def unraisable(info) -> None:
        if isinstance(info.exc_value, KeyboardInterrupt):
            return
        hook(info)

    return unraisable


def install(say: Callable[[str], None]) -> None:
    """Install the guard in this (main) thread: ``say(text)`` prints the stopped line."""
    global _say, _watching
    _say = say
    try:
        signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:  # not the main thread (an embedding program): leave signals alone
        return
    sys.unraisablehook = _unraisable(sys.unraisablehook)
    try:
        r, w = os.pipe()
        os.set_blocking(w, False)
        signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    except (OSError, ValueError):  # pragma: no cover - then the Python handler arms it
        return
    _watching = True
    threading.Thread(target=_watch, args=(r,), name="maglev-match-interrupt-watcher",
                     daemon=True).start()
