"""Maps of stability, h, w0 and chi over two-parameter design grids.

A grid is two swept parameters of a :class:`~maglev_match.params.Params`: model-A
parameters (omega1, sigma, kP, kD, ke, ...) or engineering quantities (L, EI, mbar, l, k)
from which omega1 and sigma derive. Every grid point is validated before any work starts.

Work is split into tiles of whole rows (fixed y, x varying). Within a row the cycles are
*continued along the row*: the row is a path through parameter space
(:func:`~maglev_match.dynamics.paths.path_system`), its Hopf points are located on that
path, and from each one the cycle branch is followed across the adjacent stable stretch;
h at every grid point of the stretch is read off that one branch. Tiles run on a Dask
cluster (a local one by default, or an existing scheduler), are written to a checkpoint
folder as they finish, and a resumed map skips the tiles already there. Tile results do not
depend on which worker ran them, so a resumed map equals a map computed in one go bit for bit.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import signal
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match import checkpoint as checkpoint_mod
from maglev_match.options import CollocationMesh
from maglev_match.params import FIELD_NAMES, ParameterError, Params, make_params

__all__ = ["Axis", "MapSpec", "parse_axis", "compute_row", "run_map", "map_dataset",
           "spot_check", "map_warnings", "MAP_VARIABLES", "REASON_CODES"]

CASE_CODES = {"unstable_equilibrium": 0, "unstable_cycle": 1, "no_cycle_within_limits": 2}
MAP_VARIABLES = ("chi", "h", "w0", "stable", "max_real_part", "hopf_distance", "case",
                 "omega1_point", "sigma_point", "current_reverses", "resolved", "reason")
# why a point is unresolved (variable ``reason``; 0 for resolved points)
REASON_FAILED = 1
REASON_MAX_STEPS = 2
REASON_NO_HOPF = 3
REASON_NO_BRANCH = 4
REASON_CODES = {
    0: "",
    REASON_FAILED: "the cycle continuation failed (Newton or step size) before the point",
    REASON_MAX_STEPS: "the cycle branch reached its step limit before the point",
    REASON_NO_HOPF: "max Re(lambda) changes sign next to the stable stretch without a Hopf "
                    "point, even on a refined scan",
    REASON_NO_BRANCH: "no cycle branch could be started at the Hopf point",
}
# self-check: share of points recomputed point-wise, at most this many, and the tolerance
SPOT_CHECK_FRACTION = 0.01
SPOT_CHECK_MAX = 12
SPOT_CHECK_TOL = 0.03
# One worker process per core, each single-threaded: on 2 cores a row of 100 points ran in
# 1.6 s single-threaded against 2.3 s with XLA's and BLAS's own thread pools (measured before
# the row scan of issue 14; a warm single-threaded row now takes ~0.8 s).
SINGLE_THREADED_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
}
MALLOC_TRIM_THRESHOLD = 256 * 2**20
MALLOC_MMAP_THRESHOLD = 64 * 2**20  # a fixed trim threshold disables glibc's adaptive one
SCHEDULER_TIMEOUT = "10s"  # waiting for an existing scheduler to answer
# Largest grid accepted (points); beyond it the result arrays alone would not fit.
MAX_POINTS = 4_000_000


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
    """What to map: base parameters, the two axes and the numerical settings."""

    base: dict[str, Any]  # Params.as_input_dict() of the base point
    x: Axis
    y: Axis
    rows_per_tile: int = 4
    ntst: int = 30
    ncol: int = 4
    max_steps: int = 300

    def key(self) -> str:
        """A fingerprint of the spec, stored with checkpoints so a resume can't mix maps."""
        d = {"base": {k: self.base[k] for k in sorted(self.base)}, "x": self.x.__dict__,
             "y": self.y.__dict__, "rows_per_tile": self.rows_per_tile, "ntst": self.ntst,
             "ncol": self.ncol, "max_steps": self.max_steps}
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

    @property
    def tiles(self) -> list[tuple[int, int]]:
        r = self.rows_per_tile
        return [(a, min(a + r, self.y.count)) for a in range(0, self.y.count, r)]


