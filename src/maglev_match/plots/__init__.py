"""Figures. One module per analysis (``rootlocus``, ``hopf``, ``cycles``, ``simulate``,
``maps``); the shared style and the saving helper live in ``plots.base`` and are
re-exported here; :func:`figure_of` and :func:`plot` draw any result."""

from __future__ import annotations

from pathlib import Path

from maglev_match.plots.base import STYLE, _units, new_figure, plt, save_figure

__all__ = ["STYLE", "new_figure", "save_figure", "figure_of", "plot", "plt", "_units"]


def figure_of(result, **kw):
    """The figure of an analysis result, the one the command line draws for it:

    * :class:`~maglev_match.dynamics.equilibria.RootLocusResult`: the root locus;
    * :class:`~maglev_match.dynamics.hopf.HopfScan`: the margin along the parameter with
      the Hopf points;
    * a :class:`~maglev_match.dynamics.hopf_curve.HopfCurve` or a list of them: the Hopf
      curve with l1 along it;
    * :class:`~maglev_match.dynamics.cycles.CycleBranch` (or a list): the bifurcation
      diagram of the cycles (max/min gap deviation);
    * :class:`~maglev_match.analyses.simulation.MaglevSimulation` (or a list): the time histories;
    * an :class:`xarray.Dataset` with ``chi``: the design map;
    * :class:`~maglev_match.analyses.sensitivity.IndexSensitivity`: the tornado figure;
    * :class:`~maglev_match.analyses.design.DesignResult`: the design search path.

    Keyword arguments go to the figure function. Returns the matplotlib figure."""
    items = list(result) if isinstance(result, list | tuple) else [result]
    if not items:
        raise ValueError("nothing to plot")
    kind = type(items[0]).__name__
    if kind == "RootLocusResult":
        from maglev_match.plots.rootlocus import root_locus_figure

        r = items[0]
        return root_locus_figure(r.values, r.eigenvalues, r.param, _units(r.param)[0], **kw)
    if kind == "HopfScan":
        from maglev_match.plots.hopf import hopf_scan_figure

        return hopf_scan_figure(items[0], items[0].param, _units(items[0].param)[0], **kw)
    if kind == "HopfCurve":
        from maglev_match.plots.hopf import hopf_curve_figure

        names = tuple(items[0].params)
        return hopf_curve_figure(items, names, _units(*names), **kw)
    if kind == "CycleBranch":
        from maglev_match.plots.cycles import cycle_diagram

        return cycle_diagram(items, items[0].param, **kw)[0]
    if kind == "MaglevSimulation":
        from maglev_match.plots.simulate import simulation_figure

        return simulation_figure(items, **kw)[0]
    if kind == "Dataset" and "chi" in getattr(items[0], "data_vars", {}):
        from maglev_match.plots.maps import map_figure

        return map_figure(items[0], **kw)
    if kind == "IndexSensitivity":
        from maglev_match.plots.design import tornado_figure

        return tornado_figure(items[0], **kw)
    if kind == "DesignResult":
        from maglev_match.plots.design import design_path_figure

        return design_path_figure(items[0], **kw)
    raise TypeError(f"no figure for a {kind}")


def plot(result, path: str | Path | None = None, **kw):
    """Draw ``result`` (see :func:`figure_of`); with ``path``, save it as PNG and SVG
    there (suffix replaced) and return the written files, else return the figure."""
    fig = figure_of(result, **kw)
    if path is None:
        return fig
    return save_figure(fig, path)
