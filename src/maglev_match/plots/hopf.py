"""Hopf-curve figure in the style of the paper's Fig. 4: the plane of two parameters with
the stable region S and the unstable region U shaded, the Hopf curve drawn solid where the
bifurcation is subcritical (l1 > 0) and dashed where it is supercritical (l1 < 0), and the
codimension-two points marked and labelled."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.colors import ListedColormap
from scipy import ndimage

from maglev_match.dynamics.hopf_curve import HopfCurve
from maglev_match.plots import new_figure

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

    Returns the figure.
    """
    fig, ax = new_figure(figsize=(7.5, 5.2))
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
    ax.set_xlabel(f"{params[0]} ({units[0]})" if units[0] else params[0])
    ax.set_ylabel(f"{params[1]} ({units[1]})" if units[1] else params[1])
    if grid is not None:
        ax.set_xlim(grid[0].min(), grid[0].max())
        ax.set_ylim(grid[1].min(), grid[1].max())
    ax.set_title(title or "Hopf curve: S stable, U unstable equilibrium")
    ax.legend(loc="best", fontsize=8, framealpha=0.85)
    return fig
