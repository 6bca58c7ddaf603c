"""Return-or-collide thresholds along lines of initial states, for many lines at once.

Model-agnostic. A *line* is a parameter vector ``P_k`` and a one-parameter family of
initial states ``x0(k, d)``, d >= 0 a disturbance size. A run from ``x0(k, d)`` either
*returns* (converges to the reference equilibrium, :mod:`maglev_match.dynamics.integrate.simulate`)
or *collides* (an event fires). The threshold d*_k separates the two: smaller sizes return,
larger ones collide. This module brackets d*_k for every line by batched simulations:

* **Warm lines** have a guess g_k (e.g. the threshold at a neighbouring parameter point,
  extrapolated) and a spread e_k (how far off the guess may be). The first round tries
  g - tol/2 and g + tol/2, plus g -/+ (tol/2 + 2 e) when e > tol/2; when the threshold lies
  between the two inner sizes, two runs settle the line. A miss widens: sizes d, 2d, 3d
  beyond the last size of the same outcome, d = tol at first and 4 times larger each
  round (small misses, the common case, are bracketed to ``tol`` at once); a bracket wider
  than ``tol`` is cut into equal parts, at most ``warm_sizes + 1`` per round.
* **Cold lines** (no guess) follow the point-wise bisection of
  :func:`maglev_match.analyses.simulation.critical_disturbance_of_system`: ``cold_sizes`` sizes
  spread
  over the range, then the bracket cut into ``cold_sizes + 1`` parts per round.

Every round gathers the runs of all lines into one list, sorts it by an expected-cost key
(so that long runs share kernel calls with long runs: a vmapped integration lasts as long
as its slowest run) and integrates it in chunks of ``chunk`` runs (one compiled shape).
A run still undecided at the horizon ``t_max`` is continued from where it stopped, up to
``max_extend`` times with the horizon doubled each time (``t_max``, ``2 t_max``, ``4 t_max``
in all, as the point-wise search re-runs with 20, 40 and 80 s); still undecided, or failed,
it is *unresolved* and left out of the bracket, never counted as a return.

The rules of the result are those of the point-wise search, so the two agree within
``tol`` wherever the set of returning sizes along the line is an interval:

* ``bracketed``: a returning size and a colliding one no more than ``tol`` apart;
* ``all_return``: the largest size searched returned. That size is ``top_fraction`` of the
  line's range (the point-wise search's first round ends at ``cold_sizes / (cold_sizes + 1)``
  of the range and never tries larger sizes); the supported size is then the whole range;
* ``all_collide``: a size no larger than ``tol`` collided and none returned;
* ``open``: none of these within ``max_rounds`` rounds (unresolved runs, or no progress).

Bracketing is the textbook safeguard of root finding on a sign change (Press et al.,
*Numerical Recipes*, 3rd ed., sec. 9.1); the warm start is a continuation in the
parameters, as in AUTO's predictor (Doedel, *AUTO-07p* manual), applied to a threshold.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.integrate.simulate import (
    COLLISION,
    CONVERGED,
    FAILED,
    SimulationOptions,
    simulate_batch,
)
from maglev_match.dynamics.system import System

__all__ = ["ThresholdStatus", "ThresholdOptions", "ThresholdBatch", "bracket_thresholds"]


class ThresholdStatus(StrEnum):
    """How the search of one line ended (the point-wise search's statuses)."""

    BRACKETED = "bracketed"
    ALL_RETURN = "all_return"
    ALL_COLLIDE = "all_collide"
    OPEN = "open"


@dataclass(frozen=True)
class ThresholdOptions:
    """Settings of :func:`bracket_thresholds` (checked on construction).

    tol : bracket width to reach (units of the sizes, e.g. m).
    t_max : first horizon of a run (s); ``max_extend`` continuations double it each time.
    max_rounds : rounds of batched runs before a line is given up as ``open``.
    cold_sizes : sizes per round of a line without a guess (the point-wise search's batch).
    warm_sizes : at most this many sizes per round of a warm line once it is bracketed.
    top_fraction : the largest size searched, as a fraction of the line's range.
    chunk : runs per compiled batch call (one compiled shape; short rounds are padded).
    slice_time, slice_steps : runs advance in slices of at most this many seconds and
        steps, regrouped between slices (:func:`_run_lanes`); the first slice of a round
        is at most ``first_slice_steps`` steps.
    max_unresolved : a line with this many unresolved runs is given up (``open``): its
        sizes near the threshold linger beyond the longest horizon, and every further
        run there costs that horizon.
    """

    tol: float = 1e-5
    t_max: float = 20.0
    max_extend: int = 2
    max_rounds: int = 16
    cold_sizes: int = 10
    warm_sizes: int = 4
    top_fraction: float = 10.0 / 11.0
    chunk: int = 32
    slice_time: float = 5.0
    slice_steps: int = 400
    first_slice_steps: int = 100
    max_unresolved: int = 2

    def __post_init__(self) -> None:
        for name, value in (("tol", self.tol), ("t_max", self.t_max),
                            ("slice_time", self.slice_time)):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"ThresholdOptions.{name} = {value!r}: must be a finite "
                                 "number > 0")
        for name, value, lo in (("max_extend", self.max_extend, 0),
                                ("max_rounds", self.max_rounds, 1),
                                ("cold_sizes", self.cold_sizes, 1),
                                ("warm_sizes", self.warm_sizes, 1),
                                ("chunk", self.chunk, 1),
                                ("slice_steps", self.slice_steps, 1),
                                ("first_slice_steps", self.first_slice_steps, 1),
                                ("max_unresolved", self.max_unresolved, 1)):
            if isinstance(value, bool) or not isinstance(value, int) or value < lo:
                raise ValueError(f"ThresholdOptions.{name} = {value!r}: must be a whole "
                                 f"number >= {lo}")
        if not 0 < self.top_fraction <= 1:
            raise ValueError(f"ThresholdOptions.top_fraction = {self.top_fraction!r}: must "
                             "lie in (0, 1]")


