"""Figures. One module per analysis (``rootlocus``, ``hopf``, ``cycles``, ``simulate``,
``index``, ``maps``, ``design``, ``speed``); the shared style and the saving helper live in
``plots.base``. Each module registers the drawer of its result types with
:data:`maglev_match.core.results.figure` when it is imported (this package imports them
all), so that every result's ``.plot()`` finds its figure; :func:`figure_of` and
:func:`plot` draw any result.

Figures depend on results, never the reverse: no numerical module imports this package.
"""

from __future__ import annotations

from pathlib import Path

from maglev_match.core.results import draw, figure_for
from maglev_match.plots import (  # noqa: F401  (each registers its drawers)
    cycle_curves,
    cycles,
    design,
    hopf,
    index,
    irregular,
    iso,
    maps,
    rootlocus,
    simulate,
    speed,
)
from maglev_match.plots.base import STYLE, new_figure, plt, save_figure

__all__ = ["STYLE", "new_figure", "save_figure", "figure_of", "plot", "plt"]


def figure_of(result, **kw):
    """The figure of an analysis result, the one the command line draws for it:

    * :class:`~maglev_match.dynamics.equilibria.StabilityResult`: its eigenvalues in the
      complex plane;
    * :class:`~maglev_match.dynamics.equilibria.RootLocusResult`: the root locus;
    * :class:`~maglev_match.dynamics.hopf.HopfScan`: the margin along the parameter with
      the Hopf points;
    * a :class:`~maglev_match.dynamics.hopf_curve.HopfCurve` or a list of them: the Hopf
      curve with l1 along it;
    * :class:`~maglev_match.dynamics.cycles.CycleBranch` (or a list): the bifurcation
      diagram of the cycles (max/min gap deviation);
    * :class:`~maglev_match.analyses.simulation.MaglevSimulation` (or a list): the time
      histories; :class:`~maglev_match.api.simulation.UserSimulation`: each state against
      time;
    * :class:`~maglev_match.analyses.matching.MatchingIndex`: chi_paper, chi_simulation and
      the headline chi over the reading bands; :class:`~maglev_match.api.index.IndexSpread`:
      the histogram of the sampled chi (else the linearised spread);
    * an :class:`xarray.Dataset` with ``chi``: the design map;
    * :class:`~maglev_match.analyses.sensitivity.IndexSensitivity`: the tornado figure;
    * :class:`~maglev_match.analyses.design.DesignResult`: the design search path;
    * :class:`~maglev_match.analyses.speed.sweep.SpeedSweep` and
      :class:`~maglev_match.analyses.speed.spans.SpanRun`: the figures at speed.

    Keyword arguments go to the figure function. Returns the matplotlib figure."""
    return figure_for(result, **kw)


def plot(result, path: str | Path | None = None, **kw):
    """Draw ``result`` (see :func:`figure_of`); with ``path``, save it as PNG and SVG
    there (suffix replaced) and return the written files, else return the figure."""
    return draw(result, path, **kw)
