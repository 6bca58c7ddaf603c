"""A solved critical size confirmed by one simulation just below it.

A solved size (:mod:`maglev_match.analyses.critical`) solves the condition of *one* contact:
the one the bracket's smallest colliding run hit. Along a disturbance line, another contact
(a later extremum of the gap, at the same or the other limit) can start to collide at a
size inside the same bracket, below the solved one. The solved size is then not the
critical disturbance, however accurately it solves its own condition: runs between the two
collide.

Found on a map of the soft turnout (omega1 = 116.061 rad/s, sigma = 3.909e-4 1/kg, beam
up): the bracket's smallest collision (5.3193 mm) hit the lower limit at t = 0.178 s, and
its grazing condition solved at 5.3181 mm; but every size from 5.3126 mm collides at the
lower limit at t = 0.228 s, one gap extremum later, and the critical size is 5.3123 mm.

So every solved size is checked with one run of the limited model at
(1 - :data:`CHECK_BELOW`) of it. It must not collide (within 20 times the contact time, at
least 2 s, for a grazing contact; within the search's first horizon for a basin
boundary). If it does, that run is the new smallest collision: the bracket narrows to it,
the size is classified and solved again from the new bracket (the contact that run hit),
and checked again, at most :data:`CONFIRM_ROUNDS` times; after that the narrowed bracket's
midpoint stands, unsolved, and the result says why.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from maglev_match.maglev.base import MaglevModel

__all__ = ["CHECK_BELOW", "CONFIRM_ROUNDS", "confirmed", "run_below"]

#: the check run's size, relative to the solved one (the continuation's check step)
CHECK_BELOW = 1e-4
#: solves from a narrowed bracket before the bisection's midpoint is kept
CONFIRM_ROUNDS = 3


def run_below(m: MaglevModel, res: Any) -> Any:
    """The check run of a solved size ``res`` (a
    :class:`~maglev_match.analyses.critical.CriticalSize`): one simulation of the limited
    model from the disturbance of size ``res.size * (1 - CHECK_BELOW)`` in its direction,
    as a :class:`~maglev_match.analyses.simulation.Run` ('undecided' if it neither
    collided nor settled within its horizon)."""
    from maglev_match.analyses.simulation import Run
    from maglev_match.dynamics.integrate.simulate import (
        COLLISION,
        CONVERGED,
        SimulationOptions,
        simulate_batch,
    )

    # a contact of the same kind comes within a few gap extrema of the solved one: 20 times
    # its time (at least 2 s) suffices for a grazing contact; a basin boundary's runs
    # linger near the saddle cycle, so they get the search's whole first horizon
    horizon = float(m.critical_search.as_kwargs()["t_max"])
    if str(res.mechanism) == "grazing" and res.t_star is not None:
        horizon = min(horizon, max(2.0, 20.0 * float(res.t_star)))
    system, x_ref = m.system(limited=True), m.equilibrium()
    size = float(res.size) * (1.0 - CHECK_BELOW)
    x0 = m.disturbance(res.direction).x0_of(np.array([size]))
    if x0.shape[-1] != system.dim:
        x0, x_ref = system.lift(x0), system.lift(x_ref)
    b = simulate_batch(system, x0, horizon, event_fn=m.gap_events(), x_ref=x_ref,
                       options=SimulationOptions(stop_on_converged=True))
    code = int(b.outcome_code[0])
    outcome = ("collision" if code == COLLISION else "return" if code == CONVERGED
               else "undecided")
    time = (float(b.event_time[0]) if code == COLLISION else
            float(b.converged_time[0]) if code == CONVERGED else None)
    return Run(size=size, outcome=outcome, time=time,
               margins=tuple(float(v) for v in b.min_event_value[0]),
               event=int(b.event_index[0]) if code == COLLISION else -1)


def confirmed(m: MaglevModel, cd: Any, solve: Callable[[Any], Any], unsolved: Any) -> Any:
    """``solve(cd)`` (a bracket ``cd``, a
    :class:`~maglev_match.analyses.simulation.CriticalDisturbance`, classified and solved),
    confirmed by :func:`run_below` (module docstring). An unsolved result is returned as
    it is; a check run that returns or stays undecided confirms the size. ``unsolved``:
    the mechanism of a size left at the bracket's midpoint."""
    res = solve(cd)
    notes: list[str] = []
    for _ in range(CONFIRM_ROUNDS):
        if not res.solved or res.size is None:
            break
        run = run_below(m, res)
        if run.outcome != "collision":
            break
        notes.append(f"the solved size {res.size * 1e3:.7g} mm was not the critical one: a "
                     f"run at {run.size * 1e3:.7g} mm collided at {run.time:.4g} s (another "
                     "contact decides first)")
        cd = _narrowed(cd, run)
        res = solve(cd)
    else:
        if res.solved and res.size is not None and run_below(m, res).outcome == "collision":
            notes.append(f"the solved size {res.size * 1e3:.7g} mm was not confirmed either "
                         f"after {CONFIRM_ROUNDS} solves: the bracket's midpoint stands, "
                         "without a derivative")
            return replace(res, size=cd.critical, mechanism=unsolved, reason="; ".join(notes),
                           derivative_available=False, dsize_dp=None, dsize_dlimit=None)
    if notes:
        res = replace(res, reason="; ".join(notes) + "; then " + res.reason)
    return res


def _narrowed(cd: Any, run: Any) -> Any:
    """The bracket ``cd`` with ``run`` (a collision below its smallest collision) as its
    new smallest collision."""
    lo = cd.largest_return
    return replace(cd, smallest_collision=run.size, collision_time=run.time,
                   critical=None if lo is None else 0.5 * (lo + run.size),
                   runs=cd.runs + 1,
                   samples=tuple(sorted((*cd.samples, run), key=lambda r: r.size)))