@dataclass(frozen=True)
class ThresholdBatch:
    """Thresholds of many lines (arrays over the lines).

    status : :class:`ThresholdStatus` values. size : the size the runs support: the
        bracket's midpoint, the whole range for ``all_return``, 0 for ``all_collide``, NaN
        for ``open``. largest_return / smallest_collision : the bracket (NaN if none).
    collision_time : time (s) of the run at ``smallest_collision`` (NaN if none).
    runs : runs per line; unresolved : runs per line left out (undecided or failed);
        steps : integration steps per line (all its runs).
    nonmonotone : a size above the smallest collision returned (the returning sizes along
        the line are not an interval; the bracket is then one of several).
    rounds : rounds used. Cost diagnostics: ``lane_steps`` integration steps paid over all
    kernel calls (chunk size x the slowest run of the call), ``run_steps`` the steps the
    runs needed, ``calls`` kernel calls.
    """

    __repr__ = compact_repr

    status: np.ndarray
    size: np.ndarray
    largest_return: np.ndarray
    smallest_collision: np.ndarray
    collision_time: np.ndarray
    runs: np.ndarray
    unresolved: np.ndarray
    nonmonotone: np.ndarray
    steps: np.ndarray
    tol: float
    rounds: int
    lane_steps: int = 0
    run_steps: int = 0
    calls: int = 0
    warnings: tuple[str, ...] = field(default=())


@dataclass
class _Line:
    """The search state of one line."""

    upper: float  # the line's range (the size reported for all_return)
    top: float  # the largest size searched
    guess: float  # NaN: a cold line
    spread: float
    seen: dict[float, tuple[int, float]] = field(default_factory=dict)  # size -> (code, t)
    step: float = float("nan")  # expansion step of a warm line
    runs: int = 0
    unresolved: int = 0
    steps: int = 0
    done: ThresholdStatus | None = None

    def bracket(self) -> tuple[float | None, float | None]:
        """(largest return below the smallest collision, smallest collision)."""
        coll = [d for d, (c, _) in self.seen.items() if c == COLLISION]
        hi = min(coll) if coll else None
        ret = [d for d, (c, _) in self.seen.items()
               if c == CONVERGED and (hi is None or d < hi)]
        return (max(ret) if ret else None), hi


_UNRESOLVED = -1
_SLACK = 1.0000001  # bracket width compared with tol (rounding of the planned sizes)


def _status(line: _Line, tol: float) -> ThresholdStatus | None:
    """The line's final status if its runs already settle it, else None."""
    lo, hi = line.bracket()
    if hi is not None and lo is not None and hi - lo <= tol * _SLACK:
        return ThresholdStatus.BRACKETED
    if hi is None and lo is not None and lo >= line.top * (1 - 1e-12):
        return ThresholdStatus.ALL_RETURN
    if lo is None and hi is not None and hi <= tol * _SLACK:
        return ThresholdStatus.ALL_COLLIDE
    return None


