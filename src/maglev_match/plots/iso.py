"""The iso-chi curve figure: the curve chi(P1, P2) = target in the plane of its two
parameters, coloured by the part that decides chi, points whose deciding part is only
bracketed or whose corrector failed marked, the start and the special points (switches of
the deciding part, changes of mechanism) labelled; and the overlay of an iso-chi curve on
a design map (:func:`draw_iso_on_map`)."""

from __future__ import annotations

import numpy as np

from maglev_match.analyses.iso import IsoChiCurve
from maglev_match.core.results import figure
from maglev_match.plots.base import new_figure

__all__ = ["iso_figure", "draw_iso_curve", "draw_iso_contour", "draw_iso_dataset",
           "SOLVED_LABEL",
           "INTERPOLATED_LABEL"]

BASIS_COLOURS = {"paper": "tab:blue", "simulation": "tab:red"}
SOLVED_LABEL = "iso-chi curve chi = {target:g} (solved)"
INTERPOLATED_LABEL = "chi = {target:g}, interpolated from the map grid"


def draw_iso_curve(ax, curve: IsoChiCurve, xname: str | None = None) -> list:
    """Draw ``curve`` into ``ax`` (x axis: ``xname``, default the curve's first parameter;
    the other on y). Returns the legend handles."""
    a, b = curve.names
    swap = xname is not None and xname == b
    pts = curve.points
    xs = np.array([p.p2 if swap else p.p1 for p in pts])
    ys = np.array([p.p1 if swap else p.p2 for p in pts])
    switches = [s for s in curve.specials if s.kind == "basis switch" and s.located]
    handles = []
    seen: set[str] = set()

    def segment(x0, y0, x1, y1, basis):
        label = None
        if basis not in seen:
            seen.add(basis)
            label = (SOLVED_LABEL.format(target=curve.target)
                     + f", decided by the {'paper part' if basis == 'paper' else 'simulation'}")
        line, = ax.plot([x0, x1], [y0, y1], "-", color=BASIS_COLOURS.get(basis, "k"), lw=2.0,
                        label=label, zorder=5)
        if label:
            handles.append(line)

    for k in range(len(pts) - 1):
        b0, b1 = pts[k].sample.basis, pts[k + 1].sample.basis
        if b0 == b1 or not switches:
            segment(xs[k], ys[k], xs[k + 1], ys[k + 1], b0 if b0 == b1 else b1)
            continue
        # through the located switch between the two points (the corner of the curve)
        mid = np.array([0.5 * (pts[k].p1 + pts[k + 1].p1), 0.5 * (pts[k].p2 + pts[k + 1].p2)])
        scale = np.array([w[1] - w[0] for w in curve.ranges])
        sw = min(switches, key=lambda s: float(np.linalg.norm((np.array([s.p1, s.p2]) - mid)
                                                               / scale)))
        sx, sy = (sw.p2, sw.p1) if swap else (sw.p1, sw.p2)
        segment(xs[k], ys[k], sx, sy, b0)
        segment(sx, sy, xs[k + 1], ys[k + 1], b1)
    if len(pts) == 1:
        handles.append(ax.plot(xs, ys, "o", color="k", label=SOLVED_LABEL.format(
            target=curve.target))[0])
    for status, marker, colour in (("bracketed", "s", "darkorange"),
                                   ("not converged", "x", "k")):
        sel = [k for k, p in enumerate(pts) if p.status == status]
        if sel:
            handles.append(ax.plot(xs[sel], ys[sel], marker, color=colour, ms=7, mfc="none",
                                   zorder=6, label=f"{status}: {len(sel)} point(s)")[0])
    if curve.start is not None and pts:
        handles.append(ax.plot(xs[curve.start], ys[curve.start], "o", color="k", ms=5,
                               zorder=7, label="start of the curve")[0])
    for s in curve.specials:
        sx, sy = (s.p2, s.p1) if swap else (s.p1, s.p2)
        mark = "*" if s.kind == "basis switch" else "D"
        handles.append(ax.plot(sx, sy, mark, color="gold", mec="k", ms=12 if mark == "*"
                               else 7, zorder=8,
                               label=f"{s.kind}: {s.before} -> {s.after}"
                                     + ("" if s.located else " (not located)"))[0])
    return handles


def draw_iso_contour(ax, x, y, values, target: float, colour: str = "w") -> list:
    """The level set ``values`` = ``target`` of a gridded field (marching squares,
    matplotlib's contour of the stored grid), labelled as interpolated. Returns the legend
    handles (a line saying so when the level is not crossed)."""
    from matplotlib.lines import Line2D

    v = np.ma.masked_invalid(np.asarray(values, float))
    if v.count() == 0 or not (v.min() < target < v.max()):
        return [Line2D([], [], color="none", label=f"chi = {target:g} is not crossed on the "
                       "map grid")]
    ax.contour(x, y, v, levels=[target], colors=colour, linewidths=1.6, linestyles="--",
               zorder=5)
    return [Line2D([], [], color=colour, lw=1.6, ls="--",
                   label=INTERPOLATED_LABEL.format(target=target))]


def draw_iso_dataset(ax, ds, xname: str, source: str = "") -> list:
    """Draw an iso-chi curve read from its netCDF file (:meth:`IsoChiCurve.to_xarray`)
    into ``ax`` (x axis ``xname``), as solved; points not solved are marked. Returns the
    legend handles."""
    a, b = str(ds.attrs["curve_params"]).split(",")
    xs, ys = ds[a].values, ds[b].values
    if xname == b:
        xs, ys = ys, xs
    status = ds["status"].values.astype(str)
    target = float(ds.attrs["target"])
    label = SOLVED_LABEL.format(target=target) + (f" from {source}" if source else "")
    handles = [ax.plot(xs, ys, "-", color="w", lw=2.2, zorder=5, label=label)[0]]
    bad = status != "solved"
    if bad.any():
        handles.append(ax.plot(xs[bad], ys[bad], "s", color="darkorange", mfc="none", ms=7,
                               zorder=6, label=f"iso-chi curve: {int(bad.sum())} point(s) "
                                               "not solved")[0])
    return handles


def iso_figure(curve: IsoChiCurve, title: str = ""):
    """The figure of an :class:`~maglev_match.analyses.iso.IsoChiCurve`. Returns it."""
    fig, ax = new_figure(figsize=(7.5, 5.6))
    handles = draw_iso_curve(ax, curve)
    a, b = curve.names
    (lo1, hi1), (lo2, hi2) = curve.ranges
    ax.set_xlim(lo1, hi1)
    ax.set_ylim(lo2, hi2)
    ua, ub = curve.units
    ax.set_xlabel(f"{a} ({ua})" if ua not in ("", "1") else a)
    ax.set_ylabel(f"{b} ({ub})" if ub not in ("", "1") else b)
    what = "headline chi" if curve.simulate else "chi by the paper's definition"
    ax.set_title(title or f"Iso-chi curve: {what} = {curve.target:g}, model {curve.model}")
    if not curve.points:
        ax.text(0.5, 0.5, "the curve could not start:\n" + "\n".join(curve.warnings),
                ha="center", va="center", transform=ax.transAxes, wrap=True, fontsize=8)
    if handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2,
                  fontsize=8, frameon=False)
    return fig


@figure.register(IsoChiCurve)
def _iso(curve: IsoChiCurve, **kw):
    return iso_figure(curve, **kw)
