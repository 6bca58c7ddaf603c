"""The solved critical disturbance followed from design to design (continuation).

At a design next to one where the critical disturbance of a direction was solved
(:mod:`maglev_match.analyses.critical`), the condition that decided it is the same smooth
equation in the parameters, so it is not searched again:

* **predictor**: the neighbour's size plus its derivative times the parameter step,
  dd = dsize/dp . (p - p_prev), where the neighbour has the derivative; else the secant
  of the two previous points of a sequence; else the neighbour's size;
* **corrector**: Newton on the neighbour's condition at the new parameters: the grazing
  condition at the same limit and levitation point in the neighbour's time window
  (:func:`maglev_match.dynamics.escape.solve_grazing`, a few flows with sensitivities), or
  for a basin boundary the saddle cycle of the clamped system corrected by collocation
  from the neighbour's cycle and the landing on its stable manifold
  (:func:`maglev_match.dynamics.escape.solve_basin_boundary`);
* **check**: two simulations of the limited model at 1 -+ 1e-4 of the solved size: the
  smaller must return to the equilibrium, the larger collide at the same gap limit of the
  same levitation point. They are the continued size's bracket.

Where the corrector fails or the check does not hold, the mechanism may have changed (a
grazing contact turning into a basin boundary, a new contact at another extremum or
limit, the deciding direction switching): the point gets the full search
(:func:`maglev_match.analyses.critical.solve_critical`: bracketing by batched simulations,
classification, solve), and the fall-back is recorded with why
(:class:`Fallback`). :func:`follow_critical` follows a sequence of designs (a map row)
this way and locates every change of what decides the size (mechanism, limit or point)
between two neighbouring designs (:class:`MechanismChange`).

Continued and point-wise solved sizes solve the same equation to the same Newton
tolerance (relative 1e-12), so they agree to far better than 1e-9 m.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from maglev_match.analyses.confirmed import CHECK_BELOW
from maglev_match.analyses.critical import (
    FLOW,
    CriticalSize,
    Mechanism,
    critical_derivative,
    critical_from_bisection,
    disturbance_line,
    saddle_landing,
    solve_critical,
    stack_lines,
)
from maglev_match.core.params import Params
from maglev_match.core.reprs import compact_repr
from maglev_match.maglev.base import MaglevModel
from maglev_match.maglev.models import maglev_model

__all__ = ["CriticalStart", "Fallback", "MechanismChange", "FollowedCritical",
           "continue_critical", "continue_criticals", "follow_critical", "follow_grid",
           "describe", "CHECK_STEP",
           "BRACKET", "continue_cycle", "CYCLE_STEP", "CYCLE_CHANGE", "simulated_part",
           "continued_from"]

#: the relative offset of the two check runs below and above a continued size (the same
#: step as the check run below a point-wise solved size)
CHECK_STEP = CHECK_BELOW
#: the corrector looks for the size within this fraction of the prediction (or four
#: times the predicted step, if larger)
BRACKET = 0.02
#: steps per flow of the grazing corrector: a run to its extremum takes tens; a run that
#: goes through a singular limit (gap 0, where the magnet force grows without bound) is
#: cut here instead of at FLOW's 100 000 (it counts as "no extremum" either way)
GRAZING_STEPS = 500
#: the same on a discretised delay system, whose stiff past holds the step near 1e-4 s
#: (tau = 1 ms: 500 steps do not reach the contact at t* ~ 0.06-0.09 s; 20 000 do)
GRAZING_STEPS_DELAY = 20_000


@dataclass(frozen=True)
class CriticalStart:
    """A warm start: a solved :class:`CriticalSize` and the parameter vector (of the
    model's clamped system, the model's parameter order) it was solved at; ``previous``
    the start of the point before it on a sequence (for a secant predictor), or None."""

    __repr__ = compact_repr

    p: np.ndarray
    critical: CriticalSize
    previous: CriticalStart | None = None

    @classmethod
    def of(cls, params: Params | MaglevModel, critical: CriticalSize,
           previous: CriticalStart | None = None) -> CriticalStart | None:
        """The warm start of a solved size at ``params`` (None when it was not solved)."""
        if not critical.solved or critical.size is None or critical.window is None:
            return None
        m = maglev_model(params, critical.model)
        return cls(np.asarray(m.param_vector(), float).copy(), critical, previous)


@dataclass(frozen=True)
class Fallback:
    """Why a continued solve was not taken (the point then got the full search)."""

    direction: int
    mechanism: str  # the neighbour's mechanism that was continued
    reason: str


@dataclass(frozen=True)
class MechanismChange:
    """What decides the critical size changes between points ``index - 1`` and ``index``
    of a sequence (mechanism, gap limit or levitation point): located between those two
    designs."""

    index: int
    direction: int
    before: str  # e.g. 'grazing (upper limit, point 1)'
    after: str
    reason: str  # why the continuation from index - 1 did not hold (or '' if not tried)


@dataclass(frozen=True)
class FollowedCritical:
    """:func:`follow_critical`'s result: ``sizes`` (one :class:`CriticalSize` per point),
    ``how`` per point ('continued' or 'searched'), the ``fallbacks`` (index, Fallback) and
    the located ``changes``."""

    __repr__ = compact_repr

    sizes: tuple[CriticalSize, ...]
    how: tuple[str, ...]
    fallbacks: tuple[tuple[int, Fallback], ...]
    changes: tuple[MechanismChange, ...]

    @property
    def continued(self) -> int:
        return sum(h == "continued" for h in self.how)


def describe(c: CriticalSize) -> str:
    """What decided a critical size, in a few words (mechanism, limit, point)."""
    if not c.solved:
        return str(c.mechanism)
    return f"{c.mechanism} ({c.limit} limit, point {c.point or 1})"


def _key(c: CriticalSize) -> tuple[str, str | None, int]:
    return (str(c.mechanism), c.limit if c.solved else None, (c.point or 1) if c.solved else 1)


def _predict(start: CriticalStart, p: np.ndarray) -> float:
    c = start.critical
    d = float(c.size)
    if (c.dsize_dp is not None and np.size(c.dsize_dp) == p.size
            and np.all(np.isfinite(c.dsize_dp))):
        step = float(np.asarray(c.dsize_dp, float) @ (p - start.p))
        return d + step
    prev = start.previous
    if prev is not None and prev.critical.size is not None:
        dp = start.p - prev.p
        nn = float(dp @ dp)
        if nn > 0:
            # the secant along the previous step, projected on the new step (only as far
            # as a few previous steps: beyond, the neighbour's size is the safer start)
            t = float((p - start.p) @ dp) / nn
            if abs(t) <= 4.0:
                return d + t * (d - float(prev.critical.size))
    return d


def continue_critical(params: Params | MaglevModel, start: CriticalStart, *,
                      model: str = "unit", derivative: bool = False
                      ) -> tuple[CriticalSize | None, Any, Fallback | None]:
    """The critical size of ``start``'s direction at ``params``, continued from the
    neighbouring solved ``start`` (module docstring).

    Returns (size, check, None) on success: ``check`` is the
    :class:`~maglev_match.analyses.simulation.CriticalDisturbance` of the two check runs
    (status 'bracketed', 2 runs); or (None, None, :class:`Fallback`) saying why the
    continuation does not hold here (then the full search is due).
    """
    return continue_criticals(params, [start], model=model, derivative=derivative)[0]


def continue_criticals(params: Params | MaglevModel, starts: Sequence[CriticalStart], *,
                       model: str = "unit", derivative: bool = False
                       ) -> list[tuple[CriticalSize | None, Any, Fallback | None]]:
    """:func:`continue_critical` for several neighbouring solved sizes at the same design
    (the two directions of an index): the grazing correctors of all of them run as one
    batched Newton (one flow per iteration) and all their check runs as one batch of
    simulations, so the pair costs about what one direction did."""
    m = maglev_model(params, model)
    p = np.asarray(m.param_vector(), float)  # (without the delay)
    out: list[Any] = [None] * len(starts)
    work: list[tuple[int, Any, CriticalSize, float]] = []
    for i, start in enumerate(starts):
        c = start.critical
        why = None
        line = disturbance_line(m, c.direction)
        if m.params.tau > 0 and line.hs.dim != m.system().dim:
            why = "a delay (tau > 0): this model's solves are of its delay-free form"
        elif c.model != m.name:
            why = f"the start is of model {c.model}"
        elif p.shape != start.p.shape:
            why = "the parameter vectors differ in size"
        else:
            d0 = _predict(start, p)
            gap_range = float(m.disturbance(c.direction).gap_range)
            if not (0.0 < d0 < gap_range) and start.previous is not None:
                d0 = _predict(replace(start, previous=None), p)  # without the secant
            if not (0.0 < d0 < gap_range):
                why = f"the predicted size {d0 * 1e3:.6g} mm leaves the gap range"
        if why is not None:
            out[i] = (None, None, Fallback(c.direction, str(c.mechanism), why))
        else:
            work.append((i, line, c, d0))
    grazing = [w for w in work if w[2].mechanism == Mechanism.GRAZING]
    solved: dict[int, CriticalSize | str] = dict(zip(
        [w[0] for w in grazing], _grazing(m, grazing), strict=True))
    for i, line, c, d0 in work:
        if i not in solved:
            solved[i] = _basin(m, line, c, d0)
    ready = []
    for i, _, c, _ in work:
        if isinstance(solved[i], str):
            out[i] = (None, None, Fallback(c.direction, str(c.mechanism), solved[i]))
        else:
            ready.append(i)
    checks = _check(m, [solved[i] for i in ready])
    for i, check in zip(ready, checks, strict=True):
        res = solved[i]
        c = starts[i].critical
        if isinstance(check, str):
            out[i] = (None, None, Fallback(c.direction, str(c.mechanism), check))
            continue
        res = replace(res, bracket=(check.largest_return, check.smallest_collision))
        if derivative:
            res = critical_derivative(m, res)
        out[i] = (res, check, None)
    return out


def _grazing(m: MaglevModel, work: list[tuple[int, Any, CriticalSize, float]]
             ) -> list[CriticalSize | str]:
    """The grazing correctors of ``work`` ((index, line, neighbour's size, predicted
    size) per direction, all at the design ``m``), as one batched Newton."""
    from maglev_match.dynamics.escape import solve_grazing

    if not work:
        return []
    lines = [w[1] for w in work]
    cs = [w[2] for w in work]
    d0 = np.array([w[3] for w in work])
    js = [(c.point or 1) - 1 for c in cs]
    sides = np.array([1 if c.limit == "upper" else -1 for c in cs])
    W = np.array([ln.W[j] for ln, j in zip(lines, js, strict=True)])
    L = np.array([(ln.upper if sd > 0 else ln.lower) - ln.g0[j]
                  for ln, j, sd in zip(lines, js, sides, strict=True)])
    wins = np.array([c.window for c in cs], float)
    # a run through the limit has no extremum: the bracket turns such an iterate into its
    # upper end (bisection) instead of a failure
    half = np.maximum(BRACKET * d0, 4.0 * np.abs(d0 - np.array([float(c.size) for c in cs])))
    x0_of, dx0_dd = stack_lines(lines)
    sols = solve_grazing(lines[0].hs, x0_of, dx0_dd, W, L, sides, d0, wins[:, 0],
                         wins[:, 1], p=lines[0].hs.p, bracket=(d0 - half, d0 + half),
                         options=replace(FLOW, max_steps=GRAZING_STEPS_DELAY
                                         if m.params.tau > 0 else GRAZING_STEPS))
    out: list[CriticalSize | str] = []
    for c, sol, d_pred, win in zip(cs, sols, d0, wins, strict=True):
        if not sol.converged:
            out.append(f"grazing not continued: {sol.message}")
            continue
        if sol.singular:
            out.append("grazing not continued: a contact at the singular gap 0")
            continue
        shift = float(sol.t_star) - float(c.t_star)
        out.append(replace(
            c, size=float(sol.size), t_star=float(sol.t_star), iterations=sol.iterations,
            residual=float(sol.residual), window=(win[0] + shift, win[1] + shift),
            dsize_dp=None, dsize_dlimit=None, derivative_available=True, converged=True,
            growth=None, margin_below=None, evidence=None,
            reason=(f"grazing continued from a neighbouring design (predicted "
                    f"{d_pred * 1e3:.7g} mm, Newton {sol.iterations} steps): tangency at the "
                    f"{c.limit} gap limit at t* = {sol.t_star:.5g} s; checked by simulation "
                    f"at 1 -+ {CHECK_STEP:g} of the size")))
    return out


def _basin(m: MaglevModel, line: Any, c: CriticalSize, d0: float) -> CriticalSize | str:
    from maglev_match.dynamics.escape import section_walk, solve_basin_boundary
    from maglev_match.dynamics.hybrid import hybrid_periodic_orbit

    if c.orbit is None or c.window is None:
        return "basin boundary not continued: the neighbour's saddle cycle is not kept"
    orbit = hybrid_periodic_orbit(line.hs, c.orbit.segments, p=line.hs.p)
    if not orbit.converged:
        return f"the saddle cycle did not continue: {orbit.message}"
    mu = np.asarray(orbit.multipliers)
    outside = mu[np.abs(mu) > 1.0 + 1e-6]
    if outside.size != 1 or abs(np.imag(outside[0])) > 1e-9 * abs(outside[0]):
        return (f"the continued cycle has {outside.size} multiplier(s) outside the unit "
                "circle: not a saddle with one unstable direction")
    lnd, info = saddle_landing(line, orbit)
    win = c.window

    def solve(win: tuple[float, float]) -> Any:
        return solve_basin_boundary(line.hs, line.x0_of, line.dx0_dd, lnd["x_star"],
                                    lnd["left"], lnd["normal"], d0, win[0], win[1],
                                    p=line.hs.p, options=FLOW)

    sol = solve(win)
    if not sol.converged:
        # the landing time moves with the size (slowly, near the manifold): the window
        # again from the predicted run's crossings of the new cycle's section, at the
        # neighbour's crossing number
        k = (c.landing or {}).get("crossing")
        walk = section_walk(line.hs, line.x0_of(np.array([d0]))[0], lnd["normal"],
                            lnd["x_star"], win[1] + orbit.period, p=line.hs.p,
                            options=FLOW)
        if k is not None and 0 < k <= len(walk):
            t_k = walk[k - 1][0]
            win = (t_k - 0.25 * orbit.period, t_k + 0.5 * orbit.period)
            sol = solve(win)
    if not sol.converged:
        return f"basin boundary not continued: {sol.message}"
    shift = float(sol.t_land) - float(c.t_star)
    lnd = {**lnd, "distance": sol.distance, "crossing": (c.landing or {}).get("crossing")}
    return replace(
        c, size=float(sol.size), t_star=float(sol.t_land), iterations=sol.iterations,
        residual=float(sol.residual), window=(win[0] + shift, win[1] + shift),
        dsize_dp=None, dsize_dlimit=None, derivative_available=True, converged=True,
        growth=None, margin_below=None, evidence=None, landing=lnd, **info,
        reason=(f"basin boundary continued from a neighbouring design (predicted "
                f"{d0 * 1e3:.7g} mm, Newton {sol.iterations} steps): the critical run lands "
                f"on the stable manifold of the clamped system's saddle cycle (period "
                f"{orbit.period:.4g} s, unstable multiplier {info['multiplier']:.4g}) at "
                f"t = {sol.t_land:.4g} s; checked by simulation at 1 -+ {CHECK_STEP:g} of "
                "the size"))


def _check(m: MaglevModel, sizes_: list[CriticalSize]) -> list[Any]:
    """Two simulations of the limited model at 1 -+ CHECK_STEP of each size (all in one
    batch): the smaller must return, the larger collide at the size's gap limit and point.
    Per size, its :class:`~maglev_match.analyses.simulation.CriticalDisturbance` or why
    not."""
    from maglev_match.analyses.simulation import CriticalDisturbance, Run
    from maglev_match.dynamics.integrate.simulate import (
        COLLISION,
        CONVERGED,
        SimulationOptions,
        simulate_batch,
    )

    if not sizes_:
        return []
    horizon = float(m.critical_search.as_kwargs()["t_max"])
    system, x_ref = m.system(limited=True), m.equilibrium()
    pairs = [np.array([float(r.size) * (1 - CHECK_STEP), float(r.size) * (1 + CHECK_STEP)])
             for r in sizes_]
    lines = {d: m.disturbance(d) for d in {r.direction for r in sizes_}}
    x0 = np.concatenate([lines[r.direction].x0_of(sz)
                         for r, sz in zip(sizes_, pairs, strict=True)])
    if x0.shape[-1] != system.dim:
        x0, x_ref = system.lift(x0), system.lift(x_ref)
    b = simulate_batch(system, x0, horizon, event_fn=m.gap_events(), x_ref=x_ref,
                       options=SimulationOptions(stop_on_converged=True))
    out: list[Any] = []
    for i, (res, sizes) in enumerate(zip(sizes_, pairs, strict=True)):
        lo, hi = 2 * i, 2 * i + 1
        d = float(res.size)
        entry = 2 * ((res.point or 1) - 1) + (1 if res.limit == "upper" else 0)
        code = [int(b.outcome_code[lo]), int(b.outcome_code[hi])]
        if code[0] != CONVERGED:
            what = ("collided at " + ("the upper" if int(b.event_index[lo]) % 2
                                      else "the lower")
                    + f" gap limit at {float(b.event_time[lo]):.4g} s" if code[0] == COLLISION
                    else f"stayed undecided within {horizon:g} s")
            out.append(f"the check run just below the continued size {d * 1e3:.7g} mm {what}: "
                       "another contact or set decides here")
            continue
        if code[1] != COLLISION or int(b.event_index[hi]) != entry:
            out.append(f"the check run just above the continued size {d * 1e3:.7g} mm did "
                       f"not collide at the {res.limit} gap limit of point {res.point or 1}: "
                       "the condition no longer separates return from collision here")
            continue
        runs = tuple(Run(size=float(s), outcome=o, time=t,
                         margins=tuple(float(v) for v in b.min_event_value[k]),
                         event=int(b.event_index[k]) if o == "collision" else -1)
                     for k, s, o, t in ((lo, sizes[0], "return", float(b.converged_time[lo])),
                                        (hi, sizes[1], "collision", float(b.event_time[hi]))))
        out.append(CriticalDisturbance(
            direction=res.direction, largest_return=float(sizes[0]),
            smallest_collision=float(sizes[1]), critical=float(sizes.mean()),
            status="bracketed", gap_range=float(lines[res.direction].gap_range),
            tol=float(sizes[1] - sizes[0]), runs=2, unresolved=0, unresolved_sizes=(),
            horizon=horizon, rounds=1, collision_time=float(b.event_time[hi]),
            nonmonotone=False, samples=runs))
    return out


def follow_critical(params_list: Sequence[Params | MaglevModel], direction: int, *,
                    model: str = "unit", derivative: bool = False,
                    start: CriticalStart | None = None,
                    bisection_kwargs: dict[str, Any] | None = None) -> FollowedCritical:
    """The critical size of ``direction`` along a sequence of neighbouring designs (a map
    row, a path in a design search): the first point (unless ``start`` is given) by the
    full search, every next one continued from its neighbour
    (:func:`continue_critical`) where the neighbour was solved, else by the full search.
    Every fall-back is recorded with why, and every change of what decides the size
    (mechanism, gap limit, levitation point) between two neighbours is located
    (:class:`MechanismChange`). The predictor is the derivative at a searched point (it
    is computed there) and the secant of the last two points after a continued one;
    ``derivative``: also dsize/dp at every continued point (then the predictor uses it)."""
    sizes: list[CriticalSize] = []
    how: list[str] = []
    fallbacks: list[tuple[int, Fallback]] = []
    changes: list[MechanismChange] = []
    prev_c = None if start is None else start.critical
    for k, params in enumerate(params_list):
        m = maglev_model(params, model)
        res, why = None, None
        if start is not None:
            res, _, why = continue_critical(m, start, model=model, derivative=derivative)
        if res is None:
            # (with its derivative: the predictor of the next point)
            res = solve_critical(m, direction, model=model, derivative=True,
                                 bisection_kwargs=bisection_kwargs)
            how.append("searched")
            if why is not None:
                fallbacks.append((k, why))
        else:
            how.append("continued")
        if prev_c is not None and _key(prev_c) != _key(res):
            changes.append(MechanismChange(k, direction, describe(prev_c), describe(res),
                                           "" if why is None else why.reason))
        sizes.append(res)
        same = start is not None and _key(start.critical) == _key(res)
        start = CriticalStart.of(m, res, previous=start if same else None)
        prev_c = res
    return FollowedCritical(tuple(sizes), tuple(how), tuple(fallbacks), tuple(changes))


def follow_grid(rows: Sequence[Sequence[Params | MaglevModel]], direction: int, *,
                model: str = "unit", derivative: bool = False) -> list[FollowedCritical]:
    """:func:`follow_critical` along every row of a grid of designs (rows of neighbouring
    designs, each row next to the one before): the first point of a row is continued from
    the first point of the row below (where that was solved), the rest along the row.
    Changes are located within each row (their ``index``) and, for a row's first point,
    against the first point of the row below."""
    out: list[FollowedCritical] = []
    below: CriticalStart | None = None
    for row in rows:
        f = follow_critical(row, direction, model=model, derivative=derivative, start=below)
        out.append(f)
        below = CriticalStart.of(row[0], f.sizes[0]) if len(row) else None
    return out


#: the paper's cycle is continued from a neighbouring design only when no model parameter
#: moved by more than this fraction of its value ...
CYCLE_STEP = 0.05
#: ... and the continued cycle's period and largest gap deviation moved by at most this
#: fraction of the neighbour's
CYCLE_CHANGE = 0.1


def continue_cycle(system: Any, p: np.ndarray, cycle: Any, hopf_param: str,
                   hopf_value: float, x_eq: np.ndarray, *, limits: Any = None
                   ) -> tuple[Any, Any] | str:
    """The basin-bounding unstable cycle at the parameter vector ``p``, continued from
    ``cycle`` (a :class:`~maglev_match.dynamics.cycles.CyclePoint`: the bounding cycle at a
    neighbouring design, its orbit's parameter vector) instead of found again from a Hopf
    point: the Hopf point of the neighbour (``hopf_param`` = ``hopf_value``) refined at the
    new parameters (the frequency guess from the Jacobian there; ``x_eq`` the equilibrium),
    then the periodic BVP solved by collocation Newton at the new parameters from the
    neighbour's cycle (:func:`~maglev_match.dynamics.cycles.correct_cycle`, on its mesh).

    The stretch rules that keep it the same cycle and the same reading: every model
    parameter within :data:`CYCLE_STEP` of the neighbour's (relative); the Hopf point
    converged and still on the same side of the design; Newton converged with reliable
    multipliers and as many outside the unit circle as the neighbour's; the period and the
    largest gap deviation within :data:`CYCLE_CHANGE` of the neighbour's; and the cycle
    inside the limits (``limits(system, orbit)``: margins, positive inside). Returns
    (cycle point, Hopf point), or why the continuation does not hold (then the full
    search is due)."""
    from dataclasses import replace as dc_replace

    from maglev_match.dynamics.cycles import correct_cycle
    from maglev_match.dynamics.hopf import refine_hopf_point

    p = np.asarray(p, float)
    prev = np.asarray(cycle.orbit.p, float)
    if p.shape != prev.shape:
        return "the parameter vectors differ in size"
    moved = np.abs(p - prev)
    rel = np.where(prev != 0, moved / np.where(prev != 0, np.abs(prev), 1.0),
                   np.where(moved > 0, np.inf, 0.0))
    if float(np.max(rel)) > CYCLE_STEP:
        return (f"a parameter moved by {float(np.max(rel)):.3g} of its value (more than "
                f"{CYCLE_STEP:g})")
    ip = system.param_index(hopf_param)
    v, v_prev = float(p[ip]), float(prev[ip])
    ph = p.copy()
    ph[ip] = hopf_value
    x = np.asarray(x_eq, float)
    J = np.asarray(system.derivatives.jacobian_batch(x[None], ph[None]))[0]
    w = np.linalg.eigvals(J)
    w = w[w.imag > 0]
    if not w.size:
        return "no complex eigenvalue pair at the neighbour's Hopf point"
    om = float(w[int(np.argmin(np.abs(w.real)))].imag)
    hp = refine_hopf_point(system, hopf_param, float(hopf_value), x, om, p=ph,
                           value_scale=max(abs(hopf_value), abs(v)))
    if not hp.converged:
        return "the neighbour's Hopf point did not continue to the new parameters"
    if (v - hp.value) * (v_prev - hopf_value) <= 0:
        return "the design and the Hopf point changed sides"
    res = correct_cycle(system, dc_replace(cycle.orbit, p=p.copy()), hopf_param, v)
    if not res.converged or res.point is None:
        return f"the cycle did not continue: {res.message}"
    pt = res.point
    if not pt.reliable or pt.n_unstable != cycle.n_unstable:
        return (f"the continued cycle has {pt.n_unstable} unstable multiplier(s) "
                f"(the neighbour's {cycle.n_unstable}) or unreliable multipliers")
    if abs(pt.period - cycle.period) > CYCLE_CHANGE * cycle.period:
        return f"the period moved from {cycle.period:.4g} s to {pt.period:.4g} s"
    g_new = float(pt.extrema["gap_deviation"][0])
    g_old = float(cycle.extrema["gap_deviation"][0])
    if abs(g_new - g_old) > CYCLE_CHANGE * abs(g_old):
        return f"the cycle's largest gap deviation moved from {g_old:.4g} m to {g_new:.4g} m"
    if limits is not None and min(limits(system, pt.orbit).values()) <= 0:
        return "the continued cycle reaches a limit"
    return pt, hp


def simulated_part(m: MaglevModel, near: Any, kw: dict[str, Any], solve: bool,
                   say: Callable[[str], None]) -> tuple[Any, Any, Any, dict]:
    """The index's simulated part: the critical disturbance of both directions (continued
    from ``near`` where it holds, else bracketed) and, with ``solve``, the solved critical
    condition of each; returns (up, down, solved, continuation per direction). ``near``:
    a :class:`~maglev_match.analyses.matching.MatchingIndex` or None. It needs nothing of
    the index's paper part, so the index may run it beside that part
    (:mod:`maglev_match.core.beside`)."""
    from maglev_match.analyses.simulation import critical_disturbance

    cont = continued_from(m, near) if solve and near is not None else {}
    up, c_up, _ = cont.get(-1, (None, None, ""))
    down, c_down, _ = cont.get(1, (None, None, ""))
    if up is None or down is None:
        say("the critical disturbance: bracketing both directions with simulations ...")
    up = up if up is not None else critical_disturbance(m, direction=-1, **kw)
    down = down if down is not None else critical_disturbance(m, direction=1, **kw)
    solved = None
    if solve:
        say("the critical disturbance: solving the grazing or basin-boundary condition ...")
        at = np.asarray(m.param_vector(), float)
        if c_up is None:
            c_up = replace(critical_from_bisection(m, up), at=at)
        if c_down is None:
            # the saddle cycle of a basin boundary is the same set for both directions
            c_down = replace(critical_from_bisection(m, down, orbit_hint=c_up.orbit), at=at)
        solved = (c_up, c_down)
    return up, down, solved, cont


def continued_from(m: MaglevModel, near: Any) -> dict[int, tuple[Any, Any, str]]:
    """The critical sizes of ``near`` continued to the model ``m``, per direction:
    (check search, size, '') where the continuation holds, (None, None, why) where not.
    ``near``: a :class:`~maglev_match.analyses.matching.MatchingIndex`."""
    out: dict[int, tuple[Any, Any, str]] = {}
    at = np.asarray(m.param_vector(), float)
    todo = []
    for d, c in ((-1, near.critical_up), (1, near.critical_down)):
        if c is None or not c.solved or c.at is None or c.window is None:
            continue
        if c.model != m.name or np.shape(c.at) != at.shape:
            out[d] = (None, None, f"the neighbour is of model {c.model}")
            continue
        # a neighbour that was itself continued remembers its own neighbour: the secant
        # through the two predicts the size here (one Newton step fewer than from the
        # neighbour's size alone)
        prev = (None if c.previous is None or c.size is None else
                CriticalStart(np.asarray(c.previous[0]), replace(c, size=c.previous[1])))
        todo.append((d, CriticalStart(np.asarray(c.at), c, prev)))
    # both directions at once: one batched corrector and one batch of check runs
    done = continue_criticals(m, [s for _, s in todo], model=m.name)
    for (d, start), (size, check, why) in zip(todo, done, strict=True):
        out[d] = ((check, replace(size, at=at, previous=(start.p, float(start.critical.size))),
                   "") if size is not None else (None, None, why.reason))
    return out
