"""One pseudo-arclength continuation driver for every branch type: options, one step-size
rule, one event mechanism.

A branch is the solution curve of H(u) = 0, H: R^(N+1) -> R^N, in scaled unknowns u (the
last component, by convention, carries the continuation parameter). From an accepted point
u_k with unit tangent t_k (in the weighted inner product <a, b>_W = sum W a b) the
predictor is u_k + s t_k and the corrector solves the bordered system (Keller 1977; Doedel's
AUTO notes, ch. "pseudo-arclength continuation"; Kuznetsov 2004, sec. 10.2)

    [ H(u)                          ]          [ H_u(u)     ]
    [ <u - u_k, t_k>_W - s          ] = 0,     [ (W t_k)^T  ] du = -residual,

by Newton's method. The next tangent solves the same bordered matrix with right-hand side
(0, ..., 0, 1), normalised to |t|_W = 1 and oriented by <t, t_k>_W > 0.

Step-size rule (the only one in the package): a rejected corrector halves s; an accepted
step with at most ``fast_iterations`` Newton iterations multiplies s by ``grow``, one with
at least ``slow_iterations`` by ``slow_factor``; s stays in [ds_min, ds_max]. Optionally
(``predictor_tol``) an easy step grows by more, on the predicted error: the distance
e = |u_corrected - u_predicted|_W of a tangent predictor is O(s^2) (its local error is the
curvature term; Allgower & Georg 1990, sec. 6.1; Deuflhard 2004, sec. 5.1), so the step
that would make it predictor_tol is s sqrt(predictor_tol / e); the next step is 0.8 times
that, at most ``max_grow`` s, and never less than the Newton-count rule gives.

Events: a problem offers named scalar test functions g(point). They are evaluated at every
accepted point; when one changes sign between u_k and u_(k+1) its zero is located inside
that step by the Illinois variant of regula falsi on the arclength s in (0, s_step), each
trial point being re-corrected onto the branch (Dowell & Jarratt 1971). A special point is
therefore a solved point of the branch, never an extrapolation, and carries how it was
located. The parameter bounds are events too: the last point of a branch that leaves its
bounds is solved on the bound.

The problem protocol (see :class:`ContinuationProblem`) follows pacopy's and
BifurcationKit's: a corrector on the bordered system, the weights of the inner product, a
read-out of the parameter, test functions and optional hooks.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Protocol

import numpy as np

from maglev_match.core.reprs import compact_repr

__all__ = [
    "signed_geometric_mean",
    "SpecialPointKind",
    "SpecialPoint",
    "label_points",
    "StopReason",
    "ContinuationOptions",
    "Correction",
    "BranchPoint",
    "Event",
    "ContinuationResult",
    "ContinuationProblem",
    "continuation",
    "dense_bordered_newton",
    "SOLVED",
]

SOLVED = "solved"


class SpecialPointKind(StrEnum):
    """Types of special points, with the labels of AUTO-07p and MatCont (same strings in
    JSON and files): LP, BP, H on equilibrium branches; LPC, PD, NS, BP on branches of
    cycles; GH, BT, ZH, HH on Hopf curves. Two kinds are not bifurcations and are named so
    that no AUTO or MatCont user reads them as one: ``contact`` (a cycle reaches a physical
    limit of the model, e.g. the magnet touches the rail; a user-defined zero, AUTO's UZ)
    and ``bound`` (the parameter reached the end of the search interval)."""

    LP = "LP"  # fold (limit point) of equilibria
    BP = "BP"  # branch point (equilibria or cycles)
    HOPF = "H"  # Hopf point on an equilibrium branch (or where a family of cycles ends)
    LPC = "LPC"  # fold of cycles
    PD = "PD"  # period doubling (real multiplier through -1)
    NS = "NS"  # Neimark-Sacker (complex pair through the unit circle)
    CONTACT = "contact"  # a physical limit is reached (not a bifurcation)
    LIMIT = "contact"  # the earlier name of CONTACT (an alias, same member)
    GH = "GH"  # generalised Hopf (Bautin), l1 = 0 on the Hopf curve
    BT = "BT"  # Bogdanov-Takens
    ZH = "ZH"  # zero-Hopf
    HH = "HH"  # double Hopf
    BOUND = "bound"  # the parameter reached a bound of the search


class StopReason(StrEnum):
    """Why a continuation stopped."""

    MAX_STEPS = "max_steps"
    BOUND = "left parameter range"
    STEP_TOO_SMALL = "step too small"
    NEWTON_FAILED = "newton failed"
    EVENT = "terminal event"
    PROBLEM = "stopped by the problem"
    CLOSED = "the branch closed on itself"


@dataclass(frozen=True)
class ContinuationOptions:
    """Options of :func:`continuation`, checked on construction.

    Parameters
    ----------
    ds, ds_min, ds_max : initial, smallest and largest arclength step (scaled units of
        the problem's unknowns).
    max_steps : maximum number of accepted steps.
    newton_tol : Newton converges when max |du| (scaled) falls below this.
    newton_max_iter : Newton iterations per corrector.
    param_bounds : (lo, hi) of the continuation parameter (its own unit); the branch stops
        on the bound (solved there). None: no bounds.
    grow, slow_factor, shrink : step factors after an easy step, a slow step and a failure.
    fast_iterations, slow_iterations : what "easy" and "slow" mean (Newton iterations).
    event_tol : an event is solved when its bracket in s is below event_tol * step.
    event_max_iter : Illinois iterations per event.
    predictor_tol : target distance (weighted norm, scaled units) between the predicted and
        the corrected point; None: the Newton-count rule alone.
    max_grow : largest step growth per step under ``predictor_tol``.
    """

    ds: float = 0.01
    ds_min: float = 1e-8
    ds_max: float = 0.1
    max_steps: int = 500
    newton_tol: float = 1e-10
    newton_max_iter: int = 10
    param_bounds: tuple[float, float] | None = None
    grow: float = 1.5
    slow_factor: float = 0.6
    shrink: float = 0.5
    fast_iterations: int = 3
    slow_iterations: int = 6
    event_tol: float = 1e-10
    event_max_iter: int = 40
    predictor_tol: float | None = None
    max_grow: float = 4.0

    def __post_init__(self) -> None:
        for name in ("ds", "ds_min", "ds_max", "newton_tol", "grow", "event_tol"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"ContinuationOptions.{name} = {v!r}: must be a positive "
                                 "finite number")
        if not self.ds_min <= self.ds <= self.ds_max:
            raise ValueError(f"ContinuationOptions.ds = {self.ds!r}: must lie in "
                             f"[ds_min, ds_max] = [{self.ds_min!r}, {self.ds_max!r}]")
        for name in ("max_steps", "newton_max_iter", "fast_iterations", "slow_iterations",
                     "event_max_iter"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ValueError(f"ContinuationOptions.{name} = {v!r}: must be an integer "
                                 ">= 1")
        for name in ("slow_factor", "shrink"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and 0 < v < 1):
                raise ValueError(f"ContinuationOptions.{name} = {v!r}: must lie in (0, 1)")
        if self.predictor_tol is not None and not (
                isinstance(self.predictor_tol, int | float)
                and math.isfinite(self.predictor_tol) and self.predictor_tol > 0):
            raise ValueError(f"ContinuationOptions.predictor_tol = {self.predictor_tol!r}: "
                             "must be None or a positive finite number")
        if not (math.isfinite(self.max_grow) and self.max_grow >= 1):
            raise ValueError(f"ContinuationOptions.max_grow = {self.max_grow!r}: must be "
                             ">= 1")
        if self.grow < 1:
            raise ValueError(f"ContinuationOptions.grow = {self.grow!r}: must be >= 1")
        if self.param_bounds is not None:
            lo, hi = self.param_bounds
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(f"ContinuationOptions.param_bounds = {self.param_bounds!r}: "
                                 "must be finite with lo < hi")


@dataclass(frozen=True)
class SpecialPoint:
    """A special point of a branch, one record for every branch type (equilibria, cycles,
    the Hopf curve), after BifurcationKit's ``SpecialPoint``: the common fields, and the
    fields of the branch types that have them (None or empty otherwise).

    Common fields
    -------------
    type : the :class:`SpecialPointKind` value (LP, BP, H, LPC, PD, NS, GH, BT, ZH, HH,
        contact, bound).
    value : the continuation parameter there (its own unit; the first of the two on a
        Hopf curve).
    label : unique along the branch (LPC1, H2, contact1, ...).
    located : "solved" (a zero of its test function solved on the branch to the branch's
        tolerance) or the reason it could not be solved.
    step : index of the accepted branch point just before it (-1: not on a step).
    detail : e.g. the multiplier at a PD, the name of the limit at a contact, the Hopf
        point that closes a family of cycles.
    values : every continuation parameter there ((value,) on one-parameter branches).

    Branch-specific fields
    ----------------------
    x, eigenvalues : the equilibrium and its eigenvalues (equilibria, Hopf curve).
    frequency : omega of the critical pair (rad/s): H, GH, ZH, HH.
    period, extrema, point : the cycle there (cycles: period in s, observable
        (max, min), the solved :class:`~maglev_match.dynamics.cycles.CyclePoint`).
    l2 : second Lyapunov coefficient (GH); other_frequency : the second frequency (HH).
    residual : the residual of the defining system where one was solved.
    """

    __repr__ = compact_repr

    type: str
    value: float
    label: str = ""
    located: str = "solved"
    step: int = -1
    detail: str = ""
    values: tuple[float, ...] = ()
    x: np.ndarray | None = None
    eigenvalues: np.ndarray | None = None
    frequency: float = 0.0
    period: float | None = None
    extrema: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    point: Any = None
    l2: float | None = None
    other_frequency: float | None = None
    residual: float = 0.0

    def __post_init__(self) -> None:
        if not self.values:
            object.__setattr__(self, "values", (float(self.value),))

    @property
    def converged(self) -> bool:
        """Whether the point was solved (``located`` is "solved")."""
        return self.located == SOLVED

    @property
    def note(self) -> str:
        """Why the point is not solved ('' when it is)."""
        return "" if self.converged else self.located


def label_points(points: list[SpecialPoint]) -> list[SpecialPoint]:
    """The same points with labels unique along a branch: type and running number per
    type (LPC1, LPC2, BP1, ...), AUTO's and MatCont's labels."""
    counts: dict[str, int] = {}
    out = []
    for sp in points:
        counts[sp.type] = counts.get(sp.type, 0) + 1
        out.append(dataclasses.replace(sp, label=f"{sp.type}{counts[sp.type]}"))
    return out


@dataclass
class Correction:
    """A corrected point: the solution u, Newton diagnostics, and a solver of the bordered
    matrix at (or within tolerance of) the solution, used for the tangent.

    ``data`` holds whatever the problem needs later (LU factors, collocation blocks...).
    """

    u: np.ndarray
    iterations: int
    residual: float
    solve: Callable[[np.ndarray], np.ndarray]
    data: Any = None


@dataclass
class BranchPoint:
    """An accepted (or located) point of a branch."""

    u: np.ndarray  # scaled unknowns
    t: np.ndarray  # unit tangent (weighted norm), oriented along the branch
    value: float  # continuation parameter (its own unit)
    correction: Correction
    tests: dict[str, float] = field(default_factory=dict)
    kind: str = "step"
    info: dict[str, Any] = field(default_factory=dict)  # the problem's read-outs


@dataclass(frozen=True)
class Event:
    """A sign change of a test function, located inside the step after ``step``.

    ``kind`` is the test function's special-point kind (possibly re-classified by the
    problem), ``point`` the solved branch point (None when nothing could be corrected),
    ``located`` "solved" or the reason it could not be solved.
    """

    name: str
    kind: str
    step: int  # index of the accepted point before the event
    point: BranchPoint | None
    located: str
    value: float  # the test function there
    terminal: bool = False
    s: float = 0.0  # arclength from the point before the event


@dataclass
class ContinuationResult:
    """Accepted points in order, located events, and why the run stopped."""

    points: list[BranchPoint]
    events: list[Event]
    stop_reason: StopReason
    message: str = ""
    rejected: int = 0


class ContinuationProblem(Protocol):
    """What :func:`continuation` needs from a branch type.

    * ``weights`` : the weights W of the arclength inner product (same shape as u).
    * ``correct(u_pred, row, target, max_iter)`` : Newton on [H(u) = 0; row . u = target]
      from u_pred; returns a :class:`Correction` or None when Newton fails.
    * ``parameter(u)`` : the continuation parameter in its own unit.
    * ``test_functions(point)`` : mapping name -> value at an accepted point.
    * ``event_kind(name)`` : the special-point kind of a test function.
    * ``classify(name, point, a, b)`` : the kind of a located zero, or None to drop it
      (e.g. a neutral saddle found by the Hopf test function).
    * ``terminal(name)`` : whether the event stops the branch.
    * ``worth_locating(name, a, b)`` : False skips a sign change that the end points
      already show is no special point (saves the solves).
    * ``admissible(a, u_new, s)`` : reject a corrected point (branch jumping).
    * ``after_accept(point)`` : hook (mesh adaptation), returns the point to continue from.
    * ``stop(point)`` : a reason to stop after this point, or None.
    * ``event_tolerance(name)`` : the relative bracket (of the step) to which this event is
      located, or None for ``options.event_tol`` (a problem that re-solves the point of an
      event exactly anyway, e.g. at a stop value, needs only one secant trial: 1.0).
    * ``event_tests(name, point)`` : the test functions at a trial point of the location
      of event ``name`` (at least ``name``'s; default: all of ``test_functions``), so a
      problem may skip read-outs that the location does not need.
    * ``double_zero_suspect(name, a, b)`` : True when test ``name`` may have changed sign
      twice inside the step from a to b (same sign at both ends): the driver then checks
      its sign inside the step (at 1/2, then 1/4 and 3/4 of it) and, where it differs,
      locates both zeros (one on each side of that trial point); with
      ``corrector_state()`` / ``set_corrector_state(state)`` the problem's corrector state
      is restored when the check finds nothing;
    * ``rebase(a, corr)`` : called with the last accepted point and a successful
      correction of the next step; returns None to go on, or the point ``a`` expressed in
      new unknowns (the problem changed its coordinates, e.g. to a chart in which its
      equations stay regular ahead): the step is then taken again from there.
    """

    weights: np.ndarray

    def correct(self, u_pred: np.ndarray, row: np.ndarray, target: float,
                max_iter: int) -> Correction | None: ...

    def parameter(self, u: np.ndarray) -> float: ...

    def test_functions(self, point: BranchPoint) -> Mapping[str, float]: ...

    def event_kind(self, name: str) -> str: ...


def _hook(problem, name: str, default):
    return getattr(problem, name, None) or default


def dense_bordered_newton(
    fun: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    u_pred: np.ndarray,
    row: np.ndarray,
    target: float,
    tol: float,
    max_iter: int,
) -> Correction | None:
    """Newton's method on the dense bordered system [H(u) = 0; row . u = target].

    ``fun(u)`` returns (H(u), H_u(u)) with H_u of shape (N, N + 1). Converged when
    max |du| < tol; the LU factors of the last bordered matrix give the tangent."""
    u = np.array(u_pred, float)
    for k in range(1, max_iter + 1):
        g, A = fun(u)
        M = np.vstack([A, row[None, :]])
        r = np.concatenate([g, [row @ u - target]])
        try:
            du = -np.linalg.solve(M, r)
        except np.linalg.LinAlgError:  # exactly singular (e.g. at a branch point)
            return None
        if not np.all(np.isfinite(du)):
            return None
        u = u + du
        if np.max(np.abs(du)) < tol:
            res = float(np.max(np.abs(r)))
            # the bordered matrix of this last iterate serves for the tangent
            return Correction(u=u, iterations=k, residual=res,
                              solve=lambda b, M=M: np.linalg.solve(M, b), data=(g, A))
    return None


def _tangent(corr: Correction, W: np.ndarray, orient: np.ndarray) -> np.ndarray:
    e = np.zeros(corr.u.size)
    e[-1] = 1.0
    t = np.asarray(corr.solve(e), float)
    t = t / math.sqrt(float(np.sum(W * t * t)))
    if float(np.sum(W * t * orient)) < 0:
        t = -t
    return t


def continuation(
    problem: Any,
    u0: np.ndarray,
    t0: np.ndarray,
    options: ContinuationOptions,
    progress: Callable[[int, BranchPoint], None] | None = None,
    first: Correction | None = None,
) -> ContinuationResult:
    """Follow the branch of ``problem`` from u0 along the tangent direction t0.

    Parameters
    ----------
    problem : a :class:`ContinuationProblem`.
    u0 : a point on (or near) the branch, scaled unknowns; corrected first along t0
        unless ``first`` (its correction) is given.
    t0 : the initial direction (need not be exact; normalised and oriented here).
    options : :class:`ContinuationOptions`.
    progress : called as progress(step, point) after each accepted step.

    Returns
    -------
    :class:`ContinuationResult`. Failure (Newton, tiny step) is a stop reason, never raised.
    """
    W = np.asarray(problem.weights, float)
    opt = options
    classify = _hook(problem, "classify", lambda name, pt, a, b: problem.event_kind(name))
    terminal = _hook(problem, "terminal", lambda name: False)
    admissible = _hook(problem, "admissible", lambda a, u, s: True)
    after_accept = _hook(problem, "after_accept", lambda pt: pt)
    worth = _hook(problem, "worth_locating", lambda name, a, b: True)
    suspect = _hook(problem, "double_zero_suspect", lambda name, a, b: False)
    stop_hook = _hook(problem, "stop", lambda pt: None)
    rebase = getattr(problem, "rebase", None)
    t0 = np.asarray(t0, float) / math.sqrt(float(np.sum(W * t0 * t0)))

    event_tests = getattr(problem, "event_tests", None)

    def make_point(corr: Correction, orient: np.ndarray, kind: str = "step",
                   event: str | None = None) -> BranchPoint:
        t = _tangent(corr, W, orient)
        pt = BranchPoint(u=corr.u, t=t, value=float(problem.parameter(corr.u)),
                         correction=corr, kind=kind)
        if event is not None and event_tests is not None:
            pt.tests = dict(event_tests(event, pt))
        else:
            pt.tests = dict(problem.test_functions(pt))
        if opt.param_bounds is not None:
            pt.tests["__lo"] = pt.value - opt.param_bounds[0]
            pt.tests["__hi"] = opt.param_bounds[1] - pt.value
        return pt

    def correct_at(a: BranchPoint, s: float, max_iter: int | None = None):
        row = W * a.t
        corr = problem.correct(a.u + s * a.t, row, float(row @ a.u) + s,
                               max_iter or opt.newton_max_iter)
        if corr is not None and not admissible(a, corr.u, s):
            return None
        return corr

    if first is None:
        row = W * t0
        first = problem.correct(np.asarray(u0, float), row, float(row @ u0),
                                opt.newton_max_iter)
    if first is None:
        return ContinuationResult([], [], StopReason.NEWTON_FAILED,
                                  "the start point could not be corrected onto the branch")
    a = make_point(first, t0, kind="start")
    points = [a]
    events: list[Event] = []
    s = opt.ds
    rejected = 0
    reason, message = StopReason.MAX_STEPS, f"stopped after max_steps = {opt.max_steps}"
    step = 0
    rebased = 0
    while step < opt.max_steps:
        corr = correct_at(a, s)
        if corr is not None and rebase is not None and rebased < 4:
            a_new = rebase(a, corr)
            if a_new is not None:  # new coordinates: the same step again from a in them
                a = a_new
                rebased += 1
                continue
        if corr is None:
            rejected += 1
            s *= opt.shrink
            if s < opt.ds_min:
                reason = StopReason.STEP_TOO_SMALL
                message = (f"step size fell below ds_min = {opt.ds_min:g} at "
                           f"parameter {a.value:.8g} (corrector failed)")
                break
            continue
        step += 1
        b = make_point(corr, a.t)
        # every sign change of a test function inside this step, located by solving
        found: list[Event] = []
        for name, gb in b.tests.items():
            ga = a.tests.get(name, np.nan)
            if np.isfinite(ga) and np.isfinite(gb) and ga * gb > 0 and suspect(name, a, b):
                # two sign changes inside the step? The test at trial points inside it
                found.extend(_two_zeros(problem, name, a, b, s, correct_at, make_point, opt,
                                        classify, terminal, step - 1))
                continue
            if not (np.isfinite(ga) and np.isfinite(gb)) or ga == 0 or ga * gb > 0:
                continue
            if not worth(name, a, b):
                continue
            ev = _locate(problem, name, a, b, s, correct_at, make_point, opt, classify,
                         terminal, step - 1)
            if ev is not None:
                found.append(ev)
        found.sort(key=lambda e: e.s)
        stop_event = next((e for e in found if e.terminal), None)
        if stop_event is not None:
            # keep the events before the terminal one; the branch ends on it
            events.extend(e for e in found if e.s <= stop_event.s)
            if stop_event.point is not None:
                points.append(stop_event.point)
            where = stop_event.point.value if stop_event.point is not None else b.value
            if stop_event.name.startswith("__"):
                reason, message = StopReason.BOUND, f"reached the parameter bound {where:.10g}"
            else:
                reason = StopReason.EVENT
                message = f"terminal event {stop_event.kind} at {where:.10g}"
            if progress is not None:
                progress(step, points[-1])
            break
        events.extend(found)
        b = after_accept(b)
        points.append(b)
        if progress is not None:
            progress(step, b)
        why = stop_hook(b)
        if why:
            reason, message = StopReason.PROBLEM, str(why)
            break
        its = corr.iterations
        if its <= opt.fast_iterations:
            grow = opt.grow
            if opt.predictor_tol is not None:
                d = corr.u - (a.u + s * a.t)
                e = math.sqrt(float(np.sum(W * d * d)))
                if e > 0:
                    grow = max(grow, min(opt.max_grow, 0.8 * math.sqrt(opt.predictor_tol / e)))
                else:
                    grow = max(grow, opt.max_grow)
            s = min(s * grow, opt.ds_max)
        elif its >= opt.slow_iterations:
            s = max(s * opt.slow_factor, opt.ds_min)
        b.info["ds_next"] = s  # the step that follows this point (for a restart)
        a = b
    return ContinuationResult(points=points, events=events, stop_reason=reason,
                              message=message, rejected=rejected)


#: A zero whose bracket has shrunk below this fraction of its step is located, even when
#: the corrector fails at trial points closer to it (see :func:`_locate`).
PINNED = 1e-6


def _inside_step(u: np.ndarray, ua: np.ndarray, ub: np.ndarray, W: np.ndarray) -> bool:
    """Whether u lies within the step from ua to ub: no farther from either end than the
    chord (with a margin for the curvature of the branch)."""
    def dist(x, y):
        d = x - y
        return math.sqrt(float(np.sum(W * d * d)))

    chord = dist(ua, ub)
    return dist(u, ua) <= 1.2 * chord and dist(u, ub) <= 1.2 * chord


def _two_zeros(problem, name, a: BranchPoint, b: BranchPoint, s_step: float, correct_at,
               make_point, opt: ContinuationOptions, classify, terminal, step: int
               ) -> list[Event]:
    """Test ``name`` has the same sign at both ends of the step: its sign at 1/2, then 1/4
    and 3/4 of the step; at the first trial point where it differs, both zeros are located
    (one on each side of it, :func:`_locate` from a to it and from it to b). No event
    otherwise."""
    ga = a.tests[name]
    # the problem's corrector state (e.g. a kept factorisation) is restored when the check
    # finds nothing, so that the branch goes on exactly as without it
    get_state = getattr(problem, "corrector_state", None)
    state = get_state() if get_state is not None else None
    for frac in (0.5, 0.25, 0.75):
        sm = frac * s_step
        corr = correct_at(a, sm)
        if corr is None or not _inside_step(corr.u, a.u, b.u, np.asarray(problem.weights)):
            continue
        mid = make_point(corr, a.t, event=name)
        gm = mid.tests.get(name, np.nan)
        if not np.isfinite(gm) or gm * ga > 0:
            continue
        out = []
        if gm != 0.0:  # the near zero, from a; the far one from the trial point (whose
            # tangent predicts the rest of the step better than a's)
            ev = _locate(problem, name, a, mid, sm, correct_at, make_point, opt, classify,
                         terminal, step)
            if ev is not None:
                out.append(ev)
        W = np.asarray(problem.weights, float)
        s_b = float(np.sum(W * mid.t * (b.u - mid.u)))
        if gm != 0.0 and s_b > 0:
            ev = _locate(problem, name, mid, b, s_b, correct_at, make_point, opt, classify,
                         terminal, step)
            if ev is not None:
                out.append(dataclasses.replace(ev, s=sm + ev.s))
        return out
    if get_state is not None:
        problem.set_corrector_state(state)
    return []


def _locate(problem, name, a: BranchPoint, b: BranchPoint, s_step: float, correct_at,
            make_point, opt: ContinuationOptions, classify, terminal, step: int
            ) -> Event | None:
    """Zero of test function ``name`` between a (s = 0) and b (s = s_step): Illinois
    regula falsi on s, every trial re-corrected onto the branch, to the relative bracket
    ``problem.event_tolerance(name)`` (default ``opt.event_tol``), or until the test
    function is within ``problem.event_value_tolerance(name)`` of zero (when the problem
    gives one). The zero is "solved" when either holds, and also when the corrector fails
    at trials closer to it once its bracket is below :data:`PINNED` of the step, or the
    best trial's |g| below :data:`PINNED` of |g| at the step's ends (at a branch point the
    bordered matrix is singular: its neighbourhood cannot be corrected, however it was
    approached); the located point is the trial with the smallest |g|."""
    tol_hook = getattr(problem, "event_tolerance", None)
    ev_tol = tol_hook(name) if tol_hook is not None else None
    ev_tol = opt.event_tol if ev_tol is None else float(ev_tol)
    value_hook = getattr(problem, "event_value_tolerance", None)
    value_tol = value_hook(name) if value_hook is not None else None
    lo, glo, hi, ghi = 0.0, a.tests[name], s_step, b.tests[name]
    g_start = glo
    best: tuple[float, float, BranchPoint] | None = None
    best_before: tuple[float, float, BranchPoint] | None = None  # on the side of a
    side = 0
    s_prev = None
    located = f"not solved: no convergence in {opt.event_max_iter} iterations"
    W = np.asarray(problem.weights, float)
    failures = 0  # failed corrections (at most 8 per event)
    for _ in range(opt.event_max_iter):
        sm = (lo * ghi - hi * glo) / (ghi - glo) if ghi != glo else 0.5 * (lo + hi)
        if not lo < sm < hi:
            sm = 0.5 * (lo + hi)
        corr = None
        for attempt in range(3):
            if failures >= 8:
                break
            corr = correct_at(a, sm, 3 * opt.newton_max_iter if attempt == 0
                              else opt.newton_max_iter)
            if corr is not None and not _inside_step(corr.u, a.u, b.u, W):
                corr = None  # converged to a point that does not lie in this step
            if corr is not None:
                break
            failures += 1
            if attempt == 0:  # at a branch point the bordered matrix is singular: nudge
                sm = sm + 1e-7 * (hi - lo)
            else:  # the corrector fails here: try closer to the near end of the bracket
                sm = lo + 0.5 * (sm - lo)
        if corr is None:
            if best is not None and ((hi - lo) < PINNED * s_step or abs(best[0]) <= PINNED * max(
                    abs(a.tests[name]), abs(b.tests[name]))):
                # the zero is pinned (a bracket far below the step, or a test value far below
                # its values at the ends of the step, which for a simple zero bounds the
                # distance the same way); the corrector only fails closer to it (at a branch
                # point the bordered matrix is singular): the best trial is the located point
                located = SOLVED
            else:
                located = "not solved: the corrector failed inside the step"
            break
        pt = make_point(corr, a.t, event=name)
        g = pt.tests.get(name, np.nan)
        if not np.isfinite(g):
            located = "not solved: the test function is not finite inside the step"
            break
        if best is None or abs(g) <= abs(best[0]):
            best = (g, sm, pt)
        if (g == 0 or (g > 0) == (g_start > 0)) and (best_before is None
                                                      or abs(g) <= abs(best_before[0])):
            best_before = (g, sm, pt)
        if g == 0 or (hi - lo) < ev_tol * s_step or ev_tol >= 1.0 or (
                s_prev is not None and abs(sm - s_prev) < ev_tol * s_step) or (
                value_tol is not None and abs(g) <= value_tol):
            located = SOLVED
            break
        s_prev = sm
        if (g > 0) == (ghi > 0):
            hi, ghi = sm, g
            if side == -1:
                glo *= 0.5
            side = -1
        else:
            lo, glo = sm, g
            if side == 1:
                ghi *= 0.5
            side = 1
    if best is None:
        kind = problem.event_kind(name) if not name.startswith("__") else SpecialPointKind.BOUND
        return Event(name=name, kind=str(kind), step=step, point=None, located=located,
                     value=float("nan"), terminal=name.startswith("__") or bool(terminal(name)),
                     s=s_step)
    is_terminal = name.startswith("__") or bool(terminal(name))
    on_zero = value_tol is not None and abs(best[0]) <= value_tol
    if is_terminal and best_before is not None and not on_zero:
        best = best_before  # a branch ends on the near side of its terminal event
    g, sm, pt = best
    if name.startswith("__"):
        pt.kind = "bound"
        return Event(name=name, kind=str(SpecialPointKind.BOUND), step=step, point=pt,
                     located=located, value=float(g), terminal=True, s=sm)
    kind = classify(name, pt, a, b)
    if kind is None:
        return None
    pt.kind = str(kind)
    return Event(name=name, kind=str(kind), step=step, point=pt, located=located,
                 value=float(g), terminal=bool(terminal(name)), s=sm)


def signed_geometric_mean(r: np.ndarray) -> float:
    """A test function value from many factors: the sign of prod r (r complex; non-real
    factors come in conjugate pairs, so the product is real) with the geometric mean of |r|
    as magnitude (no under/overflow). Used by the cycle (PD/NS/BP) and Hopf-curve (ZH/HH)
    test functions, whose zeros are the zeros of a factor."""
    if r.size == 0:
        return 1.0
    a = np.abs(r)
    if np.any(a == 0):
        return 0.0
    real = np.abs(r.imag) <= 1e-9 * a
    sign = float(np.prod(np.sign(r.real[real]))) if np.any(real) else 1.0
    return sign * float(np.exp(np.mean(np.log(a))))
