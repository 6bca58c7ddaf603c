"""The critical disturbance at speed: the largest initial deflection d of the span the
vehicle is entering (its first mode, mid-span deflection d, at rest) from which runs with
the physical limits on (current clamp, gap range) return to the periodic response without
contact, in both directions (beam down: the gap closes; beam up: it opens), found by
bracketing on batched runs like the standstill simulation (:class:`SpeedCritical`,
:func:`critical_disturbance_at_speed`). h(v) is the smaller of the two, and
chi(v) = h(v) / w0 with w0 the standstill index's static deflection of the same model
(:mod:`maglev_match.analyses.speed.point`)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from maglev_match.analyses.speed.options import SpeedOptions
from maglev_match.analyses.speed.passage import passage_problem
from maglev_match.core.params import Params
from maglev_match.dynamics.integrate.passage import run_passages_batch
from maglev_match.dynamics.integrate.simulate import EventsWithArgs, SimulationOptions
from maglev_match.maglev import moving as mv
from maglev_match.maglev import moving_delay as md
from maglev_match.maglev.moving import MovingModel

__all__ = ["CriticalStatus", "SpeedCritical", "critical_disturbance_at_speed"]


class CriticalStatus(StrEnum):
    """How a critical-disturbance search ended (as the standstill search)."""

    BRACKETED = "bracketed"
    ALL_COLLIDE = "all_collide"
    ALL_RETURN = "all_return"
    OPEN = "open"
    NOT_COMPUTED = "not_computed"


@dataclass(frozen=True)
class SpeedCritical:
    """The critical initial deflection of the span being entered, in one direction.

    direction : +1 beam down (mid-span deflection d > 0: the gaps close), -1 beam up.
    status : 'bracketed', 'all_collide', 'all_return', 'open' or 'not_computed'.
    critical : the bracket's midpoint (m) or None; largest_return, smallest_collision (m).
    gap_range : the largest size searched (m): the deflection that would put a gap on its
        limit if the vehicle did not respond (c0 - gap_min down, gap_max - c0 up).
    runs : simulated runs; unresolved : runs neither back within ``spans`` spans nor
    collided; spans : the spans allowed; collision_time : time (s from the disturbed span's
    entry) of the collision at ``smallest_collision``; message : why not computed."""

    direction: int
    status: str
    critical: float | None
    largest_return: float | None
    smallest_collision: float | None
    gap_range: float
    tol: float
    runs: int
    unresolved: int
    spans: int
    rounds: int
    collision_time: float | None
    message: str = ""

    def supported(self) -> float | None:
        """The size this search supports (m), by the standstill index's rule: the bracket's
        midpoint, the whole range when every size returned, 0 when every size collided, for
        an open search the largest size seen to return (None if none)."""
        if self.status == CriticalStatus.ALL_RETURN:
            return float(self.gap_range)
        if self.status == CriticalStatus.ALL_COLLIDE:
            return 0.0
        if self.status == CriticalStatus.BRACKETED:
            return float(self.critical)  # type: ignore[arg-type]
        return None if self.largest_return is None else float(self.largest_return)


def critical_disturbance_at_speed(params: Params, kind: MovingModel, v: float,
                                  x_periodic: np.ndarray, opts: SpeedOptions
                                  ) -> tuple[SpeedCritical, SpeedCritical]:
    """Both directions of the critical disturbance at speed (module docstring). Each round
    runs ``critical_sizes`` sizes per direction in one vmapped batch, span after span, until
    every run has returned (state at a hand-over within ``return_tol`` of the periodic
    response), collided or used ``spans`` spans; the bracket shrinks by
    ``critical_sizes + 1`` per round."""
    problem = passage_problem(params, kind, v, limited=True)
    sys_l = problem.system
    events = EventsWithArgs(md.gap_events_for(sys_l, kind, params.n_modes),
                            (float(params.gap_min), float(params.gap_max)))
    sim = SimulationOptions(rtol=opts.critical_rtol, atol=opts.critical_rtol,
                            max_steps=1_000_000, unroll_stages=False)
    sl = mv.slot_slices(kind, params.n_modes)
    iq = sl["qB"].start  # first mode of the span being entered
    n = problem.n
    scale = problem.scale
    ranges = {+1: params.c0 - params.gap_min, -1: params.gap_max - params.c0}
    seen: dict[int, dict[float, tuple[str, float]]] = {+1: {}, -1: {}}
    unresolved = {+1: 0, -1: 0}
    runs = {+1: 0, -1: 0}
    nb = opts.critical_sizes

    def run_round(sizes: dict[int, np.ndarray]) -> None:
        dirs = [d for d in (+1, -1) if sizes[d].size]
        batch = np.concatenate([np.full(sizes[d].size, d) for d in dirs])
        size = np.concatenate([sizes[d] for d in dirs])
        X = np.tile(x_periodic, (batch.size, 1))
        X[:, iq] += batch * size
        state = np.zeros(batch.size, int)  # 0 running, 1 returned, 2 collided
        t_hit = np.full(batch.size, np.nan)
        for span in range(opts.spans):
            out = run_passages_batch(problem, X, x_periodic, system=sys_l, events=events,
                                     simulation=sim)
            new_hit = out.collided & (state == 0)
            state[new_hit] = 2
            t_hit[new_hit] = span * problem.period + out.event_time[new_hit]
            state[out.failed & (state == 0)] = 3
            dist = np.max(np.abs(out.x_next[:, :n] - x_periodic[None, :n]) / scale[None, :],
                          axis=1)
            state[(state == 0) & (dist < opts.return_tol)] = 1
            X = out.x_next
            X[state != 0] = x_periodic
            if np.all(state != 0):
                break
        for k, d in enumerate(batch):
            d = int(d)
            runs[d] += 1
            if state[k] == 1:
                seen[d][float(size[k])] = ("return", float("nan"))
            elif state[k] == 2:
                seen[d][float(size[k])] = ("collision", float(t_hit[k]))
            else:
                unresolved[d] += 1

    def bracket(d: int) -> tuple[float | None, float | None]:
        coll = [s for s, (o, _) in seen[d].items() if o == "collision"]
        hi = min(coll) if coll else None
        ret = [s for s, (o, _) in seen[d].items() if o == "return" and (hi is None or s < hi)]
        return (max(ret) if ret else None), hi

    first = {d: ranges[d] * np.arange(1, nb + 1) / (nb + 1) for d in (+1, -1)}
    run_round(first)
    rounds = 1
    while rounds < opts.critical_rounds:
        nxt = {}
        for d in (+1, -1):
            lo, hi = bracket(d)
            a = 0.0 if lo is None else lo
            b = ranges[d] if hi is None else hi
            if hi is None or b - a <= opts.critical_tol:
                nxt[d] = np.zeros(0)
            else:
                nxt[d] = a + (b - a) * np.arange(1, nb + 1) / (nb + 1)
        if not any(s.size for s in nxt.values()):
            break
        run_round(nxt)
        rounds += 1
    out = []
    for d in (+1, -1):
        lo, hi = bracket(d)
        tol = opts.critical_tol * 1.0000001
        if hi is None:
            status = CriticalStatus.ALL_RETURN if lo is not None else CriticalStatus.OPEN
        elif lo is None:
            status = CriticalStatus.ALL_COLLIDE if hi <= tol else CriticalStatus.OPEN
        else:
            status = CriticalStatus.BRACKETED if hi - lo <= tol else CriticalStatus.OPEN
        out.append(SpeedCritical(
            direction=d, status=status.value,
            critical=None if (lo is None or hi is None) else 0.5 * (lo + hi),
            largest_return=lo, smallest_collision=hi, gap_range=float(ranges[d]),
            tol=opts.critical_tol, runs=runs[d], unresolved=unresolved[d], spans=opts.spans,
            rounds=rounds, collision_time=None if hi is None else seen[d][hi][1]))
    return out[0], out[1]
