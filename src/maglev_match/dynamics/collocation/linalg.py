"""Factorisations of the bordered Jacobian of the collocation system
(:class:`~maglev_match.dynamics.collocation.bvp.CollocationProblem`), each with a
``solve(b)`` method: a sparse LU of the whole matrix (:func:`factorize`, SuperLU with a
minimum-degree ordering) and, by default, the condensation of each interval's interior
collocation unknowns (:class:`CondensedLU`, as AUTO does: Doedel, Keller & Kernevez 1991;
Doedel's AUTO notes, ch. "the linear equations"), whose remaining mesh-node system, of
fixed sparsity pattern, is factorised by sparse LU. The interval blocks are inverted or
LU-factorised by batched LAPACK calls (:func:`batched_inverse`, :func:`batched_lu_solve`;
:data:`LU_BLOCKS_FROM` chooses). The same condensation gives the Floquet transfer matrices
(:meth:`CondensedLU.transfer_matrices`). :func:`factor_jacobian` picks the factorisation
named by a :class:`~maglev_match.dynamics.collocation.bvp.LinearSolver`.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from maglev_match.dynamics.collocation.bvp import (
    CollocationParts,
    CollocationProblem,
    LinearSolver,
    interval_nodes,
    sparse_matrix,
)

__all__ = [
    "LU_BLOCKS_FROM",
    "CondensedLU",
    "batched_inverse",
    "batched_lu_solve",
    "factor_jacobian",
    "factorize",
]


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


def batched_inverse(K: np.ndarray) -> np.ndarray:
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


def batched_lu_solve(K: np.ndarray, rhs: np.ndarray) -> tuple[list, np.ndarray]:
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
    """K_j^-1 b_j for every block from :func:`batched_lu_solve`'s factors, b (B, q)."""
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
    inverse per interval block (:func:`batched_inverse`, LAPACK LU) gives [w_j; v_{j+1}] =
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

    def __init__(self, prob: CollocationProblem, pa: CollocationParts,
                 b0: np.ndarray | None = None):
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
            self.Kinv, self.K_lu = batched_inverse(self.K), None
            Z = self.Kinv @ rhs
        else:
            self.Kinv = None
            self.K_lu, Z = batched_lu_solve(self.K, rhs)
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


def factor_jacobian(prob: CollocationProblem, pa: CollocationParts, solver: str,
                    b0: np.ndarray | None = None):
    """A factorisation of the bordered Jacobian with a ``solve(b)`` method (``b0``: the
    right-hand side of the first solve, which the condensed solver handles in its setup)."""
    if solver == LinearSolver.CONDENSED:
        return CondensedLU(prob, pa, b0)
    return factorize(sparse_matrix(prob, pa))
