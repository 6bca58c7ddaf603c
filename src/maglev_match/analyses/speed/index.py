"""The matching index at speed, chi(v), defined so that it is the standstill index at v -> 0
(:class:`SpeedIndex`, :func:`index_at_speed`).

While the vehicle runs on the periodic response, the span under the centre of its layout is
suddenly displaced in its first mode so that the mean deflection under the vehicle jumps by d
(the unit: the mean over its footprint, the deflection its gap sees; the vehicle: the mean
over its six levitation points); every other state stays on the periodic response. The
standstill index's disturbance of model A is exactly this with the vehicle standing at
mid-span: x5(0) = w(0) - w0 = direction * d, everything else at the equilibrium
(:meth:`maglev_match.maglev.models.UnitModel.disturbance`). Runs with the physical limits on
(the coil current clamped at zero, a gap leaving [gap_min, gap_max] a collision) continue span
after span until the state at a hand-over is back within ``return_tol`` of the periodic
response, or a gap leaves its range, or ``spans`` spans have passed (undecided: left out).

Both directions: beam down (+1, the gaps close) and beam up (-1). The sizes cover the whole
gap range of the position: the size that would put a gap on its limit at the moment of the
disturbance if the vehicle did not respond (the last size tried lies half a tolerance inside
it). Batched rounds bracket the critical size; where the smallest collision is a grazing
contact (the run just below it came within a few bracket widths of the same limit) the size
is solved by the secant on the smallest gap margin of the runs that return (the margin is a
smooth function of d near a tangency, zero at the critical size), kept only inside the
bracket. h at a position is the smaller direction; h(v) the smallest over the positions of
the centre in the span (fractions ``positions``, default the quarter points and mid-span);
chi(v) = h(v) / w0 with the standstill index's w0. A direction in which every size up to
the gap range returned is reported as such (``all_return``): its size is the gap range, as
the standstill index counts it, and the result says so; it is never a bracket's end."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from maglev_match.analyses.speed.options import SpeedOptions, w0_of
from maglev_match.analyses.speed.passage import passage_problem, passage_states
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.integrate.passage import PassageProblem
from maglev_match.dynamics.integrate.simulate import (
    EventsWithArgs,
    SimulationOptions,
    simulate_batch,
)
from maglev_match.maglev import moving as mv
from maglev_match.maglev import moving_delay as md
from maglev_match.maglev.moving import MovingModel

__all__ = ["POSITIONS", "IndexDirection", "IndexPosition", "SpeedIndex", "index_at_speed",
           "position_time", "check_positions", "solve_grazing", "direction_text"]

#: positions of the layout's centre in the span (fractions of L) where the index is taken
POSITIONS = (0.25, 0.5, 0.75)
#: the run just below the smallest collision came within this many bracket widths of the
#: same limit: a grazing contact, solved by the secant on the smallest margin
TANGENCY = 20.0
_COLLISION, _FAILED = 1, 3


@dataclass(frozen=True)
class IndexDirection:
    """The critical jump d of the mean deflection under the vehicle, in one direction.

    direction : +1 beam down (the gaps close), -1 beam up. status : 'solved' (the grazing
    size solved inside the bracket), 'bracketed', 'all_return' (every size up to the gap
    range returned), 'all_collide', 'open' (not bracketed: undecided runs). size : the
    supported size (m): the solved or bracketed critical size, the gap range for
    'all_return', 0 for 'all_collide', for 'open' the largest size seen to return (None if
    none). largest_return, smallest_collision : the bracket (m). gap_range (m).
    collision_time : time of the smallest collision after the jump (s). limit : 'lower' or
    'upper' gap limit hit. runs, unresolved : runs made, runs left undecided."""

    direction: int
    status: str
    size: float | None
    largest_return: float | None
    smallest_collision: float | None
    gap_range: float
    tol: float
    collision_time: float | None
    limit: str | None
    runs: int
    unresolved: int
    message: str = ""

    @property
    def every_size_returned(self) -> bool:
        return self.status == "all_return"


@dataclass(frozen=True)
class IndexPosition:
    """Both directions at one position of the layout's centre: ``fraction`` of the span,
    ``time`` in the passage (s), ``slot`` 'A' or 'B' (the span displaced), ``shape`` the
    mean under the vehicle of that span's first mode; h the smaller supported size (m; None
    when a direction supports none)."""

    fraction: float
    time: float
    slot: str
    shape: float
    down: IndexDirection
    up: IndexDirection

    @property
    def h(self) -> float | None:
        sizes = [self.down.size, self.up.size]
        return None if any(s is None for s in sizes) else float(min(sizes))  # type: ignore

    @property
    def deciding(self) -> IndexDirection:
        """The direction that sets h (the down direction on a tie)."""
        if self.up.size is not None and (self.down.size is None
                                         or self.up.size < self.down.size):
            return self.up
        return self.down


@dataclass(frozen=True)
class SpeedIndex:
    """chi(v) at one speed: h (m) the smallest supported size over the positions and
    directions, chi = h / w0 (NaN when a position is unresolved), ``fraction`` and
    ``direction`` of the position and direction that decide it, ``every_size_returned`` when
    the deciding direction returned at every size up to its gap range (then h is that range,
    as the standstill index counts it), ``positions`` the details."""

    __repr__ = compact_repr

    h: float
    w0: float
    chi: float
    fraction: float | None
    direction: int | None
    every_size_returned: bool
    positions: tuple[IndexPosition, ...]

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> SpeedIndex:
        d = dict(d)
        d["positions"] = tuple(
            IndexPosition(**{**q, "down": IndexDirection(**q["down"]),
                             "up": IndexDirection(**q["up"])}) for q in d["positions"])
        return cls(**d)

    def status_text(self) -> str:
        """One line per position and direction, in words (text output)."""
        out = []
        for q in self.positions:
            for c, word in ((q.down, "beam down"), (q.up, "beam up")):
                out.append(f"centre at {q.fraction:g} L, {word}: {direction_text(c)}")
        return "; ".join(out)


def direction_text(c: IndexDirection) -> str:
    """What one direction's search found, in words."""
    mm = 1e3
    if c.status == "all_return":
        return f"every size up to the gap range ({c.gap_range * mm:.4g} mm) returned"
    if c.status == "all_collide":
        return "even the smallest size collided"
    if c.status in ("solved", "bracketed"):
        how = "grazing solved" if c.status == "solved" else "bracketed"
        return f"{c.size * mm:.5g} mm ({how})"  # type: ignore[operator]
    lr = "none" if c.largest_return is None else f"{c.largest_return * mm:.4g} mm"
    sc = "none" if c.smallest_collision is None else f"{c.smallest_collision * mm:.4g} mm"
    return (f"open ({c.unresolved} run(s) undecided; largest return {lr}, smallest "
            f"collision {sc})")


