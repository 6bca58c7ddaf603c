"""The benchmarks' timing helpers (one definition): CPU time of this process, a call timed
once (wall and CPU), and the median of repeated calls. Ratios are always taken against a
baseline timed the same way in the same process.

Imported by the bench scripts as ``from _timing import ...`` (each script puts bench/ on
``sys.path``; run as ``python bench/bench_NAME.py`` it is there already)."""

from __future__ import annotations

import os
import resource
import statistics
import time
from collections.abc import Callable
from typing import Any


def cpu() -> float:
    """User + system CPU time of this process (s)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def timed_once(fn: Callable[[], Any]) -> tuple[Any, float, float]:
    """(result, CPU s, wall s) of one call."""
    c0, w0 = cpu(), time.perf_counter()
    out = fn()
    return out, cpu() - c0, time.perf_counter() - w0


def timed(fn: Callable[[], Any], repeat: int) -> tuple[float, float, Any]:
    """(median wall s, median CPU s, last result) of ``repeat`` calls."""
    walls, cpus, out = [], [], None
    for _ in range(repeat):
        out, c, w = timed_once(fn)
        walls.append(w)
        cpus.append(c)
    return statistics.median(walls), statistics.median(cpus), out


def load() -> str:
    """The machine's load averages (1, 5, 15 min) as text."""
    return " ".join(f"{v:.2f}" for v in os.getloadavg())
