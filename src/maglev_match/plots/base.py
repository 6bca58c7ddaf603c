"""The figures' shared style and saving helper (the figure modules import these from here,
so that the package module, which dispatches to them, is not imported back)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

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


def new_figure(nrows: int = 1, ncols: int = 1, **kw):
    """A figure in the package style: returns (fig, axes)."""
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
