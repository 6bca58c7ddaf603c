"""Design-map figure: the headline index as colour over the two swept parameters, unstable
designs (no index) grey and hatched so they cannot be mistaken for small chi, the stability
boundary from the computed Hopf curve, unresolved points and the design point marked."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from maglev_match.core.results import figure
from maglev_match.plots.base import new_figure

__all__ = ["map_figure", "BOUNDARY_LABEL", "ROW_HOPF_LABEL"]

UNSTABLE_GREY = "0.78"
BOUNDARY_LABEL = "stability boundary: Hopf curve (continued)"
ROW_HOPF_LABEL = "stability boundary: Hopf points solved on each row"
_COLOUR_LABELS = {
    "chi": "chi",
    "chi_paper": "chi by the paper's definition, h / w0",
    "chi_simulation": "chi_simulation = h_simulation / w0",
}


def map_figure(ds, title: str = "", design_point: tuple[float, float] | None = None,
               variable: str = "chi", iso: float | None = None, iso_curve=None,
               iso_source: str = ""):
    """The map of :func:`maglev_match.analyses.maps.map_dataset` (or
    :func:`maglev_match.design_map`).

    Parameters
    ----------
    ds : the map Dataset (variables chi, chi_paper, chi_simulation, stable, resolved,
        hopf_x and, when the axes allow it, hopf_curve_x/hopf_curve_y over (y, x)).
    title : figure title (default: the variable and the two parameters).
    design_point : optional (x value, y value) of the design, marked with a star.
    variable : the index drawn as colour: ``chi`` (the headline index, default),
        ``chi_paper`` or ``chi_simulation``.
    iso : optional level of ``variable`` drawn as a contour line of the stored grid
        (marching squares), labelled "interpolated from the map grid".
    iso_curve : optional iso-chi curve Dataset (the netCDF file of `iso-curve`), drawn
        as solved instead of the contour (``iso_source`` names its file in the legend).

    Colour: the index at stable, resolved points (the scale starts at 0); unstable points
    (no index; the paper's chi = 0) grey with hatching; unresolved points marked with an
    orange cross and counted in the legend. The stability boundary is the Hopf curve
    continued in the map's plane (``hopf_curve_x``/``hopf_curve_y``), or, where the axes are
    beam or vehicle data, the Hopf points solved on each row (``hopf_x``); never a contour
    of the grid. Returns the figure.
    """
    if variable not in _COLOUR_LABELS:
        raise ValueError(f"variable must be one of {', '.join(_COLOUR_LABELS)}, got "
                         f"'{variable}'")
    yname, xname = ds["chi"].dims
    x, y = ds[xname].values, ds[yname].values
    stable = ds["stable"].values == 1
    resolved = ds["resolved"].values == 1
    values = ds[variable].values
    shown = np.ma.masked_where(~stable | ~np.isfinite(values), values)
    fig, ax = new_figure(figsize=(8.5, 5.8))
    handles = []
    unstable = ~stable
    if unstable.any():
        grey = np.ma.masked_where(~unstable, np.ones_like(values))
        # one hatched grey cell per unstable grid point (pcolor draws hatches per cell)
        with plt.rc_context({"hatch.color": "0.35", "hatch.linewidth": 0.6}):
            ax.pcolor(x, y, grey, shading="nearest", cmap=ListedColormap([UNSTABLE_GREY]),
                      vmin=0, vmax=1, hatch="///", edgecolors="none")
        handles.append(Patch(facecolor=UNSTABLE_GREY, edgecolor="k", hatch="///",
                             label="unstable equilibrium: no index (the paper's chi = 0)"))
    if shown.count():
        vmax = float(shown.max())
        mesh = ax.pcolormesh(x, y, shown, shading="nearest", cmap="viridis", vmin=0.0,
                             vmax=vmax if vmax > 0 else 1.0, rasterized=True)
        label = _COLOUR_LABELS[variable]
        if variable == "chi":
            label = ("headline index chi = min(chi_paper, chi_simulation)"
                     if "min(" in ds.attrs.get("index_definition", "")
                     else "chi by the paper's definition, h / w0 (no simulation)")
        fig.colorbar(mesh, ax=ax, label=label)
    handles.extend(_boundary(ax, ds, xname, x))
    if iso_curve is not None:
        from maglev_match.plots.iso import draw_iso_dataset

        handles.extend(draw_iso_dataset(ax, iso_curve, xname, iso_source))
    elif iso is not None:
        from maglev_match.plots.iso import draw_iso_contour

        handles.extend(draw_iso_contour(ax, x, y, np.where(stable, values, np.nan), iso))
    unres = stable & ~resolved
    if unres.any():
        yy, xx = np.nonzero(unres)
        handles.append(ax.plot(x[xx], y[yy], "x", color="darkorange", ms=6, mew=1.5,
                               label=f"unresolved: {int(unres.sum())} point(s) (reasons in "
                                     "the file)")[0])
    if design_point is not None:
        inside = (min(x) <= design_point[0] <= max(x)) and (min(y) <= design_point[1] <= max(y))
        handles.append(ax.plot(*design_point, "*", color="gold", mec="k", ms=15, zorder=6,
                               label=f"design point ({xname} = {design_point[0]:.4g}, "
                                     f"{yname} = {design_point[1]:.4g})"
                                     + ("" if inside else ", outside the grid"))[0])
    ax.set_xlim(x[0] - 0.5 * (x[1] - x[0]), x[-1] + 0.5 * (x[-1] - x[-2]))
    ax.set_ylim(y[0] - 0.5 * (y[1] - y[0]), y[-1] + 0.5 * (y[-1] - y[-2]))
    xu, yu = ds[xname].attrs.get("units", ""), ds[yname].attrs.get("units", "")
    ax.set_xlabel(f"{xname} ({xu})" if xu not in ("", "1") else xname)
    ax.set_ylabel(f"{yname} ({yu})" if yu not in ("", "1") else yname)
    what = {"chi": "Matching index", "chi_paper": "Matching index (paper's definition)",
            "chi_simulation": "chi_simulation"}[variable]
    ax.set_title(title or f"{what} over ({xname}, {yname})")
    if handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.11),
                  ncol=2, fontsize=8, frameon=False)
    return fig


def _boundary(ax, ds, xname: str, x: np.ndarray) -> list:
    """Draw the stability boundary from the computed Hopf curve (or the rows' solved Hopf
    points); returns the legend handles."""
    if "hopf_curve_x" in ds and np.isfinite(ds["hopf_curve_x"].values).any():
        line, = ax.plot(ds["hopf_curve_x"].values, ds["hopf_curve_y"].values, "-", color="r",
                        lw=1.8, label=BOUNDARY_LABEL, zorder=4)
        return [line]
    if "hopf_x" in ds:
        hx = ds["hopf_x"].values
        yname = ds["hopf_x"].dims[0]
        yy = np.broadcast_to(ds[yname].values[:, None], hx.shape)
        ok = np.isfinite(hx)
        if ok.any():
            pts, = ax.plot(hx[ok], yy[ok], ".", color="r", ms=4, label=ROW_HOPF_LABEL,
                           zorder=4)
            return [pts]
    return []


@figure.register(xr.Dataset)
def _map(ds: xr.Dataset, **kw):
    if "chi" not in ds.data_vars:
        raise TypeError("no figure for a Dataset without chi (a design map has one)")
    return map_figure(ds, **kw)
