"""Delay-differential systems with constant delays, turned into ODEs the rest of the engine
analyses unchanged.

Nothing here knows about maglev. A :class:`DelayDifferentialSystem` is

    x'(t) = f(x(t), y_1(t - tau_1), ..., y_K(t - tau_K), p),     y_k = g_k(x, p)  (m_k entries)

with the delays tau_k entries of the parameter vector; only the *signals* y_k need a past.

The package is organised by subject, one module each (each module's docstring gives the
method and its sources):

- :mod:`~maglev_match.dynamics.delay.system`: the delay system
  (:class:`DelayDifferentialSystem`: its delay-free ODE, its argument function) and its
  linearisation at an equilibrium (:func:`delay_jacobians`);
- :mod:`~maglev_match.dynamics.delay.discretisation`: the pseudospectral discretisation
  of the past by Chebyshev collocation (Breda, Maset & Vermiglio 2005; :func:`chebyshev_nodes`,
  :func:`nodes_for`, :func:`max_delay_for`), the discretised ODE
  (:class:`DiscretisedSystem`, :func:`discretise`) and :class:`DelayNodesError`;
- :mod:`~maglev_match.dynamics.delay.roots`: the characteristic matrix and the rightmost
  characteristic roots, corrected by Newton's method and trusted by comparing two
  discretisations (:func:`characteristic_roots`, :func:`refine_characteristic_root`,
  :func:`discretised_matrix`);
- :mod:`~maglev_match.dynamics.delay.crossings`: crossings of the imaginary axis as a delay
  varies (:func:`delay_crossings`), the critical delay (:func:`critical_delay`), the first
  Lyapunov coefficient from the characteristic matrix
  (:func:`delay_first_lyapunov_coefficient`) and the Hopf points along a delay
  (:func:`delay_hopf_points`);
- :mod:`~maglev_match.dynamics.delay.simulate`: simulation by the method of steps
  (:func:`simulate_delay`), the reference for the discretised system's simulation.

The modules depend on each other in that order (system <- discretisation <- roots <-
crossings; simulate needs only the system). Every public name of the former module
``maglev_match.dynamics.delay`` is importable from this package.
"""

from maglev_match.dynamics.delay.crossings import (
    CriticalDelay,
    DelayCrossing,
    critical_delay,
    delay_crossings,
    delay_first_lyapunov_coefficient,
    delay_hopf_points,
)
from maglev_match.dynamics.delay.discretisation import (
    NODES_MAX,
    NODES_MIN,
    NODES_PER_RATE,
    DelayNodesError,
    DiscretisedSystem,
    chebyshev_nodes,
    discretise,
    is_delay_parameter,
    max_delay_for,
    nodes_for,
)
from maglev_match.dynamics.delay.roots import (
    TRUST_TOL,
    CharacteristicRoots,
    characteristic_matrix,
    characteristic_roots,
    discretised_matrix,
    refine_characteristic_root,
)
from maglev_match.dynamics.delay.simulate import DelaySimulation, simulate_delay
from maglev_match.dynamics.delay.system import DelayDifferentialSystem, delay_jacobians

__all__ = [
    "NODES_MIN",
    "NODES_MAX",
    "NODES_PER_RATE",
    "TRUST_TOL",
    "DelayDifferentialSystem",
    "DiscretisedSystem",
    "DelayNodesError",
    "CharacteristicRoots",
    "DelayCrossing",
    "CriticalDelay",
    "DelaySimulation",
    "chebyshev_nodes",
    "nodes_for",
    "max_delay_for",
    "discretise",
    "is_delay_parameter",
    "delay_jacobians",
    "characteristic_matrix",
    "discretised_matrix",
    "characteristic_roots",
    "refine_characteristic_root",
    "delay_first_lyapunov_coefficient",
    "delay_crossings",
    "critical_delay",
    "delay_hopf_points",
    "simulate_delay",
]
