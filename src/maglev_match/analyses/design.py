"""The inverse problem: the cheapest beam or the best gains that meet requirements on the
headline matching index chi, the stability margin and chi_simulation.

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

The numerics (grid, starts, SLSQP, re-check) are model-agnostic through the small
:class:`Evaluator` interface; :class:`MaglevEvaluator` is the maglev models' (A and B).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from maglev_match.core.params import FIELD_NAMES, INTEGER_FIELDS, ParameterError, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.maglev.catalog import ModelInfo, model_info

if TYPE_CHECKING:  # the index and its sensitivities (and JAX) load when a design runs, so
    # that the parsers below answer a bad --vary or --require at once
    from maglev_match.analyses.matching import MatchingIndex
    from maglev_match.analyses.sensitivity import DerivativeStatus

__all__ = [
    "Goal",
    "Quantity",
    "DesignStatus",
    "Variable",
    "Requirement",
    "DesignProblem",
    "Evaluation",
    "DesignResult",
    "Evaluator",
    "MaglevEvaluator",
    "SystemEvaluator",
    "optimise_design",
    "parse_vary",
    "parse_requirement",
]


class Goal(StrEnum):
    MINIMIZE = "minimize"
    MAXIMIZE = "maximize"


class Quantity(StrEnum):
    """What a requirement bounds from below."""

    CHI = "chi"
    MARGIN = "margin"  # -max Re lambda (1/s)
    CHI_SIMULATION = "chi_simulation"


class DesignStatus(StrEnum):
    FEASIBLE = "feasible"  # the returned design meets every requirement when re-checked
    INFEASIBLE = "infeasible"  # none found that does: the best found is returned


@dataclass(frozen=True)
class Variable:
    """A varied parameter and its bounds (SI units)."""

    name: str
    lo: float
    hi: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.lo < self.hi):
            raise ParameterError(f"--vary {self.name}", f"{self.lo}:{self.hi}",
                                 "expected LO:HI with finite LO < HI")


@dataclass(frozen=True)
class Requirement:
    """quantity >= bound."""

    quantity: Quantity
    bound: float

    def __str__(self) -> str:
        return f"{self.quantity} >= {self.bound:g}"


@dataclass(frozen=True)
class DesignProblem:
    """What to vary, what to optimise and what to require."""

    variables: tuple[Variable, ...]
    goal: Goal
    objective: str  # a varied parameter's name (minimise) or "chi" (maximise)
    requirements: tuple[Requirement, ...] = ()

    def __post_init__(self) -> None:
        names = [v.name for v in self.variables]
        if not names:
            raise ParameterError("--vary", None, "give at least one NAME=LO:HI")
        if len(set(names)) != len(names):
            raise ParameterError("--vary", ",".join(names), "each parameter at most once")
        if self.goal == Goal.MAXIMIZE and self.objective != "chi":
            raise ParameterError("--maximize", self.objective, "only chi can be maximised")
        if self.goal == Goal.MINIMIZE and self.objective not in names:
            raise ParameterError("--minimize", self.objective,
                                 f"must be one of the varied parameters ({', '.join(names)})")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.variables)

    def values(self, u: np.ndarray) -> np.ndarray:
        lo = np.array([v.lo for v in self.variables])
        hi = np.array([v.hi for v in self.variables])
        return lo + np.clip(u, 0.0, 1.0) * (hi - lo)

    def unit(self, values: np.ndarray) -> np.ndarray:
        lo = np.array([v.lo for v in self.variables])
        hi = np.array([v.hi for v in self.variables])
        return (np.asarray(values, float) - lo) / (hi - lo)

    @property
    def widths(self) -> np.ndarray:
        return np.array([v.hi - v.lo for v in self.variables])

    @property
    def needs_simulation(self) -> bool:
        return any(r.quantity == Quantity.CHI_SIMULATION for r in self.requirements)


@dataclass(frozen=True)
class Evaluation:
    """The headline chi, its parts, the margin and their gradients (per unit of each varied
    parameter) at one point. ``dchi`` is the gradient of chi_paper (the paper's
    definition, ``chi_paper``); ``dchi_simulation`` that of chi_simulation (None where the
    simulation was not run or its critical size has no derivative)."""

    values: np.ndarray
    chi: float
    margin: float  # -max Re lambda (1/s)
    dchi: np.ndarray | None
    dmargin: np.ndarray | None
    status: DerivativeStatus | None
    index: MatchingIndex
    seconds: float = 0.0
    chi_paper: float = float("nan")
    chi_simulation: float | None = None
    dchi_simulation: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return math.isfinite(self.chi)


class Evaluator(Protocol):
    """What the optimiser needs from a model: the index (with gradients on request) at a
    point given by the varied parameters' values, and a full re-check."""

    def evaluate(self, values: np.ndarray, gradient: bool) -> Evaluation: ...

    def recheck(self, values: np.ndarray, simulate: bool) -> MatchingIndex: ...