def _cut(a: float, b: float, parts: int) -> list[float]:
    return [a + (b - a) * k / parts for k in range(1, parts)]


def _plan(line: _Line, first: bool, opts: ThresholdOptions) -> list[float]:
    """The sizes of the line's next round (empty: nothing left to try, or too many
    unresolved runs)."""
    tol = opts.tol
    lo, hi = line.bracket()
    cold = not math.isfinite(line.guess)
    if line.unresolved >= opts.max_unresolved:
        return []
    if first and cold:
        return [line.top * k / opts.cold_sizes for k in range(1, opts.cold_sizes + 1)]
    if first:
        g = min(max(line.guess, tol), line.top)
        sizes = [g - tol / 2, g + tol / 2]
        if line.spread > tol / 2:
            w = tol / 2 + 2.0 * line.spread
            sizes = [g - w, *sizes, g + w]
        line.step = tol
        sizes = [min(max(s, tol), line.top) for s in sizes]
    elif lo is not None and hi is not None:
        need = math.ceil((hi - lo) / tol - 1e-9)  # parts that reach tol in one round
        cap = (opts.cold_sizes if cold else opts.warm_sizes) + 1
        sizes = _cut(lo, hi, max(2, min(need, cap)))
    elif cold:
        # the point-wise search: cut [0 or lo, top or hi] into cold_sizes + 1 parts
        a = 0.0 if lo is None else lo
        b = line.top if hi is None else hi
        sizes = _cut(a, b, opts.cold_sizes + 1)
        if hi is None and lo is not None:
            sizes.append(line.top)
    elif hi is None and lo is not None:  # every size so far returned: widen upwards
        sizes = [min(lo + line.step * f, line.top) for f in (1.0, 2.0, 3.0)]
        line.step *= 4.0
    elif lo is None and hi is not None:  # every size so far collided: widen downwards
        sizes = [max(hi - line.step * f, tol) for f in (1.0, 2.0, 3.0)]
        line.step *= 4.0
    else:
        return []  # every run so far unresolved
    new = sorted({float(s) for s in sizes if s > 0 and float(s) not in line.seen})
    return new


