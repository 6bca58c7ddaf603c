"""BLAS thread limits without re-scanning the process's libraries at every call.

``threadpoolctl.threadpool_limits(n)`` looks up every loaded BLAS/OpenMP library each
time it is entered (about 2.7 ms; an index at a neighbouring design entered it twice, 5 %
of its time). :func:`blas_threads` keeps one ``ThreadpoolController`` and scans again only
when modules were imported since (a new extension may have brought its own BLAS); with
``None`` it changes nothing and scans nothing.
"""

from __future__ import annotations

import sys
from contextlib import AbstractContextManager, nullcontext
from typing import Any

__all__ = ["blas_threads"]

_CONTROLLER: tuple[int, Any] | None = None  # (len(sys.modules) when scanned, controller)


def _controller() -> Any:
    global _CONTROLLER
    n = len(sys.modules)
    if _CONTROLLER is None or _CONTROLLER[0] != n:
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = (len(sys.modules), ThreadpoolController())
    return _CONTROLLER[1]


def blas_threads(limit: int | None) -> AbstractContextManager:
    """A context in which the BLAS libraries use at most ``limit`` threads (None: as they
    are)."""
    if limit is None:
        return nullcontext()
    return _controller().limit(limits=limit)
