"""Hopf-curve figure in the style of the paper's Fig. 4: the plane of two parameters with
the stable region S and the unstable region U shaded, the Hopf curve drawn solid where the
bifurcation is subcritical (l1 > 0) and dashed where it is supercritical (l1 < 0), and the
codimension-two points marked and labelled."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.colors import ListedColormap
from scipy import ndimage

from maglev_match.api.hopf import HopfCurveStudy
from maglev_match.core.results import figure, figure_of_many
from maglev_match.dynamics.hopf import HopfScan
from maglev_match.dynamics.hopf_curve import HopfCurve
from maglev_match.plots.base import new_figure

_LINESTYLE = {"subcritical": "-", "supercritical": "--"}
_COLOR = {"subcritical": "C3", "supercritical": "C0"}
_MARKER = {"GH": "o", "BT": "s", "ZH": "D", "HH": "^"}


def _segments(curve: HopfCurve):
    """Runs of consecutive points with the same (criticality, others_stable)."""
    vals = curve.values()
    l1 = curve.l1()
    stable_others = np.array([pt.others_stable for pt in curve.points])
    kind = np.where(l1 > 0, "subcritical", "supercritical")
    key = list(zip(kind, stable_others, strict=True))
    start = 0
    for j in range(1, len(key) + 1):
        if j == len(key) or key[j] != key[start]:
            # include the next point so that the runs join
            stop = min(j + 1, len(key))
            yield key[start][0], bool(key[start][1]), vals[start:stop]
            start = j


def hopf_curve_figure(
    curves: Sequence[HopfCurve],
    params: tuple[str, str],
    units: tuple[str, str] = ("", ""),
    grid: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    title: str = "",
    design_point: tuple[float, float] | None = None,
):
    """Figure of Hopf curves in the (params[0], params[1]) plane.

    Parameters
    ----------
    curves : branches of the Hopf curve (from :func:`~maglev_match.dynamics.hopf_curve.hopf_curve`).
    params : the parameter names (x axis, y axis).
    units : their units for the axis labels.
    grid : optional (values1, values2, max_real_part[len(values2), len(values1)]) of the
        largest real part of the eigenvalues (1/s), used to shade S (< 0) and U (> 0).
    title : the figure title (default: what the shading means).
    design_point : optional (value of params[0], value of params[1]) of the design,
        marked with a star.

    The lower panel shows the first Lyapunov coefficient l1 along each branch against
    params[0] (symmetric-log scale: l1 spans decades), with l1 = 0 and the generalised Hopf
    points (GH, where l1 changes sign) marked.

    Returns the figure.
    """
    fig, (ax, ax_l1) = new_figure(2, 1, figsize=(7.5, 7.6), sharex=True,
                                  gridspec_kw={"height_ratios": [3.0, 1.35]})
    _l1_panel(ax_l1, curves, params, units)
    if grid is not None:
        v1, v2, mr = grid
        region = np.where(np.isfinite(mr), (mr > 0).astype(float), np.nan)
        cmap = ListedColormap(["#d8f0d8", "#f6d5d5"])
        ax.pcolormesh(v1, v2, region, cmap=cmap, vmin=0, vmax=1, shading="nearest",
                      rasterized=True)
        V1, V2 = np.meshgrid(v1, v2)
        n1 = (V1 - v1.min()) / max(np.ptp(v1), 1e-300)
        n2 = (V2 - v2.min()) / max(np.ptp(v2), 1e-300)
        for value, label in ((0.0, "S"), (1.0, "U")):
            components, count = ndimage.label(region == value)
            other = (region != value) & np.isfinite(region)
            opts = np.column_stack([n1[other], n2[other]])
            for j in range(1, count + 1):
                mask = components == j
                if mask.sum() < max(3, 0.02 * mask.size):
                    continue
                # the point of the component farthest from the other region and the frame
                pts = np.column_stack([n1[mask], n2[mask]])
                d = np.min(np.column_stack([pts, 1 - pts]), axis=1)
                if len(opts):
                    d = np.minimum(d, np.min(np.linalg.norm(
                        pts[:, None, :] - opts[None, :, :], axis=2), axis=1))
                k = int(np.argmax(d))
                ax.text(V1[mask][k], V2[mask][k], label, fontsize=18, fontweight="bold",
                        ha="center", va="center", color="0.25")
    used: set[tuple[str, bool]] = set()
    for curve in curves:
        if not curve.points:
            continue
        for kind, others_ok, seg in _segments(curve):
            label = None
            if (kind, others_ok) not in used:
                used.add((kind, others_ok))
                sign = "l1 > 0" if kind == "subcritical" else "l1 < 0"
                label = f"Hopf, {kind} ({sign})"
                if not others_ok:
                    label += ", other eigenvalues unstable"
            ax.plot(seg[:, 0], seg[:, 1], _LINESTYLE[kind],
                    color=_COLOR[kind] if others_ok else "0.55", lw=2.0, label=label)
    counts: dict[str, int] = {}
    seen: list[tuple[str, np.ndarray]] = []
    span = None
    if grid is not None:
        span = np.array([np.ptp(grid[0]), np.ptp(grid[1])])
    for curve in curves:
        for sp in curve.special_points:
            # a double-Hopf point lies on two branches: mark it once
            v = np.asarray(sp.values, float)
            scale = span if span is not None else np.maximum(np.abs(v), 1e-300)
            if any(t == sp.type and np.all(np.abs(v - w) <= 1e-6 * scale) for t, w in seen):
                continue
            seen.append((sp.type, v))
            counts[sp.type] = counts.get(sp.type, 0) + 1
            name = f"{sp.type}{counts[sp.type]}"
            text = name
            if sp.type == "GH" and sp.l2 is not None:
                text += f"\nl2 = {sp.l2:.3g}"
            ax.plot(*sp.values, _MARKER.get(sp.type, "x"), color="k", ms=7, zorder=5)
            ax.annotate(text, sp.values, textcoords="offset points", xytext=(6, 6),
                        fontsize=8)
    for t, m in _MARKER.items():
        if t in counts:
            full = {"GH": "generalised Hopf (Bautin)", "BT": "Bogdanov-Takens",
                    "ZH": "zero-Hopf", "HH": "double Hopf"}[t]
            ax.plot([], [], m, color="k", label=f"{t}: {full}")
    if design_point is not None:
        ax.plot(*design_point, "*", color="gold", mec="k", ms=15, zorder=6,
                label=f"design point ({params[0]} = {design_point[0]:.4g}, "
                      f"{params[1]} = {design_point[1]:.4g})")
    ax.set_ylabel(f"{params[1]} ({units[1]})" if units[1] else params[1])
    if grid is not None:
        ax.set_xlim(grid[0].min(), grid[0].max())
        ax.set_ylim(grid[1].min(), grid[1].max())
    ax.set_title(title or "Hopf curve: S stable, U unstable equilibrium")
    ax.legend(loc="best", fontsize=8, framealpha=0.85)
    fig.tight_layout()
    return fig


def _l1_panel(ax, curves: Sequence[HopfCurve], params: tuple[str, str],
              units: tuple[str, str]) -> None:
    """l1 along the Hopf curve against params[0]: red where subcritical (l1 > 0), blue
    where supercritical (l1 < 0), on a symmetric-log axis; GH points as circles."""
    values = [abs(v) for c in curves if c.points for v in c.l1() if np.isfinite(v) and v != 0]
    linthresh = 10.0 ** np.floor(np.log10(min(values))) if values else 1e-6
    for curve in curves:
        if not curve.points:
            continue
        v, l1 = curve.values(), curve.l1()
        for kind, _ok, seg_idx in _l1_runs(l1):
            ax.plot(v[seg_idx, 0], l1[seg_idx], _LINESTYLE[kind], color=_COLOR[kind], lw=1.6)
        for sp in curve.special_points:
            if sp.type == "GH":
                ax.plot(sp.values[0], 0.0, _MARKER["GH"], color="k", ms=6, zorder=5)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_yscale("symlog", linthresh=float(linthresh))
    ax.set_ylabel("l1 (symlog)")
    ax.set_xlabel(f"{params[0]} ({units[0]})" if units[0] else params[0])
    ax.set_title("first Lyapunov coefficient along the curve (> 0 subcritical, < 0 "
                 "supercritical)", fontsize=9)


def _l1_runs(l1: np.ndarray):
    """Index runs of equal sign of l1, overlapping by one point so the pieces join."""
    kind = np.where(l1 > 0, "subcritical", "supercritical")
    start = 0
    for j in range(1, len(kind) + 1):
        if j == len(kind) or kind[j] != kind[start]:
            yield kind[start], True, np.arange(start, min(j + 1, len(kind)))
            start = j


def hopf_scan_figure(scan, param: str, unit: str = ""):
    """The equilibrium's margin along one parameter with its Hopf points (``maglev-match
    hopf``): max Re(lambda) (1/s) of the scanned equilibrium branch against ``param``, zero
    marked, each refined Hopf point a red (subcritical, l1 > 0) or blue (supercritical,
    l1 < 0) marker labelled with its value and frequency.

    Parameters
    ----------
    scan : a :class:`~maglev_match.dynamics.hopf.HopfScan`.
    param, unit : the parameter's name and unit.

    Returns the figure.
    """
    fig, ax = new_figure(figsize=(7.0, 4.2))
    vals = np.asarray(scan.scan_values, float)
    mr = np.asarray(scan.max_real_part, float)
    if len(vals) == len(mr):
        order = np.argsort(vals, kind="stable")
        ax.plot(vals[order], mr[order], color="k", lw=1.4,
                label="max Re(lambda) of the equilibrium")
    else:  # a scan along beam data keeps the margin on its own path: points only
        ax.text(0.02, 0.95, "margin along the scan not drawn (scanned on a parameter path)",
                transform=ax.transAxes, fontsize=8, va="top")
        ax.set_xlim(min(vals.min(), scan.start), max(vals.max(), scan.stop))
    ax.axhline(0.0, color="0.4", lw=0.8)
    used = set()
    sign = {"subcritical": " (l1 > 0)", "supercritical": " (l1 < 0)"}
    for hp in scan.points:
        color = _COLOR.get(hp.kind, "0.4")
        label = None
        if hp.kind not in used:
            used.add(hp.kind)
            label = f"Hopf point, {hp.kind}{sign.get(hp.kind, '')}"
        ax.plot([hp.value], [0.0], "o", color=color, ms=8, mec="k", zorder=5, label=label)
        ax.annotate(f"{param} = {hp.value:.5g}\nomega = {hp.frequency:.4g} rad/s",
                    (hp.value, 0.0), textcoords="offset points", xytext=(6, 8), fontsize=8)
    xl = f"{param} ({unit})" if unit else param
    ax.set_xlabel(xl)
    ax.set_ylabel("max Re(lambda) (1/s)")
    ax.set_title(f"Equilibrium along {param}: unstable where max Re(lambda) > 0")
    ax.legend(loc="best", fontsize=8)
    return fig


@figure.register(HopfScan)
def _hopf_scan(scan: HopfScan, **kw):
    from maglev_match.plots.base import param_unit

    return hopf_scan_figure(scan, scan.param, param_unit(scan.param), **kw)


@figure.register(HopfCurve)
def _hopf_curve(curve: HopfCurve, **kw):
    return _hopf_curves(curve, [curve], **kw)


@figure_of_many.register(HopfCurve)
def _hopf_curves(first: HopfCurve, curves, **kw):
    from maglev_match.plots.base import param_unit

    names = tuple(first.params)
    return hopf_curve_figure(list(curves), names, tuple(param_unit(n) for n in names), **kw)


@figure.register(HopfCurveStudy)
def _hopf_curve_study(st: HopfCurveStudy, **kw):
    """The command's figure: the curves with l1 along them, the stability grid shaded, the
    design point and, for a restart, the saved point it was continued from."""
    kw.setdefault("title", st.title)
    fig = hopf_curve_figure(st.curves, st.names, st.units, st.grid,
                            design_point=st.design_point, **kw)
    if st.restart is not None:
        from pathlib import Path

        from maglev_match.plots.restart import mark_restart_point

        mark_restart_point(fig.axes[0], *st.restart.values, label=st.restart.label,
                           source=Path(st.restart.path).name)
    return fig