def bracket_thresholds(
    system: System,
    P: np.ndarray,
    x0_of: Callable[[np.ndarray, np.ndarray], np.ndarray],
    upper: np.ndarray,
    *,
    guesses: np.ndarray | None = None,
    spreads: np.ndarray | None = None,
    cost: np.ndarray | None = None,
    events=None,
    x_ref: np.ndarray | None = None,
    options: ThresholdOptions | None = None,
    sim_options: SimulationOptions | None = None,
) -> ThresholdBatch:
    """Bracket the return/collision threshold of every line (module docstring).

    Parameters
    ----------
    system : the system (one right-hand side for all lines).
    P : parameter vectors, shape (n_lines, n_params).
    x0_of : ``x0_of(lines, sizes)`` -> initial states (len(lines), dim) for line indices
        ``lines`` and sizes ``sizes`` (>= 0, the units of ``upper``).
    upper : the range of each line (shape (n_lines,)): the size where the disturbance
        leaves the physical range; sizes are searched in (0, top_fraction * upper].
    guesses : a guess of each line's threshold (NaN: a cold line).
    spreads : how far each guess may be off (>= 0; default 0).
    cost : a key per line, larger for lines whose runs are expected to be long (e.g. the
        slowest decay time of the equilibrium); runs are chunked in this order.
    events : the event function that ends a run as a collision.
    x_ref : the reference equilibrium (shared by all lines).
    options : :class:`ThresholdOptions`; sim_options : integrator options
        (``stop_on_converged`` is forced on).

    Returns
    -------
    :class:`ThresholdBatch`.
    """
    opts = options or ThresholdOptions()
    sim = dataclasses.replace(sim_options or SimulationOptions(), stop_on_converged=True)
    P = np.atleast_2d(np.asarray(P, float))
    n = len(P)
    upper = np.broadcast_to(np.asarray(upper, float), (n,))
    g = np.full(n, np.nan) if guesses is None else np.broadcast_to(
        np.asarray(guesses, float), (n,))
    e = np.zeros(n) if spreads is None else np.broadcast_to(np.asarray(spreads, float), (n,))
    key = np.zeros(n) if cost is None else np.broadcast_to(np.asarray(cost, float), (n,))
    if np.any(~np.isfinite(upper)) or np.any(upper <= 0):
        raise ValueError("every line's range must be a finite number > 0")
    lines = [_Line(upper=float(u), top=float(u) * opts.top_fraction, guess=float(gk),
                   spread=float(ek) if math.isfinite(ek) else 0.0)
             for u, gk, ek in zip(upper, g, e, strict=True)]
    stats = {"lane_steps": 0, "run_steps": 0, "calls": 0}
    rounds = 0
    for r in range(opts.max_rounds):
        lane_line: list[int] = []
        lane_size: list[float] = []
        for k, line in enumerate(lines):
            if line.done is not None:
                continue
            sizes = _plan(line, r == 0, opts)
            if not sizes:
                line.done = ThresholdStatus.OPEN
                continue
            lane_line.extend([k] * len(sizes))
            lane_size.extend(sizes)
        if not lane_line:
            break
        rounds += 1
        idx = np.asarray(lane_line)
        sizes = np.asarray(lane_size)
        # runs expected to return (below the guess) apart from those expected to collide
        # (returns take longer: they must settle), then by the lines' cost keys
        below = np.array([s < lines[k].guess for k, s in zip(idx, sizes, strict=True)])
        order = np.lexsort((-key[idx], ~below))
        codes, times, steps = _run_lanes(system, P, x0_of, idx[order], sizes[order], events,
                                         x_ref, opts, sim, stats)
        for k, s, c, t, n_steps in zip(idx[order], sizes[order], codes, times, steps,
                                       strict=True):
            line = lines[k]
            line.runs += 1
            line.steps += int(n_steps)
            if c == _UNRESOLVED:
                line.unresolved += 1
            line.seen[float(s)] = (int(c), float(t))
        for line in lines:
            if line.done is None:
                line.done = _status(line, opts.tol)
    out = {k: np.full(n, np.nan) for k in ("size", "lo", "hi", "t")}
    status = np.empty(n, dtype=object)
    nonmono = np.zeros(n, dtype=bool)
    for k, line in enumerate(lines):
        st = line.done if line.done is not None else ThresholdStatus.OPEN
        lo, hi = line.bracket()
        status[k] = st
        if lo is not None:
            out["lo"][k] = lo
        if hi is not None:
            out["hi"][k] = hi
            out["t"][k] = line.seen[hi][1]
            nonmono[k] = any(c == CONVERGED and d > hi for d, (c, _) in line.seen.items())
        if st == ThresholdStatus.BRACKETED:
            out["size"][k] = 0.5 * (lo + hi)
        elif st == ThresholdStatus.ALL_RETURN:
            out["size"][k] = line.upper
        elif st == ThresholdStatus.ALL_COLLIDE:
            out["size"][k] = 0.0
    warnings = []
    if nonmono.any():
        warnings.append(f"{int(nonmono.sum())} line(s): a size above the smallest colliding "
                        "size returned (the returning sizes are not an interval)")
    return ThresholdBatch(
        status=status, size=out["size"], largest_return=out["lo"],
        smallest_collision=out["hi"], collision_time=out["t"],
        runs=np.array([ln.runs for ln in lines]),
        unresolved=np.array([ln.unresolved for ln in lines]), nonmonotone=nonmono,
        steps=np.array([ln.steps for ln in lines]),
        tol=float(opts.tol), rounds=rounds, warnings=tuple(warnings), **stats)


