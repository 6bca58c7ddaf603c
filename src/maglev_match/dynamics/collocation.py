"""The periodic boundary-value problem by orthogonal collocation on a mesh: the Gauss
points and Lagrange basis of each interval (de Boor & Swartz 1973; Ascher, Mattheij &
Russell 1995, ch. 5), the bordered system, its sparse Jacobian, Newton's method and mesh
adaptation (as in AUTO-07p, Doedel's notes ch. "periodic solutions").

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

Linear algebra (:class:`LinearSolver`): by default each Newton step condenses the interior
nodes of every interval out of the system (:class:`CondensedLU`, as AUTO does) and solves
the remaining mesh-node system, of fixed sparsity pattern, by sparse LU; ``"sparse_lu"``
factorises the whole bordered matrix (the earlier code path, kept for comparison).
Continuation uses the chord iteration (:func:`chord_newton`): the factorisation made at
one solution serves the next corrector while the iteration contracts fast, and the same
factorisation gives the tangent and the Floquet transfer matrices
(:meth:`CondensedLU.transfer_matrices`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from functools import cache, lru_cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from maglev_match.core.aot import cached_kernel
from maglev_match.dynamics.system import System

__all__ = ["CollocationProblem", "LinearSolver"]


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
    Lj, Dj = jnp.asarray(L), jnp.asarray(D)
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
    Lj, Dj = jnp.asarray(L), jnp.asarray(D)
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


@cache
def _residual_kernel(rhs: Callable, m: int) -> Callable:
    """Jitted scaled residual of the collocation rows alone, (NTST, m, n), as
    :meth:`CollocationProblem.parts` scales it (for the chord iterations, which need no
    Jacobian)."""
    _, _, _, L, D = collocation_tables(m)
    Lj, Dj = jnp.asarray(L), jnp.asarray(D)
    f2 = jax.vmap(jax.vmap(rhs, (0, None)), (0, None))

    def res(Ui, h, T, p, sc):
        Uc = jnp.einsum("lk,jkn->jln", Lj, Ui)
        dU = jnp.einsum("lk,jkn->jln", Dj, Ui) / h[:, None, None]
        return (dU - T * f2(Uc, p)) * (h[:, None, None] / sc)

    return cached_kernel(res, rhs, m)


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
class _Parts:
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
    ) -> _Parts:
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
        return _Parts(resid=resid, blk=blk, colT=colT, colL=colL, phase=pv / pnorm,
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
            jnp.asarray(U[idx]), jnp.asarray(h), T, jnp.asarray(p), jnp.zeros_like(p))
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
        return pa.resid, _sparse_matrix(self, pa), pa.blocks

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


def _sparse_matrix(prob: CollocationProblem, pa: _Parts) -> scipy.sparse.csc_matrix:
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


def factorize(A: scipy.sparse.csc_matrix):
    """Sparse LU. The minimum-degree ordering on A^T + A keeps the fill of the staircase
    collocation structure small (measured ~3x faster than COLAMD here); threshold
    partial pivoting 0.1 as usual for sparse LU."""
    return scipy.sparse.linalg.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1)


@lru_cache(maxsize=32)
def _reduced_pattern(ntst: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The fixed sparsity pattern of the condensed system (see :class:`CondensedLU`):
    (perm, indices, indptr, size) such that the CSC matrix of the values ``v`` given in
    the assembly order is ``csc_matrix((v[perm], indices, indptr))``. Computed once per
    (NTST, n); each Newton iteration then only fills values in place."""
    M = (ntst + 1) * n + 2
    j = np.arange(ntst)[:, None, None]
    a = np.arange(n)[None, :, None]
    cc = np.concatenate([np.arange(n), n + np.arange(n), [-2, -1]])[None, None, :]
    c_rows = np.broadcast_to(j * n + a, (ntst, n, 2 * n + 2))
    c_cols = np.where(cc >= 0, j * n + cc, M + cc)
    c_cols = np.broadcast_to(c_cols, (ntst, n, 2 * n + 2))
    per = ntst * n + np.arange(n)
    rows = np.concatenate([c_rows.ravel(), per, per, np.full(M, M - 2), np.full(M, M - 1)])
    cols = np.concatenate([c_cols.ravel(), ntst * n + np.arange(n), np.arange(n),
                           np.arange(M), np.arange(M)])
    tmpl = scipy.sparse.csc_matrix((np.arange(1, rows.size + 1, dtype=float), (rows, cols)),
                                   shape=(M, M))
    tmpl.sort_indices()
    if tmpl.nnz != rows.size:  # pragma: no cover - the pattern has no duplicates
        raise AssertionError("duplicate entries in the condensed pattern")
    perm = tmpl.data.astype(np.int64) - 1
    return perm, tmpl.indices.copy(), tmpl.indptr.copy(), M


