"""The correctors of the bordered collocation system
(:class:`~maglev_match.dynamics.collocation.bvp.CollocationProblem`): Newton's method
(:func:`collocation_newton`, a factorisation per iteration, stopped early when its
quadratic convergence predicts the next update below the tolerance) and the chord
iteration (:func:`chord_newton`), AUTO's corrector with a kept factorisation: the
factorisation made at one solution serves the next corrector while the iteration
contracts fast (rate-monitored simplified Newton; Deuflhard 2004, "Newton methods for
nonlinear problems", sec. 2.1), and the same factorisation gives the tangent and the
Floquet transfer matrices
(:meth:`~maglev_match.dynamics.collocation.linalg.CondensedLU.transfer_matrices`). The
factorisations themselves are in :mod:`~maglev_match.dynamics.collocation.linalg`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from maglev_match.dynamics.collocation.bvp import CollocationProblem, LinearSolver
from maglev_match.dynamics.collocation.linalg import factor_jacobian

__all__ = [
    "CHORD_MAX_RATE",
    "ChordResult",
    "NewtonStats",
    "chord_newton",
    "collocation_newton",
]


_EARLY_STOP = True  # the condensed path's predicted-convergence stop (off: for comparisons)


def collocation_newton(
    prob: CollocationProblem,
    Y0: np.ndarray,
    Uref: np.ndarray,
    last_row: np.ndarray,
    last_rhs: float,
    tol: float,
    max_iter: int,
    solver: str | None = None,
    lazy_blocks: bool = False,
) -> tuple[np.ndarray, bool, int, float, Any, tuple | None]:
    """Newton's method on the bordered collocation system; returns (Y, converged, its,
    residual, factorisation of the last Jacobian, blocks at the solution).

    ``solver`` (default ``prob.linear_solver``): ``"sparse_lu"`` is the original
    iteration (a full sparse LU per iteration, converged when the update max |dY| < tol,
    so the last iteration only confirms); ``"condensed"`` uses :class:`CondensedLU` and
    stops one iteration earlier when the quadratic convergence of Newton's method predicts
    the next update below tol / 10: with the contraction theta = |dY_k| / |dY_{k-1}| <= 0.1
    the next update is about theta^2 |dY_k| (Deuflhard 2004, "Newton methods for nonlinear
    problems", sec. 2.1), so the error of Y_{k+1} is bounded by that. The Jacobian blocks
    returned (for the Floquet multipliers) are then re-evaluated at the returned Y. The
    iteration count returned includes the confirming iteration so saved: the continuation's
    step-size rule is calibrated on that count (counting one less grows the steps faster
    and lets a branch jump across a fold of cycles). ``lazy_blocks``: return None instead
    of re-evaluating the blocks after that early stop (the caller evaluates them at Y only
    if it needs the multipliers there)."""
    solver = prob.linear_solver if solver is None else solver
    phase = prob.phase_row(Uref)
    Y = np.array(Y0, float)
    lu = None
    blocks: tuple = ()
    rnorm = np.inf
    prev = np.inf
    for it in range(1, max_iter + 1):
        pa = prob.parts(Y, phase, Uref, last_row, last_rhs)
        r, blocks = pa.resid, pa.blocks
        rnorm = float(np.max(np.abs(r)))
        if not np.isfinite(rnorm):
            return Y, False, it, rnorm, None, blocks
        try:
            lu = factor_jacobian(prob, pa, solver, -r)
        except (RuntimeError, np.linalg.LinAlgError):  # exactly singular
            return Y, False, it, rnorm, None, blocks
        dY = lu.solve(-r)
        if not np.all(np.isfinite(dY)):
            return Y, False, it, rnorm, None, blocks
        Y = Y + dY
        step = float(np.max(np.abs(dY)))
        if step < tol:
            # the Jacobian of this last iteration (at most tol away from the solution) serves
            # for the tangent and the Floquet multipliers; the residual is bounded by it too
            return Y, True, it, rnorm, lu, blocks
        if _EARLY_STOP and solver == LinearSolver.CONDENSED and it > 1 and step <= 0.1 * prev and \
                step ** 3 < 0.1 * tol * prev ** 2:
            blocks = None if lazy_blocks else prob.jacobian_blocks(Y)
            return Y, True, it + 1, rnorm, lu, blocks
        if step > 1e3:
            break
        prev = step
    return Y, False, max_iter, rnorm, lu, blocks


@dataclass
class NewtonStats:
    """Counters of the collocation corrector (summed over a branch): correctors run,
    iterations (linear solves with the bordered Jacobian), factorisations, and how many
    factorisations were forced by a poor contraction of the chord iteration."""

    correctors: int = 0
    iterations: int = 0
    factorizations: int = 0
    refactorizations: int = 0


#: The chord iteration keeps a factorisation while the contraction rate
#: theta = |dY_k| / |dY_(k-1)| stays below this; above it the Jacobian is refactorised.
CHORD_MAX_RATE = 0.1


@dataclass(frozen=True)
class ChordResult:
    """What :func:`chord_newton` returns: the solution Y, whether it converged, the
    iterations, the residual max-norm of the last iterate it was evaluated at, the
    factorisation of the bordered Jacobian AT Y (for the tangent, the Floquet transfer
    matrices, and as the chord matrix of the next corrector), the blocks (J, T, h) at Y,
    and the factorisations this corrector made."""

    Y: np.ndarray
    converged: bool
    iterations: int
    residual: float
    lu: Any
    blocks: tuple
    factorizations: int


def chord_newton(
    prob: CollocationProblem,
    Y0: np.ndarray,
    Uref: np.ndarray,
    last_row: np.ndarray,
    last_rhs: float,
    tol: float,
    max_iter: int,
    lu0: Any = None,
    solver: str | None = None,
    stats: NewtonStats | None = None,
    at_solution: bool = True,
) -> ChordResult:
    """The chord (simplified Newton) iteration on the bordered collocation system, as AUTO
    runs its corrector with a kept factorisation: Y_(k+1) = Y_k - A^{-1} F(Y_k) with A a
    factorised Jacobian at a nearby point, kept while the observed contraction rate
    theta_k = |dY_k| / |dY_(k-1)| stays below :data:`CHORD_MAX_RATE` and refactorised at
    the current iterate otherwise (Deuflhard 2004, "Newton methods for nonlinear problems",
    sec. 2.1.4 "simplified Newton", and the rate-monitored variant of sec. 2.1.5).

    ``lu0`` (optional) is a factorisation to start with: the one the previous corrector
    left at its solution (same mesh), so that a continuation step usually factorises once.
    Without it the first iterate is factorised. The chord iterates converge linearly with
    rate theta, so the error of Y_(k+1) is at most theta / (1 - theta) |dY_k|; the
    iteration stops as soon as that bound is below tol / 10 (no iteration spent only to
    confirm), or when |dY_k| < tol right after a refactorisation (Newton's quadratic
    convergence then bounds the error far below tol).

    At the solution the residual and the Jacobian blocks are evaluated and factorised once
    more: that factorisation solves for the tangent, gives the Floquet transfer matrices
    (:meth:`CondensedLU.transfer_matrices`) and is the next corrector's ``lu0``. With
    ``at_solution`` False that last factorisation is skipped: the factorisation in force
    (at an iterate of this or the previous corrector) is returned for the tangent and the
    next corrector, and ``blocks`` is None (a caller that needs the Floquet multipliers at
    the solution evaluates the Jacobian there itself).
    """
    solver = prob.linear_solver if solver is None else solver
    phase = prob.phase_row(Uref)
    Y = np.array(Y0, float)
    lu = lu0
    nfact = 0
    prev = np.inf  # the previous update with the same matrix (inf: none yet)
    rnorm = np.inf
    it = 0
    converged = False
    while it < max_iter:
        it += 1
        newton_step = lu is None  # factorised at this very iterate: a Newton step
        if newton_step:
            pa = prob.parts(Y, phase, Uref, last_row, last_rhs)
            r = pa.resid
        else:
            r = prob.residual(Y, phase, Uref, last_row, last_rhs)
        rnorm = float(np.max(np.abs(r)))
        if not np.isfinite(rnorm):
            break
        if newton_step:
            try:
                lu = factor_jacobian(prob, pa, solver, -r)
            except (RuntimeError, np.linalg.LinAlgError):  # exactly singular
                lu = None
                break
            nfact += 1
            prev = np.inf
        dY = lu.solve(-r)
        if not np.all(np.isfinite(dY)):
            break
        step = float(np.max(np.abs(dY)))
        theta = step / prev if np.isfinite(prev) else np.nan
        if not newton_step and theta >= 1.0:
            # the kept matrix does not contract here: discard the update, refactorise
            lu = None
            if stats is not None:
                stats.refactorizations += 1
            continue
        Y = Y + dY
        if (newton_step and step < tol) or (theta < 1.0
                                            and theta / (1.0 - theta) * step < 0.1 * tol):
            converged = True
            break
        if step > 1e3:
            break
        prev = step
        if theta > CHORD_MAX_RATE:
            lu = None  # contraction too slow: a new Jacobian at the next iterate
            if stats is not None:
                stats.refactorizations += 1
    lu_out, blocks = None, ()
    if converged and not at_solution and lu is not None:
        lu_out, blocks = lu, None
    elif converged:
        # the Jacobian at the solution: tangent, Floquet transfer matrices, next chord
        pa = prob.parts(Y, phase, Uref, last_row, last_rhs)
        rnorm = float(np.max(np.abs(pa.resid)))
        try:
            lu_out = factor_jacobian(prob, pa, solver)
            nfact += 1
            blocks = pa.blocks
        except (RuntimeError, np.linalg.LinAlgError):
            converged = False
    if stats is not None:
        stats.correctors += 1
        stats.iterations += it
        stats.factorizations += nfact
    return ChordResult(Y=Y, converged=converged, iterations=it, residual=rnorm, lu=lu_out,
                       blocks=blocks, factorizations=nfact)
