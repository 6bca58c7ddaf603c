"""Periodic orbits of x' = f(x, p): orthogonal collocation, pseudo-arclength continuation
from a Hopf point, Floquet multipliers and cycle bifurcations.

Model-agnostic: works on any :class:`~maglev_match.dynamics.system.System`; observables
(read-outs) and physical limits come in as names and callables.

Discretisation (as in AUTO-07p / MATCONT). Time is rescaled to [0, 1], u' = T f(u, p).
The mesh 0 = t_0 < ... < t_NTST = 1 carries on each interval a polynomial of degree NCOL,
given by its values at NCOL + 1 equally spaced nodes (shared at interval ends, so the
profile is continuous). The equations are

* collocation at the NCOL Gauss-Legendre points of every interval: u'(z) - T f(u(z), p) = 0,
* periodicity u(1) - u(0) = 0,
* the integral phase condition  int_0^1 <u(t) - u_ref(t), u_ref'(t)> dt = 0,
* the pseudo-arclength condition <X - X_prev, X'_prev>_W - ds = 0 (or a fixed parameter),

for the unknowns X = (profile, period T, parameter). Newton's method uses the exact
Jacobian (JAX, vmapped over collocation points); by default the interior collocation
unknowns of each interval are condensed out and the small mesh-node system is factorised
by sparse LU (:class:`~maglev_match.dynamics.collocation.CondensedLU`; ``linear_solver=
"sparse_lu"`` factorises the whole system instead); the corrector is the chord iteration,
which keeps the factorisation of the previous solution while it contracts fast
(``newton="full"``: a factorisation per iteration). Floquet multipliers are those of the
product of the interval transfer matrices of the variational equation (taken from the
condensation at each solution), computed without forming the product
(:mod:`~maglev_match.dynamics.floquet`). The mesh is adapted by
equidistributing |u^(NCOL+1)|^(1/(NCOL+1)) (de Boor's criterion, as AUTO does).

The package is organised by subject:

* :mod:`~maglev_match.dynamics.cycles.orbits`: the Hopf start (:class:`HopfStart`,
  :func:`hopf_start`), the orbit (:class:`PeriodicOrbit`) and its read-outs
  (:func:`orbit_extrema`, :func:`first_harmonic`);
* :mod:`~maglev_match.dynamics.cycles.options`: :class:`CycleOptions`,
  :func:`cycle_options`, :class:`NewtonMode`, :class:`MultipliersAt`;
* :mod:`~maglev_match.dynamics.cycles.stability`: Floquet multipliers of an orbit
  (:func:`floquet_multipliers`), :class:`Stability` and :func:`stability_of`, the
  multiplier test functions of PD, NS and BP (:func:`multiplier_tests`);
* :mod:`~maglev_match.dynamics.cycles.problem`: :class:`CycleProblem`, the collocation
  BVP as a continuation problem (corrector, read-outs, test functions, mesh adaptation,
  the regular chart);
* :mod:`~maglev_match.dynamics.cycles.branch`: the driver :func:`cycle_branch`, the
  assembly of the branch and the words for its end (homoclinic approach, the family
  closing at a Hopf point), and :func:`correct_cycle`;
* :mod:`~maglev_match.dynamics.cycles.results`: :class:`CyclePoint`, :class:`CycleBranch`,
  :class:`CorrectionResult`, :class:`RestartState`, :class:`CycleStop`, the branch as an
  xarray Dataset (:func:`branch_to_xarray`) and a saved point's restart state
  (:func:`load_restart`).

The collocation BVP itself, its linear algebra and correctors are in
:mod:`~maglev_match.dynamics.collocation`. The public names are re-exported here (the
names of ``__all__``, and ``CollocationBVP``, ``adapt_mesh`` and ``blocks_at`` for the
code that imports them from this package).
"""

from maglev_match.dynamics.collocation import CollocationBVP as CollocationBVP
from maglev_match.dynamics.collocation import adapt_mesh as adapt_mesh
from maglev_match.dynamics.continuation import SpecialPoint
from maglev_match.dynamics.cycles.branch import correct_cycle, cycle_branch
from maglev_match.dynamics.cycles.options import (
    CycleOptions,
    MultipliersAt,
    NewtonMode,
    cycle_options,
)
from maglev_match.dynamics.cycles.orbits import (
    HopfStart,
    PeriodicOrbit,
    first_harmonic,
    hopf_start,
    orbit_extrema,
)
from maglev_match.dynamics.cycles.problem import CycleProblem
from maglev_match.dynamics.cycles.results import (
    CorrectionResult,
    CycleBranch,
    CyclePoint,
    CycleStop,
    RestartState,
    branch_to_xarray,
    load_restart,
)
from maglev_match.dynamics.cycles.stability import (
    Stability,
    floquet_multipliers,
    multiplier_tests,
    stability_of,
)
from maglev_match.dynamics.cycles.stability import blocks_at as blocks_at

__all__ = [
    "HopfStart",
    "PeriodicOrbit",
    "CyclePoint",
    "SpecialPoint",
    "CycleBranch",
    "CycleOptions",
    "CorrectionResult",
    "CycleStop",
    "MultipliersAt",
    "NewtonMode",
    "Stability",
    "RestartState",
    "cycle_options",
    "first_harmonic",
    "stability_of",
    "branch_to_xarray",
    "load_restart",
    "CycleProblem",
    "multiplier_tests",
    "hopf_start",
    "cycle_branch",
    "correct_cycle",
    "floquet_multipliers",
    "orbit_extrema",
]