def _run_lanes(system, P, x0_of, idx, sizes, events, x_ref, opts, sim, stats
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Outcome code (COLLISION, CONVERGED or _UNRESOLVED), time (collision or
    convergence, s, from the start of the run) and integration steps of every lane, in
    the given order.

    The runs advance in slices: a kernel call integrates a chunk of runs for at most
    ``opts.slice_time`` seconds and at most ``opts.slice_steps`` steps each (a run whose
    steps crowd, e.g. where the current clamp switches, stops early instead of holding up
    the whole chunk). After each slice the decided runs leave and the others, continued
    from where they stopped, are packed into full chunks again (runs of similar progress
    together). A run is undecided after ``t_max * 2**max_extend`` seconds in all (the
    longest horizon of the point-wise search). Continuing a run restarts the integrator's
    step-size control and the convergence hold clock (a run must again stay ``hold_time``
    inside the tolerance), so a slice boundary can delay a decision by up to
    ``hold_time``, never change it."""
    x0 = np.asarray(x0_of(idx, sizes), float)
    p = P[idx]
    m = len(idx)
    codes = np.full(m, _UNRESOLVED)
    times = np.full(m, np.nan)
    used = np.zeros(m, dtype=int)
    total = float(opts.t_max) * 2.0 ** opts.max_extend
    elapsed = np.zeros(m)
    todo = np.arange(m)
    first = True
    while todo.size:
        # a short first slice: most collisions come within it, and the runs still going
        # are regrouped before the long slices
        budget = opts.first_slice_steps if first else opts.slice_steps
        sim = dataclasses.replace(sim, max_steps=int(budget))
        first = False
        # runs of similar progress share a chunk (stable: the caller's order within ties)
        todo = todo[np.argsort(elapsed[todo], kind="stable")]
        for a in range(0, todo.size, opts.chunk):
            lanes = todo[a:a + opts.chunk]
            horizon = min(float(opts.slice_time), float(np.min(total - elapsed[lanes])))
            c, t, x_end, t_end, steps = _integrate(system, x0[lanes], p[lanes], horizon,
                                                   events, x_ref, opts.chunk, sim, stats)
            used[lanes] += steps
            hit = c == COLLISION
            conv = c == CONVERGED
            codes[lanes[hit]] = COLLISION
            codes[lanes[conv]] = CONVERGED
            times[lanes[hit | conv]] = elapsed[lanes[hit | conv]] + t[hit | conv]
            # undecided at the slice's end, or out of steps in this slice: go on from
            # where the run stopped; other failures (a non-finite state, a step size at
            # the resolution of t) stay unresolved
            out_of_steps = (c == FAILED) & (steps >= budget)
            going = (~(hit | conv) & ((c != FAILED) | out_of_steps)
                     & np.all(np.isfinite(x_end), axis=1) & (t_end > 0))
            x0[lanes[going]] = x_end[going]
            elapsed[lanes[going]] += t_end[going]
            codes[lanes[~(hit | conv | going)]] = _UNRESOLVED
            elapsed[lanes[~going]] = np.inf  # decided or given up
        todo = todo[elapsed[todo] < total * (1 - 1e-12)]
    return codes, times, used


def _integrate(system, x0, p, horizon, events, x_ref, chunk, sim, stats):
    """simulate_batch over the runs in chunks of ``chunk`` runs, a remainder of at most
    ``chunk // 4`` runs in one small chunk (the last chunk padded)."""
    m = len(x0)
    code = np.empty(m, dtype=int)
    t = np.full(m, np.nan)
    x_end = np.empty_like(x0)
    t_end = np.empty(m)
    steps = np.empty(m, dtype=int)
    small = max(1, chunk // 4)
    # full chunks, then the remainder: in a small kernel call (a second compiled shape)
    # when it fits, rather than in a chunk of mostly padding (a call's cost per step is
    # a fixed part plus a part per run: one chunk beats two small calls above that)
    full, rem = divmod(m, chunk)
    bounds = [(k * chunk, (k + 1) * chunk, chunk) for k in range(full)]
    if rem and rem > small:
        bounds.append((full * chunk, m, chunk))
    elif rem:
        bounds += [(a, min(a + small, m), small) for a in range(full * chunk, m, small)]
    for a, b, width in bounds:
        xs, ps = x0[a:b], p[a:b]
        pad = width - (b - a)
        if pad:
            xs = np.concatenate([xs, np.repeat(xs[-1:], pad, axis=0)])
            ps = np.concatenate([ps, np.repeat(ps[-1:], pad, axis=0)])
        res = simulate_batch(system, xs, horizon, p=ps, event_fn=events, x_ref=x_ref,
                             options=sim)
        k = b - a
        code[a:b] = res.outcome_code[:k]
        t[a:b] = np.where(res.outcome_code[:k] == COLLISION, res.event_time[:k],
                          res.converged_time[:k])
        x_end[a:b] = res.final_state[:k]
        t_end[a:b] = res.final_time[:k]
        steps[a:b] = res.steps[:k]
        stats["calls"] += 1
        stats["lane_steps"] += int(width * np.max(res.steps))
        stats["run_steps"] += int(np.sum(res.steps[:k]))
    return code, t, x_end, t_end, steps
