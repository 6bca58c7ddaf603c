"""Maglev physical limits as read-outs of a periodic orbit.

The cycle continuation (:func:`maglev_match.dynamics.cycles.cycle_branch`) is
model-agnostic; it takes a ``limits(system, orbit)`` callable. This module builds that
callable for the maglev models: the gap c = c0 + gap deviation must stay in
[gap_min, gap_max] and the coil current must stay non-negative, at every levitation point.
"""

from __future__ import annotations

from collections.abc import Callable

from maglev_match.core.params import Params
from maglev_match.dynamics.cycles import PeriodicOrbit, orbit_extrema
from maglev_match.dynamics.system import System

__all__ = ["GAP_LOW", "GAP_HIGH", "CURRENT_ZERO", "cycle_limit_margins", "limit_touched"]

GAP_LOW = "gap 0"  # the magnet touches the rail (gap at its lower limit)
GAP_HIGH = "gap 18 mm"  # gap at its upper limit
CURRENT_ZERO = "current 0"  # the coil current would reverse


def cycle_limit_margins(
    params: Params, include_current: bool = True
) -> Callable[[System, PeriodicOrbit], dict[str, float]]:
    """A ``limits`` function for :func:`cycle_branch`: margins (dimensionless, positive
    inside) to each physical limit over the whole cycle.

    * gap lower limit: (min gap deviation + c0 - gap_min) / (gap_max - gap_min)
    * gap upper limit: (gap_max - c0 - max gap deviation) / (gap_max - gap_min)
    * current: min current / i0 (only if ``include_current``)

    The names are :data:`GAP_LOW`, :data:`GAP_HIGH`, :data:`CURRENT_ZERO`.
    """
    c0, lo, hi = params.c0, params.gap_min, params.gap_max
    span = hi - lo
    i_ref = params.i0

    def margins(system: System, orbit: PeriodicOrbit) -> dict[str, float]:
        names = ["gap_deviation"] + (["current"] if include_current else [])
        ext = orbit_extrema(system, orbit, names)
        gmax, gmin = ext["gap_deviation"]
        out = {GAP_LOW: (gmin + c0 - lo) / span, GAP_HIGH: (hi - c0 - gmax) / span}
        if include_current:
            out[CURRENT_ZERO] = ext["current"][1] / i_ref
        return out

    return margins


def limit_touched(margins: dict[str, float]) -> str | None:
    """The name of the first limit touched (most negative margin), or None."""
    worst = min(margins, key=lambda k: margins[k]) if margins else None
    return worst if worst is not None and margins[worst] < 0 else None
