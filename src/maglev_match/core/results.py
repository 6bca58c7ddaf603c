"""Results and their figures: figures depend on results, never the reverse.

Every result of an analysis draws itself with ``result.plot(path=None, **options)``, but the
numerical modules that define the results know nothing of matplotlib or of the figure
modules. The figures register themselves here, one drawer per result type
(:func:`functools.singledispatch`)::

    from maglev_match.core.results import figure

    @figure.register
    def _(result: CycleBranch, **options):
        return cycle_diagram([result], result.param, **options)[0]

and :func:`draw` (behind every ``.plot()``) finds the drawer of the result's type. The figure
package (:data:`FIGURES`, ``maglev_match.plots``) is loaded on the first figure, by name: it
is a plug-in of the results, the way matplotlib loads its backends, so no numerical module
imports it. A list of results of one type is drawn by the drawer registered for lists of
that type (:func:`figure_of_many`): several cycle branches in one bifurcation diagram.

Standard library only.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["FIGURES", "figure", "figure_of_many", "draw", "Plottable"]

#: the package whose modules register the drawers (loaded by :func:`draw` when needed)
FIGURES = "maglev_match.plots"


@functools.singledispatch
def figure(result: Any, **options: Any) -> Any:
    """The figure (a matplotlib Figure) of one result; drawers are registered per type."""
    raise TypeError(f"no figure for a {type(result).__name__}")


@functools.singledispatch
def figure_of_many(first: Any, items: Sequence[Any], **options: Any) -> Any:
    """The figure of several results of one type (dispatched on the first of them)."""
    if len(items) == 1:
        return figure(items[0], **options)
    raise TypeError(f"no figure for a list of {type(first).__name__}")


def _has_drawer(result: Any) -> bool:
    if isinstance(result, list | tuple):
        if not result:
            return True  # (an error below, with its own message)
        return figure_of_many.dispatch(type(result[0])) is not figure_of_many.registry[object] \
            or figure.dispatch(type(result[0])) is not figure.registry[object]
    return figure.dispatch(type(result)) is not figure.registry[object]


def figure_for(result: Any, **options: Any) -> Any:
    """The figure of ``result`` (one result, or a list or tuple of results of one type),
    loading the figure package the first time a drawer is missing."""
    if not _has_drawer(result):
        importlib.import_module(FIGURES)  # registers the drawers
    if isinstance(result, list | tuple):
        items = list(result)
        if not items:
            raise ValueError("nothing to plot")
        return figure_of_many(items[0], items, **options)
    return figure(result, **options)


def draw(result: Any, path: str | Path | None = None, **options: Any) -> Any:
    """Draw ``result``; with ``path``, save the figure as PNG and SVG there (the suffix is
    replaced) and return the written files, else return the figure.

    ``ax=`` draws into existing matplotlib axes instead of a new figure: one ``Axes`` for a
    one-panel figure, a sequence (or array) of as many axes as the figure has panels
    otherwise; the figure holding them is returned (or saved)."""
    ax = options.pop("ax", None)
    if ax is not None:
        if not _has_drawer(result):
            importlib.import_module(FIGURES)
        into = importlib.import_module(f"{FIGURES}.base").drawing_into
        with into(ax):
            fig = figure_for(result, **options)
    else:
        fig = figure_for(result, **options)
    if path is None:
        return fig
    save = importlib.import_module(f"{FIGURES}.base").save_figure
    return save(fig, path)


class Plottable:
    """Mix-in of the results that have a figure: ``plot(path=None, **options)``."""

    __slots__ = ()

    def plot(self, path: str | Path | None = None, **options: Any) -> Any:
        """This result's figure, as the command line draws it; saved as PNG and SVG at
        ``path`` when given (returns the written files), else returned (a matplotlib
        Figure). ``ax=`` draws into your own axes (one per panel of the figure); the other
        ``options`` go to the figure function."""
        return draw(self, path, **options)
