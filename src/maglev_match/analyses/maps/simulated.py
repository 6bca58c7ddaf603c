"""The simulated critical disturbances of a map's rows, followed from point to point.

:func:`critical_sizes_batch` is the seam between the map and the critical-disturbance
solver (a warm-started bracketing on batched simulations of model A with the physical
limits on); :func:`simulate_rows` fills the stable points of a tile's rows coarse to fine,
each search warm-started from the sizes found around it and in the rows below. A delayed
row takes the point-wise search on the delay system instead."""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING

import numpy as np

from maglev_match.analyses.maps.rows import stretches
from maglev_match.analyses.maps.spec import (
    REASON_SIM_ROUNDS,
    REASON_SIM_UNDECIDED,
    simulation_settings,
)

if TYPE_CHECKING:
    from maglev_match.analyses.maps.spec import MapSpec

__all__ = ["critical_sizes_batch", "simulate_rows", "simulate_row", "DIRECTIONS"]

# the two directions of the beam-deflection disturbance x5(0): beam up (x5 < 0, the gap
# opens) and beam down (x5 > 0), as in the point-wise index
DIRECTIONS = (-1, 1)
ANCHOR_SPACING = 32  # cold searches at most this many grid points apart along a stretch
WARM_ANCHOR_SPACING = 2  # first searches of a row that has guesses from the rows below
SINGLE_SPREAD = 5.0  # spread of a guess from one neighbour only, in search tolerances


def critical_sizes_batch(P: np.ndarray, directions: np.ndarray,
                         guesses: np.ndarray | None = None,
                         spreads: np.ndarray | None = None, *,
                         gap_limits: np.ndarray, cost: np.ndarray | None = None):
    """The simulated critical disturbance of model A at many parameter points: **the seam
    between the map and the critical-disturbance solver**.

    For every point k, the size d_k (m) of the beam-deflection disturbance
    x5(0) = directions[k] * d_k (everything else at equilibrium) that separates return to
    the equilibrium from collision with a gap limit, with the physical limits on (current
    clamp, gap range), by the rules of the point-wise search
    (:func:`maglev_match.analyses.simulation.critical_disturbance`). Implemented by a warm-started
    bracketing on batched simulations
    (:func:`maglev_match.dynamics.integrate.threshold.bracket_thresholds`, settings
    :func:`simulation_settings`); a solver of the critical condition (grazing or basin
    boundary) with the same inputs and outputs can replace it here.

    Parameters
    ----------
    P : model A parameter vectors (:func:`maglev_match.maglev.unit.param_vector`), shape
        (n, 17).
    directions : -1 (beam up, x5(0) < 0) or +1 (beam down) per point.
    guesses : a guess of each d_k (m; NaN: none), e.g. from a neighbouring grid point.
    spreads : how far each guess may be off (m).
    gap_limits : (gap_min, gap_max) per point (m), shape (n, 2) or (2,).
    cost : a key per point, larger where runs are expected to be long (the slowest decay
        time of the equilibrium, 1 / |max Re(lambda)|).

    Returns
    -------
    :class:`~maglev_match.dynamics.integrate.threshold.ThresholdBatch` over the points: ``size``
    (the supported size in m: the bracket's midpoint, the whole gap range when every size
    returned, 0 when every size collided, NaN when unresolved), ``status``, ``unresolved``
    (runs left undecided) and the bracket.
    """
    from maglev_match.dynamics.integrate.threshold import ThresholdBatch, bracket_thresholds
    from maglev_match.maglev import unit
    from maglev_match.maglev.limits import gap_limit_events
    from maglev_match.maglev.unit import PARAM_NAMES, STATE_NAMES

    w_state = STATE_NAMES.index("w")  # x5, the beam deflection
    P = np.atleast_2d(np.asarray(P, float))
    n = len(P)
    directions = np.broadcast_to(np.asarray(directions, float), (n,))
    limits = np.broadcast_to(np.asarray(gap_limits, float), (n, 2))
    c0 = P[:, PARAM_NAMES.index("c0")]
    upper = np.where(directions < 0, limits[:, 1] - c0, c0 - limits[:, 0])
    guesses = np.full(n, np.nan) if guesses is None else np.broadcast_to(guesses, (n,))
    spreads = np.zeros(n) if spreads is None else np.broadcast_to(spreads, (n,))
    cost = np.zeros(n) if cost is None else np.broadcast_to(cost, (n,))
    system = _limited_unit_system()
    parts = []
    groups = np.unique(limits, axis=0)  # the gap limits are one argument per kernel call
    for lim in groups:
        sel = np.flatnonzero(np.all(limits == lim, axis=1))
        dirs = directions[sel]

        def x0_of(idx, sizes, dirs=dirs):
            x0 = np.zeros((len(idx), system.dim))
            x0[:, w_state] = dirs[idx] * sizes
            return x0

        parts.append((sel, bracket_thresholds(
            system, P[sel], x0_of, upper[sel], guesses=guesses[sel], spreads=spreads[sel],
            cost=cost[sel], events=gap_limit_events(unit.gap, float(lim[0]), float(lim[1])),
            x_ref=np.zeros(system.dim), options=simulation_settings())))
    if len(parts) == 1:
        return parts[0][1]
    fields = ("status", "size", "largest_return", "smallest_collision", "collision_time",
              "runs", "unresolved", "nonmonotone", "steps")
    merged = {}
    for f in fields:
        first = getattr(parts[0][1], f)
        arr = np.empty(n, dtype=first.dtype)
        for sel, part in parts:
            arr[sel] = getattr(part, f)
        merged[f] = arr
    return ThresholdBatch(
        **merged, tol=parts[0][1].tol, rounds=max(b.rounds for _, b in parts),
        lane_steps=sum(b.lane_steps for _, b in parts),
        run_steps=sum(b.run_steps for _, b in parts), calls=sum(b.calls for _, b in parts),
        warnings=tuple(w for _, b in parts for w in b.warnings))


