"""The inverse problem: the cheapest beam or the best gains meeting requirements on the
headline index (`maglev-match design`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.api.compat import deprecated
from maglev_match.api.inputs import resolve_params
from maglev_match.api.progress import reported
from maglev_match.core.params import ParameterError, Params
from maglev_match.maglev.catalog import model_info

if TYPE_CHECKING:  # pragma: no cover
    from maglev_match.analyses.design import DesignResult

__all__ = ['design_search', 'check_requirements']


@reported("design", units=False)
def design_search(params: Params | str | None = None, *,
                  vary: Mapping[str, tuple[float, float]] | Sequence[str],
                  minimize: str | None = None, maximize: str | None = None,
                  require: Mapping[str, float] | Sequence[str] = (), model: str = "unit",
                  grid: int | None = None, starts: int = 2, simulate: bool = True,
                  stage: Callable[[str], None] | None = None,
                  config: str | Path | None = None,
                  progress: Callable[[str], None] | None = None,
                  **overrides: Any) -> DesignResult:
    """The cheapest design, or the one with the largest chi, meeting requirements
    (`maglev-match design`): SLSQP on exact gradients from several grid starts (Nocedal &
    Wright 2006, ch. 18), every candidate re-checked by the full index.

    Parameters
    ----------
    params : Params | str | None
        The base parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    vary : mapping or sequence of str
        `{name: (low, high)}` of the varied parameters, e.g. `{"EI": (5e9, 4e10)}`, or
        their command-line form `["EI=5e9:4e10"]`.
    minimize, maximize : str
        Exactly one: a varied parameter to make as small as possible, or `"chi"`.
    require : mapping or sequence of str
        Lower bounds, `{"chi": 5, "margin": 0.5}` or `["chi>=5", "margin>=0.5"]`
        (chi, margin (1/s), chi_simulation).
    model : str
        `"unit"` or `"vehicle"`.
    grid, starts : int
        Start-grid points per varied parameter (default 9 for one, 5 for two) and
        optimiser runs.
    simulate : bool
        Constrain the headline index (default: both chi_paper and chi_simulation meet a
        requirement on chi); False: the paper's chi only (`--no-simulation`).
    stage : callable, optional
        Called with a line of text at each stage (as in every API function; the earlier
        name ``progress`` still works and warns).
    config : str or Path, optional
        A TOML file applied on top of the preset.
    **overrides : float
        Parameter values applied on top of the base.

    Returns
    -------
    DesignResult
        See `maglev_match.analyses.design.DesignResult`; `.plot()` draws the search.
    """
    from maglev_match.analyses.design import MaglevEvaluator, optimise_design

    if progress is not None:
        deprecated("design_search(progress=...)", "design_search(stage=...)")
        stage = stage or progress
    problem, base = design_problem(params, vary=vary, minimize=minimize, maximize=maximize,
                                   require=require, simulate=simulate, starts=starts,
                                   grid=grid, config=config, **overrides)
    evaluator = MaglevEvaluator(base, problem.names, model=model_info(model).name,
                                simulate=simulate)
    return optimise_design(problem, evaluator, grid=grid, starts=starts, progress=stage)


def check_requirements(require: Mapping[str, float] | Sequence[str] = (), *,
                       simulate: bool = True, field: str = "require",
                       switch: str = "simulate=False") -> tuple:
    """The requirements of a design, parsed and checked: ``{"chi": 5}`` or ``["chi>=5"]``
    (chi, margin in 1/s, chi_simulation); a requirement on chi_simulation while the
    simulation is switched off (``switch`` names what switched it off) is refused, naming
    both (``field`` names the requirements)."""
    from maglev_match.analyses.design import parse_requirement, refuse_switched_off

    texts = ([f"{k}>={float(v)!r}" for k, v in require.items()]
             if isinstance(require, Mapping) else list(require))
    reqs = tuple(parse_requirement(r) for r in texts)
    refuse_switched_off(reqs, texts, simulate, field, switch)
    return reqs


def design_problem(params: Params | str | None = None, *,
                   vary: Mapping[str, tuple[float, float]] | Sequence[str],
                   minimize: str | None = None, maximize: str | None = None,
                   require: Mapping[str, float] | Sequence[str] = (), simulate: bool = True,
                   starts: int = 2, grid: int | None = None, config: str | Path | None = None,
                   **overrides: Any) -> tuple[Any, Params]:
    """A design search's problem and base parameter set, checked before any work (what
    :func:`design_search` does first): the varied parameters and their ranges (valid
    parameter sets with a meaningful chi throughout), exactly one goal, the requirements,
    the counts of the search. Returns (the :class:`~maglev_match.analyses.design.
    DesignProblem`, the base :class:`Params`)."""
    from maglev_match.analyses.design import DesignProblem, Goal, check_vary_ranges, parse_vary

    if (minimize is None) == (maximize is None):
        raise ParameterError("minimize/maximize", minimize or maximize,
                             "give exactly one of them")
    if not vary:
        raise ParameterError("vary", vary, "give at least one parameter range")
    if isinstance(vary, Mapping):
        variables = tuple(parse_vary(f"{n}={float(lo)!r}:{float(hi)!r}")
                          for n, (lo, hi) in dict(vary).items())
    else:  # the command line's NAME=LO:HI
        variables = tuple(parse_vary(str(v)) for v in vary)
    reqs = check_requirements(require, simulate=simulate)
    if starts < 1:
        raise ParameterError("starts", starts, "must be at least 1")
    if grid is not None and grid < 2:
        raise ParameterError("grid", grid, "must be at least 2")
    goal = Goal.MINIMIZE if minimize is not None else Goal.MAXIMIZE
    problem = DesignProblem(variables, goal, minimize or maximize or "", reqs)
    base = resolve_params(params, config=config, **overrides)
    for var in variables:  # both ends must be valid parameter values
        base.replace(**{var.name: var.lo})
        base.replace(**{var.name: var.hi})
    check_vary_ranges(base, variables, "vary")  # valid sets with a meaningful chi throughout
    if not base.w0 > 0:
        raise ParameterError("sigma", base.sigma, "must be > 0 for the index: chi = h / w0 "
                             f"needs a beam deflection w0 > 0 (w0 = {base.w0:g} m)")
    return problem, base