def check_positions(positions) -> tuple[float, ...]:
    """The positions as a tuple of fractions in [0, 1) (ParameterError otherwise)."""
    pos = tuple(positions)
    if not pos:
        raise ParameterError("positions", pos, "must name at least one position")
    for f in pos:
        if (isinstance(f, bool) or not isinstance(f, int | float) or not math.isfinite(f)
                or not 0.0 <= f < 1.0):
            raise ParameterError("positions", f, "each must be a fraction of the span in "
                                 "[0, 1)")
    return tuple(float(f) for f in pos)


def position_time(params: Params, kind: MovingModel, v: float, fraction: float
                  ) -> tuple[float, str]:
    """(time in the passage (s), slot) at which the centre of the layout is ``fraction`` of
    a span past a support: on slot B while the layout's front is within the passage, else on
    slot A (the front at t = 0 is at the support between A and B)."""
    L = float(params.L)
    half = 0.5 * mv.layout_of(params, kind).extent
    if fraction * L + half < L:
        return (fraction * L + half) / v, "B"
    return (fraction * L - L + half) / v, "A"


def _segment_at(problem: PassageProblem, t: float) -> int:
    bounds = np.concatenate([problem.starts, [problem.period]])
    return int(np.clip(np.searchsorted(bounds, t, side="right") - 1, 0,
                       len(problem.segments) - 1))


