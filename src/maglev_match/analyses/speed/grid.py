"""The speeds of a sweep at speed: the km/h conversion, the bounds, and the checked grid of
speeds. Light (no JAX), so that the command line refuses a bad speed range at once; the
numerics are in :mod:`maglev_match.analyses.speed.sweep`, which re-exports these names."""

from __future__ import annotations

import math

import numpy as np

from maglev_match.core.params import ParameterError

__all__ = ["KMH", "SPEED_MAX", "SPEED_MIN", "MAX_SPEEDS", "speeds_kmh"]

KMH = 1.0 / 3.6  # m/s per km/h
SPEED_MAX = 250.0  # m/s (900 km/h): beyond any maglev line; keeps passages resolvable
SPEED_MIN = 1.0 * KMH  # m/s (1 km/h): the slowest speed other than 0 (a span passage at
#                        most L / SPEED_MIN, 90 s for 25 m spans)
MAX_SPEEDS = 2000  # points of one sweep


def speeds_kmh(start: float, stop: float, step: float) -> np.ndarray:
    """The speeds (km/h) from ``start`` to ``stop`` by ``step`` (``stop`` included when the
    steps reach it), checked: finite, 0 <= start <= stop <= 900 km/h, step > 0, at most
    2000 speeds."""
    for name, v in (("--from", start), ("--to", stop), ("--step", step)):
        if not math.isfinite(v):
            raise ParameterError(name, v, "must be a finite number (km/h)")
    if start < 0:
        raise ParameterError("--from", start, "must be >= 0 km/h")
    if 0 < start < SPEED_MIN / KMH:
        raise ParameterError("--from", start, f"must be 0 (standstill) or at least "
                             f"{SPEED_MIN / KMH:g} km/h: slower, one span passage lasts longer "
                             "than a run at speed can integrate")
    if stop > SPEED_MAX / KMH:
        raise ParameterError("--to", stop, f"must be at most {SPEED_MAX / KMH:g} km/h")
    if stop < start:
        raise ParameterError("--to", stop, f"must be >= --from ({start:g} km/h)")
    if not step > 0:
        raise ParameterError("--step", step, "must be > 0 km/h")
    count = int(math.floor((stop - start) / step + 1e-9)) + 1
    if count > MAX_SPEEDS:
        raise ParameterError("--step", step, f"gives {count} speeds; at most {MAX_SPEEDS}")
    kmh = start + step * np.arange(count)
    slow = kmh[(kmh > 0) & (kmh < SPEED_MIN / KMH)]
    if slow.size:
        raise ParameterError("--step", step, f"gives the speed {slow[0]:g} km/h: every speed "
                             f"must be 0 (standstill) or at least {SPEED_MIN / KMH:g} km/h")
    return kmh
