"""Options of a cycle branch: :class:`CycleOptions` (mesh, steps, tolerances, the corrector,
the linear solver, what is detected; checked on construction, a wrong value raises
``ValueError`` naming the field), :func:`cycle_options` (keyword changes over a base, the
keyword form of :func:`~maglev_match.dynamics.cycles.branch.cycle_branch`), and the choices
of the corrector (:class:`NewtonMode`: AUTO's chord iteration with a kept factorisation or
a factorisation per iteration) and of where Floquet multipliers are computed
(:class:`MultipliersAt`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from maglev_match.dynamics.collocation import LinearSolver

__all__ = [
    "CycleOptions",
    "MultipliersAt",
    "NewtonMode",
    "cycle_options",
]


class NewtonMode(StrEnum):
    """The corrector of a cycle branch."""

    CHORD = "chord"  # kept factorisation, rate-monitored (collocation.chord_newton)
    FULL = "full"  # a new factorisation every iteration (collocation.collocation_newton)


class MultipliersAt(StrEnum):
    """Where a cycle branch computes Floquet multipliers."""

    ALL = "all"  # every point the branch keeps
    LAST = "last"  # only the last point (callers that read only the end point)


_FLOQUET_METHODS = ("auto", "periodic_qz", "cyclic_qr")


@dataclass(frozen=True)
class CycleOptions:
    """Options of :func:`cycle_branch`, checked on construction (a wrong value raises
    ``ValueError`` naming the field, the value and the rule).

    Parameters
    ----------
    ntst, ncol : mesh intervals (>= 4) and collocation points per interval (2..7).
    max_steps : maximum accepted continuation steps.
    ds, ds_min, ds_max : initial, smallest and largest arclength step (scaled units: the
        profile in units of ``system.state_scale`` RMS over the mesh, the period in units
        of the Hopf period, the parameter in units of ``lam_scale``).
    param_bounds : (lo, hi): the branch stops when the parameter reaches a bound (solved
        there). The system's valid range of the parameter always bounds the branch too.
    tol : Newton tolerance on the scaled update (the branch tolerance).
    max_newton : Newton iterations per corrector (the chord corrector gets 8 more).
    adapt_every : adapt the mesh every this many steps (0: never).
    lam_scale : unit of the parameter in the arclength norm (None: 5 % of |value| at the
        Hopf point, or 0.05 when that is zero to rounding).
    max_period_factor : the branch ends as a homoclinic approach when the period exceeds
        this multiple of the Hopf period.
    trivial_tol : largest accepted |mu_trivial - 1| for reliable multipliers.
    neutral_tol : the band around |mu| = 1 in which a multiplier decides nothing (see
        :class:`Stability`); also the band of n_unstable (|mu| > 1 + neutral_tol).
    detect_special_points : locate LPC, BP, PD, NS (False: only the limit contact and the
        stop value, which end the branch; saves the solves when only the branch matters).
    linear_solver : "condensed" (default, :class:`~maglev_match.dynamics.collocation.
        CondensedLU`) or "sparse_lu" (a sparse LU of the whole system, kept as baseline).
    floquet_method : "auto", "periodic_qz" or "cyclic_qr"
        (:func:`~maglev_match.dynamics.floquet.floquet_analysis`).
    predictor_tol : target distance between predicted and corrected point (scaled units)
        by which easy steps may grow faster than the Newton-count rule allows; None: the
        Newton-count rule alone.
    newton : "chord" (default: a kept factorisation while the iteration contracts fast)
        or "full" (a factorisation every iteration).
    multipliers_at : "all" (default) or "last" (with no special-point detection: only the
        last point gets its multipliers; the others report none, ``reliable`` False).
    locate_limit : True (default): a contact with a physical limit is solved on the branch
        (its margin to the branch tolerance). False: it is only bracketed inside the step
        where the margin changes sign (one secant trial), for callers that need only
        whether and on which side a limit is reached.
    use_chart : continue in the system's regular chart (:class:`~maglev_match.dynamics.
        system.RegularChart`) once an orbit comes near the set where its equations are
        singular (model A: gap 0). False: never (the earlier behaviour).
    factor_at_solution : whether the chord corrector factorises the Jacobian once more at
        each solution (for the tangent, the Floquet transfer matrices and the next
        corrector). None (default): yes, unless neither special points nor multipliers are
        wanted along the branch (``detect_special_points`` False and ``multipliers_at``
        "last", the matching index's route), where the factorisation in force serves the
        tangent and the next corrector and the last point's Jacobian is evaluated for its
        multipliers: about one factorisation per step less.
    """

    ntst: int = 80
    ncol: int = 4
    max_steps: int = 300
    ds: float = 0.05
    ds_min: float = 1e-6
    ds_max: float = 4.0
    param_bounds: tuple[float, float] | None = None
    tol: float = 1e-10
    max_newton: int = 8
    adapt_every: int = 3
    lam_scale: float | None = None
    max_period_factor: float = 50.0
    trivial_tol: float = 1e-4
    neutral_tol: float = 1e-6
    detect_special_points: bool = True
    linear_solver: str = LinearSolver.CONDENSED
    floquet_method: str = "auto"
    predictor_tol: float | None = 0.05
    newton: str = NewtonMode.CHORD
    multipliers_at: str = MultipliersAt.ALL
    locate_limit: bool = True
    use_chart: bool = True
    factor_at_solution: bool | None = None

    def __post_init__(self) -> None:
        def bad(name, rule):
            raise ValueError(f"CycleOptions.{name} = {getattr(self, name)!r}: {rule}")

        def integer(name, lo, hi=None):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < lo or (
                    hi is not None and v > hi):
                bad(name, f"must be an integer >= {lo}" + (f" and <= {hi}" if hi else ""))

        def positive(name, allow_none=False):
            v = getattr(self, name)
            if v is None and allow_none:
                return
            if isinstance(v, bool) or not (isinstance(v, int | float | np.floating)
                                           and math.isfinite(v) and v > 0):
                bad(name, "must be a positive finite number" + (" or None" if allow_none
                                                                 else ""))

        integer("ntst", 4)
        integer("ncol", 2, 7)
        integer("max_steps", 1)
        integer("max_newton", 1)
        integer("adapt_every", 0)
        for name in ("ds", "ds_min", "ds_max", "tol", "trivial_tol", "neutral_tol"):
            positive(name)
        positive("lam_scale", allow_none=True)
        positive("predictor_tol", allow_none=True)
        if not self.ds_min <= self.ds_max:
            bad("ds_min", f"must not exceed ds_max = {self.ds_max!r}")
        if not (isinstance(self.max_period_factor, int | float)
                and math.isfinite(self.max_period_factor) and self.max_period_factor > 1):
            bad("max_period_factor", "must be a finite number > 1")
        if self.param_bounds is not None:
            try:
                lo, hi = (float(v) for v in self.param_bounds)
            except (TypeError, ValueError):
                bad("param_bounds", "must be None or (lo, hi)")
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                bad("param_bounds", "must be finite with lo < hi")
            object.__setattr__(self, "param_bounds", (lo, hi))
        for name, enum in (("linear_solver", LinearSolver), ("newton", NewtonMode),
                           ("multipliers_at", MultipliersAt)):
            v = getattr(self, name)
            if v not in tuple(enum):
                bad(name, "must be one of " + ", ".join(map(str, enum)))
            object.__setattr__(self, name, enum(v))
        if self.floquet_method not in _FLOQUET_METHODS:
            bad("floquet_method", "must be one of " + ", ".join(_FLOQUET_METHODS))
        for name in ("detect_special_points", "locate_limit", "use_chart"):
            if not isinstance(getattr(self, name), bool | np.bool_):
                bad(name, "must be True or False")
        if self.factor_at_solution not in (None, True, False):
            bad("factor_at_solution", "must be None, True or False")


_OPTION_NAMES = frozenset(f.name for f in dataclasses.fields(CycleOptions))


def cycle_options(options: CycleOptions | None = None, **changes: Any) -> CycleOptions:
    """``options`` (default :class:`CycleOptions`) with ``changes`` applied by field name;
    an unknown name raises TypeError as an unknown keyword argument would."""
    unknown = sorted(set(changes) - _OPTION_NAMES)
    if unknown:
        raise TypeError(f"cycle_branch() got an unexpected keyword argument {unknown[0]!r}")
    base = CycleOptions() if options is None else options
    if not isinstance(base, CycleOptions):
        raise TypeError(f"options must be a CycleOptions, not {type(base).__name__}")
    return dataclasses.replace(base, **changes) if changes else base
