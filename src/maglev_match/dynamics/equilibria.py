"""Equilibria of x' = f(x, p): Newton's method, eigenvalues, stability and root locus.

Model-agnostic: works on any :class:`~maglev_match.dynamics.system.System`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from maglev_match.dynamics.system import System

__all__ = [
    "EquilibriumResult",
    "StabilityResult",
    "RootLocusResult",
    "find_equilibrium",
    "eigenvalue_analysis",
    "stability",
    "root_locus",
]

# An eigenvalue whose condition number exceeds this is reported as ill-conditioned.
ILL_CONDITIONED = 1e8


@dataclass(frozen=True)
class EquilibriumResult:
    """An equilibrium found by Newton's method, with its diagnostics."""

    x: np.ndarray
    p: np.ndarray
    converged: bool
    iterations: int
    residual: float  # max |f(x)| in the state's own units per second
    scaled_residual: float  # dimensionless, see System.scaled_residual
    message: str = ""


@dataclass(frozen=True)
class StabilityResult:
    """Eigenvalues of the Jacobian at an equilibrium and the stability verdict."""

    eigenvalues: np.ndarray  # sorted by real part, largest first (1/s)
    max_real_part: float  # the stability margin is -max_real_part (1/s)
    stable: bool
    condition_numbers: np.ndarray  # of each eigenvalue (same order)
    equilibrium: EquilibriumResult
    warnings: tuple[str, ...] = ()

    @property
    def margin(self) -> float:
        """Stability margin -max Re(lambda) (1/s): positive when stable."""
        return -self.max_real_part


@dataclass(frozen=True)
class RootLocusResult:
    """Eigenvalues of the equilibrium along one parameter."""

    param: str
    values: np.ndarray
    eigenvalues: np.ndarray  # (n_values, dim), each row sorted by real part desc
    max_real_part: np.ndarray
    converged: np.ndarray  # Newton converged at each value
    equilibria: np.ndarray  # (n_values, dim)
    warnings: tuple[str, ...] = field(default=())


def find_equilibrium(
    system: System,
    p: np.ndarray | None = None,
    x0: np.ndarray | None = None,
    tol: float = 1e-12,
    max_iter: int = 50,
) -> EquilibriumResult:
    """Solve f(x, p) = 0 by Newton's method with the exact Jacobian.

    Converged when the scaled residual (dimensionless) is below ``tol``. A singular
    Jacobian or a diverging iteration is reported in the result, never raised.
    """
    p = system.p if p is None else np.asarray(p, float)
    x = np.array(system.x_guess if x0 is None else x0, dtype=float)
    message = ""
    it = 0
    fx, J = system.f_and_jacobian(x, p)
    res = float(np.max(np.abs(fx) / system.residual_scale(J)))
    while res > tol and it < max_iter:
        it += 1
        try:
            dx = np.linalg.solve(J, -fx)
        except np.linalg.LinAlgError:
            message = "singular Jacobian during Newton iteration"
            break
        # damped step: halve until the residual decreases (robust far from the solution)
        lam = 1.0
        for _ in range(30):
            trial = x + lam * dx
            f_t, J_t = system.f_and_jacobian(trial, p)
            r_trial = float(np.max(np.abs(f_t) / system.residual_scale(J_t)))
            if np.isfinite(r_trial) and r_trial < res:
                break
            lam *= 0.5
        else:
            message = "line search failed: the residual does not decrease"
            break
        x, res, fx, J = trial, r_trial, f_t, J_t
    converged = bool(res <= tol)
    if not converged and not message:
        message = f"no convergence in {max_iter} iterations (scaled residual {res:.3e})"
    return EquilibriumResult(
        x=x,
        p=np.array(p),
        converged=converged,
        iterations=it,
        residual=float(np.max(np.abs(fx))),
        scaled_residual=float(res),
        message=message,
    )


def eigenvalue_analysis(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues of J sorted by real part (largest first) and their condition numbers
    1 / |<left, right>| with unit eigenvectors."""
    w, vl, vr = scipy.linalg.eig(J, left=True, right=True)
    order = np.lexsort((-np.abs(w.imag), -w.real))
    w, vl, vr = w[order], vl[:, order], vr[:, order]
    dots = np.abs(np.sum(np.conj(vl) * vr, axis=0))
    with np.errstate(divide="ignore"):
        cond = np.where(dots > 0, 1.0 / dots, np.inf)
    return w, cond


def stability(
    system: System,
    p: np.ndarray | None = None,
    x0: np.ndarray | None = None,
    equilibrium: EquilibriumResult | None = None,
) -> StabilityResult:
    """Equilibrium, eigenvalues of its Jacobian and the verdict (stable iff all Re < 0)."""
    eq = equilibrium or find_equilibrium(system, p, x0)
    w, cond = eigenvalue_analysis(system.jacobian(eq.x, eq.p))
    warnings = []
    if not eq.converged:
        warnings.append(f"equilibrium not converged: {eq.message}")
    worst = float(np.max(cond)) if cond.size else 0.0
    if worst > ILL_CONDITIONED:
        warnings.append(
            f"eigenvalue problem ill-conditioned (largest eigenvalue condition number {worst:.2e})"
        )
    max_re = float(np.max(w.real))
    return StabilityResult(
        eigenvalues=w,
        max_real_part=max_re,
        stable=bool(max_re < 0 and eq.converged),
        condition_numbers=cond,
        equilibrium=eq,
        warnings=tuple(warnings),
    )


def root_locus(
    system: System,
    param: str,
    values: Sequence[float] | np.ndarray,
    p: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RootLocusResult:
    """Eigenvalues of the equilibrium as ``param`` runs through ``values``.

    The equilibrium is continued naturally: each Newton solve starts from the previous one.
    """
    values = np.asarray(values, dtype=float)
    base = system.p if p is None else np.asarray(p, float)
    eigs, eqs, conv = [], [], []
    x = system.x_guess
    warnings: list[str] = []
    for k, v in enumerate(values):
        pk = system.params_with(base, **{param: float(v)})
        eq = find_equilibrium(system, pk, x)
        if eq.converged:
            x = eq.x
        else:
            warnings.append(f"{param} = {v:g}: {eq.message}")
        w, _ = eigenvalue_analysis(system.jacobian(eq.x, pk))
        eigs.append(w)
        eqs.append(eq.x)
        conv.append(eq.converged)
        if progress is not None:
            progress(k + 1, len(values))
    eig_arr = np.array(eigs)
    return RootLocusResult(
        param=param,
        values=values,
        eigenvalues=eig_arr,
        max_real_part=eig_arr.real.max(axis=1),
        converged=np.array(conv),
        equilibria=np.array(eqs),
        warnings=tuple(warnings),
    )