@dataclass
class _Runs:
    """Outcome of a batch of disturbed runs: state per run 1 returned, 2 collided, 3 failed,
    0 undecided; collision time after the jump, event entry, smallest margin per entry."""

    state: np.ndarray
    t_hit: np.ndarray
    i_hit: np.ndarray
    gmin: np.ndarray


def _run_batch(problem: PassageProblem, sys_l, events, sim, X0: np.ndarray, t_from: float,
               x_periodic: np.ndarray, spans: int, return_tol: float) -> _Runs:
    """Runs from the states X0 at passage time ``t_from``: the rest of that passage, then
    whole passages, until each has returned (at a hand-over within ``return_tol`` of the
    periodic response), collided, failed or used ``spans`` passages."""
    b = X0.shape[0]
    n = problem.n
    scale = problem.scale
    state = np.zeros(b, int)
    t_hit = np.full(b, np.nan)
    i_hit = np.full(b, -1)
    gmin = None
    X = np.array(X0, float)
    elapsed = 0.0
    bounds = np.concatenate([problem.starts, [problem.period]])
    for span in range(spans):
        start = t_from if span == 0 else 0.0
        X[:, -1] = start
        for k, seg in enumerate(problem.segments):
            if bounds[k + 1] <= start:
                continue
            t0 = max(bounds[k], start)
            dur = float(bounds[k + 1] - t0)
            park = np.array(x_periodic, float)
            res = simulate_batch(sys_l, X, dur, p=seg.p, event_fn=events, x_ref=park,
                                 options=sim)
            live = state == 0
            g = np.asarray(res.min_event_value, float)
            g = np.where(live[:, None], g, np.inf)
            gmin = g if gmin is None else np.minimum(gmin, g)
            hit = (res.outcome_code == _COLLISION) & live
            bad = ((res.outcome_code == _FAILED)
                   | ~np.all(np.isfinite(res.final_state), axis=1)) & live & ~hit
            t_hit[hit] = elapsed + (t0 - start) + res.event_time[hit]
            i_hit[hit] = res.event_index[hit]
            state[hit] = 2
            state[bad] = 3
            X = np.array(res.final_state, float)
            X[:, -1] = t0 + dur
            X[state != 0] = x_periodic  # parked (cheap to integrate, the batch keeps its size)
            X[state != 0, -1] = t0 + dur
        elapsed += problem.period - start
        Xn = np.concatenate([X[:, :n] @ problem.jump.T, np.zeros((b, 1))], axis=1)
        dist = np.max(np.abs(Xn[:, :n] - x_periodic[None, :n]) / scale[None, :], axis=1)
        state[(state == 0) & (dist < return_tol)] = 1
        X = Xn
        if np.all(state != 0):
            break
    return _Runs(state, t_hit, i_hit, gmin if gmin is not None else np.zeros((b, 0)))


