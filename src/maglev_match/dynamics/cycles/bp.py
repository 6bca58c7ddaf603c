"""A branch point of cycles solved directly, on its minimally augmented system, where the
branch's own corrector cannot reach it.

At a branch point (BP) two families of cycles cross: the Jacobian F_Y of the cycle rows
(collocation, periodicity, phase: N n + 1 rows) with respect to Y = (profile, T, lambda)
(N n + 2 columns) loses rank, its null space is two-dimensional (the branch's tangent and
the other family's), while at a fold it keeps full rank (the parameter turns, the null
space is the tangent alone). Near a BP the corrector of the branch, Newton on [F; the
arclength row], is singular at the BP itself and converges ever more slowly next to it,
so the event location may fail inside the step (e.g. a BP within 1e-6 of a fold).

The system solved here (Govaerts 2000, ch. 3 and 4; MatCont's BP of cycles; Allgower &
Georg 1990, sec. 8.1): with the bordered matrix

    B = [ F_Y  b ]     B [V; g] = [0; I_2],     B^T [w; h] = [0; 1],
        [ C^T  0 ]

(b one column, C two; V two columns, g = (g1, g2)), g1 = g2 = 0 exactly where F_Y has a
two-dimensional null space. The unknowns (Y, beta), equations

    F(Y) + beta b = 0,   g1(Y) = 0,   g2(Y) = 0

(square: N n + 3), with the exact derivatives g_j' = -w^T (F_YY V_j) (a forward-over-
reverse JAX product of the collocation rows, which alone are nonlinear in Y) and beta = 0
at a branch point of the unperturbed problem (|beta| is reported: a branch point that
a symmetry breaking has unfolded has beta != 0). The borders start from inverse iterations
of B at the located trial point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse

from maglev_match.dynamics.collocation import (
    CollocationBVP,
    collocation_second_derivative,
    factorize,
    interval_nodes,
    sparse_matrix,
)

__all__ = ["BranchPointSolution", "solve_branch_point"]


@dataclass(frozen=True)
class BranchPointSolution:
    """The solved branch point: Y (scaled unknowns), beta, |g|, the Newton iterations and
    the largest residual; ``converged`` False with ``message`` when Newton failed."""

    Y: np.ndarray
    beta: float
    g: float
    iterations: int
    residual: float
    converged: bool
    message: str = ""


class _BPSystem:
    def __init__(self, prob: CollocationBVP, Uref: np.ndarray):
        self.prob = prob
        self.Uref = Uref
        self.phase = prob.phase_row(Uref)
        self.S = prob.size
        self.b: np.ndarray | None = None
        self.C: np.ndarray | None = None

    def cycle(self, Y):
        """F(Y) (S - 1) and F_Y as COO (S - 1 rows, S columns)."""
        prob, S = self.prob, self.S
        pa = prob.parts(Y, self.phase, self.Uref, np.zeros(S), 0.0)
        full = scipy.sparse.coo_matrix(sparse_matrix(prob, pa))
        keep = full.row < S - 1
        FY = (full.row[keep], full.col[keep], full.data[keep])
        return pa.resid[:-1], FY

    def bordered(self, FY, b, C):
        """(V (S x 2), g (2), w (S - 1)) of B [V; g] = [0; I], B^T [w; h] = [0; 1]."""
        S = self.S
        r, c, v = FY
        ar = np.arange(S)
        B = scipy.sparse.csc_matrix(
            (np.concatenate([v, b, C[:, 0], C[:, 1]]),
             (np.concatenate([r, np.arange(S - 1), np.full(S, S - 1), np.full(S, S)]),
              np.concatenate([c, np.full(S - 1, S), ar, ar]))), shape=(S + 1, S + 1))
        lu = factorize(B)
        E = np.zeros((S + 1, 2))
        E[S - 1, 0] = E[S, 1] = 1.0
        X = np.column_stack([lu.solve(E[:, 0]), lu.solve(E[:, 1])])
        e = np.zeros(S + 1)
        e[S] = 1.0
        y = lu.solve(e, trans="T")
        return X[:S], X[S], y[:S - 1]

    def init_borders(self, Y):
        S = self.S
        rng = np.random.default_rng(7)
        b = rng.standard_normal(S - 1)
        C = np.linalg.qr(rng.standard_normal((S, 2)))[0]
        FY = self.cycle(Y)[1]
        for _ in range(3):
            V, _, w = self.bordered(FY, b / np.linalg.norm(b), C)
            b, C = w, np.linalg.qr(V)[0]
        self.b, self.C = b / np.linalg.norm(b), C

    def g_gradient(self, Y, V, w):
        """-w^T (F_YY V_j) for the two columns of V, in the scaled unknowns (2 x S)."""
        prob = self.prob
        ntst, m, n, N = prob.mesh.size - 1, prob.m, prob.n, prob.N
        U, T, lam = prob.unpack(Y)
        p = prob.params(lam)
        sc = prob.scale
        idx = interval_nodes(ntst, m)
        Wc = w[:ntst * m * n].reshape(ntst, m, n)
        out = np.zeros((2, self.S))
        for j in range(2):
            Vs = V[:N * n, j].reshape(N, n) * sc
            vp = np.zeros_like(p)
            vp[prob.ipar] = V[-1, j] * prob.lam_scale
            gU, gT, gp = collocation_second_derivative(prob.system.rhs, m)(
                U[idx], T, p, Vs[idx], V[N * n, j] * prob.T_scale, vp, Wc,
                np.diff(prob.mesh), sc)
            gradU = np.zeros((N, n))
            np.add.at(gradU, idx, np.asarray(gU))
            out[j] = -np.concatenate([(gradU * sc).ravel(), [float(gT) * prob.T_scale,
                                      float(np.asarray(gp)[prob.ipar]) * prob.lam_scale]])
        return out


def solve_branch_point(prob: CollocationBVP, Y0: np.ndarray, *, tol: float = 1e-10,
                       max_iter: int = 12) -> BranchPointSolution:
    """The branch point of cycles near Y0 (scaled unknowns of ``prob``, on its current
    mesh) on the minimally augmented system of the module docstring. Never raises."""
    Y0 = np.asarray(Y0, float)
    Uref = prob.unpack(Y0)[0]
    sysb = _BPSystem(prob, Uref)
    S = sysb.S
    try:
        sysb.init_borders(Y0)
    except (RuntimeError, ValueError, np.linalg.LinAlgError) as e:
        return BranchPointSolution(Y0, np.nan, np.nan, 0, np.nan, False,
                                   f"the bordered matrix is singular ({e})")
    z = np.append(Y0, 0.0)
    res = np.inf
    for it in range(1, max_iter + 1):
        try:
            Y, beta = z[:S], z[S]
            F, FY = sysb.cycle(Y)
            V, g, w = sysb.bordered(FY, sysb.b, sysb.C)
            G = np.concatenate([F + beta * sysb.b, g])
            gY = sysb.g_gradient(Y, V, w)
            r, c, v = FY
            J = scipy.sparse.csc_matrix(
                (np.concatenate([v, sysb.b, gY[0], gY[1]]),
                 (np.concatenate([r, np.arange(S - 1), np.full(S, S - 1), np.full(S, S)]),
                  np.concatenate([c, np.full(S - 1, S), np.arange(S), np.arange(S)]))),
                shape=(S + 1, S + 1))
            dz = factorize(J).solve(-G)
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as e:
            return BranchPointSolution(z[:S], float(z[S]), np.nan, it, res, False,
                                       f"Newton's method failed ({e})")
        res = float(np.max(np.abs(G)))
        if not np.all(np.isfinite(dz)):
            break
        z = z + dz
        if float(np.max(np.abs(dz))) < tol:
            return BranchPointSolution(z[:S], float(z[S]), float(np.max(np.abs(g))), it, res,
                                       True)
    return BranchPointSolution(z[:S], float(z[S]), np.nan, max_iter, res, False,
                               f"Newton's method did not converge in {max_iter} iterations")