class MaglevEvaluator:
    """Model A (``model`` 'unit') or the vehicle ('vehicle') at ``base`` with the parameters
    ``names`` set to the given values; ``simulate`` (default) makes every evaluation the
    full headline index (the simulated critical disturbance solved, with its derivative),
    False the paper's chi alone (``--no-simulation``)."""

    def __init__(self, base: Params, names: Sequence[str], model: str = "unit",
                 simulate: bool = True):
        for n in names:
            if n not in FIELD_NAMES:
                raise ParameterError("--vary", n, "unknown parameter")
        self.info = model_info(model, "--model")
        self.base = base
        self.names = tuple(names)
        self.model = self.info.name
        self.simulate = bool(simulate)

    def params(self, values: np.ndarray) -> Params:
        return self.base.replace(**{n: float(v) for n, v in zip(self.names, values,
                                                                strict=True)})

    def evaluate(self, values: np.ndarray, gradient: bool) -> Evaluation:
        from maglev_match.analyses.matching import matching_index
        from maglev_match.analyses.sensitivity import index_sensitivity

        t = time.perf_counter()
        p = self.params(values)
        idx = matching_index(p, model=self.model, simulate=self.simulate)
        dchi = dmargin = dsim = None
        status = None
        if gradient:
            sens = index_sensitivity(p, idx, boundaries=False, model=self.model)
            status = sens.status
            dchi = np.array([_row(sens, n, "dchi_paper", self.info) for n in self.names])
            dmargin = np.array([_row(sens, n, "dmargin", self.info) for n in self.names])
            rows = [sens.row(n) if n in sens._by_name else None for n in self.names]
            if all(r is not None and r.dchi_simulation is not None for r in rows):
                dsim = np.array([r.dchi_simulation for r in rows])
        return Evaluation(np.asarray(values, float), idx.chi, -idx.max_real_part, dchi,
                          dmargin, status, idx, time.perf_counter() - t,
                          chi_paper=idx.chi_paper, chi_simulation=idx.chi_simulation,
                          dchi_simulation=dsim)

    def recheck(self, values: np.ndarray, simulate: bool) -> MatchingIndex:
        from maglev_match.analyses.matching import matching_index

        return matching_index(self.params(values), model=self.model,
                              simulate=simulate and self.simulate)

    def scan(self, problem: DesignProblem, n: int) -> tuple[np.ndarray, np.ndarray] | None:
        """chi and the margin on the start grid (``n`` points per varied parameter, in the
        order of :func:`_grid`) by the design map's rows: one equilibrium scan and one cycle
        continuation per Hopf point along each row (:func:`maglev_match.analyses.maps.compute_row`)
        instead of a full index per point. Only for ranking starts: each start is then
        evaluated by the full index. Model A with one or two varied parameters; None
        otherwise (the caller falls back to full indices)."""
        from maglev_match.analyses.maps import MAP_MODELS, Axis, MapSpec, compute_row

        d = len(problem.variables)
        if self.model not in MAP_MODELS or d > 2:
            return None
        from maglev_match.analyses.matching import cycle_settings

        v = problem.variables
        x = Axis(v[0].name, v[0].lo, v[0].hi, n)
        # one varied parameter: a single row (the y "axis" holds gap_max at its value)
        y = (Axis(v[1].name, v[1].lo, v[1].hi, n) if d == 2
             else Axis("gap_max", self.base.gap_max, self.base.gap_max, 1))
        spec = MapSpec(base=self.base.as_input_dict(), x=x, y=y, ntst=cycle_settings.ntst,
                       ncol=cycle_settings.ncol, max_steps=cycle_settings.max_steps)
        rows = [compute_row(spec, r) for r in range(y.count)]
        chi = np.array([r["chi"] for r in rows]).T.reshape(-1)  # x outer, y inner
        margin = -np.array([r["max_real_part"] for r in rows]).T.reshape(-1)
        return chi, margin


def _row(sens, name: str, attr: str, info: ModelInfo) -> float:
    """A derivative by a varied parameter; a derivable value (omega1, sigma) that is varied
    becomes explicit, so it has its own row."""
    try:
        return float(getattr(sens.row(name), attr))
    except KeyError:
        raise ParameterError("--vary", name,
                             f"not a parameter of {info.short}'s index") from None


