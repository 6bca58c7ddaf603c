"""What a restarted branch adds to its figure: the saved part of the branch it continues
and the point it continued from, so that the new piece is never shown alone under a label
that says it began at a Hopf point."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.lines import Line2D

__all__ = ["draw_saved_part", "mark_restart_point"]

SAVED_COLOUR = "0.55"


def draw_saved_part(ax, values: np.ndarray, ymax: np.ndarray, ymin: np.ndarray,
                    stable: np.ndarray, restart_value: float,
                    restart_y: Sequence[float], *, label: str, source: str,
                    new_branch_text: str | None = None, scale: float = 1.0) -> None:
    """Draw a saved branch (grey, stable solid / unstable dashed, max and min) and the
    restart point (a star at its max and min) on ``ax``, and rebuild the legend with both.

    Parameters
    ----------
    values, ymax, ymin, stable : the saved points (parameter, observable max/min, stability);
        NaN values are skipped.
    restart_value, restart_y : the restart point's parameter and its observable (max, min).
    label, source : the restart label and file, named in the legend.
    new_branch_text : the legend text of the new piece (replaces the text of the first
        branch entry, which would say it starts at a Hopf point).
    scale : factor applied to ymax/ymin/restart_y (e.g. 1e3 for mm).
    """
    values = np.asarray(values, float)
    ok = np.isfinite(values) & np.isfinite(ymax) & np.isfinite(ymin)
    v, hi, lo = values[ok], np.asarray(ymax, float)[ok], np.asarray(ymin, float)[ok]
    st = np.asarray(stable, bool)[ok]
    for y in (hi, lo):
        start = 0
        for k in range(1, len(v) + 1):
            if k == len(v) or st[k] != st[start]:
                end = min(k + 1, len(v))
                ax.plot(v[start:end], y[start:end] * scale, color=SAVED_COLOUR,
                        ls="-" if st[start] else "--", lw=1.3, zorder=2)
                start = k
    ax.plot([restart_value] * 2, np.asarray(restart_y, float) * scale, "*", color="k",
            ms=11, ls="none", zorder=7)
    legend = ax.get_legend()
    handles = list(legend.legend_handles) if legend is not None else []
    texts = [t.get_text() for t in legend.get_texts()] if legend is not None else []
    for h, t in zip(handles, texts, strict=False):
        h.set_label(t)
    if new_branch_text is not None:
        for h, t in zip(handles, texts, strict=False):
            if t.startswith("b1:"):
                h.set_label(new_branch_text)
                break
    if len(v):
        handles.insert(0, Line2D([], [], color=SAVED_COLOUR, lw=3,
                                 label=f"saved branch ({source})"))
    handles.insert(1 if len(v) else 0,
                   Line2D([], [], marker="*", color="k", ms=11, ls="none",
                          label=f"restart point {label}"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              frameon=False)


def mark_restart_point(ax, x: float, y: float, *, label: str, source: str) -> None:
    """Mark the point a restarted curve was continued from (a star) and add it to the
    legend (kept where the figure placed it)."""
    ax.plot([x], [y], "*", color="k", ms=13, ls="none", zorder=8,
            label=f"restart point {label} ({source})")
    legend = ax.get_legend()
    loc = legend._loc if legend is not None else "best"  # noqa: SLF001  (keep its place)
    ax.legend(loc=loc, fontsize=8, framealpha=0.85)
