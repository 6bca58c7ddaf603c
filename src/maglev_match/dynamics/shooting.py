"""Periodic orbits by single shooting: Newton's method on the flow map (model-agnostic).

An independent method to check the collocation cycles of :mod:`.cycles` and a speed
baseline. Unknowns (x0, T); equations

    phi_T(x0) - x0 = 0                 (periodicity)
    f(x_ref, p) . (x0 - x_ref) = 0     (Poincare section through the guess)

The flow and its sensitivity d phi / d x0 (the monodromy matrix at convergence) come from
integrating the variational equation Phi' = J(x) Phi with SciPy's DOP853 at tight
tolerances; the augmented right-hand side is one jitted JAX function per model.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np
import scipy.integrate
import scipy.optimize

from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.system import System

__all__ = ["ShootingResult", "shoot_periodic_orbit", "trajectory_extrema"]


@dataclass(frozen=True)
class ShootingResult:
    """A periodic orbit found by shooting, with its diagnostics."""

    __repr__ = compact_repr

    x0: np.ndarray  # a point on the orbit
    period: float  # s
    p: np.ndarray
    multipliers: np.ndarray  # eigenvalues of the monodromy matrix (all, incl. trivial)
    converged: bool
    iterations: int
    residual: float  # max |phi_T(x0) - x0| / state_scale
    message: str = ""


@cache
def _variational(rhs: Callable, n: int) -> Callable:
    jac = jax.jacfwd(rhs, argnums=0)

    def aug(y, p):
        x = y[:n]
        Phi = y[n:].reshape(n, n)
        return jnp.concatenate([rhs(x, p), (jac(x, p) @ Phi).ravel()])

    return jax.jit(aug)


def _flow(system: System, x0: np.ndarray, T: float, p: np.ndarray, rtol: float):
    n = system.dim
    aug = _variational(system.rhs, n)
    pj = jnp.asarray(p)
    y0 = np.concatenate([x0, np.eye(n).ravel()])
    atol = np.concatenate([system.state_scale * rtol * 1e-2, np.full(n * n, rtol * 1e-2)])
    sol = scipy.integrate.solve_ivp(lambda t, y: np.asarray(aug(y, pj)), (0.0, T), y0,
                                    method="DOP853", rtol=rtol, atol=atol)
    yT = sol.y[:, -1]
    return yT[:n], yT[n:].reshape(n, n), sol.success


def shoot_periodic_orbit(
    system: System,
    x0: np.ndarray,
    period: float,
    p: np.ndarray | None = None,
    tol: float = 1e-11,
    max_iter: int = 20,
    res_tol: float = 1e-11,
    rtol: float = 1e-12,
) -> ShootingResult:
    """Solve for a periodic orbit through (near) ``x0`` with period near ``period`` (s).

    Converged when the scaled Newton update is below ``tol`` or the scaled periodicity
    residual max |phi_T(x0) - x0| / state_scale is below ``res_tol``. Failure is reported in the
    result, never raised.
    """
    p = system.p if p is None else np.asarray(p, float)
    n = system.dim
    sc = np.asarray(system.state_scale, float)
    x = np.array(x0, float)
    T = float(period)
    x_ref = x.copy()
    f_ref = system.f(x_ref, p)
    message = ""
    res = np.inf
    M = np.eye(n)
    for it in range(1, max_iter + 1):
        xT, M, ok = _flow(system, x, T, p, rtol)
        if not ok:
            return ShootingResult(x, T, p, np.linalg.eigvals(M), False, it, res,
                                  "integration failed")
        G = (xT - x) / sc
        res = float(np.max(np.abs(G)))
        if it > 1 and res < res_tol:  # near a Hopf point the update may stall above tol
            return ShootingResult(x, T, p, np.linalg.eigvals(M), True, it - 1, res)
        fT = system.f(xT, p)
        A = np.zeros((n + 1, n + 1))
        A[:n, :n] = (M - np.eye(n)) * sc[None, :] / sc[:, None]
        A[:n, n] = fT / sc * T
        A[n, :n] = f_ref * sc
        A[n, :n] /= np.max(np.abs(A[n, :n]))
        rhs = np.concatenate([-G, [-(A[n, :n] @ ((x - x_ref) / sc))]])
        try:
            d = np.linalg.solve(A, rhs)
        except np.linalg.LinAlgError:
            message = "singular shooting matrix"
            break
        if np.max(np.abs(d)) > 0.5:  # damp large steps (|dT/T| or a state > 0.5 scale)
            d *= 0.5 / np.max(np.abs(d))
        x = x + d[:n] * sc
        T = T * (1.0 + d[n])
        if np.max(np.abs(d)) < tol:
            xT, M, _ = _flow(system, x, T, p, rtol)
            res = float(np.max(np.abs((xT - x) / sc)))
            return ShootingResult(x, T, p, np.linalg.eigvals(M), True, it, res)
    return ShootingResult(x, T, p, np.linalg.eigvals(M), False, max_iter, res,
                          message or f"no convergence in {max_iter} iterations")


def trajectory_extrema(
    system: System, x0: np.ndarray, period: float, p: np.ndarray, names: Sequence[str],
    rtol: float = 1e-12, samples: int = 4000,
) -> dict[str, tuple[float, float]]:
    """Max and min of named observables over one period of the orbit through x0, from a
    DOP853 dense output sampled finely and refined by a bounded scalar search."""
    f = system.derivatives.f
    pj = jnp.asarray(p)
    sol = scipy.integrate.solve_ivp(lambda t, y: np.asarray(f(y, pj)), (0.0, period), x0,
                                    method="DOP853", rtol=rtol,
                                    atol=system.state_scale * rtol * 1e-2, dense_output=True)
    t = np.linspace(0.0, period, samples + 1)
    X = sol.sol(t).T
    out = {}
    for name in names:
        vals = system.observe(name, X, p).reshape(t.size, -1)
        ext = []
        for sign in (1.0, -1.0):
            v = sign * vals
            k, c = np.unravel_index(int(np.argmax(v)), v.shape)
            lo, hi = t[max(k - 1, 0)], t[min(k + 1, t.size - 1)]

            def neg(s, c=c, sign=sign, name=name):
                return -sign * float(np.ravel(system.observe(name, sol.sol(s), p))[c])

            r = scipy.optimize.minimize_scalar(neg, bounds=(lo, hi), method="bounded",
                                               options={"xatol": 1e-12 * period})
            ext.append(sign * max(-r.fun, float(v[k, c])))
        out[name] = (ext[0], ext[1])
    return out
