"""Design-map figure: chi as colour over the two swept parameters, unstable designs
(chi = 0) grey and hatched so they cannot be mistaken for small chi, the stability boundary
(the Hopf curve of the map) overlaid, unresolved points and the design point marked."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from maglev_match.plots import new_figure

__all__ = ["map_figure"]

UNSTABLE_GREY = "0.78"


def map_figure(ds, title: str = "", design_point: tuple[float, float] | None = None):
    """The map of :func:`maglev_match.maps.map_dataset` (or :func:`maglev_match.design_map`).

    Parameters
    ----------
    ds : the map Dataset (variables chi, stable, max_real_part, resolved over (y, x)).
    title : figure title (default: the two parameters).
    design_point : optional (x value, y value) of the design, marked with a star.

    Colour: chi at stable points only (the colour scale starts at 0); unstable points
    (chi = 0 exactly) grey with hatching; points where the computation failed marked with
    an orange cross and counted in the legend; the zero contour of the largest real part
    drawn as the stability boundary. Returns the figure.
    """
    yname, xname = ds["chi"].dims
    x, y = ds[xname].values, ds[yname].values
    stable = ds["stable"].values == 1
    resolved = ds["resolved"].values == 1
    chi = np.ma.masked_where(~stable | ~np.isfinite(ds["chi"].values), ds["chi"].values)
    fig, ax = new_figure(figsize=(8.5, 5.8))
    handles = []
    unstable = ~stable
    if unstable.any():
        grey = np.ma.masked_where(~unstable, np.ones_like(ds["chi"].values))
        # one hatched grey cell per unstable grid point (pcolor draws hatches per cell)
        with plt.rc_context({"hatch.color": "0.35", "hatch.linewidth": 0.6}):
            ax.pcolor(x, y, grey, shading="nearest", cmap=ListedColormap([UNSTABLE_GREY]),
                      vmin=0, vmax=1, hatch="///", edgecolors="none")
        handles.append(Patch(facecolor=UNSTABLE_GREY, edgecolor="k", hatch="///",
                             label="unstable equilibrium: chi = 0"))
    if stable.any():
        vmax = float(np.nanmax(chi.filled(np.nan))) if chi.count() else 1.0
        mesh = ax.pcolormesh(x, y, chi, shading="nearest", cmap="viridis", vmin=0.0,
                             vmax=vmax if vmax > 0 else 1.0, rasterized=True)
        fig.colorbar(mesh, ax=ax, label="matching index chi = h / w0 (stable points)")
    mr = ds["max_real_part"].values
    if np.nanmin(mr) < 0 < np.nanmax(mr) and len(x) > 1 and len(y) > 1:
        ax.contour(x, y, mr, levels=[0.0], colors="r", linewidths=1.8)
        handles.append(ax.plot([], [], "r-", lw=1.8,
                               label="stability boundary (Hopf curve, max Re lambda = 0)")[0])
    unres = ~resolved
    if unres.any():
        yy, xx = np.nonzero(unres)
        handles.append(ax.plot(x[xx], y[yy], "x", color="darkorange", ms=6, mew=1.5,
                               label=f"unresolved: {int(unres.sum())} point(s), "
                                     "continuation failed")[0])
    if design_point is not None:
        handles.append(ax.plot(*design_point, "*", color="gold", mec="k", ms=15, zorder=6,
                               label=f"design point ({xname} = {design_point[0]:.4g}, "
                                     f"{yname} = {design_point[1]:.4g})")[0])
    xu, yu = ds[xname].attrs.get("units", ""), ds[yname].attrs.get("units", "")
    ax.set_xlabel(f"{xname} ({xu})" if xu not in ("", "1") else xname)
    ax.set_ylabel(f"{yname} ({yu})" if yu not in ("", "1") else yname)
    ax.set_title(title or f"Matching index over ({xname}, {yname})")
    if handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.11),
                  ncol=2, fontsize=8, frameon=False)
    return fig
