"""Design-map figure: chi as colour over the two swept parameters, the stability boundary
(the Hopf curve of the map) overlaid, unstable points hatched."""

from __future__ import annotations

import numpy as np

from maglev_match.plots import new_figure


def map_figure(ds, title: str = ""):
    """``ds``: the map Dataset of :func:`maglev_match.maps.map_dataset`."""
    yname, xname = ds["chi"].dims
    x, y = ds[xname].values, ds[yname].values
    chi = np.ma.masked_invalid(ds["chi"].values)
    fig, ax = new_figure(figsize=(8, 5.5))
    mesh = ax.pcolormesh(x, y, chi, shading="nearest", cmap="viridis")
    fig.colorbar(mesh, ax=ax, label="matching index chi = h / w0")
    mr = ds["max_real_part"].values
    if np.nanmin(mr) < 0 < np.nanmax(mr):
        cs = ax.contour(x, y, mr, levels=[0.0], colors="r", linewidths=1.8)
        cs.collections[0].set_label("Hopf curve (max Re lambda = 0)") if hasattr(
            cs, "collections") else None
        ax.plot([], [], "r-", label="Hopf curve (stability boundary)")
    unstable = ds["stable"].values == 0
    if unstable.any():
        ax.contourf(x, y, unstable.astype(float), levels=[0.5, 1.5], colors="none",
                    hatches=["//"])
        ax.plot([], [], "s", color="w", markeredgecolor="k", label="unstable: chi = 0 (hatched)")
    unres = ds["resolved"].values == 0
    if unres.any():
        yy, xx = np.nonzero(unres)
        ax.plot(x[xx], y[yy], "x", color="orange", ms=4, label="unresolved (continuation failed)")
    xu, yu = ds[xname].attrs.get("units", ""), ds[yname].attrs.get("units", "")
    ax.set_xlabel(f"{xname} ({xu})" if xu else xname)
    ax.set_ylabel(f"{yname} ({yu})" if yu else yname)
    ax.set_title(title or f"Matching index over ({xname}, {yname})")
    ax.legend(loc="upper right", fontsize=8)
    return fig
