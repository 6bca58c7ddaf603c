"""The records of an iso-chi curve: one evaluation of the headline index (:class:`Sample`),
a point of the curve (:class:`IsoPoint`), a special point between two neighbours
(:class:`IsoSpecial`) and what the continuation returns (:class:`Traced`). The continuation
itself is :mod:`maglev_match.analyses.iso.trace`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = ["Sample", "IsoPoint", "IsoSpecial", "Traced"]


@dataclass(frozen=True)
class Sample:
    """One evaluation of the headline index at (p1, p2).

    ``chi`` the headline (NaN: not computed, ``reason`` says why), ``chi_paper`` and
    ``chi_simulation`` its parts (None: not simulated or inconclusive), ``basis`` the
    deciding part ("paper" or "simulation"), ``mechanism`` and ``direction`` what decided
    the simulated part and in which direction, ``paper_status`` ("cycle": the unstable
    cycle solved, "rule": no cycle within the limits, h = gap range; "unstable": h = 0;
    "failed") and ``simulation_status`` ("solved", "bracketed": only the bisection's
    bracket, "inconclusive", "skipped", "off"). ``state`` is the evaluator's own record (the
    full index), not compared."""

    chi: float
    chi_paper: float
    chi_simulation: float | None = None
    basis: str = "paper"
    mechanism: str | None = None
    direction: str | None = None
    paper_status: str = "cycle"
    simulation_status: str = "off"
    reason: str = ""
    state: Any = None

    @property
    def exact(self) -> bool:
        """True when the deciding part is a solved number (not a bracket's midpoint)."""
        if not math.isfinite(self.chi):
            return False
        if self.basis == "simulation":
            return self.simulation_status == "solved"
        return self.paper_status in ("cycle", "rule", "unstable")


@dataclass(frozen=True)
class IsoPoint:
    """A point of the curve: the two parameter values, the evaluation there, the
    corrector's residual chi - target and iterations, and ``status``: "solved" (the
    deciding part solved, |chi - target| <= tol target), "bracketed" (the corrector
    converged but the deciding simulated part is only a bisection bracket), or "not
    converged" (the last iterate of a failed corrector, where the curve ends)."""

    p1: float
    p2: float
    sample: Sample
    residual: float
    iterations: int
    status: str
    branch: int = 0  # 0 the start, +1 / -1 the direction followed
    # how the gradient of chi there was obtained: "exact" (the deciding part's analytic
    # derivative) or "difference: <why not exact>" ('' where none was computed)
    gradient: str = ""


@dataclass(frozen=True)
class IsoSpecial:
    """A special point between two neighbouring curve points: ``kind`` "basis switch"
    (the deciding part changes; chi_paper = chi_simulation = target there) or "mechanism
    change"; ``before``/``after`` the labels on either side, ``located`` whether the
    location converged, ``residual`` chi_paper - chi_simulation there (switch)."""

    kind: str
    p1: float
    p2: float
    before: str
    after: str
    sample: Sample
    located: bool
    residual: float
    message: str = ""


@dataclass(frozen=True)
class Traced:
    """What :func:`trace_iso` returns: the points in order along the curve, the start's
    position among them, the special points, each direction's end, the warnings and the
    counts."""

    points: tuple[IsoPoint, ...]
    start: int | None
    specials: tuple[IsoSpecial, ...]
    ends: tuple[str, str]
    warnings: tuple[str, ...]
    evaluations: int
    cpu_seconds: float
