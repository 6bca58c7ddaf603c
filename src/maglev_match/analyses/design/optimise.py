"""The optimiser of the inverse problem: the cheapest beam or the best gains that meet
requirements on the headline matching index chi, the stability margin and chi_simulation
(:func:`optimise_design`; the problem, its evaluators and its result are in
:mod:`maglev_match.analyses.design.problem`).

Formulation (scaled variables u in [0, 1]^d, v = lo + u (hi - lo) for each varied parameter):

    minimise  v_obj            (``--minimize NAME``)   or   -chi(v)   (``--maximize chi``)
    subject to  chi(v) >= X,   margin(v) = -max Re lambda(v) >= Y,   lo <= v <= hi,

solved by sequential least-squares quadratic programming (SLSQP; Kraft 1988, as in
``scipy.optimize``) with the exact gradients of :mod:`maglev_match.analyses.sensitivity`. chi is the
headline index, min(chi_paper, chi_simulation) (the paper's chi alone with
``simulate=False``), so ``chi >= X`` is the pair of smooth constraints
chi_paper(v) >= X and chi_simulation(v) >= X, each with its own exact gradient
(chi_simulation's from the implicit function theorem on the solved critical disturbance,
:mod:`maglev_match.analyses.critical`); a requirement ``chi_simulation >= Z`` is the second alone.
chi_paper is not convex: it rises, peaks and falls to 0 at the Hopf curve, and it is
identically 0 beyond it. So the optimiser starts from the best points of a coarse grid over
the box, and in the unstable region both chi constraints use the continuous extension
chi_ext = -max Re lambda / margin_scale (< 0) whose gradient leads back to the stable side
(chi -> 0 at the boundary from both sides). Where chi_simulation has no derivative (its
critical size only bracketed by bisection) its constraint has no gradient; when a candidate
then falls short when re-checked, the requirement on chi_paper is raised by the ratio found
and the optimiser run again (at most ``sim_rounds`` times).

Every candidate is re-checked by the full index (and by simulation when chi_simulation is
required); the design returned is the best re-checked one, or, when none meets the
requirements, the best found with the status ``infeasible``.

The numerics here (grid, starts, SLSQP, constraints, polish, re-check) are model-agnostic
through the :class:`~maglev_match.analyses.design.problem.Evaluator` interface. SciPy is
imported when the search runs, not with this module.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from maglev_match.analyses.design.problem import (
    Candidate,
    DesignProblem,
    DesignResult,
    DesignStatus,
    Evaluation,
    Evaluator,
    Goal,
    Quantity,
    Requirement,
)
from maglev_match.core.params import ParameterError

if TYPE_CHECKING:
    from maglev_match.analyses.matching import MatchingIndex

__all__ = ["optimise_design"]


# ---------------------------------------------------------------------------------------
# the optimiser
# ---------------------------------------------------------------------------------------
class _Cache:
    """Evaluations by point, so SLSQP's separate calls for values and gradients share one
    index computation; counts index evaluations."""

    def __init__(self, problem: DesignProblem, evaluator: Evaluator):
        self.problem = problem
        self.evaluator = evaluator
        self.store: dict[bytes, Evaluation] = {}
        self.count = 0

    def __call__(self, u: np.ndarray, gradient: bool = True) -> Evaluation:
        u = np.clip(np.asarray(u, float), 0.0, 1.0)
        key = u.tobytes()
        ev = self.store.get(key)
        if ev is None or (gradient and ev.dchi is None):
            ev = self.evaluator.evaluate(self.problem.values(u), gradient)
            self.count += 1
            self.store[key] = ev
        return ev


def _grid(d: int, n: int) -> np.ndarray:
    axes = [np.linspace(0.0, 1.0, n)] * d
    return np.array(list(itertools.product(*axes)))


def _chi_ext(ev: Evaluation, margin_scale: float, part: str = "paper") -> float:
    """chi_paper (``part`` 'paper') or chi_simulation ('simulation') where the equilibrium is
    stable; -max Re lambda / margin_scale (<= 0) where not. A chi_simulation that could not
    be computed counts as its paper part (no constraint of its own)."""
    if ev.index.case == "unstable_equilibrium":
        return min(ev.margin, 0.0) / margin_scale
    if part == "simulation":
        return ev.chi_simulation if ev.chi_simulation is not None else ev.chi_paper
    return ev.chi_paper if math.isfinite(ev.chi_paper) else ev.chi


def _shortfall(reqs: Sequence[Requirement], chi: float, margin: float,
               chi_sim: float | None) -> float:
    """Largest relative shortfall of the requirements (0 when all are met; inf if unknown)."""
    worst = 0.0
    for r in reqs:
        v = {Quantity.CHI: chi, Quantity.MARGIN: margin,
             Quantity.CHI_SIMULATION: chi_sim}[r.quantity]
        if v is None or not math.isfinite(v):
            return math.inf
        worst = max(worst, (r.bound - v) / max(abs(r.bound), 1e-12))
    return max(worst, 0.0)


def optimise_design(
    problem: DesignProblem,
    evaluator: Evaluator,
    *,
    grid: int | None = None,
    starts: int = 2,
    maxiter: int = 40,
    sim_rounds: int = 2,
    progress: Callable[[str], None] | None = None,
) -> DesignResult:
    """Solve ``problem`` (see the module docstring).

    Parameters
    ----------
    problem : varied parameters with bounds, the goal and the requirements.
    evaluator : the model (:class:`MaglevEvaluator` for model A or B).
    grid : points per varied parameter of the coarse start grid (default 9 for one
        parameter, 5 for two, 3 beyond).
    starts : optimiser runs, from the best grid points.
    maxiter : SLSQP iterations per run.
    sim_rounds : re-runs with a raised chi requirement when chi_simulation falls short.
    """
    t0 = time.perf_counter()
    d = len(problem.variables)
    n = grid or {1: 9, 2: 5}.get(d, 3)
    cache = _Cache(problem, evaluator)
    warnings: list[str] = []
    say = progress or (lambda s: None)
    U = _grid(d, n)
    say(f"coarse grid: {len(U)} points")
    scanned = getattr(evaluator, "scan", lambda *a: None)(problem, n)
    if scanned is not None:  # the map's rows: cheap, for the starts only
        grid_chi, margins = scanned
        grid_values = [problem.values(u) for u in U]
    else:
        evs = [cache(u, gradient=False) for u in U]
        grid_chi = np.array([e.chi for e in evs])
        margins = np.array([e.margin for e in evs])
        grid_values = [e.values for e in evs]
    finite = margins[np.isfinite(margins)]
    margin_scale = float(np.max(np.abs(finite))) if finite.size else 1.0
    margin_scale = margin_scale or 1.0
    n_fail = int(np.sum(~np.isfinite(grid_chi)))
    if n_fail:
        warnings.append(f"{n_fail} of {len(U)} grid points: the index did not converge")

    reqs = list(problem.requirements)
    chi_req = next((r.bound for r in reqs if r.quantity == Quantity.CHI), None)
    sim = bool(getattr(evaluator, "simulate", False))
    if problem.needs_simulation and not sim:
        raise ParameterError("--require", "chi_simulation>=...",
                             "needs the simulation, which this evaluator does not run")
    candidates: list[Candidate] = []
    cand_index: list[MatchingIndex] = []  # the full index of each candidate
    total_its = 0

    def objective_of(values: np.ndarray, chi: float) -> float:
        if problem.goal == Goal.MAXIMIZE:
            return chi
        return float(values[problem.names.index(problem.objective)])

    def rank_starts(chi_bound: float | None) -> list[int]:
        def score(i: int) -> tuple[float, float]:
            short = _shortfall(_grad_reqs(reqs, chi_bound), grid_chi[i], margins[i], None)
            obj = objective_of(grid_values[i], grid_chi[i])
            sign = -1.0 if problem.goal == Goal.MAXIMIZE else 1.0
            return (short, sign * obj if math.isfinite(obj) else math.inf)
        order = sorted(range(len(U)), key=score)
        return order[:starts]

    def run(u0: np.ndarray, chi_bound: float | None) -> tuple[np.ndarray, int, str, list]:
        path: list[np.ndarray] = [u0]
        iobj = problem.names.index(problem.objective) if problem.goal == Goal.MINIMIZE else -1

        def fun(u):
            if iobj >= 0:
                return float(u[iobj])
            ev = cache(u)
            return -ev.chi / max(chi_bound or 1.0, 1.0)

        def jac(u):
            if iobj >= 0:
                g = np.zeros(d)
                g[iobj] = 1.0
                return g
            ev = cache(u)
            return -_grad(ev, "headline", problem, margin_scale) / max(chi_bound or 1.0, 1.0)

        cons = []
        for part, bound in _constraints(reqs, chi_bound, sim):
            sc = max(abs(bound), 1e-3)

            def cf(u, part=part, b=bound, sc=sc):
                return (_part_value(cache(u), part, margin_scale) - b) / sc

            def cj(u, part=part, sc=sc):
                return _grad(cache(u), part, problem, margin_scale) / sc

            cons.append({"type": "ineq", "fun": cf, "jac": cj})

        def cb(u):
            path.append(np.array(u))

        import scipy.optimize  # loaded with the search, not with the parsers above

        res = scipy.optimize.minimize(fun, u0, jac=jac, method="SLSQP", bounds=[(0, 1)] * d,
                                      constraints=cons, callback=cb,
                                      options={"maxiter": maxiter, "ftol": 1e-10})
        u = np.clip(res.x, 0.0, 1.0)
        u = _polish(u, cache, problem, _constraints(reqs, chi_bound, sim), margin_scale)
        path.append(u)
        return u, int(res.nit), str(res.message), path

    chi_bound = None
    for round_ in range(sim_rounds + 1):
        for i in rank_starts(chi_bound if chi_bound is not None else chi_req):
            say(f"optimiser from grid point {i + 1}"
                + (f" (round {round_ + 1})" if round_ else ""))
            u, its, msg, path = run(U[i], chi_bound)
            total_its += its
            # with the simulation on, each evaluation is the full headline index already
            ev = cache(u, gradient=False)
            chi_sim = ev.chi_simulation if sim else None
            short = _shortfall(problem.requirements, ev.chi, ev.margin, chi_sim)
            cand_index.append(ev.index)
            candidates.append(Candidate(
                start=problem.values(U[i]), values=ev.values, chi=ev.chi, margin=ev.margin,
                chi_simulation=chi_sim, feasible=short == 0.0, violation=short,
                iterations=its, evaluations=cache.count, message=msg,
                path=np.array([problem.values(x) for x in path]),
                path_chi=np.array([cache(x, gradient=False).chi for x in path]),
                chi_paper=ev.chi_paper))
        feasible = [c for c in candidates if c.feasible]
        if feasible or not sim:
            break
        # chi_simulation short where its critical size has no derivative (bisection only):
        # raise the requirement on chi_paper by the shortfall ratio and run again
        sim_bound = max([r.bound for r in reqs
                         if r.quantity in (Quantity.CHI, Quantity.CHI_SIMULATION)], default=None)
        ratios = [sim_bound / c.chi_simulation * 1.02 for c in candidates[-starts:]
                  if sim_bound is not None and c.chi_simulation and c.chi_simulation > 0
                  and c.chi_simulation < sim_bound and math.isfinite(c.chi_paper)]
        if not ratios:
            break
        last = candidates[-1]
        chi_bound = max(chi_bound or chi_req or 0.0, last.chi_paper * min(ratios))
        warnings.append(f"chi_simulation fell short where it has no derivative: the "
                        f"requirement on chi_paper raised to {chi_bound:.4g}")

    feasible = [c for c in candidates if c.feasible]
    sign = -1.0 if problem.goal == Goal.MAXIMIZE else 1.0
    if feasible:
        best = min(feasible, key=lambda c: sign * objective_of(c.values, c.chi))
        status = DesignStatus.FEASIBLE
        message = ("the design meets every requirement when re-checked by the full index"
                   + (" (the headline: both chi_paper and chi_simulation)" if sim else ""))
    else:
        pool = candidates or []
        best = min(pool, key=lambda c: (c.violation, sign * objective_of(c.values, c.chi)))
        status = DesignStatus.INFEASIBLE
        message = ("no design in the box meets the requirements; the best found "
                   f"misses them by {best.violation:.1%}")
    # the candidate's own evaluation is already the full index at these values
    final = cand_index[next(i for i, c in enumerate(candidates) if c is best)]
    active = _active(problem, best, final, chi_bound)
    return DesignResult(
        problem=problem, status=status,
        values=dict(zip(problem.names, map(float, best.values), strict=True)), index=final,
        objective=objective_of(best.values, final.chi), active=active,
        candidates=tuple(candidates), grid_values=np.array([problem.values(u) for u in U]),
        grid_chi=grid_chi, grid_shape=(n,) * d, iterations=total_its,
        evaluations=cache.count, seconds=time.perf_counter() - t0, message=message,
        warnings=tuple(warnings), margin_scale=margin_scale,
    )


def _grad_reqs(reqs: list[Requirement], chi_bound: float | None) -> tuple[Requirement, ...]:
    """The requirements on chi_paper and the margin (chi with the possibly raised bound), for
    ranking the start grid (which has chi_paper only)."""
    out = []
    for r in reqs:
        if r.quantity == Quantity.CHI_SIMULATION:
            continue
        if r.quantity == Quantity.CHI and chi_bound is not None:
            r = Requirement(Quantity.CHI, max(r.bound, chi_bound))
        out.append(r)
    if chi_bound is not None and not any(r.quantity == Quantity.CHI for r in out):
        out.append(Requirement(Quantity.CHI, chi_bound))
    return tuple(out)


def _constraints(reqs: Sequence[Requirement], chi_bound: float | None,
                 sim: bool) -> tuple[tuple[str, float], ...]:
    """The smooth constraints (part, bound) of the requirements: chi >= X is chi_paper >= X
    (or the raised bound) and, with the simulation, chi_simulation >= X (the headline is the
    smaller of the two); chi_simulation >= Z is the second alone; margin >= Y."""
    out: list[tuple[str, float]] = []
    for r in reqs:
        if r.quantity == Quantity.CHI:
            out.append(("paper", r.bound if chi_bound is None else max(r.bound, chi_bound)))
            if sim:
                out.append(("simulation", r.bound))
        elif r.quantity == Quantity.CHI_SIMULATION:
            if sim:
                out.append(("simulation", r.bound))
        else:
            out.append(("margin", r.bound))
    if chi_bound is not None and not any(r.quantity == Quantity.CHI for r in reqs):
        out.append(("paper", chi_bound))
    return tuple(out)


def _part_value(ev: Evaluation, part: str, margin_scale: float) -> float:
    if part == "margin":
        return ev.margin
    return _chi_ext(ev, margin_scale, part)


def _grad(ev: Evaluation, q: str, problem: DesignProblem,
          margin_scale: float) -> np.ndarray:
    """Gradient in the unit variables u of chi_paper ('paper'), chi_simulation
    ('simulation'), the headline ('headline', the smaller part's), their extension where
    unstable, or the margin ('margin')."""
    if ev.dchi is None or ev.dmargin is None:
        return np.zeros(len(problem.variables))
    if q == "headline":
        q = ("simulation" if ev.chi_simulation is not None and ev.chi_simulation < ev.chi_paper
             else "paper")
    if q == "margin":
        g = ev.dmargin
    elif ev.index.case == "unstable_equilibrium":
        g = ev.dmargin / margin_scale  # chi_ext = margin / margin_scale there
    elif q == "simulation":
        if ev.chi_simulation is None:
            g = ev.dchi
        elif ev.dchi_simulation is None:
            g = np.zeros(len(problem.variables))
        else:
            g = ev.dchi_simulation
    else:
        g = ev.dchi
    g = np.where(np.isfinite(g), g, 0.0)
    return g * problem.widths


def _polish(u: np.ndarray, cache: _Cache, problem: DesignProblem,
            cons: tuple[tuple[str, float], ...], margin_scale: float,
            rounds: int = 4) -> np.ndarray:
    """Move a point that misses a smooth constraint by a little onto its feasible side:
    Newton steps on the most violated one along its gradient, aiming 1e-7 (relative)
    inside, within the box."""
    for _ in range(rounds):
        ev = cache(u)
        worst = None
        for part, bound in cons:
            v = _part_value(ev, part, margin_scale)
            target = bound + 1e-7 * max(abs(bound), 1e-3)
            if v < bound and (worst is None or (bound - v) > worst[0]):
                worst = (bound - v, part, v, target)
        if worst is None:
            return u
        _, part, v, target = worst
        g = _grad(ev, part, problem, margin_scale)
        gg = float(g @ g)
        if gg == 0 or not math.isfinite(gg):
            return u
        u = np.clip(u + (target - v) * g / gg, 0.0, 1.0)
    return u


def _active(problem: DesignProblem, best: Candidate, index: MatchingIndex,
            chi_bound: float | None) -> tuple[str, ...]:
    out = []
    tol = 1e-4
    for r in problem.requirements:
        v = {Quantity.CHI: index.chi, Quantity.MARGIN: -index.max_real_part,
             Quantity.CHI_SIMULATION: index.chi_simulation}[r.quantity]
        if v is not None and math.isfinite(v) and abs(v - r.bound) <= tol * max(abs(r.bound), 1):
            out.append(str(r))
    if chi_bound is not None and not any(r.quantity == Quantity.CHI and r.bound == chi_bound
                                         for r in problem.requirements):
        if abs(index.chi - chi_bound) <= tol * max(abs(chi_bound), 1):
            out.append(f"chi >= {chi_bound:.4g} (raised for chi_simulation)")
    for var, val in zip(problem.variables, best.values, strict=True):
        w = var.hi - var.lo
        if abs(val - var.lo) <= 1e-6 * w:
            out.append(f"{var.name} = {var.lo:g} (lower bound)")
        elif abs(val - var.hi) <= 1e-6 * w:
            out.append(f"{var.name} = {var.hi:g} (upper bound)")
    return tuple(out)
