"""The critical disturbance of the maglev models, solved: what decides h_simulation in each
direction, the size to solver accuracy, and its derivative by every parameter.

The simulated critical disturbance (:func:`~maglev_match.analyses.simulation.critical_disturbance`)
is first bracketed by batched simulations with the limits on. The bracket's runs are then
read as evidence of what separates return from collision along the disturbance line:

* **grazing** (:attr:`Mechanism.GRAZING`): the runs on both sides stay together up to the
  collision, which comes at the same finite time on the colliding side (collision times
  within 25 % of each other over the last two rounds), and the largest run below it came
  close to the same gap limit. The critical run touches the limit tangentially at t*. It is
  solved as the grazing condition gap(t*; d) = limit, d gap/dt (t*; d) = 0 on the system with
  the current clamp as a piecewise-smooth flow (:mod:`maglev_match.maglev.clamp`,
  :func:`maglev_match.dynamics.escape.solve_grazing`), with forward sensitivities through
  every clamp switch (saltation matrices).
* **basin boundary** (:attr:`Mechanism.BASIN_BOUNDARY`): the collision time grows as the
  size approaches the bracket from above (by more than 25 % between the last two rounds):
  the critical run lands on the stable manifold of a saddle-type cycle of the clamped
  system, follows it and leaves on one side or the other. The cycle is computed as a
  piecewise-smooth periodic orbit (:mod:`maglev_match.dynamics.hybrid`: collocation per
  segment between clamp switches, Floquet multipliers with saltation matrices) and the size
  solved so that the run lands on the cycle's local stable manifold
  (:func:`maglev_match.dynamics.escape.solve_basin_boundary`).

A solved size must lie in the bisection's bracket (to the simulator's accuracy) and a run
just below it must not collide (:mod:`maglev_match.analyses.confirmed`: else it is solved
again from the narrowed bracket); otherwise, or when the solve fails, the bisection's
midpoint stays (:attr:`Mechanism.BISECTION`) and the result says why and that no derivative
is available there. Directions in which every size returned, or even the smallest
collided, are :attr:`Mechanism.ALL_RETURN` / :attr:`Mechanism.ALL_COLLIDE`; a search that
did not bracket is :attr:`Mechanism.UNRESOLVED`.

Derivatives: at a solved grazing size, the implicit function theorem on the grazing
condition gives dd_c/dp for every model parameter and dd_c/dL for the gap limit touched
(:func:`maglev_match.dynamics.escape.grazing_derivative`); the limit L is gap_max - c0 or
gap_min - c0 in gap-deviation units, so c0 enters twice (the model and the limit).

:func:`solve_critical_batch` solves many parameter points at once from warm starts (the
neighbour's solution on a map row), each checked by two simulations just below and above
the solved size, and falls back to the full search where a warm start fails.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from enum import StrEnum
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.analyses.confirmed import confirmed
from maglev_match.core.jax_setup import kernel_arg
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.escape import (
    basin_boundary_derivative,
    extrema_walk,
    grazing_derivative,
    section_walk,
    solve_basin_boundary,
    solve_grazing,
)
from maglev_match.dynamics.hybrid import (
    FlowOptions,
    FlowStatus,
    HybridOrbit,
    HybridSystem,
    hybrid_floquet,
    hybrid_flow,
    hybrid_periodic_orbit,
    orbit_parameter_derivative,
    segments_from_flow,
)
from maglev_match.maglev.base import MaglevModel
from maglev_match.maglev.models import maglev_model

__all__ = ["Mechanism", "CriticalSize", "solve_critical", "solve_critical_batch",
           "critical_from_bisection", "critical_derivative", "MECHANISM_TEXT",
           "GROWTH_BASIN", "disturbance_line", "stack_lines", "saddle_landing", "FLOW"]


class Mechanism(StrEnum):
    """What decided the critical disturbance of one direction."""

    GRAZING = "grazing"  # a run touching a gap limit tangentially; solved
    BASIN_BOUNDARY = "basin_boundary"  # a run landing on a saddle cycle's stable manifold
    BISECTION = "bisection"  # bracketed by simulation only (neither condition solved)
    ALL_RETURN = "all_return"  # every size up to the gap range returned
    ALL_COLLIDE = "all_collide"  # even the smallest size collided
    UNRESOLVED = "unresolved"  # no bracket (undecided runs, round limit)


MECHANISM_TEXT = {
    Mechanism.GRAZING: "grazing: the critical run touches the gap limit tangentially",
    Mechanism.BASIN_BOUNDARY: "basin boundary: the critical run lands on a saddle cycle of "
                              "the clamped system",
    Mechanism.BISECTION: "bisection only",
    Mechanism.ALL_RETURN: "every size returned",
    Mechanism.ALL_COLLIDE: "even the smallest size collided",
    Mechanism.UNRESOLVED: "unresolved",
}

#: collision times growing by more than this fraction between the smallest collision and
#: the next colliding size of the search: collision times diverge (a basin boundary)
GROWTH_BASIN = 0.25
#: the largest run below the bracket that came within this many bracket widths of the limit
#: the smallest collision hits has touched it (tangency evidence of a grazing contact)
TANGENCY = 20.0
#: a run that lands on a saddle cycle's stable manifold passes its section point within
#: this distance (max over states, in units of the state scale)
APPROACH = 0.5
#: relative slack on the bisection bracket for a solved size (the simulator's own accuracy)
BRACKET_SLACK = 2e-6
#: the flow settings of the solves (tighter than the bisection's simulations)
FLOW = FlowOptions(rtol=1e-10, atol=1e-10)


@dataclass(frozen=True)
class CriticalSize:
    """The critical disturbance of one direction.

    direction : -1 (beam up / lifted) or +1 (beam down / pushed).
    size : the critical size (m): the solved size (grazing, basin boundary), the bracket's
        midpoint (bisection), the gap range (all_return), 0 (all_collide), or None.
    mechanism : :class:`Mechanism`; converged : the size is determined and supported
        (solved inside a bracket whose lower end returned, or a conclusive search); a
        collision boundary solved above runs that stayed undecided is not; reason : the
        evidence and, where a solve failed, why.
    t_star : time of the tangency (grazing) (s); limit : the gap limit touched ('upper' or
        'lower'), point : the levitation point (model B; 1 for model A).
    bracket : (largest size that did not collide, smallest that did) of the search (m).
    iterations, residual : the Newton solve (residual in m of gap deviation).
    derivative_available : dsize/dp exists here (a solved condition); dsize_dp : by every
        model parameter (per unit of each, in the model's parameter order) or None;
        dsize_dlimit : per metre of the gap limit touched.
    window : (t_arm, t_max) of the solve (s), the warm start of a neighbouring point.
    evidence : what the bracket's runs point to ('grazing', 'basin_boundary', 'mixed' or
        None), also where the condition could not be solved (the mechanism then stays
        'bisection');
    growth : relative growth of the collision time towards the bracket (the evidence);
    margin_below : how close (m) the largest run that did not collide came to the limit the
        smallest collision hits (the tangency evidence).
    cycle_period, multiplier : the saddle cycle of the clamped system (basin boundary):
        period (s) and unstable Floquet multiplier; cycle_gap : its (max, min) gap
        deviation (m); cycle_segments : its clamped/free segments.
    at : the model parameter vector the size was solved at, where kept (the warm start of
        a neighbouring design, :mod:`maglev_match.analyses.continued`).
    """

    __repr__ = compact_repr

    direction: int
    size: float | None
    mechanism: Mechanism
    converged: bool
    reason: str
    model: str = "unit"
    t_star: float | None = None
    limit: str | None = None
    point: int | None = None
    bracket: tuple[float | None, float | None] = (None, None)
    iterations: int = 0
    residual: float | None = None
    derivative_available: bool = False
    dsize_dp: np.ndarray | None = field(default=None, repr=False, compare=False)
    dsize_dlimit: float | None = None
    window: tuple[float, float] | None = None
    growth: float | None = None
    margin_below: float | None = None
    evidence: str | None = None
    cycle_period: float | None = None
    multiplier: float | None = None
    cycle_gap: tuple[float, float] | None = None
    cycle_segments: int | None = None
    orbit: Any = field(default=None, repr=False, compare=False)
    landing: dict[str, Any] | None = field(default=None, repr=False, compare=False)
    at: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: a size continued from a neighbour: that neighbour's (parameter vector, size), for the
    #: secant predictor of the next design (not part of the answer)
    previous: tuple[np.ndarray, float] | None = field(default=None, repr=False, compare=False)

    @property
    def solved(self) -> bool:
        return self.mechanism in (Mechanism.GRAZING, Mechanism.BASIN_BOUNDARY)

    def as_json(self) -> dict[str, Any]:
        return {
            "direction": self.direction, "size": self.size, "mechanism": str(self.mechanism),
            "converged": self.converged, "reason": self.reason, "t_star": self.t_star,
            "limit": self.limit, "point": self.point, "bracket": list(self.bracket),
            "iterations": self.iterations, "residual": self.residual,
            "derivative_available": self.derivative_available,
            "dsize_dlimit": self.dsize_dlimit, "growth": self.growth,
            "margin_below": self.margin_below, "evidence": self.evidence,
            "cycle_period": self.cycle_period, "multiplier": self.multiplier,
            "cycle_gap": None if self.cycle_gap is None else list(self.cycle_gap),
            "cycle_segments": self.cycle_segments,
        }


# ---------------------------------------------------------------------------------------
# the disturbance line of each model
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Line:
    """x0(d) = base + d * dirn (a straight disturbance line), the clamped system, the gap
    deviation of each levitation point as w_j . x + g0_j, and the gap-deviation limits."""

    hs: HybridSystem
    base: np.ndarray
    dirn: np.ndarray
    W: np.ndarray  # (points, n)
    g0: np.ndarray  # (points,)
    upper: float  # gap_max - c0 (m)
    lower: float  # gap_min - c0 (m)

    def x0_of(self, d: np.ndarray) -> np.ndarray:
        d = np.atleast_1d(np.asarray(d, float))
        return self.base[None, :] + d[:, None] * self.dirn[None, :]

    def dx0_dd(self, d: np.ndarray) -> np.ndarray:
        d = np.atleast_1d(np.asarray(d, float))
        return np.broadcast_to(self.dirn, (d.size, self.dirn.size)).copy()


def stack_lines(lines: Sequence[_Line]) -> tuple[Callable, Callable]:
    """x0(d) and dx0/dd of several lines as one batch (one size per line, in order):
    lane k is line k; lanes past the last (the padding to a compiled batch size)
    repeat the last line, so a padded run is the last run again."""
    base = np.array([ln.base for ln in lines])
    dirn = np.array([ln.dirn for ln in lines])
    last = len(lines) - 1

    def x0_of(d: np.ndarray) -> np.ndarray:
        d = np.atleast_1d(np.asarray(d, float))
        k = np.minimum(np.arange(d.size), last)
        return base[k] + d[:, None] * dirn[k]

    def dx0_dd(d: np.ndarray) -> np.ndarray:
        k = np.minimum(np.arange(np.atleast_1d(d).size), last)
        return dirn[k].copy()

    return x0_of, dx0_dd


def disturbance_line(params: Params | MaglevModel, direction: int, model: str = "unit"
                     ) -> _Line:
    """The index's disturbance line of a maglev model
    (:meth:`~maglev_match.maglev.base.MaglevModel.disturbance`: model A x5(0) = direction
    d; model B x_eq + s (pressed - x_eq), d = s w_mid) with its clamped system."""
    m = maglev_model(params, model)
    dist = m.disturbance(direction)  # (checks the direction)
    params = m.params
    hs = m.clamped()
    n = hs.dim
    g = hs.observables["gap_deviation"]
    W, g0 = (np.atleast_2d(np.asarray(a)) for a in _gap_line(g)(np.zeros(n), kernel_arg(hs.p)))
    g0 = g0.ravel()
    base, dirn = np.asarray(dist.base, float), np.asarray(dist.step, float)
    if base.size < n:  # a delay: the line's states with a constant past (lift is affine)
        lift = m.system(limited=True).lift
        base, dirn = lift(base), lift(base + dirn) - lift(base)
    return _Line(hs=hs, base=base, dirn=dirn, W=W, g0=g0,
                 upper=float(params.gap_max - params.c0),
                 lower=float(params.gap_min - params.c0))


@cache
def _gap_line(g: Any) -> Any:
    """(W, g0) of the gap deviations g(x, p) = W x + g0 (linear in the state) at x: one
    compiled kernel per observable (tracing the derivative at every index cost ~6 ms a
    direction)."""
    from maglev_match.core.aot import cached_kernel

    def line(x, p):
        def gx(y):
            return jnp.atleast_1d(g(y, p))

        return jax.jacfwd(gx)(x), gx(x)

    return cached_kernel(line, g, name="critical.gap_line")


def _entry(cd: Any, size: float | None) -> int:
    r = cd.run_at(size) if size is not None else None
    return -1 if r is None else int(r.event)


def _largest_noncolliding(cd: Any) -> float | None:
    hi = cd.smallest_collision
    below = [r.size for r in cd.samples if r.outcome != "collision"
             and (hi is None or r.size < hi)]
    return max(below) if below else None


def _growth(cd: Any) -> float | None:
    """Relative growth of the collision time from the next colliding size of the search to
    the smallest collision (None without two colliding sizes)."""
    coll = sorted((r.size, r.time) for r in cd.samples if r.outcome == "collision")
    if len(coll) < 2 or coll[1][1] is None or coll[0][1] is None or coll[1][1] <= 0:
        return None
    return (coll[0][1] - coll[1][1]) / coll[1][1]


# ---------------------------------------------------------------------------------------
# classification and solve
# ---------------------------------------------------------------------------------------
def _simple(cd: Any, direction: int, model: str) -> CriticalSize | None:
    """The directions that need no solve: every size returned, even the smallest collided,
    or no bracket at all."""
    br = (_largest_noncolliding(cd), cd.smallest_collision)
    if cd.status == "all_return":
        return CriticalSize(direction, float(cd.gap_range), Mechanism.ALL_RETURN, True,
                            "every size up to the gap range returned", model=model, bracket=br)
    if cd.status == "all_collide":
        return CriticalSize(direction, 0.0, Mechanism.ALL_COLLIDE, True,
                            "even the smallest size tried collided", model=model, bracket=br)
    if cd.smallest_collision is None:
        return CriticalSize(direction, None, Mechanism.UNRESOLVED, False,
                            "no size was seen to collide, and not every size returned",
                            model=model, bracket=br)
    return None


def critical_from_bisection(params: Params | MaglevModel, cd: Any, *, model: str = "unit",
                            derivative: bool = False, orbit_hint: Any = None) -> CriticalSize:
    """Classify the bracket ``cd`` (a
    :class:`~maglev_match.analyses.simulation.CriticalDisturbance`)
    and solve the critical size (module docstring); with ``derivative`` also dsize/dp.

    Evidence: *tangency* (the largest run that did not collide came within
    :data:`TANGENCY` bracket widths of the limit the smallest collision hits) points to a
    grazing contact, *growth* of the collision time towards the bracket (by more than
    :data:`GROWTH_BASIN`) to a basin boundary. The indicated condition is solved first, the
    other tried when it fails and the evidence is mixed. ``orbit_hint``: a saddle cycle of
    the clamped system already computed at these parameters (the other direction's)."""
    m = maglev_model(params, model)
    return confirmed(m, cd, lambda c: _from_bisection(m, c, derivative, orbit_hint),
                     Mechanism.BISECTION)


def _from_bisection(m: MaglevModel, cd: Any, derivative: bool, orbit_hint: Any
                    ) -> CriticalSize:
    model = m.name
    direction = int(cd.direction)
    simple = _simple(cd, direction, model)
    if simple is not None:
        return simple
    lo, hi = _largest_noncolliding(cd), float(cd.smallest_collision)
    growth = _growth(cd)
    entry = _entry(cd, hi)
    point = entry // 2 + 1 if entry >= 0 else None
    limit = ("lower", "upper")[entry % 2] if entry >= 0 else None
    mid = 0.5 * ((lo if lo is not None else 0.0) + hi)
    bisect = CriticalSize(
        direction, mid if cd.status == "bracketed" else (
            None if cd.largest_return is None else float(cd.largest_return)),
        Mechanism.BISECTION if cd.status == "bracketed" else Mechanism.UNRESOLVED,
        cd.status == "bracketed", "", model=model, limit=limit, point=point,
        bracket=(lo, hi), growth=growth)
    if lo is None:
        return _with_reason(bisect, "no size below the smallest collision was tried")
    # tangency: the largest run that did not collide came as close to the same limit as the
    # bracket allows (a grazing contact); a basin boundary keeps it far from the limit
    below = cd.run_at(lo)
    margin = (below.margins[entry] if below is not None and 0 <= entry < len(below.margins)
              else math.nan)
    tangent = math.isfinite(margin) and margin <= TANGENCY * max(hi - lo, cd.tol)
    growing = growth is not None and growth > GROWTH_BASIN
    evidence = ("basin_boundary" if growing and not tangent else "grazing" if tangent
                and not growing else "mixed" if tangent and growing else None)
    bisect = replace(bisect, margin_below=margin, evidence=evidence)
    if tangent and not (growth is not None and growth > 4 * GROWTH_BASIN):
        res = _solve_grazing_direction(m, cd, bisect, derivative=derivative)
        if res.solved or not growing:
            return res
    if growing or not tangent:
        res = _solve_basin_direction(m, cd, bisect, derivative=derivative,
                                     orbit_hint=orbit_hint)
        if res.solved or not tangent:
            return res
    return _solve_grazing_direction(m, cd, bisect, derivative=derivative)


def _with_reason(res: CriticalSize, reason: str) -> CriticalSize:
    return replace(res, reason=reason)


def _window(line: _Line, w: np.ndarray, side: int, d: float, t_coll: float, p: np.ndarray
            ) -> tuple[float, float] | None:
    """(t_arm, t_max) around the grazing extremum of the run at size d: half-way from the
    previous extremum of the other kind, to three quarters of the way to the next one."""
    x0 = line.x0_of(np.array([d]))[0]
    ext = extrema_walk(line.hs, x0, w, 1.5 * t_coll + 0.05, p=p, options=FLOW)
    target = [(k, t, g) for k, (t, g, kind) in enumerate(ext) if kind == side]
    if not target:
        return None
    # the extremum nearest the limit among those not later than the collision (+20 %)
    cand = [e for e in target if e[1] <= 1.2 * t_coll + 1e-3] or target
    k, t_star, _ = max(cand, key=lambda e: side * e[2])
    t_prev = ext[k - 1][0] if k > 0 else 0.0
    t_next = ext[k + 1][0] if k + 1 < len(ext) else t_star + (t_star - t_prev)
    return 0.5 * (t_prev + t_star), t_star + 0.75 * max(t_next - t_star, 1e-4)


def _solve_grazing_direction(m: MaglevModel, cd: Any, bisect: CriticalSize, *,
                             derivative: bool) -> CriticalSize:
    line = disturbance_line(m, bisect.direction)
    p = line.hs.p
    j = (bisect.point or 1) - 1
    side = 1 if bisect.limit == "upper" else -1
    w = line.W[j]
    L = (line.upper if side > 0 else line.lower) - line.g0[j]
    lo, hi = bisect.bracket
    run = cd.run_at(hi)
    t_coll = float(run.time) if run is not None and run.time is not None else 1.0
    d_mid = 0.5 * (lo + hi)
    win = _window(line, w, side, d_mid, t_coll, p)
    what = (f"collision at the {bisect.limit} gap limit"
            + (f" of point {bisect.point}" if m.n_points > 1 else "")
            + f" at {t_coll:.4g} s, collision times "
            + ("steady" if bisect.growth is None else f"{100 * bisect.growth:+.0f} %")
            + " towards the bracket")
    if win is None:
        return _with_reason(bisect, f"{what}; grazing not solved: the run has no extremum of "
                            "the gap before the collision")
    slack = BRACKET_SLACK * hi + 1e-12
    box = (lo - 10 * slack - 0.5 * (hi - lo), hi + 10 * slack + 0.5 * (hi - lo))
    sol = solve_grazing(line.hs, line.x0_of, line.dx0_dd, w, L, side, d_mid, win[0], win[1],
                        p=p, bracket=box, options=FLOW)[0]
    if not sol.converged:
        # the run at the bracket's midpoint may itself be pulled through the limit (into
        # the magnet at gap 0, say), so that its window surrounds an earlier extremum far
        # from the limit; the largest returning run has its extremum at the contact
        win_lo = _window(line, w, side, lo, t_coll, p)
        if win_lo is not None and win_lo != win:
            retry = solve_grazing(line.hs, line.x0_of, line.dx0_dd, w, L, side, lo,
                                  win_lo[0], win_lo[1], p=p, bracket=box,
                                  options=FLOW)[0]
            if retry.converged:
                sol, win = retry, win_lo
    if not sol.converged:
        return _with_reason(bisect, f"{what}; grazing not solved: {sol.message}")
    if not (lo - slack <= sol.size <= hi + slack):
        return _with_reason(bisect, f"{what}; the solved grazing size {sol.size * 1e3:.7g} mm "
                            f"lies outside the bracket [{lo * 1e3:.7g}, {hi * 1e3:.7g}] mm "
                            "(another contact decides)")
    if abs(sol.t_star - t_coll) > win[1] - win[0]:
        return _with_reason(bisect, f"{what}; the grazing contact solved at t* = "
                            f"{sol.t_star:.4g} s is not the collision of the bracket (at "
                            f"{t_coll:.4g} s)")
    undecided = ("; the runs below it stayed undecided within the horizon, so no size is "
                 "confirmed to return" if cd.status != "bracketed" else "")
    res = replace(bisect, size=float(sol.size), mechanism=Mechanism.GRAZING,
                  converged=cd.status == "bracketed",
                  reason=(f"{what}; grazing solved: tangency at t* = {sol.t_star:.5g} s"
                          + ("; a contact at the singular gap 0 (the magnet force grows "
                             "without bound there): converged by the bracket of sizes"
                             if sol.singular else "") + undecided),
                  t_star=float(sol.t_star), iterations=sol.iterations,
                  residual=float(sol.residual), window=win, derivative_available=True)
    if derivative:
        res = critical_derivative(m, res)
    return res


def _saddle_cycle(line: _Line, x: np.ndarray, s: np.ndarray, p: np.ndarray, t_from: float
                  ) -> tuple[HybridOrbit | None, str]:
    """The saddle cycle a lingering run follows, from its state x (mode s) at t_from: the
    period from the run's gap maxima, then the clamped system's periodic orbit by
    collocation per segment (clamped and free pieces), checked to have exactly one real
    Floquet multiplier outside the unit circle."""
    w = line.W[0]
    ext = [e for e in extrema_walk(line.hs, x, w, 0.6, p=p, s0=s, options=FLOW)
           if e[2] == 1]
    if len(ext) < 3:
        return None, "the run has fewer than three gap maxima near the cycle"
    T_est = float(np.median(np.diff([e[0] for e in ext])))
    try:
        segs = segments_from_flow(line.hs, x, s, T_est, p=p, ntst=60, options=FLOW)
    except ValueError as exc:
        return None, f"no cycle guess from the run ({exc})"
    orbit = hybrid_periodic_orbit(line.hs, segs, p=p)
    if not orbit.converged:
        return None, f"the clamped system's cycle did not converge: {orbit.message}"
    mu = np.asarray(orbit.multipliers)
    outside = mu[np.abs(mu) > 1.0 + 1e-6]
    if outside.size != 1 or abs(np.imag(outside[0])) > 1e-9 * abs(outside[0]):
        return None, (f"the cycle has {outside.size} multiplier(s) outside the unit circle: "
                      "not a saddle with one unstable direction")
    del t_from
    return orbit, ""


def saddle_landing(line: _Line, orbit: HybridOrbit) -> tuple[dict[str, Any], dict[str, Any]]:
    """Where a run lands on the saddle cycle ``orbit``'s local stable manifold: the cycle
    point x* in the middle of its longest segment (``segment``, mesh ``node``), the section
    through it (``normal``, the flow direction in state-scale units) and the left
    eigenvector ``left`` of the monodromy matrix for the unstable multiplier (scaled to the
    unstable direction); and the cycle's facts (period, multiplier, gap extrema, segments,
    the orbit) as :class:`CriticalSize` fields."""
    sc = np.asarray(line.hs.state_scale, float)
    fq = hybrid_floquet(line.hs, orbit)
    i = int(np.argmax([sg.duration for sg in orbit.segments]))
    seg = orbit.segments[i]
    j = (seg.mesh.size - 1) // 2
    x_star = seg.states[j * orbit.ncol]
    M = fq.monodromy(i, j)
    mu, V = np.linalg.eig(M.T)
    u = int(np.argmax(np.abs(mu)))
    mu_u = float(np.real(mu[u]))
    left = np.real(V[:, u])
    mu_r, Vr = np.linalg.eig(M)
    v_u = np.real(Vr[:, int(np.argmax(np.abs(mu_r)))])
    v_u = v_u / np.max(np.abs(v_u / sc))
    left = left / float(left @ v_u)  # G in units of the unstable direction (scaled)
    f_star = line.hs.f(x_star, np.asarray(seg.mode, float), line.hs.p)
    normal = f_star / sc**2
    normal = normal / np.linalg.norm(normal * sc)
    gap_hi, gap_lo = orbit.extrema(line.hs.observables["gap_deviation"])
    info = dict(cycle_period=orbit.period, multiplier=mu_u, cycle_gap=(gap_hi, gap_lo),
                cycle_segments=len(orbit.segments), orbit=orbit)
    return dict(x_star=x_star, left=left, normal=normal, segment=i, node=j * orbit.ncol), info


def _solve_basin_direction(m: MaglevModel, cd: Any, bisect: CriticalSize, *,
                           derivative: bool, orbit_hint: HybridOrbit | None = None
                           ) -> CriticalSize:
    line = disturbance_line(m, bisect.direction)
    p = line.hs.p
    sc = np.asarray(line.hs.state_scale, float)
    lo, hi = bisect.bracket
    run = cd.run_at(hi)
    t_coll = float(run.time) if run is not None and run.time is not None else math.nan
    what = (f"collision at the {bisect.limit} gap limit at {t_coll:.4g} s, collision times "
            f"{100 * (bisect.growth or 0):+.0f} % towards the bracket (a basin boundary)")
    if not math.isfinite(t_coll) or lo is None:
        return _with_reason(bisect, f"{what}; not solved: no collision time")
    # 1. the saddle cycle: the other direction's (same parameters), or from the lingering
    #    part of the smallest colliding run (tried at a few times before its collision)
    orbit, why = orbit_hint, ""
    if orbit is None:
        x_hi = line.x0_of(np.array([hi]))[0]
        for frac in (0.5, 0.65, 0.8, 0.35):
            t_mid = frac * t_coll
            a = hybrid_flow(line.hs, x_hi, t_mid, p=p, options=FLOW)
            if a.status[0] != FlowStatus.REACHED:
                why = "the run failed before the cycle"
                continue
            orbit, why = _saddle_cycle(line, a.x[0], a.s[0], p, t_mid)
            if orbit is not None:
                break
    if orbit is None:
        return _with_reason(bisect, f"{what}; not solved: {why}")
    geo, info = saddle_landing(line, orbit)
    x_star, left, normal, mu_u = geo["x_star"], geo["left"], geo["normal"], info["multiplier"]
    i, node = geo["segment"], geo["node"]
    # 2. where the run at the bracket's midpoint passes closest before it departs
    d_mid = 0.5 * (lo + hi)
    walk = section_walk(line.hs, line.x0_of(np.array([d_mid]))[0], normal, x_star,
                        1.2 * t_coll, p=p, options=FLOW)
    if len(walk) < 3:
        return replace(_with_reason(bisect, f"{what}; not solved: the run crosses the cycle's "
                                    "section fewer than three times"), **info)
    dist = np.array([np.max(np.abs(xk - x_star) / sc) for _, xk, _ in walk])
    kmin = int(np.argmin(dist))
    if dist[kmin] > APPROACH:
        return replace(_with_reason(
            bisect, f"{what}; not solved: the run passes the saddle cycle no closer than "
            f"{dist[kmin]:.2g} (state-scale units): another set decides"), **info)
    K = kmin
    while K + 1 < len(walk) and dist[K + 1] < 2.0 * dist[kmin] + 1e-3:
        K += 1
    t_K = walk[K][0]
    T = orbit.period
    win = (t_K - 0.25 * T, t_K + 0.5 * T)
    slack = BRACKET_SLACK * hi + 1e-12
    sol = solve_basin_boundary(line.hs, line.x0_of, line.dx0_dd, x_star, left, normal, d_mid,
                               win[0], win[1], p=p,
                               bracket=(lo - 0.5 * (hi - lo), hi + 0.5 * (hi - lo)),
                               options=FLOW)
    if not sol.converged:
        return replace(_with_reason(bisect, f"{what}; not solved: {sol.message}"), **info)
    if not (lo - slack <= sol.size <= hi + slack):
        return replace(_with_reason(
            bisect, f"{what}; the solved size {sol.size * 1e3:.7g} mm lies outside the "
            f"bracket [{lo * 1e3:.7g}, {hi * 1e3:.7g}] mm"), **info)
    landing = dict(x_star=x_star, left=left, normal=normal, segment=i, node=node,
                   distance=sol.distance, crossing=K + 1)
    res = replace(bisect, size=float(sol.size), mechanism=Mechanism.BASIN_BOUNDARY,
                  converged=cd.status == "bracketed",
                  reason=(f"{what}; solved: the critical run lands on the stable manifold of "
                          f"the clamped system's saddle cycle (period {T:.4g} s, unstable "
                          f"multiplier {mu_u:.4g}, {len(orbit.segments)} segments) at its "
                          f"crossing {K + 1} of the cycle's section, t = {sol.t_land:.4g} s "
                          f"(distance {sol.distance:.2g} in state-scale units)"),
                  t_star=float(sol.t_land), iterations=sol.iterations,
                  residual=float(sol.residual), window=win, derivative_available=True,
                  landing=landing, **info)
    if derivative:
        res = critical_derivative(m, res)
    return res


def critical_derivative(params: Params | MaglevModel, res: CriticalSize) -> CriticalSize:
    """``res`` with dsize/dp (model parameters) and dsize/dlimit filled in (a solved
    grazing size; other mechanisms are returned unchanged, without a derivative).
    ``params``: the parameter set of ``res`` (its model is ``res.model``) or the model."""
    m = maglev_model(params, res.model)

    if res.mechanism == Mechanism.BASIN_BOUNDARY and res.landing is not None:
        line = disturbance_line(m, res.direction)
        lnd = res.landing
        dxs = orbit_parameter_derivative(line.hs, res.orbit, lnd["segment"], lnd["node"])
        dd = basin_boundary_derivative(
            line.hs, float(res.size), line.x0_of, line.dx0_dd, lnd["x_star"], lnd["left"],
            lnd["normal"], dxs, res.window[0], res.window[1], p=line.hs.p,
            dx0_dp=m.disturbance_derivative(res.direction, res.size), options=FLOW)
        if not np.all(np.isfinite(dd)):
            return replace(res, derivative_available=False,
                           reason=res.reason + "; the derivative run lost the section")
        return replace(res, dsize_dp=dd, dsize_dlimit=0.0)
    if res.mechanism != Mechanism.GRAZING or res.window is None or res.size is None:
        return res
    line = disturbance_line(m, res.direction)
    j = (res.point or 1) - 1
    side = 1 if res.limit == "upper" else -1
    dx0_dp = m.disturbance_derivative(res.direction, res.size)
    dd_dp, dd_dL, _ = grazing_derivative(line.hs, [res.size], line.x0_of, line.dx0_dd,
                                         line.W[j], side, res.window[0], res.window[1],
                                         p=line.hs.p, dx0_dp=dx0_dp, options=FLOW)
    if not np.all(np.isfinite(dd_dp[0])):
        return replace(res, derivative_available=False,
                       reason=res.reason + "; the derivative run lost the tangency")
    # the gap deviation g = w . x + g0(p) and the limit L = (gap limit - c0) - g0: both move
    # with the parameters; L's dependence on the model parameters enters through dd/dL
    dL_dp = _dlimit_dp(m, j)
    return replace(res, dsize_dp=dd_dp[0] + dd_dL[0] * dL_dp, dsize_dlimit=float(dd_dL[0]))


def _dlimit_dp(m: MaglevModel, j: int) -> np.ndarray:
    """d L / dp with L = (gap limit - c0) - g0_j(p), per model parameter."""
    hs = m.clamped()
    g = hs.observables["gap_deviation"]
    n = hs.dim
    dg0 = np.atleast_2d(np.asarray(jax.jacfwd(
        lambda p: jnp.atleast_1d(g(jnp.zeros(n), p)))(jnp.asarray(hs.p))))
    names = list(hs.param_names)
    dc0 = np.zeros(len(names))
    dc0[names.index("c0")] = 1.0
    return -dc0 - dg0[j]


# ---------------------------------------------------------------------------------------
# entry points
# ---------------------------------------------------------------------------------------
def solve_critical(params: Params | MaglevModel, direction: int, *, model: str = "unit",
                   bisection: Any = None, derivative: bool = False,
                   bisection_kwargs: dict[str, Any] | None = None) -> CriticalSize:
    """The critical disturbance of one direction, solved where a grazing or basin-boundary
    condition decides it (module docstring).

    Parameters
    ----------
    params : the parameter set; direction : -1 or +1 (as the bisection's).
    model : 'unit' (model A) or 'vehicle' (model B).
    bisection : an already computed :class:`~maglev_match.analyses.simulation.CriticalDisturbance`
    of
        this direction (computed when None, with ``bisection_kwargs``).
    derivative : also dsize/dp (solved sizes only).
    """
    m = maglev_model(params, model)
    if bisection is None:
        from maglev_match.analyses.simulation import critical_disturbance

        bisection = critical_disturbance(m, direction=direction, **(bisection_kwargs or {}))
    return critical_from_bisection(m, bisection, derivative=derivative)


def solve_critical_batch(
    params_list: Sequence[Params],
    direction: int,
    guesses: Sequence[CriticalSize | None] | None = None,
    *,
    model: str = "unit",
    derivative: bool = False,
    verify: bool = True,
    bisection_kwargs: dict[str, Any] | None = None,
) -> list[CriticalSize]:
    """The critical disturbance of one direction at many parameter points, from warm starts.

    Parameters
    ----------
    params_list : the parameter points (equilibria stable; each a :class:`Params`).
    direction : -1 or +1.
    guesses : per point, a solved :class:`CriticalSize` of a nearby point (e.g. the
        neighbour on a map row) or None. A grazing guess gives the limit touched, the start
        size and the time window; the Newton solves of all warm-started points run as one
        batched flow per iteration.
    model : 'unit' or 'vehicle'.
    derivative : also dsize/dp at the solved points.
    verify : check each warm-started solution with two simulations of the limited model at
        1 -+ 1e-4 of the solved size (the smaller must not collide, the larger must collide
        at the same limit); a point that fails, has no guess, or does not converge gets the
        full search (:func:`solve_critical`: bisection, classification, solve).
    bisection_kwargs : passed to the bisection of the fall-back search.

    Returns
    -------
    One :class:`CriticalSize` per point, in order.
    """
    n_pts = len(params_list)
    guesses = list(guesses) if guesses is not None else [None] * n_pts
    if len(guesses) != n_pts:
        raise ParameterError("guesses", len(guesses), f"need one per point ({n_pts})")
    out: list[CriticalSize | None] = [None] * n_pts
    warm = [k for k, g in enumerate(guesses)
            if g is not None and g.mechanism == Mechanism.GRAZING and g.window is not None
            and g.size is not None and g.direction == direction and g.model == model]
    if warm:
        lines = [disturbance_line(params_list[k], direction, model) for k in warm]
        js = [(guesses[k].point or 1) - 1 for k in warm]
        sides = np.array([1 if guesses[k].limit == "upper" else -1 for k in warm])
        W = np.array([ln.W[j] for ln, j in zip(lines, js, strict=True)])
        Lim = np.array([(ln.upper if sd > 0 else ln.lower) - ln.g0[j]
                        for ln, j, sd in zip(lines, js, sides, strict=True)])
        P = np.array([ln.hs.p for ln in lines])
        x0_of, dx0_dd = stack_lines(lines)
        d0 = np.array([guesses[k].size for k in warm])
        ta = np.array([guesses[k].window[0] for k in warm])
        tm = np.array([guesses[k].window[1] for k in warm])
        sols = solve_grazing(lines[0].hs, x0_of, dx0_dd, W, Lim, sides, d0, ta, tm, p=P,
                             options=FLOW)
        ok = [s.converged for s in sols]
        if verify:
            ok = _verify(params_list, warm, sols, ok, sides, direction, model)
        for i, k in enumerate(warm):
            if not ok[i]:
                continue
            g = guesses[k]
            out[k] = replace(g, size=float(sols[i].size), converged=True,
                             t_star=float(sols[i].t_star), iterations=sols[i].iterations,
                             residual=float(sols[i].residual), bracket=(None, None),
                             dsize_dp=None, dsize_dlimit=None, derivative_available=True,
                             reason=(f"grazing solved from a neighbour's solution (warm start): "
                                     f"tangency at t* = {sols[i].t_star:.5g} s"
                                     + ("; checked by simulation at 1 -+ 1e-4 of the size"
                                        if verify else "")))
            if derivative:
                out[k] = critical_derivative(params_list[k], out[k])
    for k in range(n_pts):
        if out[k] is None:
            out[k] = solve_critical(params_list[k], direction, model=model,
                                    derivative=derivative, bisection_kwargs=bisection_kwargs)
    return [o for o in out if o is not None]


def _verify(params_list, warm, sols, ok, sides, direction, model) -> list[bool]:
    """Two limited simulations per warm-started solution: 1 - 1e-4 must not collide,
    1 + 1e-4 must collide at the same limit (one batched call per model point set)."""
    from maglev_match.dynamics.integrate.simulate import (
        COLLISION,
        SimulationOptions,
        simulate_batch,
    )

    res = list(ok)
    opts = SimulationOptions(stop_on_converged=True)
    for i, k in enumerate(warm):
        if not ok[i]:
            continue
        m = maglev_model(params_list[k], model)
        line = disturbance_line(m, direction)
        d = sols[i].size
        x0 = line.x0_of(np.array([d * (1 - 1e-4), d * (1 + 1e-4)]))
        horizon = 2.0 * float(sols[i].t_star) + 0.5
        b = simulate_batch(m.system(limited=True), x0, horizon, event_fn=m.gap_events(),
                           x_ref=m.equilibrium(), options=opts)
        below_ok = int(b.outcome_code[0]) != COLLISION
        above_ok = (int(b.outcome_code[1]) == COLLISION
                    and int(b.event_index[1]) % 2 == (1 if sides[i] > 0 else 0))
        res[i] = bool(below_ok and above_ok)
    return res


def _finite(v: float | None) -> bool:
    return v is not None and math.isfinite(v)
