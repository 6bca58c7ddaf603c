"""Exact sensitivities of the matching index chi = h / w0, of the stability margin and of the
Hopf point, with respect to every parameter (no finite differences), and the spread of chi
under parameter scatter.

The package is organised by subject, each layer built on the one before:

* :mod:`~maglev_match.analyses.sensitivity.status`: :class:`DerivativeStatus`, how a
  derivative was obtained;
* :mod:`~maglev_match.analyses.sensitivity.cycle`: derivatives at one point of a
  :class:`~maglev_match.dynamics.system.System`, by implicit differentiation of the
  converged cycle's collocation system (d h / d p), eigenvalue perturbation (the margin)
  and the Hopf defining system (:func:`system_sensitivity`, :func:`margin_derivative`,
  :func:`hopf_derivative`);
* :mod:`~maglev_match.analyses.sensitivity.limits`: the extremes of the gap deviation over
  the cycle branch and its contacts with a gap limit (the cycle-limit case boundary);
* :mod:`~maglev_match.analyses.sensitivity.index`: the headline index's d chi / d p for the
  maglev models, through the beam and vehicle formulas (:func:`index_sensitivity`,
  :class:`IndexSensitivity`), with the stability boundary of each parameter;
* :mod:`~maglev_match.analyses.sensitivity.uncertainty`: the linearised and the Monte Carlo
  spread of chi (:func:`linearised_spread`, :func:`sampled_spread`).

Every public name is re-exported here, so ``maglev_match.analyses.sensitivity.NAME`` keeps
working. A name is looked up where it is defined: to replace one for a test (e.g.
``mc_chunk``, which :func:`sampled_spread` calls), patch the submodule that defines it
(:mod:`~maglev_match.analyses.sensitivity.uncertainty`), not this package.
"""

from __future__ import annotations

from maglev_match.analyses.sensitivity.cycle import (
    SystemSensitivity,
    hopf_derivative,  # noqa: F401  (re-exported)
    margin_derivative,  # noqa: F401  (re-exported)
    system_sensitivity,
)
from maglev_match.analyses.sensitivity.index import (
    SWITCH_TOL,  # noqa: F401  (re-exported)
    IndexSensitivity,
    ParameterSensitivity,
    derived_map,
    engineering_names,
    index_sensitivity,
)
from maglev_match.analyses.sensitivity.limits import (
    branch_extremes,  # noqa: F401  (re-exported)
    limit_contact,  # noqa: F401  (re-exported)
    unlimited_bound,  # noqa: F401  (re-exported)
)
from maglev_match.analyses.sensitivity.status import DerivativeStatus
from maglev_match.analyses.sensitivity.uncertainty import (
    SampledSpread,
    linearised_spread,
    mc_checkpoint,  # noqa: F401  (re-exported)
    mc_chunk,  # noqa: F401  (re-exported)
    mc_chunks,  # noqa: F401  (re-exported)
    sampled_spread,
)

__all__ = [
    "DerivativeStatus",
    "SystemSensitivity",
    "ParameterSensitivity",
    "IndexSensitivity",
    "system_sensitivity",
    "index_sensitivity",
    "engineering_names",
    "derived_map",
    "linearised_spread",
    "SampledSpread",
    "sampled_spread",
]
