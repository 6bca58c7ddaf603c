"""What a long job says when it is interrupted.

A job that keeps finished work on disk (the tiles of a map, the chunks of a Monte Carlo
study, the speeds of a sweep) knows how to continue it; whoever stops the process on a
Ctrl-C (the command line's interrupt guard, :mod:`maglev_match.cli.interrupts`) does not. So
while such a job runs it registers a *stop note*: a function returning the sentence to print,
with the work that is kept and how to resume ("interrupted: 3 of 200 tiles are saved in
m.nc.tiles; run the same command with --resume to continue"). The note is read at the moment
of the interrupt, so it counts the pieces finished by then.

Standard library only: the command line imports this before anything heavy.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator

__all__ = ["on_interrupt", "stop_note"]

_lock = threading.Lock()
_notes: list[Callable[[], str]] = []


@contextlib.contextmanager
def on_interrupt(note: Callable[[], str]) -> Iterator[None]:
    """Within the ``with`` block, ``note()`` is what an interrupt of this process says
    (the innermost block wins)."""
    with _lock:
        _notes.append(note)
    try:
        yield
    finally:
        with _lock:
            _notes.remove(note)


def stop_note(default: str = "interrupted") -> str:
    """The sentence of the innermost running job, or ``default`` when none runs (or its
    note fails: an interrupt must never raise here)."""
    with _lock:
        note = _notes[-1] if _notes else None
    if note is None:
        return default
    try:
        return str(note())
    except Exception:  # noqa: BLE001 - the process is stopping; say the plain thing
        return default
