"""Paper Fig. 5-style bifurcation diagram: max/min gap deviation of equilibrium and cycles
against one parameter (stable solid, unstable dashed), Hopf, fold and limit-touch points."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from maglev_match.dynamics.cycles import CycleBranch
from maglev_match.plots import new_figure

__all__ = ["cycle_diagram"]

_UNITS = {"omega1": "rad/s", "sigma": "1/kg"}
_MARK = {"LPC": ("^", "tab:purple"), "PD": ("s", "tab:brown"), "NS": ("D", "tab:olive"),
         "LIMIT": ("X", "tab:red")}


def _segments(x: np.ndarray, y: np.ndarray, flag: np.ndarray):
    """Split a curve into runs of equal flag (consecutive runs share an end point)."""
    start = 0
    for k in range(1, len(x) + 1):
        if k == len(x) or flag[k] != flag[start]:
            end = min(k + 1, len(x))
            yield x[start:end], y[start:end], bool(flag[start])
            start = k


def cycle_diagram(
    branches: Sequence[CycleBranch],
    param: str,
    equilibrium_values: np.ndarray | None = None,
    equilibrium_stable: np.ndarray | None = None,
    observable: str = "gap_deviation",
    scale: float = 1e3,
    unit: str = "mm",
    title: str = "",
    limits: tuple[float, float] | None = None,
):
    """Max and min of ``observable`` (times ``scale``, in ``unit``) over each cycle against
    ``param``; the equilibrium (observable 0) solid where stable, dashed where unstable;
    Hopf points (circles), LPC/PD/NS and LIMIT points marked. ``limits`` draws the physical
    range of the observable as dotted lines. Returns (fig, ax)."""
    fig, ax = new_figure()
    if equilibrium_values is not None and equilibrium_stable is not None:
        xs = np.asarray(equilibrium_values)
        st = np.asarray(equilibrium_stable, bool)
        for sx, sy, s in _segments(xs, np.zeros_like(xs), st):
            ax.plot(sx, sy, color="k", ls="-" if s else "--", lw=1.5)
    labelled = set()
    for b, br in enumerate(branches):
        if not br.points:
            continue
        v = br.values
        st = br.stable
        color = f"C{b}"
        for y in (br.observable_max(observable), br.observable_min(observable)):
            for sx, sy, s in _segments(v, y * scale, st):
                lab = None
                key = ("stable" if s else "unstable") + " cycle"
                if key not in labelled:
                    lab, _ = key, labelled.add(key)
                ax.plot(sx, sy, color=color, ls="-" if s else "--", lw=1.5, label=lab)
        lab = None if "Hopf" in labelled else "Hopf point"
        labelled.add("Hopf")
        ax.plot([br.hopf.value], [0.0], "o", color="tab:blue", ms=7, mfc="white", mew=2,
                label=lab)
        n_limit = 0
        for sp in br.special_points:
            mk, col = _MARK.get(sp.type, ("*", "k"))
            lab = None if sp.type in labelled else sp.type
            labelled.add(sp.type)
            ymax, ymin = sp.extrema[observable]
            ax.plot([sp.value, sp.value], [ymax * scale, ymin * scale], mk, color=col, ms=8,
                    label=lab)
            if sp.type == "LIMIT":
                n_limit += 1
                ax.annotate(f"b{b + 1}" if n_limit == 1 else f"b{b + 1}.{n_limit}",
                            (sp.value, ymax * scale), textcoords="offset points",
                            xytext=(5, 5), color=col)
    if limits is not None:
        for yl in limits:
            ax.axhline(yl * scale, color="grey", ls=":", lw=1)
    ax.set_xlabel(f"{param} ({_UNITS.get(param, 'SI')})")
    ax.set_ylabel(f"{observable.replace('_', ' ')} max/min ({unit})")
    if title:
        ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    return fig, ax
