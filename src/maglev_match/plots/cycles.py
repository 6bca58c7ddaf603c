"""Paper Fig. 5-style bifurcation diagram: max/min gap deviation of equilibrium and cycles
against one parameter (stable solid, unstable dashed), Hopf, fold and limit-touch points.

Branches are labelled ``b1``, ``b2``, ... in the order given; :func:`branch_label` is the
one place that label is made, and the command line writes the same label into its CSV and
JSON files.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.lines import Line2D

from maglev_match.api.cycles import CycleStudy, restart_point_extrema, saved_part
from maglev_match.core.results import figure, figure_of_many
from maglev_match.dynamics.cycles import CycleBranch
from maglev_match.plots.base import new_figure

__all__ = ["cycle_diagram", "branch_label"]

_UNITS = {"omega1": "rad/s", "sigma": "1/kg"}
_MARK = {"LPC": ("^", "tab:purple", "fold of cycles (LPC)"),
         "PD": ("s", "tab:brown", "period doubling (PD)"),
         "NS": ("D", "tab:olive", "torus bifurcation (NS)"),
         "contact": ("X", "tab:red", "cycle touches a physical limit")}  # named beside the mark
_BRANCH_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown",
                   "tab:pink")


def limit_touched(detail: str) -> str:
    """Which extremum of the gap a limit contact concerns: 'low' (gap 0: the cycle's
    minimum), 'high' (the upper gap limit: its maximum) or 'other' (e.g. the coil current
    reaching 0, marked at both gap extrema of that cycle)."""
    from maglev_match.maglev.limits import GAP_HIGH, GAP_LOW

    if detail == GAP_LOW:
        return "low"
    if detail == GAP_HIGH or detail.startswith("gap") and detail != GAP_LOW:
        return "high"
    return "other"


def branch_label(k: int) -> str:
    """The label of the k-th branch (0-based) in figures, CSV and JSON: 'b1', 'b2', ..."""
    return f"b{k + 1}"


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
    design_value: float | None = None,
):
    """Max and min of ``observable`` over each cycle against ``param``.

    Parameters
    ----------
    branches : cycle branches, labelled b1, b2, ... in this order and drawn in their own
        colours; along each, stable cycles solid and unstable cycles dashed.
    param : the continuation parameter.
    equilibrium_values, equilibrium_stable : the equilibrium (observable 0) along
        ``param``, drawn black, solid where stable and dashed where unstable.
    observable, scale, unit : what to plot (times ``scale``, in ``unit``).
    title : figure title.
    limits : the physical range of the observable (SI), drawn as dotted lines.
    design_value : the design value of ``param``, drawn as a vertical line.

    Hopf points are open circles; folds (LPC), period doublings (PD), torus points (NS) and
    first contacts with a physical limit (contact) are marked at the cycle's max and min.
    The legend lists every element drawn. Returns (fig, ax).
    """
    fig, ax = new_figure(figsize=(8.0, 5.0))
    handles: list = []
    if equilibrium_values is not None and equilibrium_stable is not None:
        xs = np.asarray(equilibrium_values)
        st = np.asarray(equilibrium_stable, bool)
        for sx, sy, s in _segments(xs, np.zeros_like(xs), st):
            ax.plot(sx, sy, color="k", ls="-" if s else "--", lw=1.5)
        if st.any():
            handles.append(Line2D([], [], color="k", ls="-", lw=1.5,
                                  label="equilibrium, stable"))
        if (~st).any():
            handles.append(Line2D([], [], color="k", ls="--", lw=1.5,
                                  label="equilibrium, unstable"))
    styles_seen: set[bool] = set()
    types_seen: list[str] = []
    for b, br in enumerate(branches):
        if not br.points:
            continue
        v = br.values
        st = br.stable
        colour = _BRANCH_COLOURS[b % len(_BRANCH_COLOURS)]
        for y in (br.observable_max(observable), br.observable_min(observable)):
            for sx, sy, s in _segments(v, y * scale, st):
                ax.plot(sx, sy, color=colour, ls="-" if s else "--", lw=1.5)
                styles_seen.add(s)
        handles.append(Line2D([], [], color=colour, lw=3,
                              label=f"{branch_label(b)}: cycles from the Hopf point at "
                                    f"{param} = {br.hopf.value:.5g}"))
        ax.plot([br.hopf.value], [0.0], "o", color=colour, ms=7, mfc="white", mew=2,
                zorder=5)
        ymax_end = br.observable_max(observable)[-1] * scale
        ax.annotate(branch_label(b), (v[-1], ymax_end), textcoords="offset points",
                    xytext=(4, 4), color=colour, fontsize=9, fontweight="bold")
        for sp in br.special_points:
            mk, col, _ = _MARK.get(sp.type, ("*", "k", sp.type))
            if sp.type not in types_seen:
                types_seen.append(sp.type)
            ymax, ymin = sp.extrema[observable]
            if sp.type == "contact":  # mark where the cycle touches, and name the limit
                which = limit_touched(sp.detail)
                ys = ([ymin] if which == "low" else [ymax] if which == "high"
                      else [ymax, ymin])
                ax.plot([sp.value] * len(ys), [y * scale for y in ys], mk, color=col, ms=8,
                        ls="none", zorder=6)
                ax.annotate(f"touches: {sp.detail}" if sp.detail else "touches a limit",
                            (sp.value, ys[0] * scale), textcoords="offset points",
                            xytext=(-8, -12 if which == "low" else 6), ha="right",
                            fontsize=8, color=col)
                continue
            ax.plot([sp.value, sp.value], [ymax * scale, ymin * scale], mk, color=col, ms=8,
                    ls="none", zorder=6)
    for s in (True, False):
        if s in styles_seen:
            handles.append(Line2D([], [], color="0.35", ls="-" if s else "--", lw=1.5,
                                  label="stable cycle (max/min)" if s
                                  else "unstable cycle (max/min)"))
    if any(br.points for br in branches):
        handles.append(Line2D([], [], marker="o", color="0.35", ms=7, mfc="white", mew=2,
                              ls="none", label="Hopf point"))
    for t in types_seen:
        mk, col, text = _MARK.get(t, ("*", "k", t))
        handles.append(Line2D([], [], marker=mk, color=col, ms=8, ls="none", label=text))
    if limits is not None:
        for yl in limits:
            ax.axhline(yl * scale, color="grey", ls=":", lw=1.2)
        handles.append(Line2D([], [], color="grey", ls=":", lw=1.2,
                              label=f"physical limits ({limits[0] * scale:.3g} and "
                                    f"{limits[1] * scale:.3g} {unit})"))
    if design_value is not None:
        ax.axvline(design_value, color="k", ls="-.", lw=1.0)
        handles.append(Line2D([], [], color="k", ls="-.", lw=1.0,
                              label=f"design point {param} = {design_value:.5g}"))
    ax.set_xlabel(f"{param} ({_UNITS.get(param, 'SI')})")
    ax.set_ylabel(f"{observable.replace('_', ' ')} max/min ({unit})")
    if title:
        ax.set_title(title)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              frameon=False)
    return fig, ax


@figure.register(CycleBranch)
def _cycle_branch(branch: CycleBranch, **kw):
    return _cycle_branches(branch, [branch], **kw)


@figure_of_many.register(CycleBranch)
def _cycle_branches(first: CycleBranch, branches, **kw):
    return cycle_diagram(list(branches), first.param, **kw)[0]


@figure.register(CycleStudy)
def _cycle_study(st: CycleStudy, **kw):
    """The command's figure: the branches' max/min gap deviation (a user model: its first
    observable) with the equilibrium's stability along the searched range, the gap limits,
    the design value and, for a restart, the saved part of the branch and the restart
    point."""
    import numpy as np

    at_text = ", ".join(f"{k}={v:g}" for k, v in st.at.items())
    params = st.params
    if st.restart is None:
        scan = st.scan
        vals = [float(np.min(b.values)) for b in st.branches if b.points]
        lo = min([scan.scan_values[0]] + vals)
        hi = max([scan.scan_values[-1]] + [float(np.max(b.values)) for b in st.branches
                                           if b.points])
        sel = (scan.scan_values >= lo) & (scan.scan_values <= hi)
        kw.setdefault("title", f"Cycles along {st.param}" + (f" ({at_text})" if at_text
                                                              else ""))
        if params is not None:
            kw.setdefault("limits", (params.gap_min - params.c0, params.gap_max - params.c0))
            kw.setdefault("design_value", getattr(params, st.param, None))
        fig, _ = cycle_diagram(st.branches, st.param, scan.scan_values[sel],
                               scan.max_real_part[sel] < 0, **kw)
        return fig
    from pathlib import Path

    from maglev_match.plots.restart import draw_saved_part

    rs = st.restart
    kw.setdefault("title", f"Cycles along {st.param}, restarted from {rs.label}"
                  + (f" ({at_text})" if at_text else ""))
    if params is not None:
        kw.setdefault("limits", (params.gap_min - params.c0, params.gap_max - params.c0))
        kw.setdefault("design_value", getattr(params, st.param, None))
    fig, ax = cycle_diagram(st.branches, st.param, **kw)
    observable = "gap_deviation"
    if st.param == rs.param:
        vals, hi, lo, stable = saved_part(rs, st.system, observable)
        rv = rs.value
    else:  # the saved branch lies along another parameter: only the restart point
        vals = hi = lo = np.zeros(0)
        stable = np.zeros(0, bool)
        rv = float(rs.p[list(rs.parameter_names).index(st.param)])
    draw_saved_part(ax, vals, hi, lo, stable, rv, restart_point_extrema(rs, st.system, observable),
                    label=rs.label, source=Path(rs.path).name, scale=1e3,
                    new_branch_text=f"b1: continued from {rs.label} of {Path(rs.path).name}")
    return fig
