"""How a derivative of the index was obtained: :class:`DerivativeStatus`, shared by the
cycle layer (:mod:`maglev_match.analyses.sensitivity.cycle`, the status of d h / d p) and
the index layer (:mod:`maglev_match.analyses.sensitivity.index`, that of d chi / d p)."""

from __future__ import annotations

from enum import StrEnum

__all__ = ["DerivativeStatus"]


class DerivativeStatus(StrEnum):
    """How d h / d p (of the headline index: d h_simulation / d p where chi_simulation is
    the headline) was obtained."""

    EXACT = "exact"  # implicit differentiation of the converged cycle
    ZERO = "zero"  # chi = 0 on an open set (unstable equilibrium): derivative exactly 0
    RULE = "rule"  # h = gap_max - c0 by the case rule: only those two move h
    UNDEFINED = "undefined"  # the index itself failed; no derivative
    SOLVED = "solved"  # implicit function theorem on the solved critical-disturbance condition
    UNAVAILABLE = "unavailable"  # chi_simulation only bracketed by bisection: no derivative
