"""Maps of stability and the matching index over two-parameter design grids.

A grid is two swept parameters of a :class:`~maglev_match.core.params.Params`: model-A
parameters (omega1, sigma, kP, kD, ke, ...) or engineering quantities (L, EI, mbar, l, k)
from which omega1 and sigma derive. Every grid point is validated before any work starts.

What a map stores (see :func:`map_dataset`): the *headline* index ``chi`` = min(chi_paper,
chi_simulation), the index the reading of ``maglev-match index`` uses, and its two parts:

* ``chi_paper`` = h / w0 by the paper's definition (Chen, Ma, Luo & Zou 2019), h from the
  unstable cycle that bounds the basin or the gap range;
* ``chi_simulation`` = h_simulation / w0, h_simulation the smaller of the critical
  beam-deflection disturbances in the two directions (``h_simulation_up``: x5(0) < 0,
  ``h_simulation_down``: x5(0) > 0) found by simulation with the physical limits on.

Unstable points are their own category: ``stable`` = 0 and every index variable NaN there
(the paper writes chi = 0, which a colour scale would show as a poor stable design). A point
where a part could not be resolved is marked (``resolved`` = 0, ``reason`` a code of
:data:`REASON_CODES`) and its index is NaN, never a number filled in.

Work is split into tiles of whole rows (fixed y, x varying). Within a row the cycles are
*continued along the row*: the row is a path through parameter space
(:func:`~maglev_match.dynamics.paths.path_system`), its Hopf points are located on that
path, and from each one the cycle branch is followed across the adjacent stable stretch;
h at every grid point of the stretch is read off that one branch. The critical disturbances
are *followed* too (:func:`critical_sizes_batch`, warm-started from the neighbouring points:
the row below within a tile, else a coarse-to-fine order along the row), a few batched
simulations per point instead of a cold search of ~60. Tiles run through the package's job
runner (:mod:`maglev_match.core.jobs`: here, or on a Dask cluster, a local one by default
or an existing scheduler), are written to a checkpoint folder as they finish, and a resumed
map skips the tiles already there. Tile results do not depend on
which worker ran them, so a resumed map equals a map computed in one go bit for bit.
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match.core import checkpoint as checkpoint_mod
from maglev_match.core.jobs import (  # the runner's names are imported from here too
    SINGLE_THREADED_ENV,
    Job,
    TileCount,
    dask_log_capture,
    local_cluster,
    remove_checkpoint,
    run_job,
    run_pieces_on_dask,
)
from maglev_match.core.options import CollocationMesh
from maglev_match.core.params import FIELD_NAMES, ParameterError, Params, make_params

__all__ = ["Axis", "MapSpec", "parse_axis", "compute_row", "compute_tile", "run_map",
           "map_dataset", "spot_check", "map_warnings", "critical_sizes_batch",
           "simulation_settings", "remove_checkpoint", "dask_log_capture", "MAP_VARIABLES",
           "REASON_CODES", "CASE_CODES", "BASIS_CODES", "TileCount", "run_pieces_on_dask",
           "local_cluster", "SINGLE_THREADED_ENV"]

CASE_CODES = {"unstable_equilibrium": 0, "unstable_cycle": 1, "no_cycle_within_limits": 2}
# which part decided the headline index chi (variable ``chi_basis``)
BASIS_CODES = {"paper": 0, "simulation": 1}
# the variables of a tile (each of shape (rows, nx)); ``hopf_x`` holds a row's Hopf points
# (x values) in its first entries, NaN after them
MAP_VARIABLES = ("chi", "chi_paper", "chi_simulation", "h", "h_simulation_up",
                 "h_simulation_down", "chi_basis", "w0", "stable", "max_real_part",
                 "hopf_distance", "case", "omega1_point", "sigma_point", "current_reverses",
                 "resolved", "reason", "hopf_x")
# why a point is unresolved (variable ``reason``; 0 for resolved points)
REASON_FAILED = 1
REASON_MAX_STEPS = 2
REASON_NO_HOPF = 3
REASON_NO_BRANCH = 4
REASON_SIM_UNDECIDED = 5
REASON_SIM_ROUNDS = 6
REASON_CODES = {
    0: "",
    REASON_FAILED: "the cycle continuation failed (Newton or step size) before the point",
    REASON_MAX_STEPS: "the cycle branch reached its step limit before the point",
    REASON_NO_HOPF: "max Re(lambda) changes sign next to the stable stretch without a Hopf "
                    "point, even on a refined scan",
    REASON_NO_BRANCH: "no cycle branch could be started at the Hopf point",
    REASON_SIM_UNDECIDED: "the simulated critical disturbance could not be bracketed: runs "
                          "near it neither collided nor converged within the longest horizon",
    REASON_SIM_ROUNDS: "the simulated critical disturbance search reached its round limit "
                       "without a bracket",
}
# self-check: share of points recomputed point-wise, at most this many, and the tolerance
# of the paper's h (relative: the map interpolates h between branch points)
SPOT_CHECK_FRACTION = 0.01
SPOT_CHECK_MAX = 12
SPOT_CHECK_TOL = 0.03
#: the maglev models whose map rows this module computes (model A: its rows are written on
#: model A's parameter vector and its limited system)
MAP_MODELS = ("unit",)
# Largest grid accepted (points); beyond it the result arrays alone would not fit.
MAX_POINTS = 4_000_000
# the checkpoint's format: part of every tile's fingerprint, so that tiles written before a
# change of the stored variables are never reused
TILE_FORMAT = 2


@dataclass(frozen=True)
class Axis:
    """One swept parameter: ``count`` values from ``start`` to ``stop`` inclusive."""

    name: str
    start: float
    stop: float
    count: int

    @property
    def values(self) -> np.ndarray:
        return np.linspace(self.start, self.stop, self.count)


def parse_axis(text: str, option: str) -> Axis:
    """'NAME=START:STOP:COUNT' -> Axis, with errors that name the option, value and rule."""
    if "=" not in text:
        raise ParameterError(option, text, "expected NAME=START:STOP:COUNT, e.g. omega1=40:190:100")
    name, rng = (s.strip() for s in text.split("=", 1))
    if name not in FIELD_NAMES or name in ("n_modes",):
        raise ParameterError(option, text, f"unknown parameter '{name}'; sweepable names are: "
                             + ", ".join(n for n in FIELD_NAMES if n != "n_modes"))
    parts = rng.split(":")
    if len(parts) != 3:
        raise ParameterError(option, text, "expected NAME=START:STOP:COUNT with three numbers")
    try:
        start, stop = float(parts[0]), float(parts[1])
        count = int(parts[2])
    except ValueError:
        raise ParameterError(option, text, "START and STOP must be numbers, COUNT a whole number")\
            from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise ParameterError(option, text, "START and STOP must be finite")
    if count < 2:
        raise ParameterError(option, text, "COUNT must be at least 2")
    if not start < stop:
        raise ParameterError(option, text, "the range is empty or reversed: START must be < STOP")
    return Axis(name, start, stop, count)


@dataclass(frozen=True)
class MapSpec:
    """What to map: base parameters, the two axes and the numerical settings.

    ``simulate`` (default True): also the simulated critical disturbances, so that ``chi``
    is the headline index min(chi_paper, chi_simulation); False: the paper's index only
    (``chi`` = ``chi_paper``, the simulation variables NaN)."""

    base: dict[str, Any]  # Params.as_input_dict() of the base point
    x: Axis
    y: Axis
    rows_per_tile: int = 4
    ntst: int = 30
    ncol: int = 4
    max_steps: int = 300
    simulate: bool = True

    def key(self) -> str:
        """A fingerprint of the spec, stored with checkpoints so a resume can't mix maps
        (it names the stored variables and the simulation's search settings too)."""
        d = {"base": {k: self.base[k] for k in sorted(self.base)}, "x": self.x.__dict__,
             "y": self.y.__dict__, "rows_per_tile": self.rows_per_tile, "ntst": self.ntst,
             "ncol": self.ncol, "max_steps": self.max_steps, "simulate": self.simulate,
             "format": TILE_FORMAT, "variables": list(MAP_VARIABLES)}
        if self.simulate:
            d["simulation"] = simulation_settings().__dict__
        return json.dumps(d, sort_keys=True, default=float)

    def point(self, xv: float, yv: float) -> Params:
        values = dict(self.base)
        values[self.x.name] = float(xv)
        values[self.y.name] = float(yv)
        return make_params(values)

    def validate(self) -> None:
        """Every grid point must be a valid parameter set; the grid must fit in memory."""
        n = self.x.count * self.y.count
        if n > MAX_POINTS:
            raise ParameterError("grid", f"{self.x.count} x {self.y.count}",
                                 f"at most {MAX_POINTS} points fit in memory here")
        if self.x.name == self.y.name:
            raise ParameterError("--y", self.y.name, "must differ from the --x parameter")
        for xv in (self.x.start, self.x.stop):
            for yv in (self.y.start, self.y.stop):
                self.point(xv, yv)  # raises ParameterError naming the field
        for yv in self.y.values:
            for xv in self.x.values:
                self.point(xv, yv)
        if "tau" in (self.x.name, self.y.name):  # the delay must be resolvable (its rule)
            from maglev_match.maglev.unit import unit_system

            for xv in (self.x.start, self.x.stop):
                for yv in (self.y.start, self.y.stop):
                    p = self.point(xv, yv)
                    if p.tau > 0:
                        unit_system(p)  # raises ParameterError naming tau and its bound

    @property
    def tiles(self) -> list[tuple[int, int]]:
        r = self.rows_per_tile
        return [(a, min(a + r, self.y.count)) for a in range(0, self.y.count, r)]


def compute_row(spec: MapSpec, row: int) -> dict[str, np.ndarray]:
    """The paper's index along row ``row`` (y fixed, x varying), continuing cycles along it:
    ``chi`` (= h / w0, 0 where unstable, as the paper), ``h``, ``w0``, ``stable``,
    ``max_real_part``, ``hopf_distance``, ``case``, ``omega1_point``, ``sigma_point``,
    ``current_reverses``, ``resolved``, ``reason`` and ``hopf_x`` (the row's Hopf points
    inside the grid, x values, then NaN). :func:`compute_tile` adds the simulation and
    stores the map's variables.

    The row's path is extended beyond both ends by up to one span, sampled at the grid
    spacing, so that Hopf points just outside the grid (whose cycles reach into it) are
    found with the same resolution as inside. The equilibrium is x = 0 all along the path,
    so the Hopf points are detected from the eigenvalues at three samples per path interval
    (one batched Jacobian call, :func:`_scan_hopf_points`) rather than by continuing the
    equilibrium. Self-check: every sign change of max Re
    between neighbouring path nodes must hold a Hopf point; where the first scan has none,
    the interval is scanned again finely, and if there is still none the adjacent stable
    grid points are marked unresolved (``reason`` :data:`REASON_NO_HOPF`).
    """
    from maglev_match.core import jax_setup  # noqa: F401  (workers: float64 before anything)
    from maglev_match.dynamics.basin import FAILED
    from maglev_match.dynamics.cycles import cycle_branch
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.dynamics.paths import PATH_PARAM, path_system
    from maglev_match.maglev.limits import cycle_limit_margins

    yv = spec.y.values[row]
    xs = spec.x.values
    nx = xs.size
    pts = [spec.point(xv, yv) for xv in xs]
    # the path: extension below, the grid, extension above; grid point j sits at t = j + off
    ext_lo, ext_hi = _extension(spec, xs, yv)
    system, param_vector = _row_system(pts + [q for _, q in ext_lo + ext_hi])
    P = np.array([param_vector(p) for p in pts])
    w0 = np.array([p.w0 for p in pts])
    h_max = np.array([p.gap_max - p.c0 for p in pts])

    x_nodes = np.array([x for x, _ in ext_lo[::-1]] + list(xs) + [x for x, _ in ext_hi])
    nodes = np.array([param_vector(q) for _, q in ext_lo[::-1]] + list(P)
                     + [param_vector(q) for _, q in ext_hi])
    off = len(ext_lo)
    n_nodes = len(nodes)
    # eigenvalues of the equilibrium x = 0 at every node and two points between neighbours
    # (one stacked LAPACK call); the nodes are every third sample
    w_scan = _path_eigenvalues(system, nodes)
    max_re_all = w_scan[::SCAN_PER_NODE].real.max(axis=1)
    stable_all = max_re_all < 0
    max_re = max_re_all[off:off + nx]
    stable = stable_all[off:off + nx]
    h = np.where(stable, h_max, 0.0)
    case = np.where(stable, CASE_CODES["no_cycle_within_limits"],
                    CASE_CODES["unstable_equilibrium"])
    resolved = np.ones(nx, dtype=bool)
    reason = np.zeros(nx, dtype=np.int8)
    reverses = np.zeros(nx, dtype=bool)

    t_end = n_nodes - 1.0
    # the path's parameter vector is padded (the last node repeated, beyond t_end, never
    # reached: the branches stop at t_end) to a multiple of PATH_PAD nodes, so that rows
    # whose extensions differ by a node share every compiled kernel of the path system
    pad = -n_nodes % PATH_PAD
    path = path_system(system, np.concatenate([nodes, np.repeat(nodes[-1:], pad, axis=0)]))
    limits = cycle_limit_margins(pts[0], include_current=False)
    hopf_points = _scan_hopf_points(path, w_scan, t_end, system, nodes)

    def stretch_from(k: int, step: int) -> np.ndarray:
        """The stable nodes from node k (stable) walking in direction ``step``."""
        end = k
        while 0 <= end + step < n_nodes and stable_all[end + step]:
            end += step
        return np.arange(min(k, end), max(k, end) + 1)

    def mark(tj: np.ndarray, code: int) -> None:
        j = tj[(tj >= off) & (tj < off + nx)] - off
        j = j[stable[j]]
        resolved[j] = False
        reason[j] = np.where(reason[j] == 0, code, reason[j])

    # self-check: a sign change of max Re between nodes k, k+1 needs a Hopf point there
    for k in np.flatnonzero(stable_all[:-1] != stable_all[1:]):
        if any(k <= hp.value <= k + 1 for hp in hopf_points):
            continue
        fine = locate_hopf_points(path, PATH_PARAM, float(k), float(k + 1), n_scan=17)
        found = [hp for hp in fine.points if hp.converged and k <= hp.value <= k + 1]
        if found:
            hopf_points.extend(found)
            continue
        side, step = (k, -1) if stable_all[k] else (k + 1, 1)
        mark(stretch_from(side, step), REASON_NO_HOPF)
    hopf_points.sort(key=lambda hp: hp.value)

    covered = np.zeros(nx, dtype=bool)  # grid points of a stretch next to a Hopf point
    for hp in hopf_points:
        # the nodes of the stable stretch next to this Hopf point
        j_lo, j_hi = math.floor(hp.value), math.ceil(hp.value)
        if j_hi < n_nodes and stable_all[j_hi]:
            side, step = j_hi, 1
        elif j_lo >= 0 and stable_all[j_lo]:
            side, step = j_lo, -1
        else:
            continue
        stretch = stretch_from(side, step)
        in_grid = stretch[(stretch >= off) & (stretch < off + nx)]
        if in_grid.size == 0:
            continue  # the stretch lies wholly outside the grid
        covered[in_grid - off] = True
        end = int(in_grid.max() if step > 0 else in_grid.min())
        br = cycle_branch(path, hp, PATH_PARAM, stop_at=float(end), ntst=spec.ntst,
                          ncol=spec.ncol, max_steps=spec.max_steps, limits=limits,
                          param_bounds=(0.0, t_end), lam_scale=1.0)
        t = br.values
        if t.size == 0:
            mark(in_grid, REASON_NO_BRANCH)
            continue
        gmax = br.observable_max("gap_deviation")
        imin = br.observable_min("current")
        unstable = br.n_unstable >= 1
        for k in range(t.size - 1):
            lo, hi = sorted((t[k], t[k + 1]))
            if not (hi > lo and unstable[k] and unstable[k + 1]):
                continue
            for tj in in_grid:
                if lo <= tj <= hi:
                    j = tj - off
                    s = (tj - t[k]) / (t[k + 1] - t[k])
                    g = gmax[k] + s * (gmax[k + 1] - gmax[k])
                    if case[j] != CASE_CODES["unstable_cycle"] or g < h[j]:
                        h[j] = g
                        case[j] = CASE_CODES["unstable_cycle"]
                        reverses[j] = (imin[k] + s * (imin[k + 1] - imin[k])) < 0
        reached = t.max() if step > 0 else t.min()
        heading_in = (t[min(3, t.size - 1)] - hp.value) * step > 0
        if br.stopped_reason in (*FAILED, "max_steps") and heading_in:
            # the branch was entering the stretch but stopped: what lies beyond is unknown
            beyond = in_grid[(in_grid - reached) * step > 0]
            beyond = beyond[case[beyond - off] != CASE_CODES["unstable_cycle"]]
            mark(beyond, REASON_FAILED if br.stopped_reason in FAILED else REASON_MAX_STEPS)
    hopf_x = np.full(nx, np.nan)
    if hopf_points:
        # distance to the nearest Hopf point along the row, in units of the x parameter
        # (the path position t maps to x through the nodes, extension included)
        x_hopf = np.interp([hp.value for hp in hopf_points], np.arange(n_nodes), x_nodes)
        dist = np.min(np.abs(xs[:, None] - x_hopf[None, :]), axis=1)
        inside = x_hopf[(x_hopf >= xs[0]) & (x_hopf <= xs[-1])][:nx]
        hopf_x[:inside.size] = inside
    else:
        dist = np.full(nx, np.inf)
    h = np.where(resolved, h, np.nan)
    chi = h / w0
    out = {
        "chi": chi, "h": h, "w0": w0, "stable": stable, "max_real_part": max_re,
        "hopf_distance": dist, "case": case.astype(np.int8),
        "omega1_point": P[:, system.param_index("omega1")],
        "sigma_point": P[:, system.param_index("sigma")],
        "current_reverses": reverses, "resolved": resolved, "reason": reason,
        "hopf_x": hopf_x,
    }
    # A delayed row's zero-delay points take the point-wise index (the row passed them at the
    # floor delay).
    zero_delay = [j for j, p in enumerate(pts) if p.tau == 0] if hasattr(system, "dde") else []
    _pointwise_points(out, pts, zero_delay)
    # A stable stretch with no Hopf point at either end on the path: the row has no cycle to
    # continue to its points, so "no cycle within limits" would be a claim without evidence
    # (a cycle born at a Hopf point off the row can still reach them). Both ends of such a
    # stretch are computed by the point-wise paper index, as `index` computes it (its own
    # Hopf search along omega1 and sigma); when both confirm no cycle within the limits, the
    # interior keeps that reading (a cycle's amplitude grows away from its Hopf point), else
    # every point of the stretch takes the point-wise index.
    orphan = stable & ~covered & resolved
    orphan[zero_delay] = False
    for s, e in _stretches(orphan):
        ends = sorted({int(s), int(e)})
        _pointwise_points(out, pts, ends)
        confirmed = all(out["stable"][j] and out["resolved"][j] and out["case"][j]
                        == CASE_CODES["no_cycle_within_limits"] for j in ends)
        if not confirmed:
            _pointwise_points(out, pts, range(s + 1, e))
    return out


def _row_system(points: list[Params]):
    """The system of a row and the parameter vector of a point on it: model A's ODE when
    no point of the row (extension included) has a delay; else its discretised delay system
    with nodes for the row's largest delay, the delay entering the vector as its last entry,
    and a zero delay replaced by :data:`DELAY_FLOOR` times the largest (the discretisation
    is singular at tau = 0; :func:`_pointwise_points` recomputes those points)."""
    from maglev_match.maglev.unit import param_vector, unit_system

    tau_max = max(p.tau for p in points)
    if tau_max == 0:
        return unit_system(points[0]), param_vector
    floor = DELAY_FLOOR * tau_max

    def vector(p: Params) -> np.ndarray:
        return np.append(param_vector(p), max(p.tau, floor))

    return unit_system(points[0], tau_max=tau_max), vector


def _pointwise_points(out: dict[str, np.ndarray], pts: list[Params],
                      which: Sequence[int]) -> None:
    """Points ``which`` of a row recomputed by the point-wise paper index (in place): the
    points of a stable stretch the row's path reaches from no Hopf point, and the points of
    a delayed row whose delay is 0 (e.g. the first column of a tau axis; the row's path
    passed them at the floor delay, and the point-wise index uses the delay-free model)."""
    from maglev_match.analyses.matching import matching_index

    for j in which:
        p = pts[j]
        res = matching_index(p, simulate=False)
        out["chi"][j], out["h"][j] = res.chi, res.h
        out["stable"][j], out["max_real_part"][j] = res.stable, res.max_real_part
        out["case"][j] = CASE_CODES.get(str(res.case), out["case"][j])
        out["current_reverses"][j] = res.current_reverses
        out["resolved"][j] = bool(res.converged)
        out["reason"][j] = 0 if res.converged else REASON_FAILED


PATH_PAD = 16  # the path's nodes are padded to a multiple of this (shared kernels)
DELAY_FLOOR = 1e-3  # a zero delay on a delayed row's path, as a fraction of the largest
SCAN_PER_NODE = 3  # samples of the Hopf scan per path interval (as the earlier scan)
SCAN_BATCH = 64  # the stacked Jacobian call is padded to a multiple of this many samples
REFINE_WINDOW = 4  # nodes of the short path on which a Hopf guess is refined
FINE_SCAN = 17  # samples of the fallback scan by equilibrium continuation in one interval


def _path_eigenvalues(system, nodes: np.ndarray) -> np.ndarray:
    """Eigenvalues of the Jacobian at the equilibrium x = 0 at the path positions
    t = i / SCAN_PER_NODE, i = 0 .. SCAN_PER_NODE (n_nodes - 1): shape (n_samples, dim).

    The parameter vectors are interpolated as the path system does, (1 - s) P_k + s P_{k+1}
    (so sample SCAN_PER_NODE k is exactly node k); the Jacobians come from one batched
    compiled call (padded to a multiple of :data:`SCAN_BATCH` rows so that rows of slightly
    different lengths share one kernel) and their eigenvalues from one stacked LAPACK call.
    """
    s = np.arange(SCAN_PER_NODE) / SCAN_PER_NODE
    P = ((1.0 - s)[None, :, None] * nodes[:-1, None, :]
         + s[None, :, None] * nodes[1:, None, :]).reshape(-1, nodes.shape[1])
    P = np.concatenate([P, nodes[-1:]])
    m = len(P)
    pad = -m % SCAN_BATCH
    Pp = np.concatenate([P, np.repeat(P[-1:], pad, axis=0)]) if pad else P
    J = np.asarray(system.derivatives.jacobian_batch(np.zeros((len(Pp), system.dim)), Pp))
    return np.linalg.eigvals(J[:m])


def _hopf_test_sign(w: np.ndarray) -> np.ndarray:
    """Sign of the bialternate-product Hopf test prod_{i<j} (l_i + l_j) at each row of
    eigenvalues ``w`` (shape (n_samples, dim)): it changes sign where a complex pair crosses
    the imaginary axis, and at neutral saddles (Kuznetsov 2004, sec. 10.2.2). The product is
    real (non-real sums come with their conjugates), so its sign is the product of the signs
    of the real sums."""
    i, j = np.triu_indices(w.shape[1], 1)
    sums = w[:, i] + w[:, j]
    real = np.abs(sums.imag) <= 1e-12 * np.abs(sums)
    signs = np.where(real, np.sign(sums.real), 1.0)
    return np.prod(signs, axis=1)


def _refine_on_window(path, system, nodes: np.ndarray, tg: float, om: float, t_end: float):
    """:func:`~maglev_match.dynamics.hopf.refine_hopf_point` at path position ``tg`` on the
    path through the :data:`REFINE_WINDOW` nodes around it (the same piecewise-linear path
    there, but its parameter vector is short: the parameter derivative of the crossing
    speed then differentiates with respect to a few dozen parameters, not thousands, and
    every row shares the kernels). The point is mapped back onto ``path`` (value + first
    node, the full parameter vector); a point that converges outside the window (where the
    short path would extrapolate its end segments) is refined again on the whole path."""
    import dataclasses

    from maglev_match.dynamics.hopf import refine_hopf_point
    from maglev_match.dynamics.paths import PATH_PARAM, path_system

    x0 = np.zeros(path.dim)
    scale = max(abs(tg), t_end)
    n = len(nodes)
    if n > REFINE_WINDOW:
        k0 = int(np.clip(math.floor(tg) - (REFINE_WINDOW - 2) // 2, 0, n - REFINE_WINDOW))
        window = path_system(system, nodes[k0:k0 + REFINE_WINDOW])
        hp = refine_hopf_point(window, PATH_PARAM, tg - k0, x0, om, value_scale=scale,
                               bounds=(0.0, REFINE_WINDOW - 1.0))
        if hp.converged:
            value = hp.value + k0
            return dataclasses.replace(hp, value=value,
                                       p=path.params_with(path.p, **{PATH_PARAM: value}))
    return refine_hopf_point(path, PATH_PARAM, tg, x0, om, value_scale=scale,
                             bounds=(0.0, t_end))


def _scan_hopf_points(path, w: np.ndarray, t_end: float, system, nodes: np.ndarray) -> list:
    """Converged Hopf points of the equilibrium x = 0 along the path, from the eigenvalues
    ``w`` at t = i / SCAN_PER_NODE (:func:`_path_eigenvalues`).

    The same detection as the equilibrium continuation of
    :func:`~maglev_match.dynamics.hopf.locate_hopf_points` without continuing a known
    equilibrium: a sample interval where the Hopf test changes sign and exactly one complex
    pair crosses the imaginary axis gives a Hopf guess (the real part of the crossing pair
    interpolated linearly to zero, its imaginary part as the frequency), refined by Newton's
    method on the Hopf defining system and validated
    (:func:`~maglev_match.dynamics.hopf.refine_hopf_point`). Intervals that are not this
    simple case (two pairs crossing, a sign change without a crossing pair, a crossing
    without a sign change) are scanned again by equilibrium continuation with
    :data:`FINE_SCAN` samples (which splits steps until each crossing has its own).
    """
    from maglev_match.dynamics.equilibria import pair_crossings
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.dynamics.paths import PATH_PARAM

    ts = np.arange(len(w)) / SCAN_PER_NODE
    sign = _hopf_test_sign(w)
    points: list = []

    def add(hp) -> None:
        if any(abs(hp.value - o.value) <= 1e-9 * max(1.0, abs(o.value))
               and abs(hp.frequency - o.frequency) <= 1e-6 * o.frequency for o in points):
            return
        points.append(hp)

    for i in range(len(w) - 1):
        wa, wb = w[i], w[i + 1]
        flip = sign[i] != sign[i + 1]
        crossings = pair_crossings(wa, wb)
        if not flip and crossings == 0:
            continue
        if flip and crossings == 1:
            for lam in wa[wa.imag > 1e-9]:
                mu = wb[int(np.argmin(np.abs(wb - lam)))]
                if mu.imag > 1e-9 and (lam.real > 0) != (mu.real > 0):
                    f = lam.real / (lam.real - mu.real)
                    tg = ts[i] + f * (ts[i + 1] - ts[i])
                    om = lam.imag + f * (mu.imag - lam.imag)
                    add(_refine_on_window(path, system, nodes, float(tg), float(om), t_end))
                    break
            continue
        fine = locate_hopf_points(path, PATH_PARAM, float(ts[i]), float(ts[i + 1]),
                                  n_scan=FINE_SCAN)
        for hp in fine.points:
            add(hp)
    points.sort(key=lambda hp: hp.value)
    return [hp for hp in points if hp.converged]


def _extension(spec: MapSpec, xs: np.ndarray, yv: float
               ) -> tuple[list[tuple[float, Params]], list[tuple[float, Params]]]:
    """Parameter sets beyond both ends of a row, at the grid spacing, out to one span (or
    to the last valid parameter set before that, and on a delay axis to the longest delay
    the discretisation resolves): lists of (x, Params), nearest first."""
    dx = (xs[-1] - xs[0]) / (xs.size - 1)
    tau_bound = math.inf  # along a delay axis: the longest delay the discretisation resolves
    if spec.x.name == "tau":
        from maglev_match.dynamics.delay import max_delay_for
        from maglev_match.maglev.unit import unit_dde

        tau_bound = max_delay_for(unit_dde(spec.point(xs[-1], yv)).rate_bound())
    out: list[list[tuple[float, Params]]] = []
    for end, sign in ((xs[0], -1.0), (xs[-1], 1.0)):
        side: list[tuple[float, Params]] = []
        for k in range(1, xs.size):
            xv = end + sign * k * dx
            if xv > tau_bound:
                break
            try:
                side.append((xv, spec.point(xv, yv)))
            except ParameterError:
                break
        out.append(side)
    return out[0], out[1]


# ---------------------------------------------------------------------------------------
# the simulated critical disturbance, followed along the rows
# ---------------------------------------------------------------------------------------
# the two directions of the beam-deflection disturbance x5(0): beam up (x5 < 0, the gap
# opens) and beam down (x5 > 0), as in the point-wise index
DIRECTIONS = (-1, 1)
ANCHOR_SPACING = 32  # cold searches at most this many grid points apart along a stretch
WARM_ANCHOR_SPACING = 2  # first searches of a row that has guesses from the rows below
SINGLE_SPREAD = 5.0  # spread of a guess from one neighbour only, in search tolerances
# runs per batched kernel call (64 measured no faster: a call's step costs ~75 us plus
# ~1.7 us per run on the 2-core machine, and wider chunks wait longer for their slowest run)
SIM_CHUNK = 32
_SETTINGS: list = []


def simulation_settings():
    """The search settings of the map's critical disturbances
    (:class:`~maglev_match.dynamics.integrate.threshold.ThresholdOptions`): those of the point-wise
    search :func:`maglev_match.analyses.simulation.critical_disturbance` on model A (its
    :attr:`~maglev_match.maglev.models.UnitModel.critical_search`: the tolerance, first
    horizon, horizon doublings and sizes per round, hence the largest size it tries), so
    that the map and the point-wise index agree within the tolerance."""
    if not _SETTINGS:
        from maglev_match.dynamics.integrate.threshold import ThresholdOptions
        from maglev_match.maglev.models import UnitModel

        search = UnitModel.critical_search
        batch = int(search.batch)
        _SETTINGS.append(ThresholdOptions(
            tol=float(search.tol), t_max=float(search.t_max),
            max_extend=int(search.max_extend), cold_sizes=batch,
            top_fraction=batch / (batch + 1), chunk=SIM_CHUNK))
    return _SETTINGS[0]


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


def _stretches(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end] (inclusive) of every run of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True))


def _next_targets(stable: np.ndarray, done: np.ndarray, known: np.ndarray,
                  base: np.ndarray, base_spread: np.ndarray, tol: float
                  ) -> list[tuple[int, float, float]]:
    """The points of a row to search next, coarse to fine, with their guesses:
    (j, guess or NaN, spread). In a stable stretch without a known size: its two ends and
    points ANCHOR_SPACING apart (WARM_ANCHOR_SPACING with predictions ``base`` from the
    rows below: their guesses; without, cold searches); elsewhere the ends of the stretch
    and the middle of every gap between known sizes (guesses from :func:`_guess`)."""
    out: list[tuple[int, float, float]] = []
    for s, e in _stretches(stable):
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


def _simulate_rows(spec: MapSpec, rows: tuple[int, int], paper: list[dict]
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
        row, known = _simulate_row(spec, r, pr, below)
        below.append(known)
        out.append(row)
    return out


def _simulate_row(spec: MapSpec, r: int, pr: dict, below: list[dict[int, np.ndarray]]
                  ) -> tuple[dict[str, np.ndarray], dict[int, np.ndarray]]:
    """One row of :func:`_simulate_rows` (``below``: the sizes of the rows below, for
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


def compute_tile(spec: MapSpec, rows: tuple[int, int]) -> dict[str, np.ndarray]:
    """Rows [a, b) of the map stacked: the arrays of :data:`MAP_VARIABLES`, shape
    (b - a, nx). The paper's index by :func:`compute_row`; with ``spec.simulate`` the
    critical disturbances by :func:`_simulate_rows` and the headline index
    chi = min(chi_paper, chi_simulation)."""
    paper = [compute_row(spec, r) for r in range(*rows)]
    nx = spec.x.count
    sim = (_simulate_rows(spec, rows, paper) if spec.simulate
           else [{"h_up": np.full(nx, np.nan), "h_down": np.full(nx, np.nan),
                  "reason": np.zeros(nx, np.int8)} for _ in paper])
    out = [_combine(pr, sr, spec.simulate) for pr, sr in zip(paper, sim, strict=True)]
    return {k: np.stack([o[k] for o in out]) for k in MAP_VARIABLES}


def _combine(pr: dict[str, np.ndarray], sr: dict[str, np.ndarray], simulate: bool
             ) -> dict[str, np.ndarray]:
    """The map's variables of one row from the paper's row and the simulated sizes:
    index variables NaN at unstable points and where a part is unresolved."""
    stable = np.asarray(pr["stable"], bool)
    w0 = pr["w0"]
    paper_ok = np.asarray(pr["resolved"], bool)
    h = np.where(stable, pr["h"], np.nan)
    chi_paper = h / w0
    h_sim = np.minimum(sr["h_up"], sr["h_down"])  # NaN if either is NaN
    chi_sim = np.where(stable, h_sim / w0, np.nan)
    sim_ok = ~stable | np.isfinite(h_sim) if simulate else np.ones_like(stable)
    resolved = paper_ok & sim_ok
    reason = np.where(pr["reason"] != 0, pr["reason"], sr["reason"]).astype(np.int8)
    if simulate:
        chi = np.fmin(chi_paper, chi_sim)  # NaN only if both are
        chi = np.where(resolved & stable, chi, np.nan)
        basis = np.where(stable & resolved & (chi_sim < chi_paper), BASIS_CODES["simulation"],
                         BASIS_CODES["paper"])
    else:
        chi = np.where(paper_ok, chi_paper, np.nan)
        basis = np.full(stable.shape, BASIS_CODES["paper"])
    return {
        "chi": chi, "chi_paper": chi_paper, "chi_simulation": chi_sim, "h": h,
        "h_simulation_up": np.where(stable, sr["h_up"], np.nan),
        "h_simulation_down": np.where(stable, sr["h_down"], np.nan),
        "chi_basis": basis.astype(np.int8), "w0": w0, "stable": stable,
        "max_real_part": pr["max_real_part"], "hopf_distance": pr["hopf_distance"],
        "case": pr["case"], "omega1_point": pr["omega1_point"],
        "sigma_point": pr["sigma_point"], "current_reverses": pr["current_reverses"],
        "resolved": resolved, "reason": reason, "hopf_x": pr["hopf_x"],
    }


def run_map(
    spec: MapSpec,
    checkpoint: Path,
    *,
    resume: bool = False,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    max_tiles: int | None = None,
    log: Path | None = None,
    echo_dask: bool = False,
) -> dict[str, np.ndarray]:
    """Compute the map tile by tile, here or on Dask (the package's job runner,
    :func:`maglev_match.core.jobs.run_job`), checkpointing every finished tile.

    Parameters
    ----------
    checkpoint : folder for the tiles (created); with ``resume`` its tiles are reused.
        The folder is locked for the duration of the run (a second run on it raises
        :class:`~maglev_match.core.checkpoint.CheckpointLocked`); tiles of another map or
        unreadable tiles are named in a warning and recomputed.
    scheduler : address of an existing Dask scheduler (tcp://host:port); default a local
        cluster with ``workers`` processes (default: all cores), or no cluster at all when
        ``workers == 0`` (compute in this process).
    max_tiles : compute at most this many new tiles, then stop (for tests of resuming).
    log : file that receives Dask's own messages (its logging and warnings: a port in use,
        workers killed at shutdown) instead of the terminal; created only when there is
        one (None: dropped). echo_dask : show them on the terminal too (``--debug``).
    Returns the assembled arrays, shape (ny, nx); raises RuntimeError when tiles are missing
    and :class:`~maglev_match.core.checkpoint.MapStopped` (with the resume hint) on Ctrl-C or a
    lost scheduler.
    """
    spec.validate()
    CollocationMesh(spec.ntst, spec.ncol, spec.max_steps)  # raises ParameterError
    job = Job(pieces=spec.tiles, compute=compute_tile, args_of=lambda rows: (spec, rows),
              store=lambda folder: checkpoint_mod.tile_checkpoint(
                  folder, spec.key(), MAP_VARIABLES, spec.x.count))
    return run_job(job, Path(checkpoint), resume=resume, scheduler=scheduler, workers=workers,
                   progress=progress, limit=max_tiles, log=log, echo_dask=echo_dask,
                   finish=lambda store: assemble(spec, store.folder))


def assemble(spec: MapSpec, checkpoint: Path) -> dict[str, np.ndarray]:
    """Stack the checkpointed tiles into (ny, nx) arrays (each tile checked first)."""
    key = spec.key()
    missing = [t for t in spec.tiles
               if not checkpoint_mod.check_tile(checkpoint, t, key, MAP_VARIABLES,
                                                spec.x.count).ok]
    if missing:
        raise RuntimeError(f"{len(missing)} of {len(spec.tiles)} tiles not computed yet "
                           f"(checkpoint {checkpoint}); run again with --resume")
    parts = [checkpoint_mod.load_tile(checkpoint, t) for t in spec.tiles]
    return {k: np.concatenate([p[k] for p in parts], axis=0) for k in parts[0]}


def spot_check(spec: MapSpec, data: dict[str, np.ndarray], *,
               fraction: float = SPOT_CHECK_FRACTION, max_points: int = SPOT_CHECK_MAX,
               seed: int = 0, tol: float = SPOT_CHECK_TOL,
               budget: float | None = None) -> dict[str, Any]:
    """Recompute a seeded random sample of the map's points with the point-wise index
    (:func:`maglev_match.analyses.matching.matching_index`, with the simulation when the map has it)
    and compare.

    ``fraction`` of the points, at least one and at most ``max_points`` (the cap keeps the
    check within about 10 % of the map's time). At each point:

    * the paper's h: |h_map - h_point| / h_point (0 when both are unstable; 1 when they
      disagree on stability), allowed ``tol`` (the map reads h off a branch continued
      along the row, the point-wise index off a branch continued to the point);
    * with the simulation, each direction's critical disturbance: |d_map - d_point| (m),
      allowed the search tolerance (both are brackets of that width around the critical
      size, so their midpoints differ by less);
    * the headline index chi = min(chi_paper, chi_simulation) against the point-wise
      min(chi_paper, chi_simulation): allowed the allowance of the part that decided it on
      both sides (the search tolerance / w0, or the relative tolerance of chi_paper), the
      larger of the two where the sides disagree on the part (min is 1-Lipschitz in each
      part).

    Unresolved map points are skipped (counted). ``budget`` (s): stop after the point
    during which the check's time exceeded it (at least one point is always checked); the
    sample order is seeded, so a shorter check is a prefix of a longer one. Returns the
    attributes stored on the dataset (``spot_check_records``: one row per point, the
    columns named in ``spot_check_columns``).
    """
    import time

    from maglev_match.analyses.matching import matching_index

    started = time.perf_counter()
    sim_tol = simulation_settings().tol
    ny, nx = data["stable"].shape
    n = max(1, min(max_points, math.ceil(fraction * nx * ny)))
    rng = np.random.default_rng(seed)
    flat = rng.choice(nx * ny, size=min(n, nx * ny), replace=False)
    worst = worst_sim = worst_head = 0.0
    worst_at = worst_sim_at = worst_head_at = None
    head_ok = True
    checked = skipped = 0
    records: list[list[float]] = []
    for f in (int(v) for v in flat):
        if budget is not None and checked and time.perf_counter() - started > budget:
            break
        i, j = divmod(f, nx)
        if not data["resolved"][i, j]:
            skipped += 1
            continue
        xv, yv = spec.x.values[j], spec.y.values[i]
        pt = matching_index(spec.point(xv, yv), simulate=spec.simulate)
        stable_map = bool(data["stable"][i, j])
        h_map = float(data["h"][i, j]) if stable_map else 0.0
        h_pt = float(pt.h)
        if stable_map != pt.stable or not math.isfinite(h_pt):
            diff = 1.0
        elif h_pt == 0.0:
            diff = 0.0 if h_map == 0.0 else 1.0
        else:
            diff = abs(h_map - h_pt) / abs(h_pt)
        rec = [float(xv), float(yv), h_map, h_pt, diff]
        if diff >= worst:
            worst, worst_at = diff, rec
        if spec.simulate:
            sims = []
            for key in ("up", "down"):
                d_map = float(data[f"h_simulation_{key}"][i, j])
                d_pt = getattr(pt, f"h_simulation_{key}")
                d_pt = math.nan if d_pt is None else float(d_pt)
                both_na = not stable_map and not pt.stable
                dd = 0.0 if both_na else abs(d_map - d_pt)
                dd = math.inf if math.isnan(dd) else dd
                sims += [d_map, d_pt]
                if dd >= worst_sim:
                    worst_sim, worst_sim_at = dd, (rec[:2], key, d_map, d_pt)
            chi_map = float(data["chi"][i, j])
            chi_pt = _headline(pt)
            # the part that decided the headline on both sides sets the allowance; where
            # the two sides disagree on it, the larger allowance (min is 1-Lipschitz)
            paper_allowed, sim_allowed = tol * abs(pt.chi_paper), sim_tol / float(pt.w0)
            by_sim_map = int(data["chi_basis"][i, j]) == BASIS_CODES["simulation"]
            by_sim_pt = (pt.chi_simulation is not None
                         and float(pt.chi_simulation) < float(pt.chi_paper))
            if by_sim_map and by_sim_pt:
                allowed = sim_allowed
            elif not by_sim_map and not by_sim_pt:
                allowed = paper_allowed
            else:
                allowed = max(paper_allowed, sim_allowed)
            if not stable_map and not pt.stable:
                dh = 0.0
            else:
                dh = abs(chi_map - chi_pt)
                dh = math.inf if math.isnan(dh) else dh
            ok = dh <= allowed
            head_ok = head_ok and ok
            rec += [*sims, chi_map, chi_pt, dh, allowed]
            if dh >= worst_head:
                worst_head, worst_head_at = dh, (rec[:2], chi_map, chi_pt, allowed)
        checked += 1
        records.append(rec)
    warnings = []
    if worst > tol and worst_at is not None:
        warnings.append(
            f"spot check: at {spec.x.name} = {worst_at[0]:.6g}, {spec.y.name} = {worst_at[1]:.6g} "
            f"the map gives h = {worst_at[2] * 1e3:.4g} mm and the point-wise index "
            f"{worst_at[3] * 1e3:.4g} mm (relative difference {worst:.3g} > {tol:g})")
    if spec.simulate and worst_sim > sim_tol and worst_sim_at is not None:
        (wx, wy), key, d_map, d_pt = worst_sim_at
        warnings.append(
            f"spot check: at {spec.x.name} = {wx:.6g}, {spec.y.name} = {wy:.6g} the map's "
            f"critical disturbance ({key}) is {d_map * 1e3:.5g} mm and the point-wise "
            f"search's {d_pt * 1e3:.5g} mm (difference > the search tolerance "
            f"{sim_tol * 1e3:g} mm)")
    if spec.simulate and not head_ok and worst_head_at is not None:
        (wx, wy), c_map, c_pt, allowed = worst_head_at
        warnings.append(
            f"spot check: at {spec.x.name} = {wx:.6g}, {spec.y.name} = {wy:.6g} the map's "
            f"headline chi = {c_map:.5g} and the point-wise index's {c_pt:.5g} differ by "
            f"more than the allowed {allowed:.3g}")
    columns = ["x", "y", "h_map", "h_point", "h_rel_diff"]
    if spec.simulate:
        columns += ["h_simulation_up_map", "h_simulation_up_point", "h_simulation_down_map",
                    "h_simulation_down_point", "chi_map", "chi_point", "chi_abs_diff",
                    "chi_allowed_diff"]
    passed = worst <= tol and (not spec.simulate or (worst_sim <= sim_tol and head_ok))
    out = {
        "spot_check_points": checked,
        "spot_check_planned": int(flat.size),
        "spot_check_seconds": round(time.perf_counter() - started, 3),
        "spot_check_skipped_unresolved": skipped,
        "spot_check_seed": seed,
        "spot_check_max_rel_diff": float(worst),
        "spot_check_tolerance": tol,
        "spot_check_passed": int(passed),
        "spot_check_columns": json.dumps(columns),
        "spot_check_records": json.dumps(records),
        "warnings": json.dumps(warnings),
    }
    if spec.simulate:
        out.update({
            "spot_check_simulation_max_diff": float(worst_sim),
            "spot_check_simulation_tolerance": sim_tol,
            "spot_check_headline_max_diff": float(worst_head),
            "spot_check_headline_passed": int(head_ok),
        })
    return out


def _headline(pt) -> float:
    """The headline index of a point-wise result: min(chi_paper, chi_simulation), or
    chi_paper when the simulation gave no number (not run, unstable, inconclusive)."""
    paper = float(pt.chi_paper)
    if not pt.stable:
        return math.nan
    if pt.chi_simulation is None:
        return paper
    return min(paper, float(pt.chi_simulation))


def map_warnings(ds) -> list[str]:
    """Every warning of a map dataset: the spot check's and the unresolved points by
    reason."""
    out = list(json.loads(ds.attrs.get("warnings", "[]")))
    if "reason" in ds:
        codes, counts = np.unique(ds["reason"].values, return_counts=True)
        for c, k in zip(codes, counts, strict=True):
            if c != 0:
                out.append(f"{k} unresolved point(s): {REASON_CODES.get(int(c), str(c))}")
    return out


# units and long names of the map's variables (``chi`` depends on the simulation)
_VARIABLE_DOCS: dict[str, tuple[str, str]] = {
    "chi_paper": ("1", "matching index by the paper's definition, h / w0 (NaN where unstable "
                       "or unresolved)"),
    "chi_simulation": ("1", "h_simulation / w0 with h_simulation the smaller simulated "
                            "critical disturbance of the two directions"),
    "h": ("m", "basin size by the paper's definition: the unstable cycle's largest gap "
               "deviation, or the gap range"),
    "h_simulation_up": ("m", "simulated critical beam-deflection disturbance, beam up "
                             "(x5(0) < 0), physical limits on"),
    "h_simulation_down": ("m", "simulated critical beam-deflection disturbance, beam down "
                               "(x5(0) > 0), physical limits on"),
    "chi_basis": ("code", "which part decided chi (codes in the basis_codes attribute)"),
    "w0": ("m", "static beam deflection under one levitation unit"),
    "stable": ("bool", "equilibrium stable (1) or unstable (0)"),
    "max_real_part": ("1/s", "largest real part of the eigenvalues of the equilibrium"),
    "case": ("code", "case that decided h (codes in the case_codes attribute)"),
    "omega1_point": ("rad/s", "beam first modal circular frequency at the grid point"),
    "sigma_point": ("1/kg", "force gain coefficient at the grid point"),
    "current_reverses": ("bool", "coil current on the deciding cycle would reverse (1) or "
                                 "not (0)"),
    "resolved": ("bool", "point resolved (1), or a part of its index could not be computed "
                         "(0; the reason in 'reason')"),
    "reason": ("code", "why the point is unresolved (0: resolved; codes in the reason_codes "
                       "attribute)"),
}


def map_dataset(spec: MapSpec, data: dict[str, np.ndarray], *, check: bool = True,
                seed: int = 0, budget: float | None = None, hopf_curve: bool = True,
                fraction: float = SPOT_CHECK_FRACTION, max_points: int = SPOT_CHECK_MAX):
    """The map as an xarray Dataset over coordinates named after the swept parameters.

    Variables: ``chi`` (the headline index min(chi_paper, chi_simulation), or chi_paper
    when the map was computed without the simulation: the attribute ``index_definition``
    says which), ``chi_paper``, ``chi_simulation``, ``h``, ``h_simulation_up``,
    ``h_simulation_down`` (m), ``chi_basis``, ``w0``, ``stable``, ``max_real_part``,
    ``hopf_distance``, ``case``, ``omega1_point``, ``sigma_point``, ``current_reverses``,
    ``resolved``, ``reason``, ``hopf_x`` (the Hopf points of each row, over the dimension
    ``hopf``) and, with ``hopf_curve`` when both axes are parameters of model A, the Hopf
    curve continued in the map's plane (``hopf_curve_x``, ``hopf_curve_y``,
    ``hopf_curve_l1`` over ``hopf_curve_point``, branches separated by NaN;
    :func:`maglev_match.dynamics.hopf_curve.hopf_curves_from_scans` inside the map's
    ranges). Index variables are NaN at unstable points (``stable`` = 0) and at
    unresolved ones (``resolved`` = 0, ``reason`` a code of ``reason_codes``).

    With ``check`` (default) a seeded sample of points (``fraction`` of them, at most
    ``max_points``) is recomputed point-wise (:func:`spot_check`, within ``budget``
    seconds) and the result stored in the attributes ``spot_check_*`` and ``warnings`` (a
    JSON list)."""
    import xarray as xr

    from maglev_match.core.params import PARAMETER_DOCS

    data = dict(data)
    dims = (spec.y.name, spec.x.name)
    docs = dict(_VARIABLE_DOCS)
    x_unit = PARAMETER_DOCS.get(spec.x.name, ("",))[0] or "1"
    docs["hopf_distance"] = (x_unit, "distance to the nearest Hopf point along the row "
                                     f"(in {spec.x.name})")
    if spec.simulate:
        definition = ("chi = min(chi_paper, chi_simulation): the headline index, the one the "
                      "reading of 'maglev-match index' uses")
        docs["chi"] = ("1", "headline matching index min(chi_paper, chi_simulation) (NaN "
                            "where unstable or unresolved)")
        sim_text = (f"critical disturbances by simulation with the physical limits on, both "
                    f"directions, bracketed to {simulation_settings().tol * 1e3:g} mm (the "
                    "point-wise search's tolerance)")
    else:
        definition = ("chi = chi_paper: the paper's definition only (map computed without "
                      "the simulation, --no-simulation)")
        docs["chi"] = ("1", "matching index by the paper's definition, h / w0 (map without "
                            "simulation; NaN where unstable or unresolved)")
        sim_text = "not run (--no-simulation): chi_simulation and h_simulation_* are NaN"
    attrs: dict[str, Any] = {
        "title": "maglev-match design map",
        "index_definition": definition,
        "simulation": sim_text,
        "simulation_tolerance": simulation_settings().tol if spec.simulate else math.nan,
        "case_codes": json.dumps(CASE_CODES),
        "basis_codes": json.dumps(BASIS_CODES),
        "reason_codes": json.dumps({str(k): v for k, v in REASON_CODES.items()}),
        "unstable_points": "index variables are NaN where the equilibrium is unstable "
                           "(stable = 0); the paper assigns chi = 0 there",
        "spec": spec.key(),
    }
    if check:
        attrs.update(spot_check(spec, data, seed=seed, budget=budget, fraction=fraction,
                                max_points=max_points))
    else:
        attrs["warnings"] = json.dumps(["no spot check was run"])
    variables = {}
    for k in MAP_VARIABLES:
        if k == "hopf_x":
            continue
        unit, long_name = docs.get(k, ("", k))
        variables[k] = (dims, data[k], {"units": unit, "long_name": long_name})
    hx = np.asarray(data["hopf_x"], float)
    width = max(1, int(np.max(np.sum(np.isfinite(hx), axis=1))) if hx.size else 1)
    variables["hopf_x"] = ((spec.y.name, "hopf"), hx[:, :width], {
        "units": x_unit, "long_name": f"Hopf points of each row ({spec.x.name} values inside "
        "the grid), solved on the row's path; NaN after the last"})
    coords = {
        spec.x.name: (spec.x.name, spec.x.values,
                      {"units": PARAMETER_DOCS.get(spec.x.name, ("",))[0]}),
        spec.y.name: (spec.y.name, spec.y.values,
                      {"units": PARAMETER_DOCS.get(spec.y.name, ("",))[0]}),
        "hopf": ("hopf", np.arange(width), {"units": "1", "long_name": "Hopf point number"}),
    }
    if hopf_curve:
        curve, note = _hopf_curve_in_plane(spec, hx)
        attrs["hopf_curve"] = note
        if curve is not None:
            y_unit = PARAMETER_DOCS.get(spec.y.name, ("",))[0] or "1"
            for name, col, unit, what in (
                    ("hopf_curve_x", 0, x_unit, spec.x.name),
                    ("hopf_curve_y", 1, y_unit, spec.y.name),
                    ("hopf_curve_l1", 2, "1/s", "first Lyapunov coefficient l1")):
                variables[name] = (("hopf_curve_point",), curve[:, col], {
                    "units": unit, "long_name": f"Hopf curve continued in the map's plane: "
                    f"{what} (branches separated by NaN)"})
    ds = xr.Dataset(variables, coords=coords, attrs=attrs)
    for k in ("stable", "current_reverses", "resolved", "reason", "chi_basis", "case"):
        ds[k] = ds[k].astype(np.int8)
    return ds


def _hopf_curve_in_plane(spec: MapSpec, hopf_x: np.ndarray) -> tuple[np.ndarray | None, str]:
    """The Hopf curve in the map's plane by continuation of the Hopf defining system
    (:func:`~maglev_match.dynamics.hopf_curve.hopf_curves_from_scans`), when both axes are
    parameters of model A: rows (x, y, l1) with NaN rows between branches, and a note
    saying how it was computed (or why not)."""
    from maglev_match.dynamics.hopf_curve import hopf_curves_from_scans
    from maglev_match.maglev.unit import PARAM_NAMES, unit_system

    names = (spec.x.name, spec.y.name)
    if not all(n in PARAM_NAMES for n in names):
        return None, ("not continued: the axes are not both parameters of model A (beam or "
                      "vehicle data); hopf_x holds each row's Hopf points, solved on the row")
    rows = np.flatnonzero(np.isfinite(hopf_x).any(axis=1))
    if rows.size == 0:
        return None, "no Hopf point inside the grid"
    # start branches from Hopf scans at the rows where the number of Hopf points changes
    # (a branch enters or leaves), and at the first, middle and last such row
    counts = np.sum(np.isfinite(hopf_x), axis=1)
    picks = {rows[0], rows[-1], rows[rows.size // 2]}
    picks |= {int(r) for r in np.flatnonzero(np.diff(counts) != 0) + 1 if counts[r] > 0}
    picks = sorted(picks)[:8]
    system = unit_system(make_params(spec.base))
    bounds = {spec.x.name: (spec.x.start, spec.x.stop), spec.y.name: (spec.y.start, spec.y.stop)}
    try:
        curves, _ = hopf_curves_from_scans(system, names, bounds,
                                           [float(spec.y.values[r]) for r in picks])
    except Exception as exc:  # noqa: BLE001 - a failed curve is reported, not raised
        return None, f"the continuation failed ({type(exc).__name__}: {exc})"
    parts = []
    for c in curves:
        v = c.values()
        if len(v):
            parts.append(np.column_stack([v, c.l1()]))
            parts.append(np.full((1, 3), np.nan))
    if not parts:
        return None, "the continuation gave no points"
    stalled = [c.message for c in curves if not c.converged]
    note = (f"{len(curves)} branch(es) continued by pseudo-arclength on the Hopf defining "
            "system inside the map's ranges")
    if stalled:
        note += "; stalled: " + "; ".join(stalled)
    return np.concatenate(parts[:-1]), note