class SystemEvaluator:
    """Any :class:`~maglev_match.dynamics.system.System` through
    :func:`~maglev_match.analyses.matching.index_of_system` (used for problems with known answers).

    ``make`` maps the varied values to (system, w0, h_max, search, limits)."""

    def __init__(self, names: Sequence[str], make: Callable[[np.ndarray], tuple]):
        self.names = tuple(names)
        self.make = make

    def evaluate(self, values: np.ndarray, gradient: bool) -> Evaluation:
        from maglev_match.analyses.matching import index_of_system
        from maglev_match.analyses.sensitivity import DerivativeStatus, system_sensitivity

        t = time.perf_counter()
        system, w0, h_max, search, limits = self.make(np.asarray(values, float))
        idx = index_of_system(system, system.p, w0=w0, h_max=h_max, search=search,
                              limits=limits)
        dchi = dmargin = None
        status = None
        if gradient:
            s = system_sensitivity(system, idx)
            status = s.h_status
            k = [system.param_index(n) for n in self.names]
            dchi = s.dh_dp[k] / w0 if status != DerivativeStatus.ZERO else np.zeros(len(k))
            dmargin = -s.dmax_re_dp[k]
        return Evaluation(np.asarray(values, float), idx.chi, -idx.max_real_part, dchi,
                          dmargin, status, idx, time.perf_counter() - t,
                          chi_paper=idx.chi_paper)

    def recheck(self, values: np.ndarray, simulate: bool) -> MatchingIndex:
        return self.evaluate(values, gradient=False).index


@dataclass(frozen=True)
class Candidate:
    """One optimiser run from one start, re-checked."""

    start: np.ndarray
    values: np.ndarray
    chi: float
    margin: float
    chi_simulation: float | None
    feasible: bool
    violation: float  # largest relative shortfall of a requirement (0 if feasible)
    iterations: int
    evaluations: int
    message: str
    path: np.ndarray  # (k, d) the iterates in parameter units
    path_chi: np.ndarray  # (k,) chi at the iterates
    chi_paper: float = float("nan")  # the paper's chi at the candidate


@dataclass(frozen=True)
class DesignResult(Plottable):
    """The design, its full index, active constraints and how it was found."""

    __repr__ = compact_repr

    problem: DesignProblem
    status: DesignStatus
    values: dict[str, float]
    index: MatchingIndex
    objective: float
    active: tuple[str, ...]  # requirements and bounds active at the design
    candidates: tuple[Candidate, ...]
    grid_values: np.ndarray  # (n_grid, d)
    grid_chi: np.ndarray  # (n_grid,)
    grid_shape: tuple[int, ...]
    iterations: int  # SLSQP iterations, all starts
    evaluations: int  # index evaluations, all kinds
    seconds: float
    message: str = ""
    warnings: tuple[str, ...] = ()
    margin_scale: float = field(default=1.0, repr=False)

    def as_json(self) -> dict[str, Any]:
        return {
            "status": str(self.status), "design": self.values, "objective": self.objective,
            "goal": str(self.problem.goal), "objective_name": self.problem.objective,
            "requirements": [str(r) for r in self.problem.requirements],
            "active": list(self.active), "index": self.index.as_json(),
            "iterations": self.iterations, "evaluations": self.evaluations,
            "seconds": self.seconds, "message": self.message,
            "candidates": [
                {"start": dict(zip(self.problem.names, c.start.tolist(), strict=True)),
                 "design": dict(zip(self.problem.names, c.values.tolist(), strict=True)),
                 "chi": c.chi, "chi_paper": c.chi_paper, "margin": c.margin,
                 "chi_simulation": c.chi_simulation,
                 "feasible": c.feasible, "violation": c.violation,
                 "iterations": c.iterations, "message": c.message}
                for c in self.candidates
            ],
            "warnings": list(self.warnings),
        }


# ---------------------------------------------------------------------------------------
# parsing
# ---------------------------------------------------------------------------------------
#: Parameters that are no design choice: a design varies the beam, the vehicle, the magnets
#: or the controller, never the constants of nature.
NOT_DESIGN_PARAMETERS: dict[str, str] = {
    "g": "gravity is a constant of nature, not a design choice",
    "mu0": "the vacuum permeability is a constant of nature, not a design choice",
}
#: Quantities that follow from parameters (what to vary instead).
DERIVED_QUANTITIES: dict[str, str] = {
    "i0": "the levitation current follows from m, M, g, N, A and c0: vary those",
    "w0": "the static deflection follows from sigma, m, M, g and omega1: vary the beam "
          "(EI, mbar, L) or the vehicle",
    "chi": "chi is the result: use --maximize chi or --require chi>=X",
    "h": "h is part of the result chi = h / w0",
}
#: Smallest static deflection w0 (m) a design may reach. chi = h / w0 with h at most
#: gap_max - c0 (10 mm by default): below 10 micrometres chi exceeds 1000, a number no beam
#: measurement can support (the paper's beams have w0 ~ 0.8 mm); a tiny sigma once gave
#: chi = 5.7e297.
W0_MIN = 1e-5


