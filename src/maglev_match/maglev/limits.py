"""The physical limits of the levitation magnets, in one place.

* **The coil current never reverses**: the force uses max(i, 0), and di/dt is held at 0
  while i <= 0 and di/dt < 0 (:func:`clamp_current`, :func:`hold_current_rate`; the models
  call them when ``limited=True``; :mod:`maglev_match.maglev.clamp` writes the same rule as
  free and held modes).
* **The gap must stay within [gap_min, gap_max]**; leaving it is a collision. The gap limits
  are events of a simulation (:func:`gap_limit_events`, from a model's gap function), not
  terms of the vector field, and margins of a periodic orbit (:func:`cycle_limit_margins`,
  the ``limits`` of the model-agnostic cycle continuation): the gap c = c0 + gap deviation
  must stay in [gap_min, gap_max] and the coil current non-negative, at every levitation
  point.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import jax.numpy as jnp

from maglev_match.core.params import Params

__all__ = ["clamp_current", "hold_current_rate", "gap_margins", "gap_limit_events",
           "describe_event", "LIMITS", "GAP_LOW", "GAP_HIGH", "CURRENT_ZERO",
           "cycle_limit_margins", "limit_touched"]

#: the two gap limits, in the order of the events of :func:`gap_limit_events`
LIMITS = ("lower", "upper")


def clamp_current(i):
    """The current that produces force: max(i, 0) (A)."""
    return jnp.maximum(i, 0.0)


def hold_current_rate(i, di_dt):
    """di/dt with the no-reversal rule: 0 while i <= 0 and di/dt < 0 (A/s)."""
    return jnp.where((i <= 0.0) & (di_dt < 0.0), 0.0, di_dt)


def gap_margins(gap, gap_min, gap_max):
    """Distances to the lower and upper gap limits (m); a negative entry is a collision.
    Returns an array [..., 2] with (gap - gap_min, gap_max - gap)."""
    return jnp.stack([gap - gap_min, gap_max - gap], axis=-1)


@cache
def _gap_events(gap: Callable):
    """``g(x, p, (gap_min, gap_max))``: the gap-limit margins with the limits as an argument
    (one function object per gap function, so the compiled integrator is shared by all
    limits)."""

    def events(x, p, limits):
        return jnp.reshape(gap_margins(gap(x, p), limits[0], limits[1]), (-1,))

    return events


def gap_limit_events(gap: Callable, gap_min: float, gap_max: float):
    """Event function ``g(x, p)`` of the gap limits of a model whose gap function is
    ``gap(x, p)`` (every levitation point's gap, m): entries ``2(j-1)`` and ``2(j-1)+1``
    are ``gap_j - gap_min`` and ``gap_max - gap_j`` (m) of levitation point j; negative
    means the gap left [gap_min, gap_max]. The limits are traced arguments of the compiled
    integrator (:class:`~maglev_match.dynamics.integrate.simulate.EventsWithArgs`), so
    other limit values reuse the same compiled kernel."""
    from maglev_match.dynamics.integrate.simulate import EventsWithArgs

    return EventsWithArgs(_gap_events(gap), (float(gap_min), float(gap_max)))


def describe_event(index: int) -> tuple[int, str]:
    """(levitation point, 'lower'|'upper') of an entry of :func:`gap_limit_events`."""
    return index // 2 + 1, LIMITS[index % 2]


# ---------------------------------------------------------------------------------------
# limits as read-outs of a periodic orbit
# ---------------------------------------------------------------------------------------
GAP_LOW = "gap 0"  # the magnet touches the rail (gap at its lower limit)
GAP_HIGH = "gap 18 mm"  # gap at its upper limit
CURRENT_ZERO = "current 0"  # the coil current would reverse


def cycle_limit_margins(
    params: Params, include_current: bool = True
) -> Callable:
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

    def margins(system, orbit) -> dict[str, float]:
        from maglev_match.dynamics.cycles import orbit_extrema

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