@functools.cache
def _limited_unit_system():
    """Model A with the current clamp (its parameter vector is replaced per run)."""
    from maglev_match.core.params import load_preset
    from maglev_match.maglev.unit import unit_system

    return unit_system(load_preset(), limited=True)


def _interpolate_known(j: int, known: np.ndarray, single: float) -> tuple[float, float]:
    """A value at index ``j`` from the values ``known`` (NaN: unknown) at other indices,
    and how far off it may be: cubic interpolation through two known values on each side
    (spread: its difference from the linear one), linear interpolation between the nearest
    known values on each side (spread: a quarter of their difference), linear
    extrapolation from the two nearest on one side (spread: half the step it predicts), or
    the one known value (spread ``single``)."""
    pos = np.flatnonzero(np.isfinite(known))
    left, right = pos[pos < j][::-1], pos[pos > j]
    if left.size and right.size:
        a, b = left[0], right[0]
        lin = known[a] + (known[b] - known[a]) * (j - a) / (b - a)
        if left.size > 1 and right.size > 1:
            xs = np.array([left[1], a, b, right[1]], float)
            ys = known[xs.astype(int)]
            cub = sum(ys[i] * np.prod([(j - xs[m]) / (xs[i] - xs[m]) for m in range(4)
                                       if m != i]) for i in range(4))
            return float(cub), float(abs(cub - lin))
        return float(lin), float(abs(known[b] - known[a]) / 4)
    side = left if left.size else right
    if side.size >= 2:
        a, b = side[0], side[1]
        step = (known[a] - known[b]) * (j - a) / (a - b)
        return float(known[a] + step), float(abs(step) / 2)
    return float(known[side[0]]), float(single)


def _guess(j: int, known: np.ndarray, base: np.ndarray, tol: float) -> tuple[float, float]:
    """The guess of the critical size at point ``j`` of a stretch and its spread: with a
    prediction ``base`` from the rows below, base[j] plus the correction (known - base)
    interpolated along the row (smooth where the y step changes slowly in x); without
    one, the known sizes of the row interpolated (:func:`_interpolate_known`)."""
    if math.isfinite(base[j]):
        corr = known - base
        if np.isfinite(corr).any():
            c, sp = _interpolate_known(j, corr, tol)
            return base[j] + c, sp
    return _interpolate_known(j, known, SINGLE_SPREAD * tol)


