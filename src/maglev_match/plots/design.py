"""Figures of the sensitivity analysis and of the design search: a tornado chart of the
elasticities (p / chi) d chi / d p, and the optimiser's path over the chi map of the first
two varied parameters (chi against the parameter when only one is varied), with an iso-chi
curve of the same two parameters drawn on it when one is given (``iso=``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from maglev_match.analyses.design import DesignResult
from maglev_match.analyses.sensitivity import IndexSensitivity
from maglev_match.core.results import figure
from maglev_match.plots.base import new_figure
from maglev_match.plots.iso import draw_iso_dataset


def tornado_figure(sens, top: int = 15, title: str = ""):
    """Horizontal bars of the elasticity of chi (left panel) and of the margin's elasticity
    (p / |margin|) d margin / d p (right panel) for the ``top`` parameters with the largest
    |elasticity of chi|. ``sens``: an
    :class:`~maglev_match.analyses.sensitivity.IndexSensitivity`."""
    rows = sens.sorted_rows()[:top][::-1]
    names = [r.name for r in rows]
    chi = sens.index.chi
    ela = np.array([r.elasticity if math.isfinite(r.elasticity) else 0.0 for r in rows])
    margin = -sens.index.max_real_part
    mela = np.array([r.dmargin * r.value / abs(margin) if margin else 0.0 for r in rows])
    fig, (a1, a2) = new_figure(1, 2, figsize=(10, 0.35 * len(rows) + 1.8), sharey=True)
    y = np.arange(len(rows))
    a1.barh(y, ela, color=np.where(ela >= 0, "C2", "C3"))
    a1.axvline(0, color="k", lw=0.8)
    a1.set_yticks(y, names)
    a1.set_xlabel("elasticity of chi: (p / chi) d chi / d p")
    if not chi:
        a1.text(0.5, 0.5, "chi = 0: derivative 0 (unstable equilibrium)",
                transform=a1.transAxes, ha="center")
    a2.barh(y, mela, color=np.where(mela >= 0, "C0", "C1"))
    a2.axvline(0, color="k", lw=0.8)
    a2.set_xlabel("elasticity of the margin: (p / |margin|) d margin / d p")
    fig.suptitle(title or f"Sensitivities at chi = {chi:.3g} ({sens.index.case}), "
                 f"margin = {margin:.3g} 1/s")
    return fig


def _axis_label(name: str) -> str:
    """A parameter's axis label with its unit ("EI (N m^2)"; none for dimensionless)."""
    from maglev_match.core.params import PARAMETER_DOCS

    unit = PARAMETER_DOCS.get(name, ("-", ""))[0]
    return name if unit == "-" else f"{name} ({unit})"


def iso_dataset(iso: Any, names: tuple[str, ...]) -> Any:
    """The iso-chi curve ``iso`` (an :class:`~maglev_match.analyses.iso.IsoChiCurve` or its
    netCDF form, :meth:`~maglev_match.analyses.iso.IsoChiCurve.to_xarray`) as a dataset,
    checked to be a curve in the design's two varied parameters ``names``."""
    from maglev_match.analyses.iso import IsoChiCurve
    from maglev_match.core.params import ParameterError

    ds = iso.to_xarray() if isinstance(iso, IsoChiCurve) else iso
    pair = str(getattr(ds, "attrs", {}).get("curve_params", "")).split(",")
    if len(pair) != 2:
        raise ParameterError("iso", type(iso).__name__, "must be an iso-chi curve (an "
                             "IsoChiCurve or the netCDF file `iso-curve` writes)")
    if len(names) != 2 or sorted(pair) != sorted(names):
        raise ParameterError("iso", f"a curve in ({', '.join(pair)})", "must be a curve in "
                             f"the design's two varied parameters ({', '.join(names)})")
    return ds


