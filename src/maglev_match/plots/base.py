"""The figures' shared style and saving helper (the figure modules import these from here,
so that the package module, which dispatches to them, is not imported back)."""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np

# Files only, never a display: Agg, except inside a notebook whose inline backend shows
# the figures under the cells (the tutorials are stored with those figures).
if "inline" not in str(matplotlib.rcParams.get("backend", "")).lower():
    matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from maglev_match.core.io import atomic_write  # noqa: E402

STYLE = {
    "figure.figsize": (7.0, 4.5),
    "figure.dpi": 110,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "font.size": 10,
    "savefig.bbox": "tight",
}


#: the axes a ``.plot(ax=...)`` call draws into (None: a new figure)
_INTO: contextvars.ContextVar[Any] = contextvars.ContextVar("maglev_match_plot_into", default=None)


@contextlib.contextmanager
def drawing_into(ax: Any) -> Iterator[None]:
    """Within this block the next :func:`new_figure` returns ``ax`` (the user's axes: one
    ``Axes`` or a sequence/array of them) instead of making a figure."""
    token = _INTO.set(ax)
    try:
        yield
    finally:
        _INTO.reset(token)


def _given_axes(nrows: int, ncols: int, squeeze: bool = True) -> tuple[Any, Any]:
    given = _INTO.get()
    _INTO.set(None)  # only the figure's own first new_figure takes the axes
    flat = list(np.ravel(np.asarray(given, dtype=object)))
    n = nrows * ncols
    if len(flat) != n or not all(hasattr(a, "plot") and hasattr(a, "figure") for a in flat):
        got = f"{len(flat)} axes" if all(hasattr(a, "figure") for a in flat) else repr(given)
        raise ValueError(f"ax: {got} given; this figure has {n} panel(s) ({nrows} x {ncols}), "
                         f"so pass {'one matplotlib Axes' if n == 1 else f'{n} matplotlib Axes'}")
    if n == 1 and squeeze:
        return flat[0].figure, flat[0]
    axes = np.empty(n, dtype=object)
    axes[:] = flat
    if not squeeze or (nrows > 1 and ncols > 1):
        axes = axes.reshape(nrows, ncols)  # as plt.subplots(squeeze=False) or a 2-D grid
    return flat[0].figure, axes


def new_figure(nrows: int = 1, ncols: int = 1, **kw):
    """A figure in the package style: returns (fig, axes) as ``plt.subplots`` does; inside
    :func:`drawing_into` it returns the given axes and their figure instead."""
    if _INTO.get() is not None:
        return _given_axes(nrows, ncols, bool(kw.get("squeeze", True)))
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(nrows, ncols, **kw)
    return fig, ax


def save_figure(fig, path: str | Path, formats: tuple[str, ...] = ("png", "svg")) -> list[Path]:
    """Save ``fig`` as ``path`` with each suffix in ``formats`` (the suffix of ``path`` is
    replaced); returns the written paths and closes the figure."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    written = []
    with plt.rc_context(STYLE):
        for fmt in formats:
            target = path.with_suffix("." + fmt)
            atomic_write(target, lambda tmp, fmt=fmt: fig.savefig(tmp, format=fmt))
            written.append(target)
    plt.close(fig)
    return written


def param_unit(name: str) -> str:
    """The SI unit of a parameter, for axis labels ('' for a dimensionless one)."""
    from maglev_match.core.units import unit

    return unit(name)