def solve_grazing(bracket, seen, run, tol: float, nb: int, rounds: int = 6,
                  width: float = 1e-8) -> tuple[dict[int, float], dict[int, str]]:
    """The grazing size of each bracketed direction, both directions in one batch per
    round: the secant on the smallest margin (to the limit the smallest collision hits) of
    the two largest returning runs below the bracket gives an estimate (the margin of a run
    just below a tangency is a smooth function of d, zero at the critical size); ``nb``
    sizes spaced by 1/50 of the bracket per size around it narrow the bracket, until it is
    below ``width`` (m). Returns ({direction: size}, {direction: why not solved})."""
    solving = {}
    why: dict[int, str] = {}
    for d in (+1, -1):
        lo, hi = bracket(d)
        if lo is not None and hi is not None and hi - lo <= tol * 1.0000001:
            solving[d] = seen[d][hi][2]
    done: dict[int, float] = {}
    for _ in range(rounds):
        trials = {+1: np.zeros(0), -1: np.zeros(0)}
        for d, entry in list(solving.items()):
            lo, hi = bracket(d)
            w = hi - lo
            if seen[d][hi][2] != entry:
                why[d] = "a different limit decides near the bracket"
            elif w <= width:
                done[d] = 0.5 * (lo + hi)
            else:
                ret = sorted((s, float(o[3][entry])) for s, o in seen[d].items()
                             if o[0] == "return" and s < hi)
                if len(ret) < 2:
                    why[d] = "fewer than two returning runs below the bracket"
                else:
                    (s1, g1), (s2, g2) = ret[-2], ret[-1]
                    if not (g1 > g2 > 0):
                        why[d] = "the smallest margin does not fall towards the bracket"
                    elif g2 > TANGENCY * max(w, tol):
                        why[d] = "the run below the bracket stayed far from the limit"
                    else:
                        est = s2 + g2 * (s2 - s1) / (g1 - g2)
                        if not lo - w < est < hi + w:
                            why[d] = "the secant left the bracket"
                        else:
                            step = w / (50.0 * nb)
                            t = est + step * (np.arange(nb) - 0.5 * (nb - 1))
                            t = t[(t > lo) & (t < hi)]
                            if t.size == 0:
                                t = np.array([lo + 0.5 * w])
                            trials[d] = t
                            continue
            del solving[d]
        if not solving:
            break
        run(trials)
    for d in solving:
        lo, hi = bracket(d)
        if hi - lo <= width:
            done[d] = 0.5 * (lo + hi)
        else:
            why[d] = f"the secant did not converge in {rounds} rounds"
    return done, why


def _position(params: Params, kind: MovingModel, v: float, sol, fraction: float,
              opts: SpeedOptions, problem_l: PassageProblem, events, sim) -> IndexPosition:
    """Both directions at one position (module docstring)."""
    t_pos, slot = position_time(params, kind, v, fraction)
    k = _segment_at(sol.problem, t_pos)
    x_pos = passage_states(sol.problem, sol.run.starts, np.array([t_pos]), opts)[0]
    p_seg = sol.problem.segments[k].p
    sys_ = sol.problem.system
    sl = mv.slot_slices(kind, params.n_modes)
    iq = sl["qA" if slot == "A" else "qB"].start
    dev0 = np.atleast_1d(np.asarray(sys_.observe("gap_deviation", x_pos, p_seg), float))
    e = np.zeros_like(x_pos)
    e[iq] = 1.0
    # w_j = sum G q is linear in q: the deflection per metre of the first modal coordinate
    dev1 = np.atleast_1d(np.asarray(sys_.observe("gap_deviation", x_pos + e, p_seg), float))
    dw = dev0 - dev1
    shape = float(np.mean(dw))
    if not shape > 0:
        raise FloatingPointError(f"the span under the centre at {fraction:g} L carries no "
                                 "load")
    step = e / shape  # per metre of the mean deflection under the vehicle
    rel = dw / shape  # gap change per metre of d, per point
    c0 = float(params.c0)
    room = {+1: c0 + dev0 - params.gap_min, -1: params.gap_max - c0 - dev0}
    ranges = {d: float(np.min(room[d][rel > 0] / rel[rel > 0])) for d in (+1, -1)}
    nb = opts.critical_sizes
    tol = float(opts.critical_tol)
    seen: dict[int, dict[float, tuple[str, float, int, Any]]] = {+1: {}, -1: {}}
    runs = {+1: 0, -1: 0}
    unresolved = {+1: 0, -1: 0}

    def run(sizes: dict[int, np.ndarray]) -> None:
        dirs = [d for d in (+1, -1) if sizes[d].size]
        if not dirs:
            return
        batch = np.concatenate([np.full(sizes[d].size, d) for d in dirs])
        size = np.concatenate([sizes[d] for d in dirs])
        X0 = x_pos[None, :] + (batch * size)[:, None] * step[None, :]
        pad = max(2 * nb - batch.size, 0)  # one batch size: one compiled integrator
        X0 = np.concatenate([X0, np.repeat(x_pos[None, :], pad, axis=0)])
        r = _run_batch(problem_l, problem_l.system, events, sim, X0, t_pos, sol.x0,
                       opts.spans, opts.return_tol)
        for j, d in enumerate(batch):
            d = int(d)
            runs[d] += 1
            s = float(size[j])
            if r.state[j] == 1:
                seen[d][s] = ("return", math.nan, -1, np.array(r.gmin[j], float))
            elif r.state[j] == 2:
                seen[d][s] = ("collision", float(r.t_hit[j]), int(r.i_hit[j]), None)
            else:
                unresolved[d] += 1

    def bracket(d: int) -> tuple[float | None, float | None]:
        coll = [s for s, o in seen[d].items() if o[0] == "collision"]
        hi = min(coll) if coll else None
        ret = [s for s, o in seen[d].items() if o[0] == "return" and (hi is None or s < hi)]
        return (max(ret) if ret else None), hi

    # round 1: the whole gap range, the last size half a tolerance inside its end
    first = {}
    for d in (+1, -1):
        s = ranges[d] * np.arange(1, nb + 1) / nb
        s[-1] = max(ranges[d] - 0.5 * tol, 0.5 * (s[-2] if nb > 1 else 0.0) + 0.5 * s[-1])
        first[d] = s
    run(first)
    rounds = 1
    while rounds < opts.critical_rounds + 2:  # bracket to tol (the grazing solve refines)
        nxt = {}
        for d in (+1, -1):
            lo, hi = bracket(d)
            a = 0.0 if lo is None else lo
            if hi is None or hi - a <= tol:
                nxt[d] = np.zeros(0)
            else:
                nxt[d] = a + (hi - a) * np.arange(1, nb + 1) / (nb + 1)
        if not any(s.size for s in nxt.values()):
            break
        run(nxt)
        rounds += 1

    solved, why = solve_grazing(bracket, seen, run, tol, nb)
    out = {}
    for d in (+1, -1):
        lo, hi = bracket(d)
        t_hit = None if hi is None else seen[d][hi][1]
        limit = None
        if hi is not None:
            limit = "lower" if seen[d][hi][2] % 2 == 0 else "upper"
        msg = ""
        if hi is None:
            status = "all_return" if lo is not None and unresolved[d] == 0 else "open"
            size = ranges[d] if status == "all_return" else lo
        elif lo is None:
            status = "all_collide" if hi <= tol * 1.0000001 else "open"
            size = 0.0 if status == "all_collide" else None
        elif hi - lo > tol * 1.0000001:
            status, size = "open", lo
        elif d in solved:
            status, size = "solved", solved[d]
        else:
            status, size = "bracketed", 0.5 * (lo + hi)
            msg = f"grazing not solved: {why.get(d, 'not tried')}"
        out[d] = IndexDirection(d, status, None if size is None else float(size), lo, hi,
                                ranges[d], tol, t_hit, limit, runs[d], unresolved[d], msg)
    return IndexPosition(float(fraction), float(t_pos), slot, shape, out[+1], out[-1])


