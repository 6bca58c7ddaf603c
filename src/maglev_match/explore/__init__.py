"""``maglev-match explore``: the design explorer in the browser.

A local web server (:class:`~maglev_match.explore.server.ExploreServer`) with one static
page: move the beam, the gains and the delay and see the stability margin follow at once,
and on release the headline index at that exact design (warm-started from the previous
one), the basin-bounding cycle and the critical disturbed run; the Hopf curve in the
background. It reaches the computations through :mod:`maglev_match.api` only, like the
command line (a layer beside ``cli``, see docs/architecture.md)."""

from __future__ import annotations

__all__ = ["ExploreServer"]


def __getattr__(name: str):
    if name == "ExploreServer":
        from maglev_match.explore.server import ExploreServer

        return ExploreServer
    raise AttributeError(f"module 'maglev_match.explore' has no attribute '{name}'")
