"""Exact sensitivities of the matching index chi = h / w0, of the stability margin and of the
Hopf point, with respect to every parameter (no finite differences).

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

Where h is set by a case rule the derivative is not a cycle derivative:
``unstable_equilibrium`` gives chi = 0 on an open set, so its derivative is exactly zero;
``no_cycle_within_limits`` gives h = gap_max - c0, so h moves only with those two values and
chi only through w0; a failed continuation leaves it undefined. For each parameter two case
boundaries are given: the stability boundary (max Re lambda = 0), bracketed by a scan and
solved by Newton's method with the exact slope above; and, to first order, the cycle-limit
boundary between ``unstable_cycle`` and ``no_cycle_within_limits``, where the largest (or
smallest) gap deviation over the whole cycle branch from the Hopf point to the design point
reaches a gap limit (the extreme inside the branch by Brent's method, its derivative by the
envelope theorem).

The maglev layer (:func:`index_sensitivity`) chains these model-parameter derivatives with
exact derivatives of the derived values omega1 = (pi/L)^2 sqrt(EI/mbar),
sigma = 8 k L / (pi^2 l^2 mbar) sin^2(pi l / (2 L)) and w0 = sigma (m + M) g / omega1^2
(Euler-Bernoulli beam, simply supported), so that engineering parameters (L, EI, mbar, l, k)
and the gains (kP, kD, ke, xi0, omega0) all get d chi / d p. For the full vehicle (model B)
the beam enters through the modal frequencies omega_n = n^2 omega1 of its modes and through
L and mbar directly (mode shapes at the six levitation points, modal mass); w0 is the static
mid-span deflection sum_n q_n* sin(n pi / 2), differentiated through the same formulas
(:func:`derived_map`), and h is the largest gap deviation over the six points on the cycle.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.optimize

from maglev_match.analyses.matching import MatchingIndex, matching_index
from maglev_match.core import jax_setup  # noqa: F401  (float64)
from maglev_match.core.params import PARAMETER_DOCS, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.cycles import PeriodicOrbit
from maglev_match.dynamics.equilibria import find_equilibrium
from maglev_match.dynamics.system import System
from maglev_match.maglev.base import MaglevModel
from maglev_match.maglev.beam import LIMITS as _LIMITS
from maglev_match.maglev.catalog import DEFAULT_MODEL
from maglev_match.maglev.models import maglev_model

__all__ = [
    "DerivativeStatus",
    "SystemSensitivity",
    "ParameterSensitivity",
    "IndexSensitivity",
    "system_sensitivity",
    "index_sensitivity",
    "engineering_names",
    "derived_map",
    "linearised_spread",
    "SampledSpread",
    "sampled_spread",
]

Array = Any


class DerivativeStatus(StrEnum):
    """How d h / d p (of the headline index: d h_simulation / d p where chi_simulation is
    the headline) was obtained."""

    EXACT = "exact"  # implicit differentiation of the converged cycle
    ZERO = "zero"  # chi = 0 on an open set (unstable equilibrium): derivative exactly 0
    RULE = "rule"  # h = gap_max - c0 by the case rule: only those two move h
    UNDEFINED = "undefined"  # the index itself failed; no derivative
    SOLVED = "solved"  # implicit function theorem on the solved critical-disturbance condition
    UNAVAILABLE = "unavailable"  # chi_simulation only bracketed by bisection: no derivative


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


@dataclass(frozen=True)
class ParameterSensitivity:
    """One row of the sensitivity table (SI units of the parameter)."""

    name: str
    value: float
    unit: str
    dchi: float  # d chi / d p of the headline index (NaN where not available)
    elasticity: float  # (p / chi) d chi / d p (dimensionless); nan when chi = 0
    dmargin: float  # d (-max Re lambda) / d p (1/s per unit)
    dhopf_distance: float | None  # d (relative Hopf distance) / d p
    boundary: float | None = None  # value of p at the nearest stability boundary
    boundary_relative: float | None = None  # (boundary - p) / p
    # first-order value of p where the bounding cycle's gap maximum reaches gap_max - c0
    # (the boundary between cases unstable_cycle and no_cycle_within_limits)
    limit_boundary: float | None = None
    note: str = ""
    dchi_paper: float = float("nan")  # d chi_paper / d p (the paper's definition)
    dchi_simulation: float | None = None  # d chi_simulation / d p (None: not available)
    # one-sided derivatives of the headline where it switches between its parts (or
    # h_simulation between directions): (for a decrease of p, for an increase of p)
    dchi_left: float | None = None
    dchi_right: float | None = None


@dataclass(frozen=True)
class IndexSensitivity(Plottable):
    """Sensitivities of chi, the margin and the Hopf distance of model A at one point."""

    __repr__ = compact_repr

    index: MatchingIndex
    status: DerivativeStatus
    rows: tuple[ParameterSensitivity, ...]
    system: SystemSensitivity
    limit_boundary_note: str = ""
    warnings: tuple[str, ...] = ()
    paper_status: DerivativeStatus | None = None  # how d chi_paper / dp was obtained
    simulation_status: str = ""  # how d chi_simulation / dp was obtained (or why not)
    switch_note: str = ""  # the headline at a switch between its parts: one-sided values
    _by_name: dict[str, ParameterSensitivity] = field(default_factory=dict, repr=False,
                                                     compare=False)

    def __post_init__(self) -> None:
        self._by_name.update({r.name: r for r in self.rows})

    def dchi(self, name: str) -> float:
        return self._by_name[name].dchi

    def dmargin(self, name: str) -> float:
        return self._by_name[name].dmargin

    def row(self, name: str) -> ParameterSensitivity:
        return self._by_name[name]

    def sorted_rows(self) -> list[ParameterSensitivity]:
        """Rows by |elasticity| (|d chi/dp| where chi = 0), largest first."""
        def key(r: ParameterSensitivity) -> float:
            e = r.elasticity if math.isfinite(r.elasticity) else 0.0
            return -abs(e) if self.index.chi else -abs(r.dmargin * r.value)
        return sorted(self.rows, key=key)

    def as_json(self) -> dict[str, Any]:
        return {
            "chi": self.index.chi, "chi_paper": self.index.chi_paper,
            "chi_simulation": self.index.chi_simulation,
            "reading_basis": str(self.index.reading_basis), "headline": self.index.headline,
            "paper_status": None if self.paper_status is None else str(self.paper_status),
            "simulation_status": self.simulation_status, "switch_note": self.switch_note,
            "h": self.index.h, "w0": self.index.w0,
            "case": self.index.case, "status": str(self.status),
            "max_real_part": self.index.max_real_part,
            "hopf_param": self.index.hopf_param, "hopf_value": self.index.hopf_value,
            "hopf_distance": self.index.hopf_distance,
            "t_star": self.system.t_star, "solve_residual": self.system.solve_residual,
            "limit_boundary_note": self.limit_boundary_note,
            "rows": [dict(r.__dict__) for r in self.sorted_rows()],
            "warnings": list(self.warnings),
        }


# ---------------------------------------------------------------------------------------
# system level
# ---------------------------------------------------------------------------------------
def _cycle_h_derivative(system: System, orbit: PeriodicOrbit, observable: str,
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


def branch_extremes(system: System, p: np.ndarray, search: Mapping[str, tuple[float, float]],
                    observable: str = "gap_deviation", bound: Any = None
                    ) -> dict[str, tuple[float, np.ndarray, float]] | None:
    """The largest and the smallest value of ``observable`` over the whole branch of the
    bounding cycle, from its Hopf point to the design point (continued without limits), and
    their derivatives by every parameter.

    The index's case rule looks at that whole branch: it says ``no_cycle_within_limits`` as
    soon as the branch touches a limit anywhere before the design point, so the case boundary
    is where one of these two extremes reaches its limit. An extreme inside the branch is
    located by Brent's method on the branch parameter (cycles re-solved by
    :func:`~maglev_match.dynamics.cycles.correct_cycle`); its derivative by the other
    parameters then follows from the envelope theorem (d/d lambda = 0 there).

    Returns {"max": (value, d/dp, lambda*), "min": (...)} or None when no surrounding cycle
    is found without limits either. ``bound``: the unlimited
    :func:`~maglev_match.dynamics.basin.bounding_cycle` result, when already computed
    (:func:`unlimited_bound`).
    """
    from maglev_match.dynamics.cycles import correct_cycle

    bound = bound if bound is not None else unlimited_bound(system, p, search)
    if bound.case != "unstable_cycle" or not bound.branches:
        return None
    br = bound.branches[-1]
    pts = [pt for pt in br.points if pt.converged]
    out: dict[str, tuple[float, np.ndarray, float]] = {}
    for key, sign, col in (("max", 1.0, 0), ("min", -1.0, 1)):
        vals = np.array([sign * pt.extrema[observable][col] for pt in pts])
        j = int(np.argmax(vals))
        pt = pts[j]
        if 0 < j < len(pts) - 1:
            lo, hi = sorted((pts[j - 1].value, pts[j + 1].value))
            solved: dict[float, Any] = {}

            def neg(lam: float, j: int = j, sign: float = sign, col: int = col,
                    solved: dict = solved) -> float:
                r = correct_cycle(system, pts[j].orbit, br.param, lam,
                                  observables=[observable])
                if not r.converged or r.point is None:
                    return math.inf
                solved[lam] = r.point
                return -sign * r.point.extrema[observable][col]

            res = scipy.optimize.minimize_scalar(
                neg, bounds=(lo, hi), method="bounded",
                options={"xatol": 1e-9 * max(abs(pt.value), 1e-12)})
            if float(res.x) in solved:
                pt = solved[float(res.x)]
        val, dval, _, _ = _cycle_h_derivative(system, pt.orbit, observable, sign)
        out[key] = (val, dval, float(pt.value))
    return out


def unlimited_bound(system: System, p: np.ndarray,
                    search: Mapping[str, tuple[float, float]]) -> Any:
    """The bounding-cycle search of the index with the gap limits off (index settings)."""
    from maglev_match.analyses.matching import cycle_settings as cs
    from maglev_match.dynamics.basin import bounding_cycle

    return bounding_cycle(system, np.asarray(p, float), search, limits=None, ntst=cs.ntst,
                          ncol=cs.ncol, max_steps=cs.max_steps)


def limit_contact(system: System, bound: Any, hi: float, lo: float,
                  observable: str = "gap_deviation"
                  ) -> tuple[float, np.ndarray, str, bool] | None:
    """Where a cycle branch first reaches a gap limit (``hi`` above, ``lo`` below, as gap
    deviations in m) between its Hopf point and the design point (the first such branch, in
    the index's order: nearest Hopf point first), when no branch can be continued to the
    design point even without limits (e.g. the force is singular at gap 0, so the branch
    ends at the lower limit). The contact lambda_c solves E(lambda) = limit, with E the
    extreme of ``observable`` on the cycle at the branch parameter lambda (Brent's method
    on cycles re-solved by :func:`~maglev_match.dynamics.cycles.correct_cycle`).

    Returns (lambda_c, dE/dp at the contact for every parameter, "max" or "min", whether
    the contact was solved (False: bracketed between two branch points, see below)) or None
    when no branch reaches a limit between its Hopf point and the design point."""
    from maglev_match.dynamics.cycles import correct_cycle

    br = pts = j = None
    for b in bound.branches:  # in the order of the index: nearest Hopf point first
        cand = [pt for pt in b.points if pt.converged]
        if len(cand) < 2:
            continue
        lam_h, design = cand[0].value, bound.design[b.param]
        jj = next((i for i, pt in enumerate(cand)
                   if pt.extrema[observable][0] >= hi or pt.extrema[observable][1] <= lo), None)
        # only a contact between the Hopf point and the design point decides the case
        if jj and (cand[jj].value - lam_h) * (design - lam_h) > 0 and \
                abs(cand[jj].value - lam_h) <= abs(design - lam_h):
            br, pts, j = b, cand, jj
            break
    if br is None:
        return None
    key, sign, col, limit = (("max", 1.0, 0, hi) if pts[j].extrema[observable][0] >= hi
                             else ("min", -1.0, 1, lo))
    seen: dict[float, Any] = {}

    def excess(lam: float) -> float:
        r = correct_cycle(system, pts[j - 1].orbit, br.param, lam, observables=[observable])
        if not r.converged or r.point is None:
            raise ArithmeticError(f"cycle not re-solved at {br.param} = {lam:.8g}")
        seen[lam] = r.point
        return sign * (r.point.extrema[observable][col] - limit)

    try:
        lam = scipy.optimize.brentq(excess, pts[j - 1].value, pts[j].value,
                                    xtol=1e-12 * max(abs(pts[j].value), 1.0))
        pt = seen.get(lam) or correct_cycle(system, pts[j - 1].orbit, br.param, lam,
                                            observables=[observable]).point
        solved = pt is not None
    except (ArithmeticError, ValueError):
        solved = False
    if not solved:
        # at the singular gap 0 the re-solved cycles do not bracket the contact (the
        # extreme there moves with the mesh by more than the step between branch points):
        # the contact is taken between the two branch points, by linear interpolation of
        # the extreme, with the derivative of the last cycle inside the limit
        e0, e1 = (pts[j - 1].extrema[observable][col], pts[j].extrema[observable][col])
        t = (limit - e0) / (e1 - e0) if e1 != e0 else 1.0
        lam = pts[j - 1].value + min(max(t, 0.0), 1.0) * (pts[j].value - pts[j - 1].value)
        pt = pts[j - 1]
    _, dval, _, _ = _cycle_h_derivative(system, pt.orbit, observable, sign)
    return float(lam), dval, key, solved


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
        h, dh, t_star, resid = _cycle_h_derivative(system, index.cycle.orbit, observable)
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


# ---------------------------------------------------------------------------------------
# beam and vehicle data -> model parameters, w0, h_max (the model's own map)
# ---------------------------------------------------------------------------------------
_FAR = 4.0  # boundaries are looked for within a factor 4 of the design value


def engineering_names(params: Params, model: str = "unit") -> tuple[str, ...]:
    """The parameters with a d chi / d p row (the model's
    :meth:`~maglev_match.maglev.base.MaglevModel.engineering_names`): its own parameters,
    with the derived modal values replaced by the beam's where they are derived, and
    gap_max. Model A: omega1 and sigma become L, EI, mbar, l, k; model B: omega1 becomes EI
    (:mod:`maglev_match.maglev.beam`)."""
    return maglev_model(params, model).engineering_names()


def derived_map(params: Params, model: str = "unit") -> Callable:
    """q (values of :func:`engineering_names`) -> (model parameter vector, w0, h_max), a
    JAX function so its Jacobian is exact (the model's
    :meth:`~maglev_match.maglev.base.MaglevModel.derived_map`, formulas in
    :mod:`maglev_match.maglev.beam`)."""
    return maglev_model(params, model).derived_map()


def _values(params: Params, names: tuple[str, ...]) -> np.ndarray:
    return np.array([float(getattr(params, n)) for n in names])


def index_sensitivity(params: Params, index: MatchingIndex | None = None, *,
                      boundaries: bool = True, model: str | None = None,
                      simulate: bool = True) -> IndexSensitivity:
    """d chi / d p, the elasticity (p / chi) d chi / d p, d margin / d p and the derivative of
    the relative Hopf distance for every parameter of model A or model B at ``params``.

    Parameters
    ----------
    params : the parameter set.
    index : the index at ``params`` (computed, without simulation, when not given).
    boundaries : also solve, for each parameter, the value where the equilibrium changes
        stability (Newton's method with the exact slope of max Re lambda), and the first-order
        cycle-limit boundary.
    model : 'unit' (model A) or 'vehicle' (model B); default: the model of ``index``, else
        'unit'. For the vehicle, h is the largest gap deviation over the six levitation
        points on the cycle (the envelope theorem picks the point and the time of the
        maximum) and w0 the static mid-span deflection (:func:`derived_map`).

    simulate : when ``index`` is not given, compute it with the simulation (the headline is
        then the smaller of chi_paper and chi_simulation) or without (the paper's chi).

    The derivative is that of the headline ``index.chi``. chi_paper = h / w0 gives
    d chi_paper = (dh - chi_paper dw0) / w0 with dh = (dh/dp_model)(dp_model/dq) in the
    cycle case and dh = d(gap_max - c0) in case ``no_cycle_within_limits``; the vehicle's
    take one implicit solve on its cycle. chi_simulation = h_simulation / w0 with
    h_simulation the solved critical size of the deciding direction: its derivative comes
    from the implicit function theorem on the solved grazing or basin-boundary condition
    (:func:`maglev_match.analyses.critical.critical_derivative`), so it exists only where that
    direction was solved. Where the headline sits at a switch between its two parts (or
    h_simulation between its two directions) the one-sided derivatives are given
    (``dchi_left``, ``dchi_right``).
    """
    from threadpoolctl import threadpool_limits

    m = maglev_model(params, model or (index.model if index is not None else "unit"))
    # small dense blocks: BLAS threads only contend (as in matching_index)
    with threadpool_limits(m.blas_threads):
        return _index_sensitivity(m, index, boundaries, simulate)


#: two parts of the headline (or two directions of h_simulation) within this relative
#: distance are treated as a switch: one-sided derivatives
SWITCH_TOL = 1e-6


def _simulation_derivative(m: MaglevModel, idx: MatchingIndex, Pq: np.ndarray,
                           names: tuple[str, ...]) -> tuple[dict[str, np.ndarray], str]:
    """d h_simulation / dq of each direction whose critical size was solved (keys 'up',
    'down'), in the engineering parameters q, and a text on how (or why not)."""
    from maglev_match.analyses.critical import critical_derivative

    out: dict[str, np.ndarray] = {}
    why = []
    for key, crit in (("up", idx.critical_up), ("down", idx.critical_down)):
        if crit is None or not crit.solved:
            if crit is not None:
                why.append(f"{key}: {crit.mechanism} (no derivative)")
            continue
        c = crit if crit.dsize_dp is not None else critical_derivative(m, crit)
        if c.dsize_dp is None:
            why.append(f"{key}: {c.mechanism}, derivative run failed")
            continue
        dq = c.dsize_dp @ Pq
        if c.limit == "upper" and "gap_max" in names:
            dq = dq + (c.dsize_dlimit or 0.0) * np.array([1.0 if n == "gap_max" else 0.0
                                                          for n in names])
        out[key] = dq
        why.append(f"{key}: implicit function theorem on the solved {c.mechanism} condition")
    return out, "; ".join(why)


def _index_sensitivity(m: MaglevModel, index: MatchingIndex | None, boundaries: bool,
                       simulate: bool = True) -> IndexSensitivity:
    params = m.params
    idx = index if index is not None else matching_index(m, simulate=simulate)
    system = m.system()
    search = m.hopf_search()
    names = m.engineering_names()
    q = _values(params, names)
    fmap = m.derived_map()
    jac = _map_jacobian(fmap)
    (pm, w0, hmax), (Pq, W0q, Hq) = jac(jnp.asarray(q))
    Pq, W0q, Hq = np.asarray(Pq), np.asarray(W0q), np.asarray(Hq)
    w0 = float(w0)
    sens = system_sensitivity(system, idx, np.asarray(pm))
    warnings = list(sens.warnings)
    if abs(w0 - idx.w0) > 1e-8 * abs(idx.w0):
        warnings.append(f"the static deflection of the beam formulas, {w0:.10g} m, differs "
                        f"from the index's w0 {idx.w0:.10g} m")
    status = sens.h_status
    paper_status = status
    if status == DerivativeStatus.RULE:
        dh_q = Hq
    else:
        dh_q = sens.dh_dp @ Pq
    chi_p = idx.chi_paper
    if status == DerivativeStatus.ZERO:
        dchi_paper = np.zeros(len(names))
    else:
        dchi_paper = (dh_q - chi_p * W0q) / w0
    # the headline: chi_paper, chi_simulation, or a switch between them
    chi = idx.chi
    dchi = dchi_paper
    dchi_sim = None
    left = right = None
    sim_status = ""
    switch_note = ""
    if idx.chi_simulation is not None and idx.h_simulation is not None:
        dh_sims, sim_status = _simulation_derivative(m, idx, Pq, names)
        sizes = {"up": idx.h_simulation_up, "down": idx.h_simulation_down}
        near = [k for k, v in sizes.items() if v is not None
                and abs(v - idx.h_simulation) <= SWITCH_TOL * idx.h_simulation]
        if all(k in dh_sims for k in near):
            parts = [(dh_sims[k] - idx.chi_simulation * W0q) / w0 for k in near]
            dchi_sim = parts[0] if len(parts) == 1 else np.minimum(parts[0], parts[1])
            if len(parts) == 2:
                switch_note = ("h_simulation is at a switch between its two directions: "
                               "one-sided derivatives")
                left, right = np.maximum(parts[0], parts[1]), np.minimum(parts[0], parts[1])
        tie = (math.isfinite(chi_p) and abs(chi_p - idx.chi_simulation)
               <= SWITCH_TOL * max(abs(chi_p), 1e-300))
        if tie:
            switch_note = ("the headline is at a switch between chi_paper and chi_simulation: "
                           "one-sided derivatives")
            if dchi_sim is not None and status != DerivativeStatus.UNDEFINED:
                left = np.maximum(dchi_paper, dchi_sim if left is None else left)
                right = np.minimum(dchi_paper, dchi_sim if right is None else right)
                dchi = right
            else:
                dchi = np.full(len(names), np.nan)
                status = DerivativeStatus.UNAVAILABLE
        elif idx.reading_basis == "simulation":
            if dchi_sim is not None:
                dchi = dchi_sim if right is None else right
                status = DerivativeStatus.SOLVED
            else:
                dchi = np.full(len(names), np.nan)
                status = DerivativeStatus.UNAVAILABLE
            if left is not None and right is not None and not switch_note:
                switch_note = "one-sided derivatives"
        elif left is not None:  # the switch is in the non-deciding part: headline smooth
            left = right = None
            switch_note = ""
    dmargin = -(sens.dmax_re_dp @ Pq)
    ddist = None
    if sens.dhopf_dp is not None and idx.hopf_param is not None:
        k = system.param_index(idx.hopf_param)
        v = float(np.asarray(pm)[k])
        a = float(sens.hopf_value)
        # distance = |a - v| / |v| with a = alpha_H(p), v the design value of that parameter
        sgn = math.copysign(1.0, a - v)
        dd_dp = sgn * sens.dhopf_dp / abs(v)
        dd_dp[k] += -sgn / abs(v) - abs(a - v) * math.copysign(1.0, v) / v**2
        ddist = dd_dp @ Pq
    bounds: dict[str, tuple[float | None, str]] = {}
    if boundaries:
        bounds = _stability_boundaries(system, fmap, q, names)
    # the other case boundary: the branch's extreme gap deviation reaching a gap limit
    limit_b = np.full(len(names), np.nan)
    limit_note = ""
    if boundaries and paper_status in (DerivativeStatus.EXACT, DerivativeStatus.RULE):
        ubound = unlimited_bound(system, np.asarray(pm), search)
        ext = branch_extremes(system, np.asarray(pm), search, bound=ubound)
        lo_lim = params.gap_min - params.c0
        contact = (limit_contact(system, ubound, float(hmax), lo_lim)
                   if ext is None and paper_status == DerivativeStatus.RULE else None)
        if ext is None and contact is None:
            limit_note = "no surrounding cycle without the gap limit either: no cycle-limit " \
                         "boundary"
        elif ext is None:
            # the branch cannot reach the design point: the case changes where its contact
            # with the limit, lambda_c(q), meets the design value of the branch parameter.
            # E(lambda_c, p) = limit(q)  =>  d lambda_c / dq = -(dE/dp Pq - dlimit/dq) / E_lam
            lam_c, dE, which, solved = contact
            k = system.param_index(idx.hopf_param)
            e_lam = dE[k]
            dE_other = dE.copy()
            dE_other[k] = 0.0
            c0_k = np.array([1.0 if n == "c0" else 0.0 for n in names])
            dlimit = Hq if which == "max" else -c0_k
            dlam_c = -(dE_other @ Pq - dlimit) / e_lam
            G = lam_c - float(np.asarray(pm)[k])
            dG = dlam_c - Pq[k]
            with np.errstate(divide="ignore", invalid="ignore"):
                pick = np.where(dG != 0, -G / dG, np.nan)
            limit_b = q + pick
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = limit_b / q
            limit_b = np.where((ratio >= 1.0 / _FAR) & (ratio <= _FAR), limit_b, np.nan)
            lim_v = float(hmax) if which == "max" else lo_lim
            limit_note = (f"the cycle branch from the Hopf point at {idx.hopf_param} = "
                          f"{idx.hopf_value:.6g} reaches the gap-deviation limit "
                          f"{lim_v * 1e3:.4g} mm at {idx.hopf_param} = {lam_c:.6g} and cannot "
                          "be continued to the design point"
                          + ("" if solved else " (contact bracketed between two branch points, "
                             "not solved: the cycle is near-singular at gap 0)")
                          + "; 'cycle-limit boundary': where that contact meets the design "
                          "point, to first order")
        else:
            (hi_v, hi_d, hi_l), (lo_v, lo_d, lo_l) = ext["max"], ext["min"]
            c0_k = np.array([1.0 if n == "c0" else 0.0 for n in names])
            # margins to the limits of the gap deviation: (gap_max - c0) - max, min - (gap_min - c0)
            margins = [(float(hmax) - hi_v, Hq - hi_d @ Pq),
                       (lo_v - (params.gap_min - params.c0), lo_d @ Pq + c0_k)]
            with np.errstate(divide="ignore", invalid="ignore"):
                deltas = np.array([np.where(d != 0, -m / d, np.nan) for m, d in margins])
            short = [i for i, (m, _) in enumerate(margins) if m < 0]
            if short:  # case rule in force: every short margin must be made good
                dd = deltas[short]
                same = np.all(np.sign(dd) == np.sign(dd[0]), axis=0)
                pick = np.where(same, dd[np.argmax(np.abs(np.nan_to_num(dd)), axis=0),
                                         np.arange(len(names))], np.nan)
            else:  # the nearest of the two contacts
                pick = deltas[np.argmin(np.abs(np.nan_to_num(deltas, nan=np.inf)), axis=0),
                              np.arange(len(names))]
            limit_b = q + pick
            # a first-order extrapolation far from the design point says nothing: keep it
            # within the factor the stability scan uses
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = limit_b / q
            limit_b = np.where((ratio >= 1.0 / _FAR) & (ratio <= _FAR), limit_b, np.nan)
            limit_note = (f"along the cycle branch from the Hopf point to the design point the "
                          f"gap deviation reaches {hi_v * 1e3:.4g} mm (at {idx.hopf_param} = "
                          f"{hi_l:.5g}) and {lo_v * 1e3:.4g} mm (at {lo_l:.5g}); the limits are "
                          f"{float(hmax) * 1e3:.4g} mm and "
                          f"{(params.gap_min - params.c0) * 1e3:.4g} mm. 'cycle-limit "
                          "boundary': where the first of them is reached, to first order")
    rows = []
    for i, n in enumerate(names):
        note = ""
        if status == DerivativeStatus.ZERO:
            note = "chi = 0 throughout the unstable region: derivative exactly 0"
        elif status == DerivativeStatus.RULE and n not in ("gap_max", "c0"):
            note = "h = gap_max - c0 by the case rule: chi moves only through w0"
        elif status == DerivativeStatus.UNDEFINED:
            note = "undefined: the index did not converge"
        b, bnote = bounds.get(n, (None, ""))
        if bnote:
            note = (note + "; " if note else "") + bnote
        ela = q[i] / chi * dchi[i] if chi and math.isfinite(chi) else float("nan")
        if status == DerivativeStatus.UNAVAILABLE and not note:
            note = "d chi_simulation not available: its critical size is only bracketed"
        rows.append(ParameterSensitivity(
            name=n, value=float(q[i]), unit=PARAMETER_DOCS.get(n, ("", ""))[0],
            dchi=float(dchi[i]), elasticity=float(ela), dmargin=float(dmargin[i]),
            dchi_paper=float(dchi_paper[i]),
            dchi_simulation=None if dchi_sim is None else float(dchi_sim[i]),
            dchi_left=None if left is None else float(left[i]),
            dchi_right=None if right is None else float(right[i]),
            dhopf_distance=None if ddist is None else float(ddist[i]),
            boundary=b, boundary_relative=None if b is None else (b - q[i]) / q[i], note=note,
            limit_boundary=float(limit_b[i]) if np.isfinite(limit_b[i]) else None,
        ))
    return IndexSensitivity(index=idx, status=status, rows=tuple(rows), system=sens,
                            limit_boundary_note=limit_note, warnings=tuple(warnings),
                            paper_status=paper_status, simulation_status=sim_status,
                            switch_note=switch_note)


@cache
def _map_jacobian(fmap: Callable) -> Callable:
    """(values, Jacobians) of the derived map at q, compiled once per map."""

    def fun(q):
        return fmap(q), jax.jacfwd(fmap)(q)

    return jax.jit(fun)


def _stability_boundaries(system: System, fmap: Callable, q: np.ndarray,
                          names: tuple[str, ...], factor: float = _FAR, n_scan: int = 33,
                          max_iter: int = 30) -> dict[str, tuple[float | None, str]]:
    """For each parameter q_k alone: the nearest value where max Re lambda changes sign.

    A log-spaced scan of max Re lambda over [q_k / factor, q_k factor] brackets the sign
    changes; the one nearest q_k is refined by Newton's method with the exact slope of the
    rightmost eigenvalue (eigenvalue perturbation), safeguarded by bisection."""
    out: dict[str, tuple[float | None, str]] = {}
    jac = _map_jacobian(fmap)

    def mre(qv: np.ndarray, k: int, x0):
        (pm, _, _), (Pq, _, _) = jac(jnp.asarray(qv))
        pm, col = np.asarray(pm), np.asarray(Pq)[:, k:k + 1]
        mr, d, x, _ = margin_derivative(system, pm, x0, directions=col)
        return mr, float(d[0]), x

    for k, name in enumerate(names):
        if name in _LIMITS:
            out[name] = (None, "does not affect stability")
            continue
        grid = q[k] * np.geomspace(1.0 / factor, factor, n_scan)
        vals, x = [], None
        for v in grid:
            qv = q.copy()
            qv[k] = v
            try:
                eq = find_equilibrium(system, np.asarray(jac(jnp.asarray(qv))[0][0]), x)
            except np.linalg.LinAlgError:
                vals.append(np.nan)
                continue
            x = eq.x if eq.converged else None
            J = system.jacobian(eq.x, eq.p)
            vals.append(float(np.max(np.linalg.eigvals(J).real)) if eq.converged else np.nan)
        vals_a = np.asarray(vals)
        brackets = [i for i in range(n_scan - 1)
                    if np.isfinite(vals_a[i]) and np.isfinite(vals_a[i + 1])
                    and np.sign(vals_a[i]) != np.sign(vals_a[i + 1])]
        if not brackets:
            out[name] = (None, f"no stability boundary within a factor {factor:g}")
            continue
        i = min(brackets, key=lambda i: abs(math.log(grid[i] * grid[i + 1]) / 2
                                            - math.log(q[k])))
        lo, hi = float(grid[i]), float(grid[i + 1])
        flo = vals_a[i]
        v = 0.5 * (lo + hi)
        found = None
        for _ in range(max_iter):
            qv = q.copy()
            qv[k] = v
            mr, slope, _ = mre(qv, k, None)
            if np.sign(mr) == np.sign(flo):
                lo = v
            else:
                hi = v
            if abs(mr) < 1e-12 or abs(hi - lo) < 1e-13 * abs(v):
                found = v
                break
            nv = v - mr / slope if slope else 0.5 * (lo + hi)
            if not min(lo, hi) < nv < max(lo, hi):
                nv = 0.5 * (lo + hi)
            v = nv
        out[name] = (found if found is not None else v,
                     "" if found is not None else "boundary located to the bracket only")
    return out


def linearised_spread(sens: IndexSensitivity, scatter: Mapping[str, float]
                      ) -> dict[str, Any]:
    """Standard deviation of chi to first order for independent parameters with relative
    standard deviations ``scatter`` (name -> percent): sd = sqrt(sum (dchi/dp p pct/100)^2)."""
    parts = {}
    for name, pct in scatter.items():
        r = sens.row(name)
        parts[name] = abs(r.dchi * r.value * pct / 100.0)
    sd = math.sqrt(sum(v * v for v in parts.values()))
    return {"chi": sens.index.chi, "sd": sd, "contributions": parts}


# ---------------------------------------------------------------------------------------
# sampled spread (Monte Carlo on Dask, resumable)
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SampledSpread:
    """chi over N parameter sets drawn around ``base`` (independent normal relative
    scatter per parameter), beside the linearised estimate."""

    n: int
    chi: np.ndarray  # (n,) NaN where the index failed or the sample was not a valid set
    samples: np.ndarray  # (n, len(names))
    names: tuple[str, ...]
    mean: float
    sd: float
    quantiles: dict[str, float]  # "5%", "50%", "95%"
    failed: int  # samples whose index did not converge
    invalid: int  # samples outside the parameter rules (not computed)
    linearised: dict[str, Any] | None = None

    def fraction_below(self, bound: float) -> float:
        ok = np.isfinite(self.chi)
        return float(np.mean(self.chi[ok] < bound)) if ok.any() else float("nan")

    def as_json(self) -> dict[str, Any]:
        return {"n": self.n, "mean": self.mean, "sd": self.sd, "quantiles": self.quantiles,
                "failed": self.failed, "invalid": self.invalid, "names": list(self.names),
                "linearised": self.linearised}


def _chunk_key(base: Params, scatter: Mapping[str, float], n: int, seed: int,
               chunk: int, model: str = "unit") -> str:
    import json

    d = {"base": {k: v for k, v in sorted(base.as_input_dict().items())},
         "scatter": dict(sorted(scatter.items())), "n": n, "seed": seed, "chunk": chunk}
    if model != DEFAULT_MODEL:  # model A's key as before: its existing checkpoints resume
        d["model"] = model
    return json.dumps(d, sort_keys=True, default=float)


def _sample(base: Params, scatter: Mapping[str, float], n: int, seed: int) -> np.ndarray:
    names = tuple(scatter)
    rng = np.random.default_rng(seed)
    v0 = np.array([float(getattr(base, k)) for k in names])
    pct = np.array([scatter[k] for k in names]) / 100.0
    return v0 * (1.0 + pct * rng.standard_normal((n, len(names))))


def mc_chunk(base_values: dict[str, Any], names: tuple[str, ...], rows: np.ndarray,
             model: str = "unit") -> np.ndarray:
    """chi (no simulation) of ``model`` for each row of sampled values; NaN where the index
    failed, -inf where the sample breaks a parameter rule. Runs on a Dask worker."""
    from maglev_match.core.params import ParameterError, make_params

    out = np.empty(len(rows))
    for i, r in enumerate(rows):
        vals = dict(base_values, **{k: float(v) for k, v in zip(names, r, strict=True)})
        try:
            p = make_params(vals)
        except ParameterError:
            out[i] = -np.inf
            continue
        out[i] = matching_index(p, model=model, simulate=False).chi
    return out


def mc_checkpoint(folder: Any, key: str) -> Any:
    """The Monte Carlo study's checkpoint folder (:class:`maglev_match.core.checkpoint.Checkpoint`):
    ``study.json`` and one ``chunk_AAAAAAA_BBBBBBB.npz`` per chunk of samples [A, B), each
    holding ``chi`` of shape (B - A,) with the study's fingerprint; the map's guarantees (a
    lock, atomic writes, damaged or foreign chunks named and recomputed)."""
    from pathlib import Path

    from maglev_match.core.checkpoint import Checkpoint

    return Checkpoint(folder=Path(folder), spec_key=key,
                      shapes_of=lambda rows: {"chi": (rows[1] - rows[0],)}, prefix="chunk",
                      digits=7, spec_name="study.json", what="Monte Carlo study",
                      noun="chunk", stale=("chunk_*.npy",))


def mc_chunks(n: int, chunk: int) -> list[tuple[int, int]]:
    """The sample ranges [a, b) of the chunks of a study of ``n`` samples."""
    return [(a, min(a + chunk, n)) for a in range(0, n, chunk)]


def sampled_spread(base: Params, scatter: Mapping[str, float], n: int, checkpoint: Any, *,
                   seed: int = 0, chunk: int = 16, resume: bool = False,
                   workers: int | None = None, scheduler: str | None = None,
                   progress: Callable[[int, int], None] | None = None,
                   linearised: dict[str, Any] | None = None,
                   model: str = "unit") -> SampledSpread:
    """The distribution of chi over ``n`` samples, chunk by chunk on Dask (the map's worker
    set-up: single-threaded processes, glibc's malloc thresholds), each chunk saved in
    ``checkpoint`` as it finishes; with ``resume`` finished chunks are reused.

    The folder has the map's guarantees (:func:`mc_checkpoint`): it is locked while the study
    runs (a second run on it raises :class:`~maglev_match.core.checkpoint.CheckpointLocked`),
    chunks are written atomically with the fingerprint of the study (base, scatter, n, seed,
    chunk size, model), and on resume a chunk of another study, a truncated or otherwise
    damaged chunk is named in a :class:`~maglev_match.core.checkpoint.CheckpointWarning` and
    recomputed. ``workers == 0`` computes in this process; ``model`` 'unit' or 'vehicle'.
    """
    import contextlib

    from maglev_match.analyses.maps import TileCount, dask_log_capture, run_pieces_on_dask
    from maglev_match.core.options import MonteCarloOptions
    from maglev_match.core.params import ParameterError

    MonteCarloOptions(samples=n, seed=seed, workers=workers, chunk=chunk)  # checks them
    n = int(n)
    names = tuple(scatter)
    X = _sample(base, scatter, n, int(seed))
    pieces = mc_chunks(n, chunk)
    ck = mc_checkpoint(checkpoint, _chunk_key(base, scatter, n, seed, chunk, model))
    base_values = base.as_input_dict()
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(ck.locked(resume, run="Monte Carlo run"))
        except ValueError as exc:
            raise ParameterError("--resume", str(ck.folder), str(exc)) from None
        todo = ck.todo(pieces)
        count = TileCount(len(pieces) - len(todo), len(pieces), ck.folder,
                          noun="Monte Carlo chunks")
        if progress:
            progress(count.done, len(pieces))
        with count.stoppable():
            if todo and workers == 0 and scheduler is None:
                for a, b in todo:
                    ck.save((a, b), {"chi": mc_chunk(base_values, names, X[a:b], model)})
                    count.done += 1
                    if progress:
                        progress(count.done, len(pieces))
            elif todo:
                with dask_log_capture(ck.folder / "dask.log"):
                    run_pieces_on_dask(
                        {(a, b): (mc_chunk, (base_values, names, X[a:b], model))
                         for a, b in todo},
                        lambda piece, chi: ck.save(piece, {"chi": chi}), scheduler, workers,
                        progress, count)
        bad = [t for t in pieces if not ck.check(t).ok]
        if bad:
            raise RuntimeError(f"{len(bad)} of {len(pieces)} Monte Carlo chunks are missing "
                               f"or damaged in {ck.folder} after the run")
        chi = np.concatenate([ck.load(t)["chi"] for t in pieces])
    invalid = int(np.sum(chi == -np.inf))
    chi = np.where(chi == -np.inf, np.nan, chi)
    failed = int(np.sum(np.isnan(chi))) - invalid
    ok = chi[np.isfinite(chi)]
    q = {f"{int(100 * x)}%": float(np.quantile(ok, x)) if ok.size else float("nan")
         for x in (0.05, 0.5, 0.95)}
    return SampledSpread(n=n, chi=chi, samples=X, names=names,
                         mean=float(np.mean(ok)) if ok.size else float("nan"),
                         sd=float(np.std(ok, ddof=1)) if ok.size > 1 else float("nan"),
                         quantiles=q, failed=failed, invalid=invalid, linearised=linearised)
