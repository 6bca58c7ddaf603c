"""Curves of cycle bifurcations in two parameters: the fold of cycles (LPC), the period
doubling (PD) and the Neimark-Sacker (torus, NS) bifurcation, continued from a located
special point of a one-parameter cycle branch.

Method (and why). The curve is the solution set of a *minimally augmented* collocation
system (:mod:`~maglev_match.dynamics.cycle_curves.augmented`): the cycle's own collocation,
periodicity and phase rows with a second free parameter, plus one scalar test function g
from a bordered matrix of the cycle Jacobian (Govaerts 2000; MatCont's LPC and PD curves;
BifurcationKit.jl's codimension-two periodic orbits). It was preferred over the fully
extended system (the cycle plus its critical Floquet eigenfunction, twice the unknowns)
because it reuses the engine's collocation rows and sparse Jacobian unchanged
(:class:`~maglev_match.dynamics.collocation.CollocationProblem`): the only new derivative
is the gradient of g, -w^T (A_z v), which JAX gives exactly from the same right-hand side,
so Newton's method converges quadratically on a system one row larger than a cycle
branch's, with no second discretised eigenfunction to normalise or remesh. The borders of
the bordered matrix follow the singular vectors of the previous point, which keeps it well
conditioned along the curve.

* :mod:`~maglev_match.dynamics.cycle_curves.augmented`: the augmented system and g;
* :mod:`~maglev_match.dynamics.cycle_curves.ns`: the NS system (a complex test function
  of the multiplier e^{i theta}, theta one more unknown);
* :mod:`~maglev_match.dynamics.cycle_curves.curve`: the driver :func:`cycle_curve`
  (pseudo-arclength in (p1, p2), Newton, step control, mesh adaptation, the multipliers);
* :mod:`~maglev_match.dynamics.cycle_curves.codim2`: codimension-two points on the curve
  (CPC, LPPD, LPNS on LPC; LPPD, PDNS, R2, GPD on PD; R1-R4, LPNS, PDNS, CH on NS);
* :mod:`~maglev_match.dynamics.cycle_curves.cusp`: the CPC solved (the curve's tangent in
  the parameter plane vanishes);
* :mod:`~maglev_match.dynamics.cycle_curves.flip`: the period doubling's normal-form
  coefficient (:func:`flip_coefficient`), read out along PD curves (GPD where it vanishes);
* :mod:`~maglev_match.dynamics.cycle_curves.torus`: the Neimark-Sacker normal-form
  coefficient (:func:`torus_coefficient`) on the same Poincare map, read out along NS
  curves (CH, the Chenciner point, where it vanishes);
* :mod:`~maglev_match.dynamics.cycle_curves.gh`: the LPC curve born at a generalised Hopf
  point of a Hopf curve (branch switching, :func:`lpc_from_generalised_hopf`);
* :mod:`~maglev_match.dynamics.cycle_curves.results`: :class:`CycleCurve`,
  :class:`CycleCurvePoint`, :class:`CurveStop`.

Limits: the curve is continued in the system's own coordinates (a regular chart of the
system is not used), with the mesh (NTST, NCOL) of the start orbit.
"""

from maglev_match.dynamics.cycle_curves.augmented import AugmentedCycleSystem, CurveKind
from maglev_match.dynamics.cycle_curves.codim2 import codim2_tests, detect_codim2
from maglev_match.dynamics.cycle_curves.curve import cycle_curve, start_from
from maglev_match.dynamics.cycle_curves.flip import FlipCoefficient, flip_coefficient
from maglev_match.dynamics.cycle_curves.gh import lpc_from_generalised_hopf
from maglev_match.dynamics.cycle_curves.ns import NSCycleSystem
from maglev_match.dynamics.cycle_curves.results import CurveStop, CycleCurve, CycleCurvePoint
from maglev_match.dynamics.cycle_curves.torus import TorusCoefficient, torus_coefficient

__all__ = [
    "AugmentedCycleSystem",
    "CurveKind",
    "CurveStop",
    "CycleCurve",
    "CycleCurvePoint",
    "FlipCoefficient",
    "NSCycleSystem",
    "TorusCoefficient",
    "codim2_tests",
    "cycle_curve",
    "detect_codim2",
    "flip_coefficient",
    "lpc_from_generalised_hopf",
    "start_from",
    "torus_coefficient",
]
