"""The discretisation of the periodic boundary-value problem by orthogonal collocation on a
mesh: the Gauss points and Lagrange basis of each interval (de Boor & Swartz 1973; Ascher,
Mattheij & Russell 1995, ch. 5), the JAX kernels of the collocation rows, the bordered
system :class:`CollocationProblem` with its residual and Jacobian blocks, the whole sparse
Jacobian, the evaluation of a profile and mesh adaptation (as in AUTO-07p, Doedel's notes
ch. "periodic solutions").

Time is rescaled to [0, 1], u' = T f(u, p). The mesh 0 = t_0 < ... < t_NTST = 1 carries on
each interval a polynomial of degree NCOL given by its values at NCOL + 1 equally spaced
nodes (shared at interval ends, so the profile is continuous); N = NTST NCOL + 1 nodes.

Unknowns (scaled, Y = X / S): X = (U_0, ..., U_{N-1}, T, lambda), U_k in R^n, S = (state
scale per node, T0, lambda scale). The bordered system F(Y) = 0 and the rows of its sparse
Jacobian dF/dY (:meth:`CollocationProblem.evaluate`)::

                          U_0 ... U_{N-1}          T        lambda
    collocation   [ h_j (L'(z)U/h_j - T f(L(z)U)) | -h_j f | -h_j T f_lambda ]  NTST NCOL n rows
                    (blocks of NCOL x (NCOL+1) nodes of interval j, scaled by 1/scale)
    periodicity   [ -I  0 ...  0  +I               |   0    |   0            ]  n rows
    phase         [ int <., u_ref'> dt (weights)   |   0    |   0            ]  1 row
    last          [ row (arclength W t, or e_lambda for a fixed parameter)   ]  1 row

Collocation at the NCOL Gauss-Legendre points z of every interval; the integral phase
condition int_0^1 <u - u_ref, u_ref'> dt = 0 fixes the time shift. For sensitivities (e.g.
of a limit contact to a parameter, by the implicit function theorem) the problem offers at a
converged Y: the residual and its sparse Jacobian (:meth:`CollocationProblem.evaluate`),
the derivative of the residual with respect to any model parameter by JAX autodiff of f
(:meth:`CollocationProblem.param_derivative`), and the profile at a time s with its
derivative with respect to Y (:meth:`CollocationProblem.profile_at`).

Solving it: the factorisations of the bordered Jacobian are in
:mod:`~maglev_match.dynamics.collocation.linalg`, the Newton and chord correctors in
:mod:`~maglev_match.dynamics.collocation.newton`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from functools import cache, lru_cache

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse

from maglev_match.core.aot import cached_kernel
from maglev_match.core.jax_setup import kernel_arg, to_device
from maglev_match.dynamics.system import System

__all__ = [
    "CollocationBVP",
    "CollocationParts",
    "CollocationProblem",
    "LinearSolver",
    "adapt_mesh",
    "collocation_kernel",
    "collocation_tables",
    "evaluate_profile",
    "interval_nodes",
    "lagrange_basis",
    "node_times",
    "remesh",
    "scaled_collocation_rows",
    "sparse_matrix",
]


@cache
def collocation_tables(m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Nodes c_k = k/m, Gauss points z_l, weights w_l on [0, 1]; L[l,k] = ell_k(z_l),
    D[l,k] = ell_k'(z_l) for the Lagrange basis on the nodes."""
    c = np.linspace(0.0, 1.0, m + 1)
    g, w = np.polynomial.legendre.leggauss(m)
    z, w = 0.5 * (g + 1.0), 0.5 * w
    L, D = lagrange_basis(c, z)
    return c, z, w, L, D


