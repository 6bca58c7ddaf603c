"""The figure of a curve of cycle bifurcations: the curve in its parameter plane (p1
across, p2 up), its start and end, the codimension-two points, and the period along it."""

from __future__ import annotations

import numpy as np

from maglev_match.api.cycle_curves import CycleCurveStudy
from maglev_match.core.results import figure
from maglev_match.dynamics.cycle_curves import CycleCurve
from maglev_match.plots.base import new_figure

__all__ = ["cycle_curve_figure"]

_MARK = {"CPC": ("v", "tab:red"), "LPPD": ("s", "tab:brown"), "LPNS": ("D", "tab:olive"),
         "PDNS": ("D", "tab:olive")}


def cycle_curve_figure(curve: CycleCurve, title: str | None = None, ax=None, **_):
    """The curve in (p1, p2) with its special points (left) and its period against p2
    (right); with ``ax`` the curve alone is drawn on that axis (e.g. a Hopf curve's)."""
    a, b = curve.params
    if ax is None:
        fig, (ax, ax2) = new_figure(1, 2, figsize=(11, 4.5))
    else:
        fig, ax2 = ax.figure, None
    ok = curve.stopped_reason != "the start could not be corrected onto the curve"
    ax.plot(curve.p1, curve.p2, "-", color="tab:purple", lw=1.6, label=f"{curve.kind} curve")
    if curve.points:
        k = [i for i, c in enumerate(curve.points) if c.kind == "start"] or [0]
        ax.plot(curve.p1[k], curve.p2[k], "o", color="k", ms=5, label="start")
        ends = [0, len(curve.points) - 1] if k[0] > 0 else [len(curve.points) - 1]
        ax.plot(curve.p1[ends], curve.p2[ends], "x", color="k", ms=6,
                label=f"end: {curve.stopped_reason}")
        marks = [i for i, c in enumerate(curve.points) if c.kind == "mark"]
        if marks:
            ax.plot(curve.p1[marks], curve.p2[marks], "+", color="tab:blue", ms=8,
                    label=f"solved at the given {b}")
    for sp in curve.special_points:
        m, c = _MARK.get(sp.type, ("*", "k"))
        ax.plot([sp.values[0]], [sp.values[1]], m, color=c, ms=7, label=sp.label)
    ax.set_xlabel(a)
    ax.set_ylabel(b)
    if not ok or curve.warnings:
        ax.text(0.01, 0.01, "\n".join(curve.warnings)[:300], transform=ax.transAxes,
                fontsize=7, color="tab:red", va="bottom")
    ax.legend(fontsize=8, frameon=False)
    if ax2 is not None:
        ax2.plot(curve.p2, curve.periods, "-", color="tab:purple")
        ax2.set_xlabel(b)
        ax2.set_ylabel("period (s)")
        if curve.points:
            ax2.set_ylim(auto=True)
            ax2.margins(y=0.1 if np.ptp(curve.periods) > 0 else 0.5)
    fig.suptitle(title or f"{curve.kind} curve of cycles in ({a}, {b})")
    return fig


@figure.register(CycleCurve)
def _cycle_curve(curve: CycleCurve, **kw):
    return cycle_curve_figure(curve, **kw)


@figure.register(CycleCurveStudy)
def _cycle_curve_study(st: CycleCurveStudy, **kw):
    at = ", ".join(f"{k}={v:g}" for k, v in st.at.items())
    start = st.restart_of or st.start_label
    kw.setdefault("title", f"{st.kind} curve of cycles in ({st.x}, {st.y}), model "
                  f"{st.model}, from {start}" + (f" ({at})" if at else ""))
    return cycle_curve_figure(st.curve, **kw)