def _next_targets(stable: np.ndarray, done: np.ndarray, known: np.ndarray,
                  base: np.ndarray, base_spread: np.ndarray, tol: float
                  ) -> list[tuple[int, float, float]]:
    """The points of a row to search next, coarse to fine, with their guesses:
    (j, guess or NaN, spread). In a stable stretch without a known size: its two ends and
    points ANCHOR_SPACING apart (WARM_ANCHOR_SPACING with predictions ``base`` from the
    rows below: their guesses; without, cold searches); elsewhere the ends of the stretch
    and the middle of every gap between known sizes (guesses from :func:`_guess`)."""
    out: list[tuple[int, float, float]] = []
    for s, e in stretches(stable):
        todo = [j for j in range(s, e + 1) if not done[j]]
        if not todo:
            continue
        seg_known = np.full(known.size, np.nan)
        seg_known[s:e + 1] = known[s:e + 1]
        seg_base = np.full(known.size, np.nan)
        seg_base[s:e + 1] = base[s:e + 1]
        known_here = np.flatnonzero(np.isfinite(seg_known)).tolist()
        if not known_here:
            warm = np.isfinite(seg_base[s:e + 1]).any()
            spacing = WARM_ANCHOR_SPACING if warm else ANCHOR_SPACING
            anchors = sorted({s, e, *range(s + spacing, e, spacing)})
            for j in sorted({min(todo, key=lambda j, a=a: abs(j - a)) for a in anchors}):
                out.append((j, float(seg_base[j]), float(base_spread[j])))
            continue
        marks = [s - 1, *known_here, e + 1]
        picks = set()
        for a, b in zip(marks[:-1], marks[1:], strict=True):
            gap = [j for j in todo if a < j < b]
            if not gap:
                continue
            if a < s:
                picks.add(gap[0])  # the stretch's start
            elif b > e:
                picks.add(gap[-1])  # the stretch's end
            else:
                picks.add(min(gap, key=lambda j, m=(a + b) / 2: abs(j - m)))
        for j in sorted(picks):
            g, sp = _guess(j, seg_known, seg_base, tol)
            out.append((j, g, sp))
    return out


def simulate_rows(spec: MapSpec, rows: tuple[int, int], paper: list[dict]
                  ) -> list[dict[str, np.ndarray]]:
    """The critical disturbances in both directions at the stable points of rows
    [a, b), followed from point to point (:func:`critical_sizes_batch` per step).

    Along a row, every stable stretch is filled coarse to fine (:func:`_next_targets`):
    first its ends and a few points between, then the middles of the gaps, each new point
    guessed from the sizes already found around it. In the first row of a tile the first
    points are cold searches; in a later row every guess starts from the rows below (linear
    extrapolation in y) corrected by what the row has found so far (:func:`_guess`). Every
    search brackets the size to the point-wise tolerance, so the guesses change the cost,
    never the rule. Returns per row ``h_up``, ``h_down`` (m,
    NaN where unstable or unresolved) and ``reason`` (0 or a simulation reason code)."""
    below: list[dict[int, np.ndarray]] = []  # per row and direction: the sizes found
    out = []
    for r, pr in zip(range(*rows), paper, strict=True):
        row, known = simulate_row(spec, r, pr, below)
        below.append(known)
        out.append(row)
    return out


