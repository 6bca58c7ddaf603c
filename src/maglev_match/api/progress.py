"""Progress of long API calls, for Python users: what the command line prints.

A map, a speed sweep, a design search or the vehicle's index can take minutes. The API
functions that take a ``stage=`` (a line of text when a stage starts) or a ``progress=``
(units done of a total) callback use these when given; when not given, and progress is
on, they report themselves: a line per stage on standard error (``maglev-match [ 12.3 s]
stage ...``) and a progress bar of the units (tqdm: a widget in a Jupyter notebook that
has ipywidgets, a text bar elsewhere).

Progress is on in a Jupyter notebook and in an interactive Python session, and off in
scripts (whose standard error may be a log). :func:`show_progress` turns it on or off for
the process; the environment variable ``MAGLEV_MATCH_PROGRESS`` (``1``/``0``) sets the
default; a callback passed to a call always wins, and ``stage=False`` /
``progress=False`` silence one call.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import os
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["show_progress", "progress_shown", "reporting", "reported"]

_SETTING: bool | None = None  # None: automatic


def show_progress(on: bool | None = True) -> None:
    """Turn the progress of long API calls on (True) or off (False) for this process, or
    back to automatic (None: on in a notebook or an interactive session, off in scripts,
    unless ``MAGLEV_MATCH_PROGRESS`` says otherwise)."""
    global _SETTING
    if on is not None and not isinstance(on, bool):
        from maglev_match.core.params import ParameterError

        raise ParameterError("on", on, "True, False or None")
    _SETTING = on


def _shell() -> Any:
    """The running IPython shell (a Jupyter kernel's or an IPython terminal's), or None.
    (A module merely imported, as ``ipykernel`` by a tool that starts kernels elsewhere,
    says nothing about this process.)"""
    ipy = sys.modules.get("IPython")
    if ipy is None:
        return None
    try:
        return ipy.get_ipython()
    except Exception:  # noqa: BLE001 - an IPython too old or half loaded: no shell
        return None


def _interactive() -> bool:
    if _shell() is not None:  # a Jupyter kernel or an IPython session
        return True
    return bool(getattr(sys, "ps1", None)) or bool(sys.flags.interactive)


def progress_shown() -> bool:
    """Whether API calls without callbacks report their progress (see the module)."""
    if _SETTING is not None:
        return _SETTING
    env = os.environ.get("MAGLEV_MATCH_PROGRESS", "").strip().lower()
    if env in ("0", "false", "no", "off"):
        return False
    if env in ("1", "true", "yes", "on"):
        return True
    return _interactive()


class _Reporter:
    """Stage lines on standard error and a progress bar of the units."""

    def __init__(self, what: str, stream: Any = None) -> None:
        self.what = what
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = time.perf_counter()
        self.bar: Any = None

    def stage(self, text: str) -> None:
        if self.bar is not None:
            self.bar.write(self._line(text), file=self.stream)
        else:
            print(self._line(text), file=self.stream, flush=True)

    def _line(self, text: str) -> str:
        return f"maglev-match [{time.perf_counter() - self.t0:7.1f} s] {text}"

    def units(self, done: int, total: int) -> None:
        if self.bar is None:
            self.bar = _bar(total, self.what, self.stream)
        if self.bar.total != total:
            self.bar.total = total
        self.bar.n = done
        self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _bar(total: int, what: str, stream: Any) -> Any:
    from tqdm import std

    bar_cls = std.tqdm
    if type(_shell()).__name__ == "ZMQInteractiveShell":  # a Jupyter kernel
        try:  # a widget when the notebook can show one
            import ipywidgets  # noqa: F401
            from tqdm import notebook

            bar_cls = notebook.tqdm
        except ImportError:
            pass
    return bar_cls(total=total, desc=f"maglev-match {what}", unit=" units", file=stream,
                   leave=True, dynamic_ncols=True)


@contextlib.contextmanager
def reporting(what: str, stage: Callable[[str], None] | bool | None = None,
              progress: Callable[[int, int], None] | bool | None = None,
              stream: Any = None,
              ) -> Iterator[tuple[Callable[[str], None] | None,
                                  Callable[[int, int], None] | None]]:
    """The ``(stage, progress)`` callbacks an API call of ``what`` passes on: the caller's
    own where given, none where ``False``, else (when :func:`progress_shown`) lines on
    standard error and a progress bar, closed when the block ends."""
    own = progress_shown() and (stage is None or progress is None)
    rep = _Reporter(what, stream) if own else None
    s = stage if callable(stage) else (rep.stage if rep is not None and stage is None else None)
    p = progress if callable(progress) else (
        rep.units if rep is not None and progress is None else None)
    try:
        yield s, p
    finally:
        if rep is not None:
            rep.close()


def reported(what: str, units: bool = True) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorate an API function that takes ``stage=`` (and, with ``units``, a
    ``progress=(done, total)`` callback): called without them while progress is shown, it
    reports itself (:func:`reporting`); ``False`` silences one of them."""
    def decorate(fn: Callable[..., Any]) -> Callable[..., Any]:
        names = inspect.signature(fn).parameters
        assert "stage" in names and (not units or "progress" in names), fn

        @functools.wraps(fn)
        def call(*args: Any, **kw: Any) -> Any:
            given = kw.pop("progress", None) if units else False
            with reporting(what, kw.pop("stage", None), given) as (say, count):
                kw["stage"] = say
                if units:
                    kw["progress"] = count
                return fn(*args, **kw)
        return call
    return decorate