def compute_row(spec: MapSpec, row: int) -> dict[str, np.ndarray]:
    """All map variables along row ``row`` (y fixed, x varying), continuing cycles along it.

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
    from maglev_match import jax_setup  # noqa: F401  (workers: float64 before anything)
    from maglev_match.dynamics.basin import FAILED
    from maglev_match.dynamics.cycles import cycle_branch
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.dynamics.paths import PATH_PARAM, path_system
    from maglev_match.limits_check import cycle_limit_margins

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
    if hopf_points:
        # distance to the nearest Hopf point along the row, in units of the x parameter
        # (the path position t maps to x through the nodes, extension included)
        x_hopf = np.interp([hp.value for hp in hopf_points], np.arange(n_nodes), x_nodes)
        dist = np.min(np.abs(xs[:, None] - x_hopf[None, :]), axis=1)
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
    }
    _zero_delay_points(out, pts, system)
    return out


def _row_system(points: list[Params]):
    """The system of a row and the parameter vector of a point on it: model A's ODE when
    no point of the row (extension included) has a delay; else its discretised delay system
    with nodes for the row's largest delay, the delay entering the vector as its last entry,
    and a zero delay replaced by :data:`DELAY_FLOOR` times the largest (the discretisation
    is singular at tau = 0; :func:`_zero_delay_points` recomputes those points)."""
    from maglev_match.models.unit import param_vector, unit_system

    tau_max = max(p.tau for p in points)
    if tau_max == 0:
        return unit_system(points[0]), param_vector
    floor = DELAY_FLOOR * tau_max

    def vector(p: Params) -> np.ndarray:
        return np.append(param_vector(p), max(p.tau, floor))

    return unit_system(points[0], tau_max=tau_max), vector


def _zero_delay_points(out: dict[str, np.ndarray], pts: list[Params], system) -> None:
    """The points of a delayed row whose delay is 0 (e.g. the first column of a tau axis),
    recomputed with the delay-free model by the point-wise index (in place); the row's path
    passed them at the floor delay."""
    if not hasattr(system, "dde"):
        return
    from maglev_match.matching import matching_index

    for j, p in enumerate(pts):
        if p.tau != 0:
            continue
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
    from maglev_match.dynamics.equilibria import _pair_crossings
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
        crossings = _pair_crossings(wa, wb)
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
    to the last valid parameter set before that): lists of (x, Params), nearest first."""
    dx = (xs[-1] - xs[0]) / (xs.size - 1)
    out: list[list[tuple[float, Params]]] = []
    for end, sign in ((xs[0], -1.0), (xs[-1], 1.0)):
        side: list[tuple[float, Params]] = []
        for k in range(1, xs.size):
            xv = end + sign * k * dx
            try:
                side.append((xv, spec.point(xv, yv)))
            except ParameterError:
                break
        out.append(side)
    return out[0], out[1]


def compute_tile(spec: MapSpec, rows: tuple[int, int]) -> dict[str, np.ndarray]:
    """Rows [a, b) of the map stacked: arrays of shape (b - a, nx)."""
    out = [compute_row(spec, r) for r in range(*rows)]
    return {k: np.stack([o[k] for o in out]) for k in out[0]}


def _tile_path(folder: Path, rows: tuple[int, int]) -> Path:
    return checkpoint_mod.tile_path(folder, rows)


def _save_tile(folder: Path, rows: tuple[int, int], data: dict[str, np.ndarray],
               spec: MapSpec) -> None:
    """Atomically write a tile with its map's fingerprint (see :mod:`maglev_match.checkpoint`)."""
    checkpoint_mod.save_tile(folder, rows, data, spec.key())


def run_map(
    spec: MapSpec,
    checkpoint: Path,
    *,
    resume: bool = False,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    max_tiles: int | None = None,
) -> dict[str, np.ndarray]:
    """Compute the map tile by tile on Dask, checkpointing every finished tile.

    Parameters
    ----------
    checkpoint : folder for the tiles (created); with ``resume`` its tiles are reused.
        The folder is locked for the duration of the run (a second run on it raises
        :class:`~maglev_match.checkpoint.CheckpointLocked`); tiles of another map or
        unreadable tiles are named in a warning and recomputed.
    scheduler : address of an existing Dask scheduler (tcp://host:port); default a local
        cluster with ``workers`` processes (default: all cores), or no cluster at all when
        ``workers == 0`` (compute in this process).
    max_tiles : compute at most this many new tiles, then stop (for tests of resuming).
    Returns the assembled arrays, shape (ny, nx); raises RuntimeError when tiles are missing
    and :class:`~maglev_match.checkpoint.MapStopped` (with the resume hint) on Ctrl-C or a
    lost scheduler.
    """
    spec.validate()
    CollocationMesh(spec.ntst, spec.ncol, spec.max_steps)  # raises ParameterError
    if workers is not None and workers < 0:
        raise ParameterError("--workers", workers, "must be >= 0 (0: compute in this process)")
    checkpoint = Path(checkpoint)
    key = spec.key()
    with checkpoint_mod.lock_folder(checkpoint):
        try:
            checkpoint_mod.prepare_folder(checkpoint, key, resume)
        except ValueError as exc:
            raise ParameterError("--resume", str(checkpoint), str(exc)) from None
        missing, _ = checkpoint_mod.usable_tiles(checkpoint, spec.tiles, key, MAP_VARIABLES,
                                                 spec.x.count)
        done = len(spec.tiles) - len(missing)
        todo = missing if max_tiles is None else missing[:max_tiles]
        total = len(spec.tiles)
        if progress:
            progress(done, total)
        if todo:
            if workers == 0 and scheduler is None:
                try:
                    for t in todo:
                        _save_tile(checkpoint, t, compute_tile(spec, t), spec)
                        done += 1
                        if progress:
                            progress(done, total)
                except KeyboardInterrupt:
                    raise checkpoint_mod.MapStopped(
                        _stopped_text("interrupted", done, total, checkpoint), 130) from None
            else:
                _run_on_dask(spec, todo, checkpoint, scheduler, workers, progress, done, total)
        return assemble(spec, checkpoint)