def parse_vary(text: str) -> Variable:
    """``NAME=LO:HI`` -> :class:`Variable`; the name must be a design parameter (not a
    constant of nature such as g or mu0, nor a derived quantity such as w0 or i0)."""
    if "=" not in text or ":" not in text:
        raise ParameterError("--vary", text, "expected NAME=LO:HI, e.g. EI=5e9:4e10")
    name, rng = (s.strip() for s in text.split("=", 1))
    if name in NOT_DESIGN_PARAMETERS:
        raise ParameterError("--vary", name, NOT_DESIGN_PARAMETERS[name])
    if name in DERIVED_QUANTITIES:
        raise ParameterError("--vary", name, f"is derived, not a parameter: "
                             f"{DERIVED_QUANTITIES[name]}")
    if name not in FIELD_NAMES:
        raise ParameterError("--vary", name, "unknown parameter")
    if name in INTEGER_FIELDS:
        raise ParameterError("--vary", name, "a whole-number parameter cannot be varied "
                             "continuously")
    try:
        lo, hi = (float(s) for s in rng.split(":"))
    except ValueError:
        raise ParameterError("--vary", text, "expected NAME=LO:HI with numbers") from None
    return Variable(name, lo, hi)


def _samples(var: Variable, n: int = 17) -> np.ndarray:
    if var.lo > 0:
        return np.geomspace(var.lo, var.hi, n)
    return np.linspace(var.lo, var.hi, n)


def check_vary_ranges(base: Params, variables: Sequence[Variable], field: str = "--vary"
                      ) -> None:
    """Refuse, before any index is computed, ranges that contain invalid parameter sets or
    designs whose static deflection w0 falls below :data:`W0_MIN` (where chi = h / w0 is
    meaningless). Sampled: every corner of the box, and 17 points along each range with the
    other variables at the base values (w0 is monotone in sigma, omega1, EI, m, M; the
    samples catch the rest, e.g. L through sin^2 in sigma). ``field`` names the ranges in
    the message (``--vary`` on the command line, ``vary`` in the API)."""
    names = [v.name for v in variables]
    points = [dict(zip(names, c, strict=True))
              for c in itertools.product(*[(v.lo, v.hi) for v in variables])]
    for v in variables:
        points += [{v.name: float(x)} for x in _samples(v)]
    for pt in points:
        where = ", ".join(f"{k} = {x:.6g}" for k, x in pt.items())
        try:
            p = base.replace(**pt)
        except ParameterError as exc:
            raise ParameterError(f"{field} {' '.join(names)}", where,
                                 f"this point of the ranges is not a valid parameter set "
                                 f"({exc}); narrow the ranges") from None
        w0 = p.w0
        if not w0 >= W0_MIN:
            chi_max = (p.gap_max - p.c0) / w0 if w0 > 0 else math.inf
            raise ParameterError(
                f"{field} {' '.join(names)}", where,
                f"the static deflection w0 = {w0:.3g} m there is below {W0_MIN:g} m, where "
                f"chi = h / w0 (up to {chi_max:.3g}) has no physical meaning; narrow the "
                "ranges")


def parse_requirement(text: str) -> Requirement:
    """``chi>=5``, ``margin>=0.5``, ``chi_simulation>=3`` -> :class:`Requirement`."""
    if ">=" not in text:
        raise ParameterError("--require", text, "expected QUANTITY>=VALUE, e.g. chi>=5")
    name, raw = (s.strip() for s in text.split(">=", 1))
    try:
        q = Quantity(name)
    except ValueError:
        raise ParameterError("--require", name,
                             "must be one of " + ", ".join(q.value for q in Quantity)) from None
    try:
        bound = float(raw)
    except ValueError:
        raise ParameterError("--require", text, "the bound must be a number") from None
    if not math.isfinite(bound):
        raise ParameterError("--require", text, "the bound must be finite")
    return Requirement(q, bound)


def refuse_switched_off(reqs: Sequence[Requirement], texts: Sequence[str], simulate: bool,
                        option: str, switch: str) -> None:
    """A requirement on chi_simulation while the simulation is switched off (``switch``:
    the option or argument that did it) is a usage error naming both."""
    if simulate:
        return
    for r, text in zip(reqs, texts, strict=True):
        if r.quantity == Quantity.CHI_SIMULATION:
            raise ParameterError(f"{option} {text}", switch, "chi_simulation is switched off "
                                 f"by {switch}: drop one of the two")


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
