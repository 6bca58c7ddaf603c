"""Piecewise-smooth (hybrid) systems: smooth vector fields joined at event surfaces.

Model-agnostic. A :class:`HybridSystem` has K *switches*, each on or off; a *mode* is the
vector s in {0, 1}^K of their states, and every mode has a smooth vector field
``rhs(x, p, s)``; a switch toggles when its guard crosses zero, and the state may then be
projected onto the new mode's constraint surface (the Filippov systems of saturations and
clamps; Filippov 1988, ch. 2; di Bernardo, Budd, Champneys & Kowalczyk 2008,
*Piecewise-smooth Dynamical Systems*, sec. 2.4).

The package is organised by subject, one module each (each module's docstring gives the
method and its sources):

- :mod:`~maglev_match.dynamics.hybrid.system`: the system (:class:`HybridSystem`);
- :mod:`~maglev_match.dynamics.hybrid.flow`: the flow with forward sensitivities, switches
  located as events and crossed with the saltation jump (:func:`hybrid_flow`,
  :class:`FlowOptions`, :class:`FlowStatus`, :class:`LinearStop`, :class:`HybridFlow`);
- :mod:`~maglev_match.dynamics.hybrid.saltation`: the saltation matrix of a switch
  (:func:`saltation_matrix`);
- :mod:`~maglev_match.dynamics.hybrid.orbits`: periodic orbits by collocation per segment
  (:func:`hybrid_periodic_orbit`, :class:`Segment`, :class:`HybridOrbit`,
  :func:`segments_from_flow`, :func:`orbit_parameter_derivative`);
- :mod:`~maglev_match.dynamics.hybrid.floquet`: their Floquet multipliers by the periodic
  Schur algorithm (:func:`hybrid_floquet`, :class:`HybridFloquet`);
- :mod:`~maglev_match.dynamics.hybrid.shooting`: the same orbits by single shooting, an
  independent method (:func:`shoot_hybrid_orbit`, :class:`ShotOrbit`).

The modules depend on each other in that order (system <- flow, saltation <- floquet <-
orbits; shooting needs the flow). Every public name of the former module
``maglev_match.dynamics.hybrid`` is importable from this package.
"""

from maglev_match.dynamics.hybrid.floquet import HybridFloquet, hybrid_floquet
from maglev_match.dynamics.hybrid.flow import (
    FlowOptions,
    FlowStatus,
    HybridFlow,
    LinearStop,
    hybrid_flow,
)
from maglev_match.dynamics.hybrid.orbits import (
    HybridOrbit,
    Segment,
    hybrid_periodic_orbit,
    orbit_parameter_derivative,
    segments_from_flow,
)
from maglev_match.dynamics.hybrid.saltation import saltation_matrix
from maglev_match.dynamics.hybrid.shooting import ShotOrbit, shoot_hybrid_orbit
from maglev_match.dynamics.hybrid.system import HybridSystem

__all__ = [
    "HybridSystem",
    "FlowOptions",
    "FlowStatus",
    "LinearStop",
    "HybridFlow",
    "hybrid_flow",
    "Segment",
    "HybridOrbit",
    "hybrid_periodic_orbit",
    "shoot_hybrid_orbit",
    "hybrid_floquet",
    "HybridFloquet",
    "ShotOrbit",
    "saltation_matrix",
    "segments_from_flow",
    "orbit_parameter_derivative",
]
