"""A part of a computation run beside the rest of it, in a second thread.

The headline index has two parts that do not need each other: the paper's part (the
equilibrium, the Hopf point, the cycle branch: mostly Python driving small kernels) and the
simulated part (the critical disturbance of both directions: mostly long compiled runs).
XLA and LAPACK release the interpreter lock while they compute, so on a machine with two
free cores the two parts overlap almost fully: a whole ``maglev-match index`` process took
4.44 s wall one after the other and 3.31 s beside each other (medians of 5, interleaved,
the 2-core VM, 2026-12-05), and the answer is the same to the last bit (each part computes
exactly what it computed before, in its own thread).

:class:`Beside` starts ``fn(*args)`` in a thread at once. :meth:`Beside.result` waits for
it and returns its value or raises its exception. :meth:`Beside.stop` asks it to stop and
waits until it has: the work checks :func:`stop_point` before each compiled kernel it
starts (the simulation kernel, the flow with sensitivities), so it stops within one kernel
call, and the caller re-raises its own exception (a Ctrl-C, an error of the other part)
only once no thread of this package computes any more.

Standard library only.
"""

from __future__ import annotations

import contextvars
import os
import threading
from collections.abc import Callable
from typing import Any

__all__ = ["Beside", "Stopped", "stop_point", "two_cores"]

_STOP: contextvars.ContextVar[threading.Event | None] = contextvars.ContextVar(
    "maglev_match_beside_stop", default=None)


class Stopped(Exception):
    """The work of a :class:`Beside` was asked to stop (raised inside its thread only)."""


def stop_point() -> None:
    """Raise :class:`Stopped` if the :class:`Beside` this code runs in was asked to stop;
    nothing elsewhere. Called before each compiled kernel a long part starts."""
    ev = _STOP.get()
    if ev is not None and ev.is_set():
        raise Stopped()


def two_cores() -> bool:
    """True where this process may use two cores or more (a process pinned to one core,
    ``MAGLEV_MATCH_THREADS=1``, may not)."""
    try:
        return len(os.sched_getaffinity(0)) > 1
    except (AttributeError, OSError):  # no affinity on this platform
        return (os.cpu_count() or 1) > 1


class Beside:
    """``fn(*args)``, started now in a thread of its own (see the module docstring)."""

    def __init__(self, fn: Callable[..., Any], *args: Any) -> None:
        self._stop = threading.Event()
        self._value: Any = None
        self._error: BaseException | None = None

        def run() -> None:
            _STOP.set(self._stop)
            try:
                self._value = fn(*args)
            except BaseException as exc:  # noqa: BLE001 - handed to the caller by result()
                self._error = exc

        self._thread = threading.Thread(
            target=contextvars.copy_context().run, args=(run,),
            name="maglev-match-beside", daemon=True)
        self._thread.start()

    def result(self) -> Any:
        """The value of ``fn(*args)`` once it has finished (its exception raised here)."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value

    def stop(self) -> None:
        """Ask the work to stop at its next kernel call and wait until it has."""
        self._stop.set()
        self._thread.join()
