"""The inverse problem: the cheapest beam or the best gains that meet requirements on the
headline matching index chi, the stability margin and chi_simulation.

Two modules:

* :mod:`~maglev_match.analyses.design.problem`: what is solved and on what: the varied
  parameters, the goal and the requirements (:class:`DesignProblem`), the evaluators of the
  index and its exact gradients (:class:`MaglevEvaluator` for the maglev models,
  :class:`SystemEvaluator` for any System), the result (:class:`DesignResult`) and the
  parsing and checks of ``--vary`` and ``--require``; light (no JAX, no SciPy);
* :mod:`~maglev_match.analyses.design.optimise`: how it is solved (:func:`optimise_design`):
  a coarse start grid, SLSQP with the exact gradients of
  :mod:`maglev_match.analyses.sensitivity` from its best points, the smooth constraints,
  the polish onto the feasible side and the re-check of every candidate by the full index.

Every public name is re-exported here, so ``maglev_match.analyses.design.NAME`` keeps
working.
"""

from __future__ import annotations

from maglev_match.analyses.design.optimise import optimise_design
from maglev_match.analyses.design.problem import (
    DERIVED_QUANTITIES,  # noqa: F401  (re-exported)
    NOT_DESIGN_PARAMETERS,  # noqa: F401  (re-exported)
    W0_MIN,  # noqa: F401  (re-exported)
    Candidate,  # noqa: F401  (re-exported)
    DesignProblem,
    DesignResult,
    DesignStatus,
    Evaluation,
    Evaluator,
    Goal,
    MaglevEvaluator,
    Quantity,
    Requirement,
    SystemEvaluator,
    Variable,
    check_varied_name,  # noqa: F401  (re-exported)
    check_vary_ranges,  # noqa: F401  (re-exported)
    parse_requirement,
    parse_vary,
    refuse_switched_off,  # noqa: F401  (re-exported)
)

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
