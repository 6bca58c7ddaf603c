"""The periodic boundary-value problem by orthogonal collocation on a mesh (de Boor &
Swartz 1973; Ascher, Mattheij & Russell 1995, ch. 5): the discretisation, the linear
algebra of its bordered Jacobian and the Newton and chord correctors, as in AUTO-07p
(Doedel's notes, ch. "periodic solutions").

The package is organised by subject:

* :mod:`~maglev_match.dynamics.collocation.bvp`: the discretisation. Collocation tables
  and Lagrange basis, the JAX kernels of the collocation rows, the bordered system
  :class:`CollocationProblem` (``CollocationBVP``) with its residual, Jacobian blocks
  (:class:`CollocationParts`) and whole sparse Jacobian (:func:`sparse_matrix`), the
  evaluation of a profile (:func:`evaluate_profile`) and mesh adaptation
  (:func:`adapt_mesh`, :func:`remesh`). The module docstring gives the rows of the system.
* :mod:`~maglev_match.dynamics.collocation.linalg`: the factorisations of the bordered
  Jacobian (:class:`LinearSolver`): by default the condensation of each interval's interior
  nodes (:class:`CondensedLU`, as AUTO does), whose mesh-node system of fixed sparsity
  pattern is factorised by sparse LU; ``"sparse_lu"`` factorises the whole bordered matrix
  (:func:`factorize`, the earlier code path, kept for comparison). The same condensation
  gives the Floquet transfer matrices (:meth:`CondensedLU.transfer_matrices`).
* :mod:`~maglev_match.dynamics.collocation.newton`: the correctors. Newton's method
  (:func:`collocation_newton`) and the chord iteration (:func:`chord_newton`) that
  continuation uses: the factorisation made at one solution serves the next corrector
  while the iteration contracts fast, and gives the tangent and the transfer matrices.

The names of the three modules are re-exported here. Module-level settings
(``linalg.LU_BLOCKS_FROM``, ``newton.CHORD_MAX_RATE``) are read from their own modules:
change them there.
"""

from maglev_match.dynamics.collocation.bvp import (
    CollocationBVP,
    CollocationParts,
    CollocationProblem,
    LinearSolver,
    adapt_mesh,
    collocation_kernel,
    collocation_second_derivative,
    collocation_tables,
    evaluate_profile,
    interval_nodes,
    lagrange_basis,
    node_times,
    remesh,
    scaled_collocation_rows,
    sparse_matrix,
)
from maglev_match.dynamics.collocation.linalg import (
    CondensedLU,
    batched_inverse,
    batched_lu_solve,
    factor_jacobian,
    factorize,
)
from maglev_match.dynamics.collocation.newton import (
    ChordResult,
    NewtonStats,
    chord_newton,
    collocation_newton,
)

__all__ = [
    "CollocationProblem",
    "LinearSolver",
    "CollocationBVP",
    "CollocationParts",
    "ChordResult",
    "CondensedLU",
    "NewtonStats",
    "adapt_mesh",
    "batched_inverse",
    "batched_lu_solve",
    "chord_newton",
    "collocation_kernel",
    "collocation_newton",
    "collocation_tables",
    "evaluate_profile",
    "factor_jacobian",
    "factorize",
    "interval_nodes",
    "lagrange_basis",
    "node_times",
    "remesh",
    "collocation_second_derivative",
    "scaled_collocation_rows",
    "sparse_matrix",
]