def _batched_inverse(K: np.ndarray) -> np.ndarray:
    """Inverses of a stack of small square matrices (B, q, q) by LAPACK's LU (dgetrf) and
    its inverse from the factors (dgetri), one call pair per matrix: for the 36 x 36
    interval blocks of model A (NCOL 4) this measured 1.3 ms against 2.1 ms for NumPy's
    batched ``inv`` (which solves against the identity) on 80 blocks. Raises
    ``numpy.linalg.LinAlgError`` on an exactly singular block, like ``numpy.linalg.inv``."""
    getrf, getri = scipy.linalg.lapack.dgetrf, scipy.linalg.lapack.dgetri
    out = np.empty_like(K, dtype=float)
    for j in range(K.shape[0]):
        lu, piv, info = getrf(K[j])
        if info == 0:
            out[j], info = getri(lu, piv)
        if info != 0:
            raise np.linalg.LinAlgError(f"interval block {j} is singular (LAPACK info {info})")
    return out


#: Interval blocks of this order (NCOL n) and larger are factorised by LU and solved
#: (dgetrf + dgetrs, ~2/3 q^3 + 2 q^2 (n + 3) flops per block) instead of inverted
#: (dgetrf + dgetri + a product, ~2 q^3 + 2 q^2 (n + 3)): for the 40-state vehicle (q = 160)
#: that is 2.2x less arithmetic where the factorisation dominates; below it (model A,
#: q = 36) the explicit inverse wins, because each later right-hand side (the chord
#: iterations) is then one batched matrix-vector product instead of a LAPACK call per
#: block.
LU_BLOCKS_FROM = 64


def _batched_lu_solve(K: np.ndarray, rhs: np.ndarray) -> tuple[list, np.ndarray]:
    """LU factors of each block K_j (LAPACK dgetrf on K_j^T, which is K_j's own memory in
    Fortran order: no copy) and the solutions K_j^-1 rhs_j (dgetrs, transposed).
    Raises ``numpy.linalg.LinAlgError`` on an exactly singular block."""
    getrf, getrs = scipy.linalg.lapack.dgetrf, scipy.linalg.lapack.dgetrs
    out = np.empty(rhs.shape)
    factors = []
    for j in range(K.shape[0]):
        lu, piv, info = getrf(np.asfortranarray(K[j].T), overwrite_a=True)
        if info != 0:
            raise np.linalg.LinAlgError(f"interval block {j} is singular (LAPACK info {info})")
        out[j], info = getrs(lu, piv, rhs[j], trans=1)
        factors.append((lu, piv))
    return factors, out


def _lu_solve_blocks(factors: list, b: np.ndarray) -> np.ndarray:
    """K_j^-1 b_j for every block from :func:`_batched_lu_solve`'s factors, b (B, q)."""
    getrs = scipy.linalg.lapack.dgetrs
    return np.stack([getrs(lu, piv, b[j], trans=1)[0] for j, (lu, piv) in enumerate(factors)])


