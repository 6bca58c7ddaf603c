"""The critical normal-form coefficient of a period doubling (flip) of cycles, from the
Poincare map of the collocated cycle.

What it is. At a period doubling the Poincare map P of the cycle (on a section through a
point of the cycle) has a simple multiplier -1; restricted to its one-dimensional centre
manifold it reads eta -> -eta + c eta^3 + O(eta^4) (Kuznetsov 2004, Elements of Applied
Bifurcation Theory, sec. 5.4, the flip normal form). For the map x -> A x + B(x, x) / 2 +
C(x, x, x) / 6 (x the deviation from the fixed point) the coefficient is (ibid., the
critical normal-form coefficient of the flip)::

    c = <p, C(q, q, q)> / 6 + <p, B(q, (I - A)^{-1} B(q, q))> / 2,

A q = -q, A^T p = -p, <p, q> = 1, with |q| = 1 in the system's scaled states (the state
vector divided by ``system.state_scale``). c > 0: the period-doubled cycle is born stable
on the side where the cycle is unstable (supercritical flip); c < 0: subcritical. A
generalised period doubling (GPD) is a zero of c on a PD curve. (The second iterate of P
then reads eta -> eta - 2 c eta^3 on the centre manifold.)

How. The method chosen is the "cubic coefficient of the Poincare map on the collocated
cycle", not the periodic boundary-value formulas of Kuznetsov, Govaerts, Doedel and
Dhooge (2005): P is composed of the classical Runge-Kutta (RK4) flow over the cycle's
period T0, substeps following the collocation mesh (and enough of them for RK4's stability
on the largest Jacobian eigenvalue along the cycle), and one more RK4 step of the length
delta(x) that brings the point back to the section {<(y - x0) / S, f0 / S> = 0} (a few
Newton iterations on the scalar delta; the step's local error is O(delta^5), delta = O(|x
- x*|), so the map is exact to third order in the deviation up to the integrator's global
error). Its fixed point x* (near the collocated cycle's first node x0) is solved by
Newton's method. A is the exact Jacobian of this discrete map in orthonormal coordinates
of the section (JAX forward mode); B(q, q), C(q, q, q) and B(q, h) are fourth-order
central differences of A(x) q and A(x) h along q (steps 1 % and 2 % of the cycle's
amplitude in scaled states; nested forward-mode derivatives through the integrator and the
return-time iterations compiled for over a minute, the differences reuse the one compiled
Jacobian).

The map, its fixed point and Jacobian (:func:`poincare_map`, :class:`PoincareMap`) and the
difference stencils (:func:`difference_stencil`) are shared with the Neimark-Sacker coefficient
(:mod:`~maglev_match.dynamics.cycle_curves.torus`).

Accuracy: the RK4 global error, O(h^4) with h the substep, and the differences' O(eps^4)
(checked against a system whose Poincare map is known in closed form,
tests/test_flip_coefficient.py); the multiplier of A nearest -1 is returned with the
coefficient, a check of the integration against the collocation's Floquet multiplier.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.dynamics.cycles.orbits import PeriodicOrbit
from maglev_match.dynamics.system import System

__all__ = ["FlipCoefficient", "PoincareMap", "flip_coefficient", "poincare_map"]

_NEWTON_DELTA = 3  # Newton iterations on the return time's correction (unrolled): from
# delta = 0 the k-th iterate's error is O(|x - x*|^(2^k)), so 3 make its derivatives up to
# the third exact at the fixed point


@dataclass(frozen=True)
class FlipCoefficient:
    """The flip coefficient ``c`` of the module docstring, the multiplier of the Poincare
    map nearest -1 (``multiplier``, from the RK4 map: it checks the integration against the
    collocation's), the residual of the map's fixed point, the number of RK4 steps and
    ``error``, an estimate of c's error from the finite differences (below it, c is zero
    within its accuracy).
    ``ok`` False (and ``message`` why) where it could not be computed; c is then nan."""

    c: float
    multiplier: float
    residual: float
    steps: int
    ok: bool = True
    message: str = ""
    error: float = float("nan")


@cache
def _kernels(rhs):
    def rk4(x, p, h):
        k1 = rhs(x, p)
        k2 = rhs(x + 0.5 * h * k1, p)
        k3 = rhs(x + 0.5 * h * k2, p)
        k4 = rhs(x + h * k3, p)
        return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    def flow(x, p, hs):
        def body(y, h):
            return rk4(y, p, h), None
        return jax.lax.scan(body, x, hs)[0]

    def poincare(y, x0, S, Q, f0s, p, hs):
        """P in section coordinates y (x = x0 + S * (Q y))."""
        z = flow(x0 + S * (Q @ y), p, hs)

        def g(d):
            return jnp.dot((rk4(z, p, d) - x0) / S, f0s)

        d = 0.0 * y[0]
        for _ in range(_NEWTON_DELTA):
            gd, dg = jax.jvp(g, (d,), (jnp.ones_like(d),))
            d = d - gd / dg
        return Q.T @ ((rk4(z, p, d) - x0) / S)

    def value_jac(y, args):
        f = lambda u: poincare(u, *args)  # noqa: E731
        return f(y), jax.jacfwd(f)(y)

    def jacobians(ys, args):  # DP at a batch of points (one dispatch for the stencils)
        return jax.vmap(lambda u: jax.jacfwd(lambda v: poincare(v, *args))(u))(ys)

    return jax.jit(value_jac), jax.jit(
        jax.vmap(lambda x, p: jnp.max(jnp.abs(jnp.linalg.eigvals(jax.jacfwd(rhs)(x, p)))),
                 in_axes=(0, None))), jax.jit(jacobians)


def _differences(D, y, r, eps, D0):
    """The first and second derivatives of x -> D(x) in the direction r at y, by the
    fourth-order central differences (steps eps, 2 eps; D0 = D(y)): with D(x) = DP(x) q,
    these are B(q, r) and C(q, r, r) (truncation O(eps^4), rounding O(1e-16 / eps^2));
    then the same by the second-order differences (step eps), whose distance from the
    former estimates the error."""
    return difference_stencil(D(y + eps * r), D(y - eps * r), D(y + 2 * eps * r),
                              D(y - 2 * eps * r), D0, eps)


def difference_stencil(Dp1, Dm1, Dp2, Dm2, D0, eps):
    """:func:`_differences` from the values at y + eps r, y - eps r, y + 2 eps r, y - 2 eps r
    and y (these may be matrices DP(x), applied to vectors afterwards: the stencils are
    linear)."""
    first = (8.0 * (Dp1 - Dm1) - (Dp2 - Dm2)) / (12.0 * eps)
    second = (-Dp2 + 16.0 * Dp1 - 30.0 * D0 + 16.0 * Dm1 - Dm2) / (12.0 * eps ** 2)
    first2 = (Dp1 - Dm1) / (2.0 * eps)
    second2 = (Dp1 - 2.0 * D0 + Dm1) / eps ** 2
    return first, second, first2, second2


def _steps(orbit: PeriodicOrbit, spectral: np.ndarray, per_interval: int) -> np.ndarray:
    """RK4 substeps (s): ``per_interval`` per mesh interval at least, more where the
    largest Jacobian eigenvalue modulus rho needs them (h rho <= 1.5, inside RK4's
    stability region on every axis)."""
    T = float(orbit.period)
    dt = np.diff(np.asarray(orbit.mesh, float)) * T
    m = orbit.ncol
    rho = np.asarray(spectral, float)
    # the largest rho over each interval's nodes
    rho_i = np.array([rho[i * m:(i + 1) * m + 1].max() for i in range(dt.size)])
    k = np.maximum(per_interval, np.ceil(dt * rho_i / 1.5)).astype(int)
    return np.repeat(dt / k, k)


@dataclass(frozen=True)
class PoincareMap:
    """The RK4 Poincare map of a collocated cycle at its fixed point (module docstring):
    ``value_jac(y, args)`` -> (P(y), DP(y)) in section coordinates y, ``y`` the fixed
    point, ``A`` = DP(y), ``residual`` of the fixed point, ``steps`` the RK4 steps, ``eps``
    the finite differences' step (1 % of the cycle's amplitude in scaled states)."""

    value_jac: object
    jacobians: object
    args: tuple
    y: np.ndarray
    A: np.ndarray
    residual: float
    steps: int
    eps: float

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """DP(x) at a point x of the section (section coordinates)."""
        return np.asarray(self.value_jac(jnp.asarray(x), self.args)[1])

    def jacobians_at(self, xs: np.ndarray) -> np.ndarray:
        """DP(x) at the rows x of ``xs`` (one batched evaluation)."""
        return np.asarray(self.jacobians(jnp.asarray(xs), self.args))


def poincare_map(system: System, orbit: PeriodicOrbit, *, per_interval: int = 8,
                 tol: float = 1e-12) -> PoincareMap | tuple[str, float, int]:
    """The :class:`PoincareMap` of ``orbit`` (its fixed point solved by Newton's method to
    ``tol``), or (why it failed, the residual, the RK4 steps)."""
    value_jac, spectral, jacobians = _kernels(system.rhs)
    p = jnp.asarray(np.asarray(orbit.p, float))
    x0 = np.asarray(orbit.states[0], float)
    S = np.asarray(system.state_scale, float)
    f0s = np.asarray(system.rhs(jnp.asarray(x0), p), float) / S
    nrm = float(np.linalg.norm(f0s))
    if not nrm > 0:
        return "the vector field vanishes at the cycle's first node", math.nan, 0
    f0s = f0s / nrm
    n = x0.size
    # an orthonormal basis of the section's tangent space (the complement of f0s)
    Qf, _ = np.linalg.qr(np.column_stack([f0s, np.eye(n)]))
    Q = Qf[:, 1:n]
    hs = _steps(orbit, np.asarray(spectral(jnp.asarray(orbit.states), p)), per_interval)
    args = (jnp.asarray(x0), jnp.asarray(S), jnp.asarray(Q), jnp.asarray(f0s), p,
            jnp.asarray(hs))
    y = np.zeros(n - 1)
    res = math.inf
    for _ in range(20):
        Py, DP = value_jac(jnp.asarray(y), args)
        Py, DP = np.asarray(Py), np.asarray(DP)
        F = Py - y
        res = float(np.max(np.abs(F)))
        if not np.all(np.isfinite(DP)) or not np.isfinite(res):
            return ("the Poincare map is not finite (the RK4 integration diverged)", res,
                    hs.size)
        if res < tol:
            break
        try:
            y = y - np.linalg.solve(DP - np.eye(n - 1), F)
        except np.linalg.LinAlgError:
            return ("the Poincare map's fixed point is singular (a multiplier 1 besides the "
                    "trivial one)", res, hs.size)
    else:
        if res > 1e-9:
            return (f"the Poincare map's fixed point did not converge (residual {res:.2e})",
                    res, hs.size)
    amp = float(np.max(np.linalg.norm((orbit.states - orbit.states.mean(axis=0)) / S,
                                      axis=1)))
    eps = 1e-2 * (amp if amp > 0 else 1.0)
    return PoincareMap(value_jac, jacobians, args, y, DP, res, hs.size, eps)


def flip_coefficient(system: System, orbit: PeriodicOrbit, *, per_interval: int = 8,
                     tol: float = 1e-12) -> FlipCoefficient:
    """The flip coefficient c of the cycle ``orbit`` at (or near) a period doubling
    (module docstring). ``per_interval``: RK4 substeps per mesh interval at least.
    Never raises on a numerical failure: ``ok`` False and ``message`` say what failed."""
    pm = poincare_map(system, orbit, per_interval=per_interval, tol=tol)
    if not isinstance(pm, PoincareMap):
        message, res, steps = pm
        return FlipCoefficient(math.nan, math.nan, res, steps, False, message)
    value_jac, args, y, A, res, eps = pm.value_jac, pm.args, pm.y, pm.A, pm.residual, pm.eps
    hs_size = pm.steps
    ev, V = np.linalg.eig(A)
    i = int(np.argmin(np.abs(ev + 1.0)))
    mult = float(ev[i].real)
    evl, Vl = np.linalg.eig(A.T)
    j = int(np.argmin(np.abs(evl + 1.0)))
    q = np.real(V[:, i])
    q /= np.linalg.norm(q)
    pa = np.real(Vl[:, j])
    pq = float(pa @ q)
    if abs(pq) < 1e-12 or abs(ev[i].imag) > 1e-8:
        return FlipCoefficient(math.nan, mult, res, hs_size, False,
                               "the multiplier -1 is not simple (a second multiplier at -1: "
                               "R2)")
    pa = pa / pq

    def dq(x):  # DP(x) q
        return np.asarray(value_jac(jnp.asarray(x), args)[1]) @ q

    Bqq, Cqqq, Bqq2, Cqqq2 = _differences(dq, y, q, eps, A @ q)
    c, c2 = (_coefficient(A, pa, B, C, y, q, eps, args, value_jac, k)
             for B, C, k in ((Bqq, Cqqq, 0), (Bqq2, Cqqq2, 2)))
    # the error: the second-order differences' distance (an upper estimate of the fourth-
    # order ones' truncation) plus the rounding of a second difference of DP q
    rounding = 1e-15 * float(np.abs(pa) @ np.abs(A @ q)) / eps ** 2
    error = abs(c - c2) + rounding
    if not math.isfinite(c):
        return FlipCoefficient(math.nan, mult, res, hs_size, False,
                               "the coefficient is not finite")
    return FlipCoefficient(c, mult, res, hs_size, error=error)


def _coefficient(A, pa, Bqq, Cqqq, y, q, eps, args, value_jac, k) -> float:
    """c = <p, C(q, q, q)> / 6 + <p, B(q, (I - A)^{-1} B(q, q))> / 2 (module docstring),
    B(q, h) by the differences of :func:`_differences` (``k``: 0 the fourth-order ones, 2
    the second-order ones)."""
    h = np.linalg.solve(np.eye(A.shape[0]) - A, Bqq)
    Bqh = _differences(lambda x: np.asarray(value_jac(jnp.asarray(x), args)[1]) @ h,
                       y, q, eps, A @ h)[k]
    return float(pa @ Cqqq) / 6.0 + float(pa @ Bqh) / 2.0
