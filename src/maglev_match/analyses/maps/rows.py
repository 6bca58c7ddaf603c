"""The paper's index along one row of a map (y fixed, x varying): :func:`compute_row`.

The row is a path through parameter space, extended beyond both ends of the grid
(:func:`row_extension`); the Hopf points on it are found from the eigenvalues of the
equilibrium x = 0 at three samples per path interval (:func:`path_eigenvalues`,
:func:`scan_hopf_points`), and from each one the cycle branch is continued across the
adjacent stable stretch, so that h at every grid point of the stretch is read off that one
branch. Points the row cannot decide (a zero delay on a delayed row, a stable stretch that
no Hopf point on the path reaches) take the point-wise index."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from maglev_match.analyses.maps.spec import (
    CASE_CODES,
    REASON_FAILED,
    REASON_MAX_STEPS,
    REASON_NO_BRANCH,
    REASON_NO_HOPF,
)
from maglev_match.core.params import ParameterError, Params

if TYPE_CHECKING:
    from maglev_match.analyses.maps.spec import MapSpec

__all__ = ["compute_row", "row_extension", "path_eigenvalues", "hopf_test_sign",
           "scan_hopf_points", "stretches", "SCAN_PER_NODE"]


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
    (one batched Jacobian call, :func:`scan_hopf_points`) rather than by continuing the
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
    ext_lo, ext_hi = row_extension(spec, xs, yv)
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
    w_scan = path_eigenvalues(system, nodes)
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
    hopf_points = scan_hopf_points(path, w_scan, t_end, system, nodes)

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
    for s, e in stretches(orphan):
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


def path_eigenvalues(system, nodes: np.ndarray) -> np.ndarray:
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


def hopf_test_sign(w: np.ndarray) -> np.ndarray:
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


def scan_hopf_points(path, w: np.ndarray, t_end: float, system, nodes: np.ndarray) -> list:
    """Converged Hopf points of the equilibrium x = 0 along the path, from the eigenvalues
    ``w`` at t = i / SCAN_PER_NODE (:func:`path_eigenvalues`).

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
    sign = hopf_test_sign(w)
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


def row_extension(spec: MapSpec, xs: np.ndarray, yv: float
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


def stretches(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end] (inclusive) of every run of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True))
