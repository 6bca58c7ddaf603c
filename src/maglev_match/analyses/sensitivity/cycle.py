"""Exact derivatives at one point of a :class:`~maglev_match.dynamics.system.System` with
respect to every parameter (no finite differences): of the gap maximum h on the converged
unstable cycle, of the stability margin and of the Hopf point (:func:`system_sensitivity`,
:class:`SystemSensitivity`).

Three layers, each exact to round-off on the discretised problem:

* **h at a converged unstable cycle** (case ``unstable_cycle``). The cycle solves the
  collocation system F(Y, p) = 0 (collocation, periodicity, phase condition; de Boor &
  Swartz 1973, Doedel's AUTO notes). Implicit differentiation gives, for all parameters at
  once, one sparse LU and one multi-right-hand-side solve

      (dF/dY) dY/dp = - dF/dp,

  with dF/dp from automatic differentiation of the vector field at the collocation points.
  h = max_t g(u(t), p) for the gap observable g. At the maximiser t* (located on the
  collocation polynomial) the envelope theorem gives

      dh/dp = dg/dx(u(t*), p) . du(t*)/dp + dg/dp(u(t*), p),

  where du(t*)/dp is the same polynomial combination of the nodal dY/dp (the shift of t*
  contributes nothing to first order, since d g(u(t))/dt = 0 there).
* **Stability margin** max Re lambda of the equilibrium Jacobian J(x*(p), p): first-order
  eigenvalue perturbation (Kato 1966; Kuznetsov 2004, sec. 10.2)

      d lambda/dp_k = w^H (dJ/dp_k) v / (w^H v),   dJ/dp_k = J_x[dx*/dp_k] + J_p_k,
      dx*/dp_k = -J^{-1} f_p_k,

  with w, v the left and right eigenvectors of the rightmost eigenvalue.
* **Hopf point** along the index's Hopf parameter alpha: implicit differentiation of the
  standard defining system (Kuznetsov 2004, sec. 10.2.2)

      f(x, p) = 0,  J v1 + omega v2 = 0,  J v2 - omega v1 = 0,  <c, v1> = 1,  <c, v2> = 0

  in z = (x, v1, v2, omega, alpha): dz/dp = -(dG/dz)^{-1} dG/dp.

This is the only module that touches the collocation internals
(:func:`_collocation_system`); the case boundaries built on these derivatives are in
:mod:`maglev_match.analyses.sensitivity.limits` and
:mod:`maglev_match.analyses.sensitivity.index`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.optimize

from maglev_match.analyses.matching import MatchingIndex
from maglev_match.analyses.sensitivity.status import DerivativeStatus
from maglev_match.core import jax_setup  # noqa: F401  (float64)
from maglev_match.dynamics.cycles import PeriodicOrbit
from maglev_match.dynamics.equilibria import find_equilibrium
from maglev_match.dynamics.system import System

__all__ = [
    "SystemSensitivity",
    "system_sensitivity",
    "cycle_h_derivative",
    "margin_derivative",
    "hopf_derivative",
]


# ---------------------------------------------------------------------------------------
# the one place that touches collocation internals
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Collocation:
    """What the implicit differentiation needs from the collocation discretisation."""

    A: Any  # sparse Jacobian dF/dY of the bordered system, scaled unknowns
    dF_dp: np.ndarray  # (size, n_params)
    S: np.ndarray  # scale of the unknowns: X = S Y
    idx: np.ndarray  # (NTST, NCOL + 1) node numbers of each mesh interval
    solve: Callable[[np.ndarray], np.ndarray]  # A^{-1} b (sparse LU, b may have columns)
    basis: Callable[[np.ndarray], np.ndarray]  # local Lagrange values (len(s), NCOL + 1)


def _collocation_system(system: System, orbit: PeriodicOrbit) -> _Collocation:
    """The collocation system of a converged ``orbit`` at fixed parameters: its sparse
    Jacobian dF/dY (scaled unknowns Y = X / S, X = (nodal profile, T, lambda)), factorised,
    and dF/dp (size, n_params) for every parameter of ``system``.

    Rows (de Boor & Swartz 1973; Doedel's AUTO notes):

        [ collocation at the Gauss points  (NTST NCOL n) ]   u'(z) - T f(u(z), p) = 0
        [ periodicity                      (n)           ]   u(1) - u(0) = 0
        [ integral phase condition         (1)           ]   against the orbit itself
        [ lambda fixed                     (1)           ]   one parameter as unknown

    The bordered unknown lambda does not move (last row), so dF/dp carries the direct
    parameter derivative, -T h_j f_p(u(z), p) / scale, in the collocation rows only.

    This is the ONLY function that uses the collocation problem
    (:class:`~maglev_match.dynamics.collocation.CollocationProblem`, the same bordered system
    the continuation solves, and its sparse LU).
    """
    from maglev_match.dynamics.collocation import (
        CollocationProblem,
        collocation_tables,
        factorize,
        interval_nodes,
        lagrange_basis,
    )

    p = np.asarray(orbit.p, float)
    m, ntst, n = orbit.ncol, orbit.ntst, system.dim
    prob = CollocationProblem(system=system, ipar=0, p0=p.copy(),
                              mesh=np.asarray(orbit.mesh, float), m=m,
                              scale=np.asarray(system.state_scale, float),
                              T_scale=orbit.period, lam_scale=abs(p[0]) if p[0] != 0 else 1.0)
    Y = prob.pack(orbit.states, orbit.period, p[0])
    last_row = np.zeros(prob.size)
    last_row[-1] = 1.0
    phase = prob.phase_row(orbit.states)
    _, A, _ = prob.evaluate(Y, phase, orbit.states, last_row, float(Y[-1]))
    _, _, _, L, _ = collocation_tables(m)
    idx = interval_nodes(ntst, m)
    Uc = np.einsum("lk,jkn->jln", L, orbit.states[idx])  # (ntst, m, n) at Gauss points
    fp = np.asarray(_param_jacobian_batch(system.rhs)(jnp.asarray(Uc.reshape(-1, n)),
                                                      jnp.asarray(p)))  # (ntst m, n, np)
    h = np.diff(np.asarray(orbit.mesh, float))
    fp = fp.reshape(ntst, m, n, p.size)
    sc = prob.scale
    rows = (-orbit.period * h[:, None, None, None] * fp / sc[None, None, :, None])
    dF = np.zeros((prob.size, p.size))
    dF[: ntst * m * n] = rows.reshape(ntst * m * n, p.size)
    lu = factorize(A)
    nodes = np.linspace(0.0, 1.0, m + 1)
    return _Collocation(A=A, dF_dp=dF, S=prob.S(), idx=idx, solve=lu.solve,
                        basis=lambda s: lagrange_basis(nodes, np.atleast_1d(s))[0])


@cache
def _param_jacobian_batch(rhs: Callable) -> Callable:
    return jax.jit(jax.vmap(jax.jacfwd(rhs, argnums=1), (0, None)))


@cache
def _observable_derivs(g: Callable) -> Callable:
    """(g, dg/dx, dg/dp) of an observable, as arrays (vector observables: one row each)."""

    def fun(x, p):
        val = jnp.atleast_1d(g(x, p))
        gx = jax.jacfwd(lambda y: jnp.atleast_1d(g(y, p)))(x)
        gp = jax.jacfwd(lambda q: jnp.atleast_1d(g(x, q)))(p)
        return val, gx, gp

    return jax.jit(fun)


@cache
def _observable_batch(g: Callable) -> Callable:
    return jax.jit(jax.vmap(lambda x, p: jnp.atleast_1d(g(x, p)), (0, None)))


# ---------------------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SystemSensitivity:
    """Derivatives with respect to the parameter vector of a :class:`System`.

    ``dh_dp`` (m per unit of each parameter), ``dmax_re_dp`` (1/s per unit),
    ``dhopf_dp`` d alpha_H / dp of the Hopf point along ``hopf_param`` (None without one).
    """

    param_names: tuple[str, ...]
    h: float
    h_status: DerivativeStatus
    dh_dp: np.ndarray
    max_real_part: float
    dmax_re_dp: np.ndarray
    hopf_param: str | None = None
    hopf_value: float | None = None
    dhopf_dp: np.ndarray | None = None
    t_star: float | None = None  # normalised time of the gap maximum on the cycle
    solve_residual: float | None = None  # relative residual of the implicit solve
    warnings: tuple[str, ...] = ()

    def dh(self, name: str) -> float:
        return float(self.dh_dp[self.param_names.index(name)])


# ---------------------------------------------------------------------------------------
# system level
# ---------------------------------------------------------------------------------------
def cycle_h_derivative(system: System, orbit: PeriodicOrbit, observable: str,
                       sign: float = 1.0) -> tuple[float, np.ndarray, float, float]:
    """h = max over the orbit of ``observable`` (min with ``sign`` = -1) and dh/dp for every
    parameter (implicit differentiation + envelope theorem). Returns (h, dh_dp, t_star,
    relative residual of the implicit solve)."""
    col = _collocation_system(system, orbit)
    A, dF, S, idx, basis = col.A, col.dF_dp, col.S, col.idx, col.basis
    dY = col.solve(-dF)
    resid = float(np.linalg.norm(A @ dY + dF) / max(np.linalg.norm(dF), 1e-300))
    dX = dY * S[:, None]
    n, m, ntst = system.dim, orbit.ncol, orbit.ntst
    nnodes = orbit.states.shape[0]
    dU = dX[: nnodes * n].reshape(nnodes, n, -1)
    g = system.observables[observable]
    p = np.asarray(orbit.p, float)
    pj = jnp.asarray(p)
    # coarse pass over every interval, then Brent's method on the polynomial pieces around it
    ncoarse = 8 * m + 1
    Lc = basis(np.linspace(0.0, 1.0, ncoarse))
    nodes = orbit.states[idx]  # (ntst, m+1, n)
    Xc = np.einsum("sk,jkn->jsn", Lc, nodes).reshape(-1, n)
    vals = sign * np.asarray(_observable_batch(g)(jnp.asarray(Xc), pj)).reshape(ntst, ncoarse,
                                                                                 -1)
    j0, _, comp = np.unravel_index(int(np.argmax(vals)), vals.shape)
    gb = _observable_batch(g)

    def neg(loc: float, j: int) -> float:
        x = basis(np.array([loc]))[0] @ nodes[j]
        return -sign * float(np.asarray(gb(jnp.asarray(x[None]), pj))[0, comp])

    best = (np.inf, 0, 0.0)
    for j in ((j0 - 1) % ntst, j0, (j0 + 1) % ntst):
        r = scipy.optimize.minimize_scalar(neg, bounds=(0.0, 1.0), args=(j,), method="bounded",
                                           options={"xatol": 1e-13})
        for loc in (float(r.x), 0.0, 1.0):
            v = neg(loc, j)
            if v < best[0]:
                best = (v, j, loc)
    _, j, loc = best
    ell = basis(np.array([loc]))[0]  # (m+1,)
    x_star = ell @ nodes[j]
    du = np.einsum("k,knq->nq", ell, dU[idx[j]])  # (n, n_params)
    val, gx, gp = (np.asarray(a) for a in _observable_derivs(g)(jnp.asarray(x_star), pj))
    dh = gx[comp] @ du + gp[comp]
    mesh = np.asarray(orbit.mesh)
    t_star = float(mesh[j] + loc * (mesh[j + 1] - mesh[j]))
    return float(val[comp]), dh, t_star, resid


@cache
def _eig_kernel(rhs: Callable) -> Callable:
    """dJ/ds along directions (dx, dp): vmapped over the columns of (DX, DP)."""

    def jac(x, p):
        return jax.jacfwd(rhs, argnums=0)(x, p)

    def dJ(x, p, dx, dp):
        return jax.jvp(jac, (x, p), (dx, dp))[1]

    return jax.jit(jax.vmap(dJ, (None, None, 1, 1)))


def margin_derivative(system: System, p: np.ndarray, x_eq: np.ndarray | None = None,
                      directions: np.ndarray | None = None
                      ) -> tuple[float, np.ndarray, np.ndarray, list[str]]:
    """max Re lambda of the equilibrium and its derivative along each column of
    ``directions`` (n_params, k) (default: every parameter), by first-order eigenvalue
    perturbation with the equilibrium's drift dx*/dp = -J^{-1} f_p included.

    Returns (max Re lambda, derivatives (k,), equilibrium x, warnings)."""
    p = np.asarray(p, float)
    warnings: list[str] = []
    eq = find_equilibrium(system, p, x_eq)
    if not eq.converged:
        warnings.append(f"equilibrium not converged: {eq.message}")
    x = eq.x
    J = system.jacobian(x, p)
    fp = system.param_jacobian(x, p)
    D = np.eye(p.size) if directions is None else np.asarray(directions, float)
    dxs = -np.linalg.solve(J, fp @ D)
    dJ = np.asarray(_eig_kernel(system.rhs)(jnp.asarray(x), jnp.asarray(p), jnp.asarray(dxs),
                                            jnp.asarray(D)))  # (k, n, n)
    w, vl, vr = scipy.linalg.eig(J, left=True, right=True)
    order = np.lexsort((-w.imag, -w.real))
    k0 = int(order[0])
    lam = w[k0]
    others = np.delete(w, [i for i in range(w.size)
                           if abs(w[i] - lam) < 1e-12 or abs(w[i] - np.conj(lam)) < 1e-12])
    if others.size and np.min(np.abs(others.real - lam.real)) < 1e-9 * max(1.0, abs(lam)):
        warnings.append("two distinct eigenvalues share the largest real part: the margin is "
                        "not differentiable here")
    wl, vv = vl[:, k0], vr[:, k0]
    denom = np.vdot(wl, vv)
    dlam = np.einsum("i,kij,j->k", np.conj(wl), dJ, vv) / denom
    return float(lam.real), np.real(dlam), x, warnings


@cache
def _hopf_kernels(rhs: Callable, ipar: int) -> tuple[Callable, Callable, Callable]:
    """The Hopf defining system G(z, p, c), z = (x, v1, v2, omega, alpha), and its
    Jacobians dG/dz and dG/dp (Kuznetsov 2004, sec. 10.2.2)."""

    def G(z, p, c):
        n = c.shape[0]
        x, v1, v2, om, al = z[:n], z[n:2 * n], z[2 * n:3 * n], z[3 * n], z[3 * n + 1]
        pp = p.at[ipar].set(al)

        def f(y):
            return rhs(y, pp)

        fx, jv1 = jax.jvp(f, (x,), (v1,))
        jv2 = jax.jvp(f, (x,), (v2,))[1]
        return jnp.concatenate([fx, jv1 + om * v2, jv2 - om * v1,
                                jnp.stack([c @ v1 - 1.0, c @ v2])])

    return (jax.jit(G), jax.jit(jax.jacfwd(G, argnums=0)), jax.jit(jax.jacfwd(G, argnums=1)))


def hopf_derivative(system: System, p: np.ndarray, param: str, value: float
                    ) -> tuple[float, np.ndarray, list[str]]:
    """The Hopf point alpha_H of the equilibrium along ``param`` near ``value`` (others at
    ``p``), refined by Newton on the defining system, and d alpha_H / dp for every parameter
    by implicit differentiation (entry of ``param`` itself is 0: alpha is an unknown)."""
    warnings: list[str] = []
    k = system.param_index(param)
    p = np.asarray(p, float)
    ph = p.copy()
    ph[k] = value
    eq = find_equilibrium(system, ph)
    J = system.jacobian(eq.x, ph)
    w, V = np.linalg.eig(J)
    cand = [i for i in range(w.size) if w[i].imag > 1e-9]
    if not cand:
        return float("nan"), np.full(p.size, np.nan), ["no complex pair at the Hopf point"]
    i = min(cand, key=lambda i: abs(w[i].real))
    q = V[:, i]
    # phase so that Re q and Im q are orthogonal, then normalise <c, v1> = 1
    v1, v2 = np.real(q), np.imag(q)
    th = 0.5 * math.atan2(-2.0 * v1 @ v2, v1 @ v1 - v2 @ v2)
    qq = q * np.exp(1j * th)
    v1, v2 = np.real(qq), np.imag(qq)
    c = v1 / float(v1 @ v1)
    n = system.dim
    z = np.concatenate([eq.x, v1, v2, [w[i].imag], [value]])
    G, DGz, DGp = _hopf_kernels(system.rhs, k)
    pj, cj = jnp.asarray(p), jnp.asarray(c)
    for _ in range(12):
        g = np.asarray(G(jnp.asarray(z), pj, cj))
        A = np.asarray(DGz(jnp.asarray(z), pj, cj))
        dz = np.linalg.solve(A, -g)
        z = z + dz
        if np.max(np.abs(dz[-1])) <= 1e-13 * max(1.0, abs(z[-1])) and np.max(
                np.abs(dz[3 * n])) <= 1e-13 * max(1.0, abs(z[3 * n])):
            break
    else:
        warnings.append("Newton on the Hopf defining system did not settle in 12 steps")
    A = np.asarray(DGz(jnp.asarray(z), pj, cj))
    Gp = np.asarray(DGp(jnp.asarray(z), pj, cj))
    dz = np.linalg.solve(A, -Gp)
    return float(z[-1]), dz[-1], warnings


def system_sensitivity(system: System, index: MatchingIndex, p: np.ndarray | None = None,
                       observable: str = "gap_deviation") -> SystemSensitivity:
    """d h / d p, d max Re lambda / d p and d alpha_H / dp for the parameters of ``system``
    at the point of ``index`` (a result of :func:`maglev_match.analyses.matching.index_of_system`).

    In case ``unstable_cycle`` dh/dp is exact (implicit differentiation of the cycle); in
    the case-rule cases dh/dp of the system parameters is zero (status ``zero`` / ``rule``);
    a failed index gives ``undefined`` (NaN)."""
    p = np.asarray(system.p if p is None else p, float)
    names = tuple(system.param_names)
    warnings: list[str] = []
    max_re, dmr, x_eq, w = margin_derivative(system, p)
    warnings.extend(w)
    dhopf = None
    hval = None
    if index.hopf_param is not None and index.hopf_value is not None:
        hval, dhopf, w = hopf_derivative(system, p, index.hopf_param, index.hopf_value)
        warnings.extend(w)
    t_star = resid = None
    if index.case == "unstable_cycle" and index.cycle is not None:
        h, dh, t_star, resid = cycle_h_derivative(system, index.cycle.orbit, observable)
        status = DerivativeStatus.EXACT
        if abs(h - index.h) > 1e-6 * max(abs(index.h), 1e-12):
            warnings.append(f"the refined gap maximum {h:.12g} differs from the index's h "
                            f"{index.h:.12g}")
        if resid > 1e-8:
            warnings.append(f"the implicit solve left a relative residual {resid:.1e}")
    elif index.case == "unstable_equilibrium":
        h, dh, status = 0.0, np.zeros(p.size), DerivativeStatus.ZERO
    elif index.converged and math.isfinite(index.h):
        h, dh, status = index.h, np.zeros(p.size), DerivativeStatus.RULE
    else:
        h, dh, status = float("nan"), np.full(p.size, np.nan), DerivativeStatus.UNDEFINED
        warnings.append("the index did not converge: no derivative")
    return SystemSensitivity(
        param_names=names, h=h, h_status=status, dh_dp=np.asarray(dh, float),
        max_real_part=max_re, dmax_re_dp=dmr, hopf_param=index.hopf_param,
        hopf_value=hval, dhopf_dp=dhopf, t_star=t_star, solve_residual=resid,
        warnings=tuple(warnings),
    )