def simulate_row(spec: MapSpec, r: int, pr: dict, below: list[dict[int, np.ndarray]]
                 ) -> tuple[dict[str, np.ndarray], dict[int, np.ndarray]]:
    """One row of :func:`simulate_rows` (``below``: the sizes of the rows below, for
    guesses). Returns the row's variables and its sizes for the next row's guesses."""
    from maglev_match.maglev.unit import PARAM_NAMES, param_vector

    tol = simulation_settings().tol
    top = simulation_settings().top_fraction
    xs = spec.x.values
    nx = xs.size
    pts = [spec.point(xv, spec.y.values[r]) for xv in xs]
    if any(p.tau > 0 for p in pts):  # the batched search runs model A's ODE: not a delay
        return (_simulate_row_pointwise(pts, np.asarray(pr["stable"], bool)),
                {d: np.full(nx, np.nan) for d in DIRECTIONS})
    P = np.array([param_vector(p) for p in pts])
    limits = np.array([[p.gap_min, p.gap_max] for p in pts])
    c0 = P[:, PARAM_NAMES.index("c0")]
    uppers = {-1: limits[:, 1] - c0, 1: c0 - limits[:, 0]}
    stable = np.asarray(pr["stable"], bool)
    max_re = np.asarray(pr["max_real_part"], float)
    # long runs where the equilibrium's slowest mode decays slowly
    cost = np.where(stable, 1.0 / np.maximum(-max_re, 1e-12), 0.0)
    size = {d: np.full(nx, np.nan) for d in DIRECTIONS}
    known = {d: np.full(nx, np.nan) for d in DIRECTIONS}
    done = {d: ~stable for d in DIRECTIONS}
    unresolved = {d: np.zeros(nx, bool) for d in DIRECTIONS}
    undecided = {d: np.zeros(nx, bool) for d in DIRECTIONS}

    def run(lanes: list[tuple[int, int, float, float]]) -> None:
        """Search the (direction, point, guess, spread) lanes in one batch."""
        if not lanes:
            return
        js = np.array([j for _, j, _, _ in lanes])
        res = critical_sizes_batch(
            P[js], np.array([d for d, _, _, _ in lanes], float),
            np.array([g for *_, g, _ in lanes]), np.array([e for *_, e in lanes]),
            gap_limits=limits[js], cost=cost[js])
        for k, (d, j, _, _) in enumerate(lanes):
            done[d][j] = True
            size[d][j] = res.size[k]
            if math.isfinite(res.size[k]):
                known[d][j] = min(res.size[k], top * uppers[d][j])  # a guess, so <= top
            else:
                unresolved[d][j] = True
                undecided[d][j] = res.unresolved[k] > 0

    # predictions from the rows below (this tile): linear extrapolation in y from two
    # rows (spread: half the step), or the row below (spread: half a tolerance)
    base = {d: np.full(nx, np.nan) for d in DIRECTIONS}
    base_spread = {d: np.full(nx, tol / 2) for d in DIRECTIONS}
    if below:
        for d in DIRECTIONS:
            v1 = below[-1][d]
            v2 = below[-2][d] if len(below) > 1 else np.full(nx, np.nan)
            two = np.isfinite(v1) & np.isfinite(v2)
            base[d] = np.where(two, 2 * v1 - v2, v1)
            base_spread[d] = np.where(two, np.abs(v1 - v2) / 2, tol / 2)
    while True:  # along the row, coarse to fine
        lanes = [(d, j, g, e) for d in DIRECTIONS
                 for j, g, e in _next_targets(stable, done[d], known[d], base[d],
                                              base_spread[d], tol)]
        if not lanes:
            break
        run(lanes)
    reason = np.zeros(nx, np.int8)
    for d in DIRECTIONS:
        code = np.where(undecided[d], REASON_SIM_UNDECIDED, REASON_SIM_ROUNDS)
        reason = np.where(unresolved[d] & stable & (reason == 0), code, reason)
    return ({"h_up": size[-1], "h_down": size[1], "reason": reason.astype(np.int8)},
            known)


def _simulate_row_pointwise(pts: list, stable: np.ndarray) -> dict[str, np.ndarray]:
    """A row with a delay: each stable point's critical disturbances by the point-wise
    search on the delay system (:func:`maglev_match.analyses.simulation.critical_disturbance`, the
    index's own search and rule), since the batched search of
    :func:`critical_sizes_batch` integrates model A's ODE."""
    from maglev_match.analyses.matching import supported_size
    from maglev_match.analyses.simulation import critical_disturbance

    settings = simulation_settings()
    nx = len(pts)
    size = {d: np.full(nx, np.nan) for d in DIRECTIONS}
    reason = np.zeros(nx, np.int8)
    for j, p in enumerate(pts):
        if not stable[j]:
            continue
        for d in DIRECTIONS:
            cd = critical_disturbance(p, direction=d, tol=settings.tol)
            if cd.status in ("bracketed", "all_return", "all_collide"):
                size[d][j] = supported_size(cd)  # the index's rule
            elif reason[j] == 0:  # open: runs left undecided; no number
                reason[j] = REASON_SIM_UNDECIDED
    return {"h_up": size[-1], "h_down": size[1], "reason": reason}