def _stopped_text(what: str, done: int, total: int, checkpoint: Path) -> str:
    return (f"{what}: {done} of {total} tiles are saved in {checkpoint}; run the same command "
            "with --resume to continue")


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """Ignore SIGINT while worker processes are started, so that they inherit the ignored
    disposition: Ctrl-C in a terminal reaches the whole process group, and only this
    (the client) process should react; the workers are shut down by the client."""
    try:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: signals cannot be changed here
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _run_on_dask(spec, todo, checkpoint, scheduler, workers, progress, done, total) -> None:
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        n = workers or os.cpu_count() or 1
        import dask

        # Dask's nannies set MALLOC_TRIM_THRESHOLD_=65536 so that workers hand memory back
        # to the OS; for this workload that turns every large temporary array into an
        # mmap/munmap pair (measured: ~1200 per second, a third of the worker's CPU time in
        # the kernel). The tiles are small, so keep glibc's default behaviour.
        with dask.config.set({
            "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": MALLOC_TRIM_THRESHOLD,
            "distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_": MALLOC_MMAP_THRESHOLD,
        }), _sigint_ignored():
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=None, env=SINGLE_THREADED_ENV)
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise ParameterError("--scheduler", scheduler,
                                 f"no Dask scheduler answered there ({exc})") from None
    futures: dict = {}
    try:
        futures = {client.submit(compute_tile, spec, t, pure=False, retries=2): t for t in todo}
        for fut in as_completed(futures):
            t = futures[fut]
            try:
                data = fut.result()
            except KeyboardInterrupt:
                raise
            except Exception as exc:
                if _is_lost_connection(exc):
                    _quiet_logging()  # the client's reconnect attempts end in tracebacks
                    raise checkpoint_mod.MapStopped(_stopped_text(
                        f"lost the Dask scheduler ({type(exc).__name__})", done, total,
                        checkpoint)) from None
                raise
            _save_tile(checkpoint, t, data, spec)
            done += 1
            if progress:
                progress(done, total)
    except KeyboardInterrupt:
        # stop quietly: the shutdown of interrupted workers is expected, not news
        _quiet_logging()
        if cluster is not None:  # the local workers too (they log to our stderr)
            with contextlib.suppress(Exception):
                client.run(_quiet_logging)
        if cluster is None:  # an existing scheduler: drop our tasks there
            with contextlib.suppress(Exception):
                client.cancel(list(futures))
        raise checkpoint_mod.MapStopped(
            _stopped_text("interrupted", done, total, checkpoint), 130) from None
    except (OSError, TimeoutError) as exc:
        _quiet_logging()
        raise checkpoint_mod.MapStopped(_stopped_text(
            f"lost the Dask scheduler ({type(exc).__name__}: {exc})", done, total,
            checkpoint)) from None
    finally:
        with contextlib.suppress(Exception):
            client.close(timeout=10)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close(timeout=10)