def design_path_figure(result, title: str = "", iso: Any = None, iso_source: str = ""):
    """The coarse chi map used for the starts and every optimiser path, the design marked.
    ``result``: a :class:`~maglev_match.analyses.design.DesignResult`. ``iso``: an iso-chi
    curve in the two varied parameters (:func:`iso_dataset`), drawn as solved, its points
    not solved marked (``iso_source`` names its file in the legend)."""
    prob = result.problem
    names = prob.names
    iso_ds = None if iso is None else iso_dataset(iso, tuple(names))
    chi_req = [r.bound for r in prob.requirements if r.quantity == "chi"]
    if len(names) == 1:
        fig, ax = new_figure()
        x = result.grid_values[:, 0]
        order = np.argsort(x)
        # unstable points (chi = 0) are marked on the axis, not joined to the rest
        gx, gchi = x[order], _stable_only(result.grid_chi[order])
        ax.plot(gx, gchi, "o--", color="0.6",
                label="coarse grid: chi_paper = h / w0 (cheap; only to choose the starts)")
        _mark_unstable(ax, gx, result.grid_chi[order])
        for k, c in enumerate(result.candidates):
            xs = c.path[:, 0]
            ax.plot(xs, _stable_only(c.path_chi), ".-", color=f"C{k % 9 + 1}", alpha=0.7,
                    label=f"optimiser run {k + 1} ({c.iterations} it.): headline chi")
            _mark_unstable(ax, xs, c.path_chi)
        for b in chi_req:
            ax.axhline(b, color="r", ls="--", label=f"chi >= {b:g}")
        ax.plot([result.values[names[0]]], [result.index.chi], "*", ms=16, color="gold",
                markeredgecolor="k", label=f"design ({result.status})")
        ax.set_xlabel(_axis_label(names[0]))
        ax.set_ylabel("chi (grid: chi_paper; runs, design: headline)")
    else:
        fig, ax = new_figure(figsize=(8, 5.5))
        n = result.grid_shape[0]
        gv = result.grid_values
        chi = result.grid_chi.reshape(n, n, *([n] * (len(names) - 2)))
        while chi.ndim > 2:
            chi = np.nanmax(chi, axis=-1)
        x = np.unique(gv[:, 0])
        y = np.unique(gv[:, 1])
        mesh = ax.pcolormesh(x, y, np.ma.masked_invalid(chi.T), shading="nearest",
                             cmap="viridis")
        fig.colorbar(mesh, ax=ax, label="chi_paper = h / w0 on the coarse start grid")
        for b in chi_req:
            if np.nanmin(chi) < b < np.nanmax(chi):
                ax.contour(x, y, chi.T, levels=[b], colors="r", linestyles="--")
                ax.plot([], [], "r--", label=f"chi_paper = {b:g} on the grid")
        for k, c in enumerate(result.candidates):
            ax.plot(c.path[:, 0], c.path[:, 1], ".-", color="w", alpha=0.9)
            ax.plot(c.path[0, 0], c.path[0, 1], "o", color="w", markeredgecolor="k",
                    label="start" if k == 0 else None)
        if iso_ds is not None:
            draw_iso_dataset(ax, iso_ds, names[0], iso_source)
        ax.plot([result.values[names[0]]], [result.values[names[1]]], "*", ms=16,
                color="gold", markeredgecolor="k", label=f"design ({result.status})")
        ax.set_xlabel(_axis_label(names[0]))
        ax.set_ylabel(_axis_label(names[1]))
    reqs = ", ".join(str(r) for r in prob.requirements)
    ax.set_title(title or f"{prob.goal} {prob.objective}" + (f" subject to {reqs}" if reqs
                                                              else ""))
    ax.legend(fontsize=8, loc="best")
    return fig


def _stable_only(chi) -> np.ndarray:
    """chi with the unstable points (chi <= 0) and failures as NaN: lines break there."""
    chi = np.asarray(chi, float).copy()
    chi[~(chi > 0)] = np.nan
    return chi


def _mark_unstable(ax, x, chi) -> None:
    """Crosses on the axis at the unstable points (chi = 0), labelled once per axes."""
    chi = np.asarray(chi, float)
    bad = np.isfinite(chi) & (chi <= 0)
    if bad.any():
        seen = any(t.get_label() == "unstable (chi = 0)" for t in ax.lines)
        ax.plot(np.asarray(x)[bad], np.zeros(int(bad.sum())), "x", color="r",
                label=None if seen else "unstable (chi = 0)")


@figure.register(IndexSensitivity)
def _tornado(sens: IndexSensitivity, **kw):
    return tornado_figure(sens, **kw)


@figure.register(DesignResult)
def _design_path(result: DesignResult, **kw):
    return design_path_figure(result, **kw)
