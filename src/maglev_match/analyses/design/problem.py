"""The design problem and what it is evaluated on: the varied parameters with their bounds
(:class:`Variable`), the goal and the requirements on the headline index chi, the margin
and chi_simulation (:class:`Requirement`, :class:`DesignProblem`), the index and its exact
gradients at one point (:class:`Evaluation`) from a model through the small
:class:`Evaluator` interface (:class:`MaglevEvaluator` for the maglev models A and B,
:class:`SystemEvaluator` for any :class:`~maglev_match.dynamics.system.System`), the
result (:class:`Candidate`, :class:`DesignResult`), and the parsing and checks of
``--vary NAME=LO:HI`` and ``--require QUANTITY>=VALUE``.

The gradients are those of :mod:`maglev_match.analyses.sensitivity`; the optimiser that
solves the problem is :mod:`maglev_match.analyses.design.optimise`. Importing this module
loads neither JAX nor SciPy, so that the parsers answer a bad --vary or --require at once.
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
    from maglev_match.analyses.sensitivity.status import DerivativeStatus

__all__ = [
    "Goal",
    "Quantity",
    "DesignStatus",
    "Variable",
    "Requirement",
    "DesignProblem",
    "Evaluation",
    "DesignResult",
    "Candidate",
    "Evaluator",
    "MaglevEvaluator",
    "SystemEvaluator",
    "parse_vary",
    "parse_requirement",
    "check_vary_ranges",
    "refuse_switched_off",
    "NOT_DESIGN_PARAMETERS",
    "DERIVED_QUANTITIES",
    "W0_MIN",
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


#: an evaluation continues the critical disturbances of the previous one when no varied
#: parameter moved by more than this fraction of its previous value
NEAR_STEP = 0.05


class MaglevEvaluator:
    """Model A (``model`` 'unit') or the vehicle ('vehicle') at ``base`` with the parameters
    ``names`` set to the given values; ``simulate`` (default) makes every evaluation the
    full headline index (the simulated critical disturbance solved, with its derivative),
    False the paper's chi alone (``--no-simulation``).

    An evaluation within :data:`NEAR_STEP` of the previous one (every varied parameter)
    continues that one's solved critical disturbances instead of searching them again
    (``matching_index(..., near=previous)``: Newton on the same condition, two check runs;
    the full search where that does not hold). The re-check (:meth:`recheck`) is always
    the full point-wise index."""

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
        self._last: tuple[np.ndarray, MatchingIndex] | None = None

    def _near(self, values: np.ndarray) -> MatchingIndex | None:
        """The previous evaluation's index when it is a neighbouring design."""
        if not self.simulate or self._last is None:
            return None
        prev, idx = self._last
        step = np.abs(np.asarray(values, float) - prev)
        return idx if np.all(step <= NEAR_STEP * np.abs(prev)) else None

    def params(self, values: np.ndarray) -> Params:
        return self.base.replace(**{n: float(v) for n, v in zip(self.names, values,
                                                                strict=True)})

    def evaluate(self, values: np.ndarray, gradient: bool) -> Evaluation:
        from maglev_match.analyses.matching import matching_index
        from maglev_match.analyses.sensitivity.index import index_sensitivity

        t = time.perf_counter()
        p = self.params(values)
        idx = matching_index(p, model=self.model, simulate=self.simulate,
                             near=self._near(values))
        if self.simulate:
            self._last = (np.array(values, float), idx)
        dchi = dmargin = dsim = None
        status = None
        if gradient:
            sens = index_sensitivity(p, idx, boundaries=False, model=self.model)
            status = sens.status
            dchi = np.array([_row(sens, n, "dchi_paper", self.info) for n in self.names])
            dmargin = np.array([_row(sens, n, "dmargin", self.info) for n in self.names])
            rows = [sens.row(n) if sens.has_row(n) else None for n in self.names]
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
        order the optimiser, :mod:`maglev_match.analyses.design.optimise`, lays it out) by
        the design map's rows: one equilibrium scan and one cycle
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
        from maglev_match.analyses.sensitivity.cycle import system_sensitivity
        from maglev_match.analyses.sensitivity.status import DerivativeStatus

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

    def to_xarray(self) -> Any:
        """The search as an :class:`xarray.Dataset`. The best point: ``design`` (the varied
        parameters' values) over ``variable``, with ``lower_bound``, ``upper_bound`` and
        ``variable_unit``, the 0-d ``objective`` and the design's index ``chi``,
        ``chi_paper``, ``chi_simulation``, ``h``, ``w0``, ``max_real_part``. The optimiser's
        path: ``path`` over (``candidate``, ``iteration``, ``variable``) and ``path_chi``
        over (``candidate``, ``iteration``), padded with NaN after each run's
        ``path_length``; each run's ``start``, ``candidate_design``, ``candidate_chi``,
        ``candidate_chi_paper``, ``candidate_chi_simulation``, ``candidate_margin``,
        ``candidate_feasible``, ``candidate_violation``, ``candidate_iterations`` and
        ``candidate_evaluations``. The coarse start grid: ``grid_value`` over
        (``grid_point``, ``variable``) and ``grid_chi``. Status, goal, requirements, active
        constraints, counts, messages and warnings are attributes (lists as JSON)."""
        import json

        import xarray as xr

        from maglev_match.core.datasets import annotate
        from maglev_match.core.params import PARAMETER_DOCS

        names = list(self.problem.names)
        cands = self.candidates
        d = len(names)
        k_max = max((len(c.path) for c in cands), default=0)
        path = np.full((len(cands), k_max, d), np.nan)
        path_chi = np.full((len(cands), k_max), np.nan)
        for j, c in enumerate(cands):
            k = len(c.path)
            path[j, :k] = np.asarray(c.path, float).reshape(k, d)
            path_chi[j, :k] = np.asarray(c.path_chi, float)

        def num(v: Any) -> float:
            return float("nan") if v is None else float(v)

        def per_candidate(name: str, dtype: Any = float) -> np.ndarray:
            if dtype is float:
                return np.array([num(getattr(c, name)) for c in cands], float)
            return np.array([getattr(c, name) for c in cands], dtype)

        units = {n: PARAMETER_DOCS.get(n, ("",))[0] for n in names}
        obj = self.problem.objective
        ix = self.index
        data: dict[str, Any] = {
            "design": ("variable", np.array([self.values[n] for n in names], float)),
            "lower_bound": ("variable", np.array([v.lo for v in self.problem.variables])),
            "upper_bound": ("variable", np.array([v.hi for v in self.problem.variables])),
            "variable_unit": ("variable", np.array([units[n] for n in names], dtype=str)),
            "objective": ((), float(self.objective)),
            "chi": ((), num(ix.chi)), "chi_paper": ((), num(ix.chi_paper)),
            "chi_simulation": ((), num(ix.chi_simulation)), "h": ((), num(ix.h)),
            "w0": ((), num(ix.w0)), "max_real_part": ((), num(ix.max_real_part)),
            "path": (("candidate", "iteration", "variable"), path),
            "path_chi": (("candidate", "iteration"), path_chi),
            "path_length": ("candidate", np.array([len(c.path) for c in cands], np.int64)),
            "start": (("candidate", "variable"),
                      np.array([c.start for c in cands], float).reshape(len(cands), d)),
            "candidate_design": (("candidate", "variable"),
                                 np.array([c.values for c in cands], float).reshape(
                                     len(cands), d)),
            "candidate_chi": ("candidate", per_candidate("chi")),
            "candidate_chi_paper": ("candidate", per_candidate("chi_paper")),
            "candidate_chi_simulation": ("candidate", per_candidate("chi_simulation")),
            "candidate_margin": ("candidate", per_candidate("margin")),
            "candidate_feasible": ("candidate", per_candidate("feasible", np.int8)),
            "candidate_violation": ("candidate", per_candidate("violation")),
            "candidate_iterations": ("candidate", per_candidate("iterations", np.int64)),
            "candidate_evaluations": ("candidate", per_candidate("evaluations", np.int64)),
            "grid_value": (("grid_point", "variable"),
                           np.asarray(self.grid_values, float).reshape(-1, d)),
            "grid_chi": ("grid_point", np.asarray(self.grid_chi, float)),
        }
        coords = {"variable": ("variable", names),
                  "candidate": ("candidate", np.arange(1, len(cands) + 1)),
                  "iteration": ("iteration", np.arange(k_max)),
                  "grid_point": ("grid_point", np.arange(len(self.grid_chi)))}
        see = "SI (see variable_unit)"
        docs = {  # name: (units, long name)
            "design": (see, "the design: value of each varied parameter"),
            "lower_bound": (see, "lower bound of the varied parameter"),
            "upper_bound": (see, "upper bound of the varied parameter"),
            "variable_unit": ("1", "SI unit of the varied parameter"),
            "objective": ("1" if obj == "chi" else units.get(obj, ""),
                          f"objective ({self.problem.goal} {obj}) at the design"),
            "chi_paper": ("1", "the paper's chi at the design"),
            "chi_simulation": ("1", "chi_simulation at the design (NaN: not simulated)"),
            "path": (see, "optimiser iterates"),
            "path_chi": ("1", "chi at the optimiser iterates"),
            "path_length": ("1", "iterates of the run"),
            "start": (see, "start of the run (from the coarse grid)"),
            "candidate_design": (see, "the run's end point, re-checked"),
            "candidate_chi": ("1", "headline chi of the run's end point"),
            "candidate_chi_paper": ("1", "the paper's chi of the run's end point"),
            "candidate_chi_simulation": ("1", "chi_simulation of the run's end point"),
            "candidate_margin": ("1/s", "stability margin of the run's end point"),
            "candidate_feasible": ("1", "the run's end point meets every requirement (1) "
                                        "or not (0)"),
            "candidate_violation": ("1", "largest relative shortfall of a requirement"),
            "candidate_iterations": ("1", "optimiser iterations of the run"),
            "candidate_evaluations": ("1", "index evaluations of the run"),
            "grid_value": (see, "coarse start grid point"),
            "grid_chi": ("1", "chi on the coarse start grid"),
            "variable": ("1", "varied parameter"),
            "candidate": ("1", "optimiser run (1-based)"),
            "iteration": ("1", "iterate number"),
            "grid_point": ("1", "coarse grid point number"),
        }
        ds = xr.Dataset(data, coords=coords, attrs={
            "title": "maglev-match design search",
            "status": str(self.status), "goal": str(self.problem.goal),
            "objective_name": obj,
            "requirements": json.dumps([str(r) for r in self.problem.requirements]),
            "active": json.dumps(list(self.active)), "iterations": int(self.iterations),
            "evaluations": int(self.evaluations), "seconds": float(self.seconds),
            "grid_shape": json.dumps(list(self.grid_shape)), "message": self.message,
            "candidate_messages": json.dumps([c.message for c in cands]),
            "case": str(ix.case), "reading": ix.reading,
            "warnings": json.dumps(list(self.warnings))})
        return annotate(ds, units={k: u for k, (u, _) in docs.items()},
                        long_names={k: n for k, (_, n) in docs.items()})


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


def check_varied_name(field: str, name: str) -> None:
    """A ParameterError (naming ``field``) unless ``name`` is a parameter a design can vary
    continuously: not a constant of nature, not a derived quantity, a known field, not a
    whole number."""
    if name in NOT_DESIGN_PARAMETERS:
        raise ParameterError(field, name, NOT_DESIGN_PARAMETERS[name])
    if name in DERIVED_QUANTITIES:
        raise ParameterError(field, name, f"is derived, not a parameter: "
                             f"{DERIVED_QUANTITIES[name]}")
    if name not in FIELD_NAMES:
        raise ParameterError(field, name, "unknown parameter")
    if name in INTEGER_FIELDS:
        raise ParameterError(field, name, "a whole-number parameter cannot be varied "
                             "continuously")


def parse_vary(text: str) -> Variable:
    """``NAME=LO:HI`` -> :class:`Variable`; the name must be a design parameter (not a
    constant of nature such as g or mu0, nor a derived quantity such as w0 or i0)."""
    if "=" not in text or ":" not in text:
        raise ParameterError("--vary", text, "expected NAME=LO:HI, e.g. EI=5e9:4e10")
    name, rng = (s.strip() for s in text.split("=", 1))
    check_varied_name("--vary", name)
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
