"""The physical limits of the levitation magnets, as a separate layer the models call when
``limited=True``.

* The coil current never reverses: the force uses max(i, 0), and di/dt is held at 0 while
  i <= 0 and di/dt < 0.
* The gap must stay within [gap_min, gap_max]; leaving it is a collision. The gap limits
  are events for the simulator (see :func:`gap_margins`), not terms of the vector field.
"""

from __future__ import annotations

import jax.numpy as jnp


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