def index_at_speed(params: Params, model: str, v: float, sol,
                   opts: SpeedOptions | None = None,
                   positions=POSITIONS) -> SpeedIndex:
    """chi(v) at speed v (m/s > 0) from the periodic response ``sol``
    (:func:`~maglev_match.analyses.speed.point.periodic_response`): the module docstring."""
    opts = opts or SpeedOptions()
    kind = MovingModel(model)
    pos = check_positions(positions)
    problem_l = passage_problem(params, kind, v, limited=True)
    events = EventsWithArgs(md.gap_events_for(problem_l.system, kind, params.n_modes),
                            (float(params.gap_min), float(params.gap_max)))
    sim = SimulationOptions(rtol=opts.critical_rtol, atol=opts.critical_rtol,
                            max_steps=1_000_000, unroll_stages=False)
    found = tuple(_position(params, kind, v, sol, f, opts, problem_l, events, sim)
                  for f in pos)
    w0 = w0_of(params, kind)
    hs = [q.h for q in found]
    if any(h is None for h in hs):
        return SpeedIndex(math.nan, w0, math.nan, None, None, False, found)
    k = int(np.argmin(hs))
    q = found[k]
    c = q.deciding
    h = float(hs[k])  # type: ignore[arg-type]
    return SpeedIndex(h, w0, h / w0 if w0 > 0 else math.nan, q.fraction, c.direction,
                      c.every_size_returned, found)
