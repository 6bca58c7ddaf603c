"""Time simulation of the maglev models with the physical limits.

Glue between the models and the model-agnostic integrator
:mod:`maglev_match.dynamics.integrate.simulate`:

* the gap-limit events of model A (one levitation point) and model B (six points):
  ``g = (gap - gap_min, gap_max - gap)`` per point, a negative entry is a collision;
* named initial conditions: the equilibrium, a beam-deflection disturbance ``x5(0)``
  (model A, paper Figs. 6-8), the vehicle "pressed onto the free beam" (model B, paper
  Section 5) and an absolute modal coordinate ``q1(0)`` (model B, paper Fig. 13b);
* the outcome of a run in the domain's words (collision time, lower/upper limit,
  levitation point), time histories as an :class:`xarray.Dataset` (CSV / netCDF);
* :func:`critical_disturbance`: the beam-deflection disturbance of model A that separates
  return from collision, by bracketing on batched runs.

Levitation points are numbered from 1: model A has the single point 1, model B the points
j = 1..6 (points 2k-1, 2k on frame k).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core.io import atomic_write, atomic_write_netcdf
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.integrate.simulate import (
    COLLISION,
    CONVERGED,
    SimulationOptions,
    SimulationResult,
    simulate,
    simulate_batch,
)
from maglev_match.dynamics.system import System
from maglev_match.maglev.base import INITIAL_CONDITIONS, MaglevModel
from maglev_match.maglev.limits import describe_event
from maglev_match.maglev.models import maglev_model

__all__ = [
    "INITIAL_CONDITIONS",
    "MaglevSimulation",
    "CriticalDisturbance",
    "Run",
    "equilibrium_state",
    "initial_state",
    "simulate_maglev",
    "history_dataset",
    "save_history",
    "critical_disturbance",
    "critical_disturbance_of_system",
    "vehicle_critical_disturbance",
    "vehicle_disturbance_geometry",
]


# ---------------------------------------------------------------------------------------
# initial conditions
# ---------------------------------------------------------------------------------------
def equilibrium_state(params: Params | MaglevModel, model: str = "unit") -> np.ndarray:
    """The static equilibrium of the model (:meth:`MaglevModel.equilibrium`): x = 0 for
    model A; the closed-form equilibrium of model B (beam statically deflected, gaps at c0,
    currents at the levitation current)."""
    return maglev_model(params, model).equilibrium()


def initial_state(
    params: Params | MaglevModel,
    model: str = "unit",
    *,
    initial: str = "equilibrium",
    x5: float | None = None,
    q1: float | None = None,
    state: np.ndarray | None = None,
) -> np.ndarray:
    """An initial state by name (:meth:`MaglevModel.initial_state`).

    Parameters
    ----------
    params : the parameter set (``model`` names the model) or a maglev model.
    initial : 'equilibrium' (both models) or 'pressed' (model B: vehicle pressed onto the
        free beam, i.e. every vehicle and controller state at equilibrium and q_n = 0,
        q_n' = 0).
    x5 : model A only: beam deflection x5(0) (m) added to the base state (the paper's
        Figs. 6-8 use x5(0) = -1.5, -2.2, -0.1, -4 mm; x5 < 0 opens the gap).
    q1 : model B only: the first modal coordinate q1(0) (m), *absolute* (undeflected
        beam = 0), set on top of the base state. The paper's Fig. 13b ("every state 0
        except q1 = 3 mm", with absolute q) is ``initial='pressed', q1=3e-3``.
    state : an explicit full state (overrides everything else).
    """
    return maglev_model(params, model).initial_state(initial, x5=x5, q1=q1, state=state)


# ---------------------------------------------------------------------------------------
# one run
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MaglevSimulation(Plottable):
    """One simulated run of model A or B.

    outcome : 'collision' | 'converged' | 'running' | 'failed'.
    collision_time : s or None; limit : 'lower' | 'upper' | None; point : levitation point
        (1-based) or None.
    final_gap_deviation : gap minus c0 at the end of the run (m): a float for model A, a
        list of six for model B.
    result : the integrator's :class:`SimulationResult` (histories, diagnostics).
    initial_text : the initial state in words (the model's
        :meth:`~maglev_match.maglev.base.MaglevModel.describe_state`).
    levitation_current : the coil current at the equilibrium (A), per levitation point.
    """

    params: Params
    model: str
    limited: bool
    x0: np.ndarray
    t_end: float
    outcome: str
    collision_time: float | None
    limit: str | None
    point: int | None
    final_gap_deviation: float | list[float]
    result: SimulationResult
    warnings: tuple[str, ...] = field(default=())
    initial_text: str = ""
    levitation_current: float = float("nan")

    def __repr__(self) -> str:
        """One line: model, limits, horizon and outcome (not the histories)."""
        what = f"outcome={self.outcome!r}"
        if self.outcome == "collision":
            what += (f", collision_time={self.collision_time:.6g}, limit={self.limit!r}, "
                     f"point={self.point}")
        return (f"MaglevSimulation(model={self.model!r}, limited={self.limited}, "
                f"t_end={self.t_end:g}, {what}, saved_points={len(self.result.t)})")

    def to_xarray(self):
        """The history as an :class:`xarray.Dataset` with units, long names, the parameter
        set and the package version (:func:`maglev_match.core.datasets.simulation_dataset`)."""
        from maglev_match.core.datasets import annotate_history
        from maglev_match.maglev.catalog import model_info

        return annotate_history(history_dataset(self), self,
                                f"maglev-match simulation, {model_info(self.model).label}")

    def save_history(self, path: str | Path) -> Path:
        """Write the history to ``path`` (:func:`save_history`: '.nc' netCDF, else CSV)."""
        return save_history(self, path)

    def summary(self) -> dict[str, Any]:
        """The outcome of the run in machine-readable form (SI units)."""
        return {
            "outcome": self.outcome,
            "collision_time": self.collision_time,
            "limit": self.limit,
            "point": self.point,
            "final_gap_deviation": self.final_gap_deviation,
        }


def _lifted(system: System, x: np.ndarray) -> np.ndarray:
    """State(s) of the model (rows) as states of ``system``: with a delay (tau > 0) the
    system is the discretised delay system, whose extra states hold the past; a model state
    given alone means a constant past (the state held for t <= 0)."""
    lift = getattr(system, "lift", None)
    return np.asarray(x, float) if lift is None else lift(x)


def simulate_maglev(
    params: Params | MaglevModel,
    model: str = "unit",
    x0: np.ndarray | None = None,
    t_end: float = 5.0,
    *,
    limited: bool = True,
    n_save: int = 2001,
    options: SimulationOptions | None = None,
) -> MaglevSimulation:
    """Simulate a maglev model (``params`` with ``model`` 'unit' or 'vehicle', or a
    :class:`MaglevModel`) from ``x0`` over [0, t_end] (s).

    With ``limited`` (default) the current clamp (no current reversal) is in the vector field
    and leaving the gap range [gap_min, gap_max] ends the run as a collision; without it
    the smooth model runs with no events. ``converged`` means the state stayed within
    ``options.converge_tol`` (scaled by the model's state scales: 1 mm, 1 cm/s, 1 A) of the
    equilibrium for ``options.hold_time`` seconds AND the equilibrium attracts (every
    eigenvalue of its Jacobian has a negative real part); a run that stays near an unstable
    equilibrium is ``running``, with a warning saying why.
    """
    m = maglev_model(params, model)
    params = m.params
    system = m.system(limited=limited)
    x_start = m.equilibrium() if x0 is None else np.asarray(x0, float)
    res = simulate(
        system, _lifted(system, x_start), t_end,
        event_fn=m.gap_events() if limited else None,
        x_ref=_lifted(system, m.equilibrium()),
        options=options, n_save=n_save,
    )
    point = limit = None
    if res.event_index is not None:
        point, limit = describe_event(res.event_index)
    gap_dev = np.asarray(m.gap()(jnp.asarray(res.final_state), jnp.asarray(system.p))) \
        - params.c0
    final_gap: float | list[float] = (float(gap_dev[0]) if m.n_points == 1
                                      else [float(v) for v in gap_dev])
    return MaglevSimulation(
        params=params, model=m.name, limited=limited, x0=x_start, t_end=float(t_end),
        outcome=res.outcome, collision_time=res.event_time, limit=limit, point=point,
        final_gap_deviation=final_gap, result=res, warnings=res.warnings,
        initial_text=m.describe_state(x_start), levitation_current=m.levitation_current,
    )


# ---------------------------------------------------------------------------------------
# histories
# ---------------------------------------------------------------------------------------
@cache
def _gap_and_rate(rhs, gap_fn):
    def one(x, p):
        g, gd = jax.jvp(lambda y: gap_fn(y, p), (x,), (rhs(x, p),))
        return g, gd

    return jax.jit(jax.vmap(one, in_axes=(0, None)))


def history_dataset(sim: MaglevSimulation):
    """The saved history as an :class:`xarray.Dataset` (SI units).

    Variables: every state (by its name), ``gap`` and ``gap_deviation`` (c - c0) and
    ``gap_rate`` (dc/dt) per levitation point, ``current`` per point (the force-producing
    current max(i, 0) when the limits are on), ``beam_deflection`` (model A: w = x5;
    model B: the modal coordinates q_n). Rows after the end of the run are dropped.
    Attributes: outcome, collision time/limit/point, model, t_end.
    """
    import xarray as xr

    res = sim.result
    params = sim.params
    m = maglev_model(params, sim.model)
    system = m.system(limited=sim.limited)
    keep = np.all(np.isfinite(res.x), axis=1)
    t, x = res.t[keep], res.x[keep]
    # append the collision instant so the history ends exactly at the limit
    if res.event_time is not None and res.event_state is not None:
        t = np.append(t, res.event_time)
        x = np.vstack([x, res.event_state])
    p = jnp.asarray(system.p)
    if len(t):
        gap, rate = (np.asarray(a) for a in _gap_and_rate(system.rhs, m.gap())(jnp.asarray(x), p))
    else:
        gap = rate = np.zeros((0, m.n_points))
    points = np.arange(1, gap.shape[1] + 1)
    data: dict[str, Any] = {}
    for k, name in enumerate(system.state_names):
        data[name] = ("time", x[:, k])
    data["gap"] = (("time", "point"), gap)
    data["gap_deviation"] = (("time", "point"), gap - params.c0)
    data["gap_rate"] = (("time", "point"), rate)
    current, beam, beam_coords = m.history_parts(x)
    data["beam_deflection"] = beam
    if sim.limited:
        current = np.maximum(current, 0.0)
    data["current"] = (("time", "point"), np.reshape(current, (len(t), -1)))
    coords: dict[str, Any] = {"time": t, "point": points, **beam_coords}
    ds = xr.Dataset(data, coords=coords)
    units = {"gap": "m", "gap_deviation": "m", "gap_rate": "m/s", "current": "A",
             "beam_deflection": "m", "time": "s"}
    for k, u in units.items():
        ds[k].attrs["units"] = u
    ds.attrs.update({
        "model": sim.model,
        "limits": int(sim.limited),
        "outcome": str(sim.outcome),  # (a StrEnum: netCDF attributes take plain str)
        "collision_time": -1.0 if sim.collision_time is None else sim.collision_time,
        "collision_limit": sim.limit or "",
        "collision_point": -1 if sim.point is None else sim.point,
        "t_end": sim.t_end,
        "gap_min": params.gap_min,
        "gap_max": params.gap_max,
        "c0": params.c0,
    })
    return ds


def save_history(sim: MaglevSimulation, path: str | Path) -> Path:
    """Write the history to ``path``: '.nc' -> netCDF (h5netcdf), else CSV (one column per
    variable and point, e.g. ``gap_deviation_3``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ds = sim.to_xarray()  # units, long names, parameters
    if path.suffix == ".nc":
        atomic_write_netcdf(path, ds)
        return path
    cols: dict[str, np.ndarray] = {"time": ds["time"].values}
    for name, var in ds.data_vars.items():
        if var.ndim == 1:
            cols[str(name)] = var.values
        else:
            other = var.dims[1]
            for k, lab in enumerate(ds[other].values):
                cols[f"{name}_{lab}"] = var.values[:, k]
    header = ",".join(cols)
    atomic_write(path, lambda tmp: np.savetxt(tmp, np.column_stack(list(cols.values())),
                                              delimiter=",", header=header, comments=""))
    return path


# ---------------------------------------------------------------------------------------
# basin read-out
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Run:
    """One simulated size of a critical-disturbance search.

    size : disturbance size (m); outcome : 'collision' | 'return' | 'undecided';
    time : collision time, or the start of the final stretch near the equilibrium for a
    return (s), None when undecided; margins : the smallest value of each gap-limit margin
    seen over the run (m; entries as :func:`gap_limit_events`); event : the margin entry
    that went negative (collisions) or -1.
    """

    size: float
    outcome: str
    time: float | None
    margins: tuple[float, ...]
    event: int = -1


@dataclass(frozen=True)
class CriticalDisturbance:
    """The beam-deflection disturbance of model A that separates return from collision.

    The disturbance is x5(0) = direction * size with everything else at equilibrium.

    direction : -1 (x5 < 0, the paper's case: the gap opens) or +1.
    largest_return : largest size (m) seen to return (converge) below ``smallest_collision``,
        or None. smallest_collision : smallest size (m) seen to collide, or None: the search
        narrows the bracket between it and the largest size below it that did *not* collide
        (returned or stayed undecided), so it is the smallest colliding size to within
        ``tol`` even where runs below it stay undecided.
    critical : midpoint of the bracket (m), or None when there is no bracket.
    status : 'bracketed' (both ends found, width <= tol), 'all_collide' (no size down to tol
        returned), 'all_return' (every size up to the gap range returned), 'open' (the
        bracket did not shrink to tol, or its lower end is an undecided run).
    gap_range : the largest meaningful size (m): the disturbance that puts the gap on
        its limit at t = 0.
    runs : number of simulated runs; unresolved : runs that neither collided nor converged
        even on the longest horizon (never counted as returns); unresolved_sizes : them.
    horizon : the longest horizon used (s). rounds : batched rounds.
    collision_time : collision time (s) of the run at ``smallest_collision``.
    nonmonotone : True if some size returned above a colliding one (the basin along this
        line is not an interval); warnings : messages.
    largest_undecided : the largest undecided size below ``smallest_collision`` (m) or None.
    samples : every run of the search (:class:`Run`, by size), the evidence the solved
        critical size is classified from (:mod:`maglev_match.analyses.critical`).
    """

    __repr__ = compact_repr

    direction: int
    largest_return: float | None
    smallest_collision: float | None
    critical: float | None
    status: str
    gap_range: float
    tol: float
    runs: int
    unresolved: int
    unresolved_sizes: tuple[float, ...]
    horizon: float
    rounds: int
    collision_time: float | None
    nonmonotone: bool
    warnings: tuple[str, ...] = field(default=())
    largest_undecided: float | None = None
    samples: tuple[Run, ...] = field(default=(), repr=False, compare=False)

    @property
    def converged(self) -> bool:
        return self.status in ("bracketed", "all_collide", "all_return")

    def run_at(self, size: float | None) -> Run | None:
        """The recorded run at ``size`` (exact match), or None."""
        return next((r for r in self.samples if r.size == size), None)


def critical_disturbance(
    params: Params | MaglevModel,
    *,
    model: str = "unit",
    direction: int = -1,
    t_max: float | None = None,
    tol: float | None = None,
    max_extend: int | None = None,
    batch: int | None = None,
    max_rounds: int | None = None,
    options: SimulationOptions | None = None,
) -> CriticalDisturbance:
    """The critical disturbance of a maglev model with the limits on (the simulation
    cross-check of h): the size d along the model's disturbance line
    (:meth:`MaglevModel.disturbance`) that returns to the equilibrium for smaller d and
    collides for larger d. Model A: x5(0) = direction * d; model B: the state
    x_eq + s (pressed - x_eq), d = s w_mid measured as the mid-span beam displacement (m)
    from its static position (direction -1 lifts the beam towards the free beam).

    The runs use the limited model: the coil current is clamped at zero (the force uses
    max(i, 0) and di/dt is held at 0 while i <= 0 and falling) and leaving the gap range
    [gap_min, gap_max] is a collision. See :func:`critical_disturbance_of_system` for the
    bracketing.

    Parameters
    ----------
    params : the parameter set (``model`` names the model) or a maglev model.
    direction : -1 for the beam above its static position (model A: x5(0) < 0, the gap
        opens: the paper's Figs. 6-8), +1 for the beam pressed further down.
    t_max : first horizon (s). tol : bracket width to reach (m).
    max_extend : how many times the horizon may double for undecided runs.
    batch : sizes per batched call. max_rounds : bound on rounds. Each defaults to the
        model's :attr:`~MaglevModel.critical_search` (model A: 20 s, 1e-5 m, 2, 10 sizes,
        12 rounds: three rounds reach the tolerance over a 10 mm range, 11^3 > 1e-2 / 1e-5;
        model B: 10 s, 2e-5 m, 1, 8 sizes, 8 rounds, 9^3 > 1e-2 / 2e-5).
    options : integrator options (``stop_on_converged`` is forced on).

    Returns
    -------
    :class:`CriticalDisturbance`.
    """
    m = maglev_model(params, model)
    line = m.disturbance(direction)  # (checks the direction)
    given = {"t_max": t_max, "tol": tol, "max_extend": max_extend, "batch": batch,
             "max_rounds": max_rounds}
    search = {**m.critical_search.as_kwargs(),
              **{k: v for k, v in given.items() if v is not None}}
    return critical_disturbance_of_system(
        m.system(limited=True), line.x0_of, line.gap_range, events=m.gap_events(),
        x_ref=m.equilibrium(), direction=line.direction, options=options, **search)


def vehicle_disturbance_geometry(params: Params) -> tuple[np.ndarray, np.ndarray, float]:
    """Model B's "pressed" disturbance line: (x_eq, delta, w_mid); deprecated, use
    ``VehicleModel(params).pressed_geometry``."""
    import warnings

    warnings.warn("vehicle_disturbance_geometry(params) is deprecated: use "
                  "maglev_match.maglev.models.VehicleModel(params).pressed_geometry (goes away "
                  "in 0.4)", DeprecationWarning, stacklevel=2)
    return maglev_model(params, "vehicle").pressed_geometry


def vehicle_critical_disturbance(params: Params, **kwargs: Any) -> CriticalDisturbance:
    """Model B's critical disturbance; deprecated, use
    ``critical_disturbance(params, model="vehicle", ...)``."""
    import warnings

    warnings.warn("vehicle_critical_disturbance(params, ...) is deprecated: use "
                  "critical_disturbance(params, model='vehicle', ...) (goes away in 0.4)",
                  DeprecationWarning, stacklevel=2)
    return critical_disturbance(params, model="vehicle", **kwargs)


def critical_disturbance_of_system(
    system: System,
    x0_of,
    gap_range: float,
    *,
    events=None,
    x_ref: np.ndarray | None = None,
    direction: int = -1,
    t_max: float = 20.0,
    tol: float = 1e-5,
    max_extend: int = 2,
    batch: int = 16,
    max_rounds: int = 12,
    options: SimulationOptions | None = None,
) -> CriticalDisturbance:
    """The disturbance size that separates return from collision, for any system.

    ``x0_of(sizes)`` maps an array of disturbance sizes (>= 0, in the unit of
    ``gap_range``) to initial states (batch, dim); ``events`` ends a run as a collision.
    Each round simulates ``batch`` sizes spread inside the current bracket in one vmapped
    call, so the bracket shrinks by a factor ``batch + 1`` per round. A round lasts as long
    as its slowest run (the one closest to the critical size), and a vmapped step costs a
    fixed part plus a part per run: a few rounds of a few sizes are cheaper than fewer
    rounds of many (model A: 3 rounds of 10 sizes 0.19 s CPU against 3 rounds of 16
    0.23 s, 2 rounds of 31 0.25 s; model B: 3 x 8 1.2 s against 3 x 16 1.9 s; both
    directions, measured 2026-11-25). A run that neither
    collides nor converges by the horizon ``t_max`` (s) is re-run with the horizon doubled,
    up to ``max_extend`` times; if still undecided it is *unresolved* and left out of the
    bracket (never counted as a return). Sizes are searched in (0, gap_range): the clamp
    rule is that a size beyond ``gap_range`` is not a disturbance inside the physical range,
    so when every size returns the result is ``all_return`` at ``gap_range``.
    """
    if not tol > 0:
        raise ParameterError("tol", tol, "must be > 0")
    if x_ref is not None:
        x_ref = _lifted(system, x_ref)
    opts = options or SimulationOptions()
    opts = dataclasses.replace(opts, stop_on_converged=True)

    sizes_seen: dict[float, tuple[str, float]] = {}
    margins_seen: dict[float, tuple[tuple[float, ...], int]] = {}
    unresolved: list[float] = []
    runs = 0
    horizon = float(t_max)
    warnings: list[str] = []

    def run(sizes: np.ndarray) -> None:
        nonlocal runs, horizon
        pending = np.asarray(sizes, float)
        t = float(t_max)
        for ext in range(max_extend + 1):
            if pending.size == 0:
                break
            b = simulate_batch(system, _lifted(system, x0_of(pending)), t, event_fn=events,
                               x_ref=x_ref, options=opts)
            runs += pending.size
            horizon = max(horizon, t)
            undecided = []
            for k, d in enumerate(pending):
                code = int(b.outcome_code[k])
                margins_seen[float(d)] = (tuple(float(v) for v in b.min_event_value[k]),
                                          int(b.event_index[k]))
                if code == COLLISION:
                    sizes_seen[float(d)] = ("collision", float(b.event_time[k]))
                elif code == CONVERGED:
                    sizes_seen[float(d)] = ("return", float(b.converged_time[k]))
                else:
                    undecided.append(d)
            pending = np.asarray(undecided)
            if ext < max_extend:
                t *= 2.0
        unresolved.extend(float(d) for d in pending)

    def bracket() -> tuple[float | None, float | None, float | None]:
        """(largest return below hi, smallest collision hi, largest non-colliding size
        below hi: a return or an undecided run)."""
        coll = [d for d, (o, _) in sizes_seen.items() if o == "collision"]
        hi = min(coll) if coll else None
        ret = [d for d, (o, _) in sizes_seen.items() if o == "return" and (hi is None or d < hi)]
        lo = max(ret) if ret else None
        below = ret + [d for d in unresolved if hi is None or d < hi]
        lo_any = max(below) if below else None
        return lo, hi, lo_any

    # round 1: spread over the whole range (the last size just inside the limit)
    first = gap_range * np.arange(1, batch + 1) / (batch + 1)
    run(first)
    rounds = 1
    lo, hi, lo_any = bracket()
    while rounds < max_rounds:
        # narrow between the smallest collision and the largest size below it that did not
        # collide (an undecided run included: the collision boundary is then still located,
        # so the smallest collision quoted is the smallest size that collides)
        a = 0.0 if lo_any is None else lo_any
        b = gap_range if hi is None else hi
        if hi is None or b - a <= tol:
            break
        if lo_any is None and b <= tol:
            break
        run(a + (b - a) * np.arange(1, batch + 1) / (batch + 1))
        rounds += 1
        lo, hi, lo_any = bracket()

    nonmonotone = any(o == "return" and hi is not None and d > hi
                      for d, (o, _) in sizes_seen.items())
    if nonmonotone:
        warnings.append("some sizes above the smallest colliding size returned: the set of "
                        "returning disturbances along this line is not an interval")
    if unresolved:
        warnings.append(f"{len(unresolved)} run(s) neither collided nor converged within "
                        f"{horizon:g} s; left out of the bracket")
    undecided_below = lo_any is not None and (lo is None or lo_any > lo)
    if hi is None:
        status = "all_return" if lo is not None else "open"
    elif lo is None and not undecided_below:
        status = "all_collide" if hi <= tol * 1.0000001 else "open"
    elif undecided_below:
        status = "open"
    else:
        status = "bracketed" if hi - lo <= tol * 1.0000001 else "open"
    if status == "open":
        if undecided_below and hi is not None and hi - lo_any <= tol * 1.0000001:
            warnings.append(f"the smallest collision is located to {tol:g}, but the size just "
                            "below it neither collided nor converged within the horizon")
        else:
            warnings.append("the bracket did not shrink to tol (round limit or unresolved "
                            "runs)")
    samples = []
    for d in sorted(set(sizes_seen) | set(unresolved)):
        o, tt = sizes_seen.get(d, ("undecided", None))
        mg, ev = margins_seen.get(d, ((), -1))
        samples.append(Run(size=d, outcome=o, time=tt, margins=mg,
                           event=ev if o == "collision" else -1))
    return CriticalDisturbance(
        direction=direction,
        largest_return=lo,
        smallest_collision=hi,
        critical=None if (lo is None or hi is None) else 0.5 * (lo + hi),
        status=status,
        gap_range=float(gap_range),
        tol=float(tol),
        runs=runs,
        unresolved=len(unresolved),
        unresolved_sizes=tuple(sorted(unresolved)),
        horizon=horizon,
        rounds=rounds,
        collision_time=None if hi is None else sizes_seen[hi][1],
        nonmonotone=nonmonotone,
        warnings=tuple(warnings),
        largest_undecided=lo_any if undecided_below else None,
        samples=tuple(samples),
    )