def _quiet_logging() -> None:
    """Silence Dask's shutdown chatter (cancelled tasks, heartbeats to a closing scheduler)
    after an interrupt: the shutdown is expected, not news."""
    prefixes = ("distributed", "tornado", "asyncio")
    names = [n for n in list(logging.root.manager.loggerDict) if n.startswith(prefixes)]
    for name in (*prefixes, *names):  # Dask's config gives some loggers their own levels
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _is_lost_connection(exc: BaseException) -> bool:
    """Whether a task's exception means the cluster went away (not an error in the task)."""
    from concurrent.futures import CancelledError

    name = type(exc).__name__
    return isinstance(exc, CancelledError | OSError | TimeoutError) or name in (
        "FutureCancelledError", "CommClosedError", "CancelledError")


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
    (:func:`maglev_match.matching.matching_index`, no simulation) and compare h.

    ``fraction`` of the points, at least one and at most ``max_points`` (the cap keeps the
    check within about 10 % of the map's time: a point-wise index costs roughly as much as
    a few dozen map points). The disagreement at a point is |h_map - h_point| / h_point
    (0 when both are 0; 1 when they disagree on stability). Unresolved map points are
    skipped (counted). ``budget`` (s): stop after the point during which the check's time
    exceeded it (at least one point is always checked); the sample order is seeded, so a
    shorter check is a prefix of a longer one. Returns the attributes stored on the dataset.
    """
    import time

    from maglev_match.matching import matching_index

    started = time.perf_counter()

    ny, nx = data["h"].shape
    n = max(1, min(max_points, math.ceil(fraction * nx * ny)))
    rng = np.random.default_rng(seed)
    flat = rng.choice(nx * ny, size=min(n, nx * ny), replace=False)
    worst, worst_at, checked, skipped = 0.0, None, 0, 0
    records = []
    for f in (int(v) for v in flat):
        if budget is not None and checked and time.perf_counter() - started > budget:
            break
        i, j = divmod(f, nx)
        if not data["resolved"][i, j]:
            skipped += 1
            continue
        xv, yv = spec.x.values[j], spec.y.values[i]
        pt = matching_index(spec.point(xv, yv), simulate=False)
        h_map, h_pt = float(data["h"][i, j]), float(pt.h)
        if bool(data["stable"][i, j]) != pt.stable or not math.isfinite(h_pt):
            diff = 1.0
        elif h_pt == 0.0:
            diff = 0.0 if h_map == 0.0 else 1.0
        else:
            diff = abs(h_map - h_pt) / abs(h_pt)
        checked += 1
        records.append([float(xv), float(yv), h_map, h_pt, diff])
        if diff >= worst:
            worst, worst_at = diff, records[-1]
    warnings = []
    if worst > tol and worst_at is not None:
        warnings.append(
            f"spot check: at {spec.x.name} = {worst_at[0]:.6g}, {spec.y.name} = {worst_at[1]:.6g} "
            f"the map gives h = {worst_at[2] * 1e3:.4g} mm and the point-wise index "
            f"{worst_at[3] * 1e3:.4g} mm (relative difference {worst:.3g} > {tol:g})")
    return {
        "spot_check_points": checked,
        "spot_check_planned": int(flat.size),
        "spot_check_seconds": round(time.perf_counter() - started, 3),
        "spot_check_skipped_unresolved": skipped,
        "spot_check_seed": seed,
        "spot_check_max_rel_diff": float(worst),
        "spot_check_tolerance": tol,
        "spot_check_passed": int(worst <= tol),
        "spot_check_records": json.dumps(records),
        "warnings": json.dumps(warnings),
    }


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


def map_dataset(spec: MapSpec, data: dict[str, np.ndarray], *, check: bool = True,
                seed: int = 0, budget: float | None = None):
    """The map as an xarray Dataset over coordinates named after the swept parameters.

    With ``check`` (default) a seeded sample of points is recomputed point-wise
    (:func:`spot_check`, within ``budget`` seconds) and the result stored in the attributes
    ``spot_check_*`` and
    ``warnings`` (a JSON list). ``reason`` codes the cause of every unresolved point
    (attribute ``reason_codes``)."""
    import xarray as xr

    from maglev_match.params import PARAMETER_DOCS

    data = dict(data)
    if "reason" not in data:  # tiles computed before the reason variable existed
        data["reason"] = np.where(data["resolved"], 0, -1).astype(np.int8)
    dims = (spec.y.name, spec.x.name)
    units = {"chi": "1", "h": "m", "w0": "m", "stable": "bool", "max_real_part": "1/s",
             "hopf_distance": PARAMETER_DOCS.get(spec.x.name, ("",))[0], "case": "code",
             "omega1_point": "rad/s", "sigma_point": "1/kg", "current_reverses": "bool",
             "resolved": "bool", "reason": "code"}
    attrs: dict[str, Any] = {
        "title": "maglev-match design map",
        "case_codes": json.dumps(CASE_CODES),
        "reason_codes": json.dumps({str(k): v for k, v in REASON_CODES.items()}),
        "spec": spec.key(),
    }
    if check:
        attrs.update(spot_check(spec, data, seed=seed, budget=budget))
    else:
        attrs["warnings"] = json.dumps(["no spot check was run"])
    ds = xr.Dataset(
        {k: (dims, data[k], {"units": units.get(k, "")}) for k in MAP_VARIABLES},
        coords={
            spec.x.name: (spec.x.name, spec.x.values,
                          {"units": PARAMETER_DOCS.get(spec.x.name, ("",))[0]}),
            spec.y.name: (spec.y.name, spec.y.values,
                          {"units": PARAMETER_DOCS.get(spec.y.name, ("",))[0]}),
        },
        attrs=attrs,
    )
    ds["stable"] = ds["stable"].astype(np.int8)
    ds["current_reverses"] = ds["current_reverses"].astype(np.int8)
    ds["resolved"] = ds["resolved"].astype(np.int8)
    ds["reason"] = ds["reason"].astype(np.int8)
    return ds