class CondensedLU:
    """Solver of the bordered collocation system by condensation of each interval's interior
    collocation unknowns (Doedel, Keller & Kernevez 1991; AUTO-07p's "condensation of
    parameters", Doedel's AUTO notes, ch. "the linear equations").

    On mesh interval j the m n collocation rows involve the left mesh node v_j, the m - 1
    interior nodes w_j, the right mesh node v_{j+1} and the two border unknowns (T, lambda)::

        A0_j v_j + Aint_j w_j + Aend_j v_{j+1} + cT_j dT + cL_j dlambda = b_j.

    The square block K_j = [Aint_j | Aend_j] (m n x m n) is the collocation matrix of the
    initial-value problem on one interval (nonsingular for a Gauss collocation step, which
    is A-stable, and well conditioned when T h_j |J| is moderate, as the mesh keeps it). One
    inverse per interval block (:func:`_batched_inverse`, LAPACK LU) gives [w_j; v_{j+1}] =
    K_j^{-1} b_j - X_j (v_j, dT, dlambda) with X_j = K_j^{-1} [A0_j cT_j cL_j]. The last n
    rows are n condensed equations v_{j+1} + X_j^end (v_j, dT, dlambda) = (K_j^{-1} b_j)^end
    free of w_j; substituting w_j into the two dense rows (phase and arclength) leaves a
    system in the (NTST + 1) n mesh unknowns and the two borders, (NTST + 1) n + 2 equations
    whose sparsity pattern is fixed (block bidiagonal rows, periodicity, two dense rows and
    columns: filled in place, :func:`_reduced_pattern`) and factorised by SuperLU. The
    interior unknowns are then recovered interval by interval. Every step is an exact
    equivalence transformation, so the solution equals that of the whole system up to
    rounding (tested to 1e-12 relative).

    The right-hand side b0 of the first solve (the Newton step) is solved alongside X_j; a
    right-hand side that vanishes on the collocation rows (the tangent, e_last) needs no
    interval solve at all; any other one (a chord iteration) costs one batched
    matrix-vector product with the kept K_j^{-1}. The end rows of X_j are the interval
    transfer matrices of the variational equation (:meth:`transfer_matrices`).

    Parameters
    ----------
    prob : the collocation problem (for NTST, NCOL, n).
    pa : the Jacobian blocks (:meth:`CollocationProblem.parts`).
    b0 : the right-hand side of the first solve (optional).
    """

    def __init__(self, prob: CollocationProblem, pa: _Parts, b0: np.ndarray | None = None):
        ntst, m, n = prob.mesh.size - 1, prob.m, prob.n
        self.ntst, self.m, self.n, self.size = ntst, m, n, prob.size
        mn, ni = m * n, (m - 1) * n
        A = pa.blk
        B = np.concatenate([A[:, :, :n], A[:, :, m * n:], pa.colT.reshape(ntst, mn, 1),
                            pa.colL.reshape(ntst, mn, 1)], axis=2)  # (ntst, mn, 2n+2)
        nodes = interval_nodes(ntst, m)
        inner = nodes[:, 1:m]  # (ntst, m-1) interior node indices
        ph = pa.phase.reshape(-1, n)
        last = pa.last
        lU = last[:-2].reshape(-1, n)
        # one batched LU solve per interval: [Aint | Aend] [w; v_{j+1}] = b - A0 v_j - ...,
        # with the right-hand side of the first solve (the Newton step) solved alongside
        self.K = A[:, :, n:]
        cols = [B[:, :, :n], B[:, :, 2 * n:]]
        self._b0 = None
        if b0 is not None:
            self._b0 = np.array(b0, float)
            cols.append(self._b0[:ntst * mn].reshape(ntst, mn, 1))
        # the explicit inverse of each interval block: every later right-hand side (the
        # chord iterations) then costs one batched matrix-vector product, not an LU solve
        rhs = np.concatenate(cols, axis=2)
        if mn < LU_BLOCKS_FROM:
            self.Kinv, self.K_lu = _batched_inverse(self.K), None
            Z = self.Kinv @ rhs
        else:
            self.Kinv = None
            self.K_lu, Z = _batched_lu_solve(self.K, rhs)
        X = Z[:, :, :n + 2]
        self.X_end = X[:, ni:, :n]  # v_{j+1} = -X_end v_j on the homogeneous rows
        self._Sb0 = Z[:, :, n + 2] if b0 is not None else None
        C = np.concatenate([X[:, ni:, :n], np.broadcast_to(np.eye(n), (ntst, n, n)),
                            X[:, ni:, n:]], axis=2)  # (ntst, n, 2n+2) condensed rows
        if m > 1:
            self.G = np.concatenate([X[:, :ni, :n], np.zeros((ntst, ni, n)),
                                     X[:, :ni, n:]], axis=2)  # (ntst, ni, 2n+2)
            self.p_in = ph[inner].reshape(ntst, ni)
            self.l_in = lU[inner].reshape(ntst, ni)
            pG = np.einsum("ji,jic->jc", self.p_in, self.G)
            lG = np.einsum("ji,jic->jc", self.l_in, self.G)
        else:
            pG = lG = np.zeros((ntst, 2 * n + 2))
        M = (ntst + 1) * n + 2

        def dense_row(coef_nodes, coef_T, coef_L, sub):
            row = np.zeros(M)
            row[:-2] = coef_nodes[nodes[:, 0].tolist() + [nodes[-1, -1]]].ravel()
            row[-2], row[-1] = coef_T, coef_L
            # node j's entries are row[j n: (j + 1) n]: the left ends of intervals 0..ntst-1
            # and the right ends of 0..ntst-1 are two runs without repeats
            row[:ntst * n] -= sub[:, :n].ravel()
            row[n:(ntst + 1) * n] -= sub[:, n:2 * n].ravel()
            row[-2] -= sub[:, 2 * n].sum()
            row[-1] -= sub[:, 2 * n + 1].sum()
            return row

        prow = dense_row(ph, 0.0, 0.0, pG)
        lrow = dense_row(lU, last[-2], last[-1], lG)
        vals = np.concatenate([C.ravel(), np.ones(n), -np.ones(n), prow, lrow])
        perm, indices, indptr, M = _reduced_pattern(ntst, n)
        Ared = scipy.sparse.csc_matrix((vals[perm], indices, indptr), shape=(M, M))
        self.lu = scipy.sparse.linalg.splu(Ared, permc_spec="MMD_AT_PLUS_A",
                                           diag_pivot_thresh=0.1)
        self.inner = inner

    def transfer_matrices(self, scale: np.ndarray) -> np.ndarray:
        """The interval transfer matrices P_j, v(t_{j+1}) = P_j v(t_j), of the variational
        equation v' = T f_x(u(t)) v discretised by the same collocation (NTST, n, n), in the
        state's own units (``scale``: the state scale of the problem).

        They are a by-product of the condensation: the homogeneous collocation rows of
        interval j, K_j [w_j; v_{j+1}] = -A0_j v_j, give v_{j+1} = -X_j^end v_j with
        X_j = K_j^{-1} A0_j already formed for the Newton step (Doedel's AUTO notes, ch.
        "Floquet multipliers": the multipliers come from the condensed blocks). In scaled
        unknowns v / S, so P_j = S (-X_j^end) S^{-1}."""
        sc = np.asarray(scale, float)
        return -self.X_end * (sc[None, :, None] / sc[None, None, :])

    def solve(self, b: np.ndarray) -> np.ndarray:
        """The solution x of J x = b (the full bordered Jacobian), b of shape (size,)."""
        ntst, m, n = self.ntst, self.m, self.n
        b = np.asarray(b, float)
        mn = m * n
        bc = b[:ntst * mn].reshape(ntst, mn)
        ni = (m - 1) * n
        if self._b0 is not None and np.array_equal(b, self._b0):
            Sb = self._Sb0
        elif not np.any(bc):  # e.g. the tangent: only the last row
            Sb = np.zeros((ntst, mn))
        else:
            Sb = (np.einsum("jab,jb->ja", self.Kinv, bc) if self.Kinv is not None
                  else _lu_solve_blocks(self.K_lu, bc))
        rhs = np.empty((ntst + 1) * n + 2)
        rhs[:ntst * n] = Sb[:, ni:].ravel()
        rhs[ntst * n:(ntst + 1) * n] = b[ntst * mn:ntst * mn + n]
        rhs[-2], rhs[-1] = b[-2], b[-1]
        if m > 1:
            g = Sb[:, :ni]
            rhs[-2] -= float(np.sum(self.p_in * g))
            rhs[-1] -= float(np.sum(self.l_in * g))
        z = self.lu.solve(rhs)
        x = np.empty(self.size)
        V = z[:-2].reshape(ntst + 1, n)
        X = x[:-2].reshape(-1, n)
        X[0::m] = V
        x[-2:] = z[-2:]
        if m > 1:
            zj = np.concatenate([V[:-1], V[1:], np.broadcast_to(z[-2:], (ntst, 2))], axis=1)
            w = g - np.einsum("jic,jc->ji", self.G, zj)
            X[self.inner.ravel()] = w.reshape(-1, n)
        return x


def _factor(prob: CollocationProblem, pa: _Parts, solver: str, b0: np.ndarray | None = None):
    """A factorisation of the bordered Jacobian with a ``solve(b)`` method (``b0``: the
    right-hand side of the first solve, which the condensed solver handles in its setup)."""
    if solver == LinearSolver.CONDENSED:
        return CondensedLU(prob, pa, b0)
    return factorize(_sparse_matrix(prob, pa))


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
            lu = _factor(prob, pa, solver, -r)
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
                lu = _factor(prob, pa, solver, -r)
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
            lu_out = _factor(prob, pa, solver)
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