def lagrange_basis(c: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives of the Lagrange basis on nodes c at points s: (len(s), len(c))."""
    s = np.asarray(s, float)
    n = c.size
    L = np.ones((s.size, n))
    D = np.zeros((s.size, n))
    for k in range(n):
        others = [i for i in range(n) if i != k]
        denom = np.prod([c[k] - c[i] for i in others])
        for i in others:
            L[:, k] *= s - c[i]
        for i in others:
            term = np.ones(s.size)
            for r in others:
                if r != i:
                    term *= s - c[r]
            D[:, k] += term
        L[:, k] /= denom
        D[:, k] /= denom
    return L, D


def node_times(mesh: np.ndarray, m: int) -> np.ndarray:
    h = np.diff(mesh)
    t = (mesh[:-1, None] + h[:, None] * (np.arange(m) / m)[None, :]).ravel()
    return np.append(t, mesh[-1])


def interval_nodes(ntst: int, m: int) -> np.ndarray:
    return np.arange(ntst)[:, None] * m + np.arange(m + 1)[None, :]


def evaluate_profile(mesh: np.ndarray, m: int, U: np.ndarray, s: np.ndarray) -> np.ndarray:
    ntst = mesh.size - 1
    j = np.clip(np.searchsorted(mesh, s, side="right") - 1, 0, ntst - 1)
    loc = (s - mesh[j]) / (mesh[j + 1] - mesh[j])
    c = np.linspace(0.0, 1.0, m + 1)
    L, _ = lagrange_basis(c, loc)  # (len(s), m+1)
    nodes = U[interval_nodes(ntst, m)[j]]  # (len(s), m+1, dim)
    return np.einsum("sk,skn->sn", L, nodes)


@cache
def collocation_kernel(rhs: Callable, m: int) -> Callable:
    """Jitted collocation kernel for one right-hand side and NCOL (cached)."""
    _, _, _, L, D = collocation_tables(m)
    Lj, Dj = to_device(L), to_device(D)
    jac = jax.jacfwd(rhs, argnums=0)

    def f_dir(x, p, e):
        return jax.jvp(lambda q: rhs(x, q), (p,), (e,))[1]

    f2 = jax.vmap(jax.vmap(rhs, (0, None)), (0, None))
    j2 = jax.vmap(jax.vmap(jac, (0, None)), (0, None))
    fp2 = jax.vmap(jax.vmap(f_dir, (0, None, None)), (0, None, None))

    def kernel(Ui, h, T, p, e):
        # Ui (ntst, m+1, n) node values per interval; h (ntst,) interval lengths
        Uc = jnp.einsum("lk,jkn->jln", Lj, Ui)
        dU = jnp.einsum("lk,jkn->jln", Dj, Ui) / h[:, None, None]
        F = f2(Uc, p)
        return dU - T * F, F, j2(Uc, p), fp2(Uc, p, e)

    return cached_kernel(kernel, rhs, m)


@cache
def _parts_kernel(rhs: Callable, m: int) -> Callable:
    """Jitted residual and Jacobian blocks of the collocation rows, scaled as in
    :meth:`CollocationProblem.parts`, in one XLA call (cached per right-hand side, NCOL).

    Returns (r_col (NTST, m, n), colT (NTST, m, n), colL (NTST, m, n), blk (NTST, m n,
    (m+1) n) with rows (l, a) and columns (k, b), J (NTST, m, n, n))."""
    _, _, _, L, D = collocation_tables(m)
    Lj, Dj = to_device(L), to_device(D)
    base = collocation_kernel(rhs, m)

    def parts(Ui, h, T, p, e, sc, T_scale, lam_scale):
        res, F, J, Fp = base(Ui, h, T, p, e)
        ntst, n = Ui.shape[0], Ui.shape[2]
        hs = h[:, None, None] / sc
        # [j, l, a, k, b]: D_lk delta_ab - T h_j L_lk J_ab(z_l), rows / sc_a, columns * sc_b
        eye = jnp.eye(n)
        blk = (Dj[None, :, None, :, None] * eye[None, None, :, None, :]
               - (T * h)[:, None, None, None, None] * Lj[None, :, None, :, None]
               * J[:, :, :, None, :])
        blk = blk * (sc[None, None, None, None, :] / sc[None, None, :, None, None])
        return (res * hs, -F * hs * T_scale, -T * Fp * hs * lam_scale,
                blk.reshape(ntst, m * n, (m + 1) * n), J)

    return cached_kernel(parts, rhs, m)


def scaled_collocation_rows(rhs: Callable, m: int) -> Callable:
    """The collocation rows (NTST, m, n) as :meth:`CollocationProblem.parts` scales them,
    (U' - T f(U, p)) h / sc at the collocation points, as a pure JAX function
    ``rows(Ui, h, T, p, sc)`` of the node values per interval (not jitted: for kernels
    built on it, such as the chord iterations' residual and the test-function gradient of
    the cycle curves)."""
    _, _, _, L, D = collocation_tables(m)
    Lj, Dj = jnp.asarray(L), jnp.asarray(D)
    f2 = jax.vmap(jax.vmap(rhs, (0, None)), (0, None))

    def rows(Ui, h, T, p, sc):
        Uc = jnp.einsum("lk,jkn->jln", Lj, Ui)
        dU = jnp.einsum("lk,jkn->jln", Dj, Ui) / h[:, None, None]
        return (dU - T * f2(Uc, p)) * (h[:, None, None] / sc)

    return rows


@cache
def collocation_second_derivative(rhs: Callable, m: int) -> Callable:
    """Jitted gradient with respect to (nodes per interval, T, p) of
    phi = sum Wc * (d/d eps) R(U + eps V, T + eps vT, p + eps vp), R the scaled collocation
    rows of :func:`scaled_collocation_rows` (physical unknowns): the bilinear products
    w^T (R_zz v) that the gradients of bordered test functions need (a branch point of
    cycles; the LPC, PD and NS curves, with vp = 0). Called as
    ``kernel(Ui, T, p, Vi, vT, vp, Wc, h, sc) -> (gU, gT, gp)``."""
    rows = scaled_collocation_rows(rhs, m)

    def phi(Ui, T, p, Vi, vT, vp, Wc, h, sc):
        _, jv = jax.jvp(lambda a, b, c: rows(a, h, b, c, sc), (Ui, T, p), (Vi, vT, vp))
        return jnp.sum(Wc * jv)

    return cached_kernel(jax.grad(phi, argnums=(0, 1, 2)), rhs, m,
                         name="collocation.second_derivative")


@cache
def _residual_kernel(rhs: Callable, m: int) -> Callable:
    """Jitted scaled residual of the collocation rows alone, (NTST, m, n), as
    :meth:`CollocationProblem.parts` scales it (for the chord iterations, which need no
    Jacobian)."""
    return cached_kernel(scaled_collocation_rows(rhs, m), rhs, m,
                         name="collocation.bvp.scaled_rows")


@lru_cache(maxsize=32)
def _pattern(ntst: int, m: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices of the collocation blocks (ntst, m, m+1, n, n)."""
    j = np.arange(ntst)[:, None, None, None, None]
    l_ = np.arange(m)[None, :, None, None, None]
    k = np.arange(m + 1)[None, None, :, None, None]
    a = np.arange(n)[None, None, None, :, None]
    b = np.arange(n)[None, None, None, None, :]
    shape = (ntst, m, m + 1, n, n)
    rows = np.broadcast_to((j * m + l_) * n + a, shape).ravel()
    cols = np.broadcast_to((j * m + k) * n + b, shape).ravel()
    return rows, cols


@dataclass(frozen=True)
class CollocationParts:
    """Residual and Jacobian blocks of the bordered system at one point (scaled).

    resid : (size,) residual; blk : (NTST, m n, (m+1) n) collocation blocks, row l n + a
    (equation at Gauss point l, component a), column k n + b (node k of interval j,
    component b); colT, colL :
    (NTST m n,) the T and lambda columns of the collocation rows; phase : (N n,) the phase
    row; last : (size,) the last row; blocks : (J, T, h) for the Floquet multipliers."""

    resid: np.ndarray
    blk: np.ndarray
    colT: np.ndarray
    colL: np.ndarray
    phase: np.ndarray
    last: np.ndarray
    blocks: tuple


class LinearSolver(StrEnum):
    """How the Newton corrector solves the bordered collocation system."""

    CONDENSED = "condensed"  # interior nodes condensed per interval, then a small sparse LU
    SPARSE_LU = "sparse_lu"  # sparse LU of the whole system, rebuilt from COO (the old path)


@dataclass
class CollocationProblem:
    """The collocation BVP in one parameter (see the module docstring for the rows).

    Scaled unknowns Y = X / S with X = (profile nodes (N*n), T, lambda); ``ipar`` is the
    index of lambda in the parameter vector ``p0``; ``mesh`` (NTST + 1,) and ``m`` = NCOL.
    """

    system: System
    ipar: int
    p0: np.ndarray
    mesh: np.ndarray
    m: int
    scale: np.ndarray  # state scale (n,)
    T_scale: float
    lam_scale: float
    linear_solver: str = LinearSolver.CONDENSED

    @property
    def n(self) -> int:
        return self.system.dim

    @property
    def N(self) -> int:
        return (self.mesh.size - 1) * self.m + 1

    @property
    def size(self) -> int:
        return self.N * self.n + 2

    def S(self) -> np.ndarray:
        """The scale of the unknowns, X = S Y (remembered while N and the scales stay)."""
        key = (self.N, self.T_scale, self.lam_scale, self.scale.tobytes())
        memo = self.__dict__.get("_S")
        if memo is None or memo[0] != key:
            S = np.concatenate([np.tile(self.scale, self.N), [self.T_scale, self.lam_scale]])
            S.flags.writeable = False
            memo = (key, S)
            self.__dict__["_S"] = memo
        return memo[1]

    def W(self) -> np.ndarray:
        """Weights of the arclength inner product (RMS over nodes for the profile)."""
        return np.concatenate([np.full(self.N * self.n, 1.0 / self.N), [1.0, 1.0]])

    def unpack(self, Y: np.ndarray) -> tuple[np.ndarray, float, float]:
        X = Y * self.S()
        return X[:-2].reshape(self.N, self.n), float(X[-2]), float(X[-1])

    def pack(self, U: np.ndarray, T: float, lam: float) -> np.ndarray:
        return np.concatenate([np.ravel(U), [T, lam]]) / self.S()

    def params(self, lam: float) -> np.ndarray:
        p = np.array(self.p0, float)
        p[self.ipar] = lam
        return p

    def phase_row(self, Uref: np.ndarray) -> np.ndarray:
        """Coefficients c (N, n) with int <u, u_ref'> dt = sum c * U."""
        ntst, m = self.mesh.size - 1, self.m
        _, _, w, L, D = collocation_tables(m)
        idx = interval_nodes(ntst, m)
        Ui = Uref[idx]  # (ntst, m+1, n)
        dref = np.einsum("lk,jkn->jln", D, Ui)  # h_j u_ref' at Gauss points (h cancels)
        coef = np.einsum("l,lk,jln->jkn", w, L, dref)
        row = np.zeros((self.N, self.n))
        np.add.at(row, idx, coef)
        return row

    def parts(
        self,
        Y: np.ndarray,
        phase: np.ndarray,
        Uref: np.ndarray,
        last_row: np.ndarray,
        last_rhs: float,
    ) -> CollocationParts:
        """The residual and the nonzero blocks of the Jacobian of the bordered system (in
        scaled unknowns), without assembling a matrix: what both linear solvers start from
        (see :meth:`evaluate` for the row layout)."""
        ntst, m = self.mesh.size - 1, self.m
        U, T, lam = self.unpack(Y)
        p = self.params(lam)
        h = np.diff(self.mesh)
        e = np.zeros_like(p)
        e[self.ipar] = 1.0
        idx = interval_nodes(ntst, m)
        sc = self.scale
        out = _parts_kernel(self.system.rhs, m)(
            U[idx], h, T, p, e, sc, self.T_scale, self.lam_scale)
        r_col, colT, colL, blk, J = (np.asarray(a) for a in out)
        r_col, colT, colL = r_col.ravel(), colT.ravel(), colL.ravel()
        pv = (phase * sc).ravel()  # d/dY of the phase integral
        pnorm = np.max(np.abs(pv)) or 1.0
        resid = np.concatenate([
            r_col,
            (U[-1] - U[0]) / sc,
            [np.sum(phase * (U - Uref)) / pnorm],
            [float(last_row @ Y) - last_rhs],
        ])
        return CollocationParts(resid=resid, blk=blk, colT=colT, colL=colL, phase=pv / pnorm,
                                last=np.asarray(last_row, float), blocks=(J, T, h))

    def residual(
        self,
        Y: np.ndarray,
        phase: np.ndarray,
        Uref: np.ndarray,
        last_row: np.ndarray,
        last_rhs: float,
    ) -> np.ndarray:
        """The residual of the bordered system alone (equal to ``parts(...).resid``), one
        compiled call without the Jacobian blocks (the chord iterations of
        :func:`collocation_newton`)."""
        ntst, m = self.mesh.size - 1, self.m
        U, T, lam = self.unpack(Y)
        sc = self.scale
        r_col = np.asarray(_residual_kernel(self.system.rhs, m)(
            U[interval_nodes(ntst, m)], np.diff(self.mesh), T, self.params(lam), sc))
        pnorm = np.max(np.abs(phase * sc)) or 1.0
        return np.concatenate([
            r_col.ravel(),
            (U[-1] - U[0]) / sc,
            [np.sum(phase * (U - Uref)) / pnorm],
            [float(last_row @ Y) - last_rhs],
        ])

    def jacobian_blocks(self, Y: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
        """(J, T, h) at Y: df/dx at the Gauss points (NTST, m, n, n), the period (s) and the
        mesh interval lengths, as :meth:`parts` returns them (for the Floquet multipliers)."""
        ntst, m = self.mesh.size - 1, self.m
        U, T, lam = self.unpack(Y)
        p = self.params(lam)
        h = np.diff(self.mesh)
        idx = interval_nodes(ntst, m)
        _, _, J, _ = collocation_kernel(self.system.rhs, m)(
            kernel_arg(U[idx]), kernel_arg(h), T, kernel_arg(p), np.zeros_like(p))
        return np.asarray(J), T, h

    def evaluate(
        self,
        Y: np.ndarray,
        phase: np.ndarray,
        Uref: np.ndarray,
        last_row: np.ndarray,
        last_rhs: float,
    ) -> tuple[np.ndarray, scipy.sparse.csc_matrix, tuple]:
        """Residual and sparse Jacobian (in scaled unknowns) of the bordered system.
        ``last_row`` is the linear condition appended last (arclength or fixed parameter):
        last_row . Y = last_rhs."""
        pa = self.parts(Y, phase, Uref, last_row, last_rhs)
        return pa.resid, sparse_matrix(self, pa), pa.blocks

    def param_derivative(self, Y: np.ndarray, name: str) -> np.ndarray:
        """d F / d p_name at Y (same row layout and scaling as :meth:`evaluate`), by JAX
        forward-mode differentiation of f with respect to the parameter vector. Only the
        collocation rows depend on p; for name = the continuation parameter this is the
        lambda column of the Jacobian divided by the lambda scale."""
        ntst, m, n = self.mesh.size - 1, self.m, self.n
        U, T, lam = self.unpack(Y)
        p = self.params(lam)
        h = np.diff(self.mesh)
        e = np.zeros_like(p)
        e[self.system.param_index(name)] = 1.0
        idx = interval_nodes(ntst, m)
        _, _, _, Fp = collocation_kernel(self.system.rhs, m)(
            jnp.asarray(U[idx]), jnp.asarray(h), T, jnp.asarray(p), jnp.asarray(e))
        col = (-T * np.asarray(Fp) * h[:, None, None] / self.scale).ravel()
        return np.concatenate([col, np.zeros(n + 2)])

    def profile_at(self, Y: np.ndarray, s: float) -> tuple[np.ndarray, scipy.sparse.csr_matrix]:
        """The state u(s) at normalised time s in [0, 1] (its unit) and du(s)/dY, a sparse
        (n, size) matrix (u(s) is linear in the node values: the Lagrange basis of the
        interval containing s times the state scale)."""
        ntst, m, n = self.mesh.size - 1, self.m, self.n
        s = float(s) % 1.0
        j = int(np.clip(np.searchsorted(self.mesh, s, side="right") - 1, 0, ntst - 1))
        loc = (s - self.mesh[j]) / (self.mesh[j + 1] - self.mesh[j])
        L, _ = lagrange_basis(np.linspace(0.0, 1.0, m + 1), np.array([loc]))
        nodes = interval_nodes(ntst, m)[j]  # (m+1,)
        U, _, _ = self.unpack(Y)
        u = L[0] @ U[nodes]
        rows = np.repeat(np.arange(n)[None, :], m + 1, axis=0).ravel()
        cols = (nodes[:, None] * n + np.arange(n)[None, :]).ravel()
        vals = (L[0][:, None] * self.scale[None, :]).ravel()
        D = scipy.sparse.csr_matrix((vals, (rows, cols)), shape=(n, self.size))
        return u, D


CollocationBVP = CollocationProblem  # the name used inside the package


def sparse_matrix(prob: CollocationProblem, pa: CollocationParts) -> scipy.sparse.csc_matrix:
    """The whole bordered Jacobian as a sparse matrix (assembled from COO triplets)."""
    ntst, m, n, N = prob.mesh.size - 1, prob.m, prob.n, prob.N
    rows, cols = _pattern(ntst, m, n)
    nc = ntst * m * n
    per_rows = nc + np.arange(n)
    ph_row = nc + n
    last = nc + n + 1
    size = prob.size
    ar = np.arange(nc)
    all_rows = np.concatenate([
        rows, per_rows, per_rows, np.full(N * n, ph_row), ar, ar,
        np.full(size, last),
    ])
    all_cols = np.concatenate([
        cols, (N - 1) * n + np.arange(n), np.arange(n), np.arange(N * n),
        np.full(nc, size - 2), np.full(nc, size - 1), np.arange(size),
    ])
    vals = np.concatenate([
        pa.blk.reshape(ntst, m, n, m + 1, n).transpose(0, 1, 3, 2, 4).ravel(), np.ones(n),
        -np.ones(n), pa.phase, pa.colT, pa.colL, pa.last,
    ])
    return scipy.sparse.csc_matrix((vals, (all_rows, all_cols)), shape=(size, size))


def adapt_mesh(mesh: np.ndarray, m: int, U: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """A new mesh (same NTST) equidistributing |u^(m+1)|^(1/(m+1)) (de Boor)."""
    ntst = mesh.size - 1
    h = np.diff(mesh)
    idx = interval_nodes(ntst, m)
    Ui = U[idx] / scale  # (ntst, m+1, n)
    # m-th derivative of each interval's polynomial: m-th finite difference / (h/m)^m
    dm = np.diff(Ui, n=m, axis=1)[:, 0, :] / (h[:, None] / m) ** m
    # (m+1)-th derivative between neighbours (periodic)
    nxt = np.roll(dm, -1, axis=0)
    hn = np.roll(h, -1)
    dm1 = np.linalg.norm(2.0 * (nxt - dm) / (h + hn)[:, None], axis=1)
    dens = 0.5 * (dm1 + np.roll(dm1, 1))
    phi = dens ** (1.0 / (m + 1))
    phi = phi + 0.05 * np.mean(phi) + 1e-300  # keep some points everywhere
    cum = np.concatenate([[0.0], np.cumsum(phi * h)])
    cum /= cum[-1]
    new = np.interp(np.linspace(0.0, 1.0, ntst + 1), cum, mesh)
    new[0], new[-1] = 0.0, 1.0
    # limit the ratio of neighbouring intervals for stability of the corrector
    return new


def remesh(mesh_old, m, U, mesh_new) -> np.ndarray:
    return evaluate_profile(mesh_old, m, U, node_times(mesh_new, m) % 1.0 * (1 - 1e-15))
