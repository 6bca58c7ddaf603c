"""The minimally augmented collocation systems of a fold of cycles (LPC) and of a period
doubling (PD) in two parameters, with their exact Jacobians (the Neimark-Sacker system,
which adds the angle theta as an unknown, is :mod:`~maglev_match.dynamics.cycle_curves.ns`).

Unknowns (scaled as in :class:`~maglev_match.dynamics.collocation.CollocationProblem`):
z = (U_0, ..., U_{N-1}, T, p1, p2). Equations: the collocation rows, periodicity and the
integral phase condition of the cycle (N n + 1 rows, with p2 a second free parameter), the
scalar test function g(z) = 0 of the bifurcation, and one more linear condition (the
pseudo-arclength row of the continuation, or p2 fixed).

The test function g comes from a bordered matrix (Govaerts 2000, ch. 3 and 4; MatCont's
LPC and PD curves; BifurcationKit.jl's ``src/periodicorbit/codim2``)::

    M(z) = [ A(z)  b ]      M [v; g] = [0; 1],    M^T [w; h] = [0; 1],
           [ c^T   0 ]

so that A v = -g b: g = 0 exactly where A is singular (v then spans its kernel, w its
left kernel). The derivative is g_z = -w^T (A_z v), evaluated by JAX (forward over
reverse mode differentiation of the collocation rows; the periodicity and phase rows are
linear in the unknowns and contribute nothing).

* LPC: A is the Jacobian of (collocation, periodicity, phase) with respect to (profile,
  T) at fixed parameters. Its kernel is the generalised Floquet vector (v' = T f_x v +
  sigma f, v periodic, int <v, u_ref'> = 0) that exists exactly when the multiplier 1 is
  double (a fold of cycles; the phase row excludes the trivial direction v = u').
* PD: A is the collocation rows with respect to the profile alone at the fixed period,
  with the anti-periodicity v(1) + v(0) = 0 in place of periodicity (N n square): its
  kernel is the Floquet solution with multiplier -1.

The borders b, c are the left and right singular vectors of the previous point (updated
after each accepted point, as MatCont does), so M stays well conditioned along the curve.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import scipy.sparse

from maglev_match.dynamics.collocation import (
    CollocationProblem,
    collocation_second_derivative,
    factorize,
    interval_nodes,
    sparse_matrix,
)

__all__ = ["CurveKind", "AugmentedCycleSystem", "Evaluation"]


class CurveKind(StrEnum):
    """The bifurcation of cycles continued in two parameters (AUTO / MatCont labels)."""

    LPC = "LPC"  # fold of cycles: a double multiplier +1
    PD = "PD"  # period doubling: a multiplier -1
    NS = "NS"  # Neimark-Sacker (torus): a complex pair e^{+-i theta} (ns.py)


@dataclass(frozen=True)
class Evaluation:
    """The augmented system at one point: residual (N n + 2: cycle rows, then g), its
    Jacobian (sparse COO, N n + 2 rows by N n + 3 columns), the test function g, the kernel
    vector v and left kernel vector w of the bordered matrix, and the collocation blocks
    (J, T, h) for the Floquet multipliers."""

    resid: np.ndarray
    jac: scipy.sparse.coo_matrix
    g: float
    v: np.ndarray
    w: np.ndarray
    blocks: tuple


class AugmentedCycleSystem:
    """The cycle rows of :class:`CollocationProblem` with a second free parameter and the
    bordered test function of ``kind`` (module docstring).

    ``prob.ipar`` is the first parameter (scaled by ``prob.lam_scale``); ``ipar2`` the
    second, scaled by ``scale2``. The unknown vector is z = (Y, p2 / scale2) with Y the
    problem's own scaled unknowns."""

    def __init__(self, prob: CollocationProblem, ipar2: int, scale2: float, kind: CurveKind):
        self.prob = prob
        self.ipar2 = int(ipar2)
        self.scale2 = float(scale2)
        self.kind = CurveKind(kind)
        self.b: np.ndarray | None = None
        self.c: np.ndarray | None = None

    # --- unknowns ---
    @property
    def size(self) -> int:
        return self.prob.size + 1

    @property
    def i_p1(self) -> int:
        """Index of p1 in z."""
        return self.prob.size - 1

    @property
    def i_p2(self) -> int:
        """Index of p2 in z (the last unknown here; the NS system has one more)."""
        return self.prob.size

    def angle(self, z: np.ndarray) -> float:
        """The angle theta of the critical multipliers e^{+-i theta} (NS only; nan)."""
        return float("nan")

    def border_size(self) -> int:
        p = self.prob
        return p.N * p.n + 1 if self.kind == CurveKind.LPC else p.N * p.n

    def split(self, z: np.ndarray) -> tuple[np.ndarray, float]:
        return z[:self.i_p2], float(z[self.i_p2] * self.scale2)

    def join(self, Y: np.ndarray, p2: float) -> np.ndarray:
        return np.append(Y, p2 / self.scale2)

    def unpack(self, z: np.ndarray) -> tuple[np.ndarray, float, float, float]:
        """(U, T, p1, p2) in physical units."""
        Y, p2 = self.split(z)
        self.prob.p0[self.ipar2] = p2
        U, T, p1 = self.prob.unpack(Y)
        return U, T, p1, p2

    def weights(self) -> np.ndarray:
        return np.append(self.prob.W(), 1.0)

    # --- the bordered matrix ---
    def test_entries(self, full: scipy.sparse.coo_matrix
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """The COO entries (rows, cols, values) and the order k of A(z) of the module
        docstring, from the cycle Jacobian ``full`` (the rows and columns of
        :func:`sparse_matrix`, as COO)."""
        p = self.prob
        Nn, n = p.N * p.n, p.n
        r, c, v = full.row, full.col, full.data
        if self.kind == CurveKind.LPC:
            k = Nn + 1
            keep = (r < k) & (c < k)
            return r[keep], c[keep], v[keep], k
        nc = Nn - n
        keep = (r < nc) & (c < Nn)
        a = np.arange(n)
        return (np.concatenate([r[keep], nc + a, nc + a]),
                np.concatenate([c[keep], a, Nn - n + a]),
                np.concatenate([v[keep], np.ones(2 * n)]), Nn)

    def test_matrix(self, full: scipy.sparse.spmatrix) -> scipy.sparse.csc_matrix:
        """A(z) as a sparse matrix (see :meth:`test_entries`)."""
        r, c, v, k = self.test_entries(scipy.sparse.coo_matrix(full))
        return scipy.sparse.csc_matrix((v, (r, c)), shape=(k, k))

    def bordered_solve(self, A, b: np.ndarray, c: np.ndarray
                       ) -> tuple[np.ndarray, float, np.ndarray]:
        """(v, g, w) of M [v; g] = [0; 1] and M^T [w; h] = [0; 1]; ``A`` a sparse matrix
        or the COO entries of :meth:`test_entries`."""
        if isinstance(A, tuple):
            r, cc, vals, k = A
        else:
            Ac = scipy.sparse.coo_matrix(A)
            r, cc, vals, k = Ac.row, Ac.col, Ac.data, Ac.shape[0]
        ar = np.arange(k)
        M = scipy.sparse.csc_matrix(
            (np.concatenate([vals, b, c]),
             (np.concatenate([r, ar, np.full(k, k)]), np.concatenate([cc, np.full(k, k), ar]))),
            shape=(k + 1, k + 1))
        lu = factorize(M)
        e = np.zeros(k + 1)
        e[-1] = 1.0
        x = lu.solve(e)
        y = lu.solve(e, trans="T")
        return x[:-1], float(x[-1]), y[:-1]

    def init_borders(self, z: np.ndarray, c0: np.ndarray | None = None) -> None:
        """Borders near the singular vectors of A at z: two passes of the bordered solve
        (inverse iteration) from ``c0`` (or a smooth start) and a fixed b."""
        k = self.border_size()
        rng = np.random.default_rng(0)
        b = rng.standard_normal(k)
        c = rng.standard_normal(k) if c0 is None else np.asarray(c0, float)
        A = self.test_entries(self._full(z)[0])
        for _ in range(3):
            v, _, w = self.bordered_solve(A, b / np.linalg.norm(b), c / np.linalg.norm(c))
            b, c = w, v
        self.b, self.c = b / np.linalg.norm(b), c / np.linalg.norm(c)

    def update_borders(self, ev: Evaluation) -> None:
        """The borders of the next point: the singular vectors at an accepted point."""
        self.b = ev.w / np.linalg.norm(ev.w)
        self.c = ev.v / np.linalg.norm(ev.v)

    # --- the system ---
    def _full(self, z: np.ndarray, phase=None, Uref=None):
        prob = self.prob
        Y, p2 = self.split(z)
        prob.p0[self.ipar2] = p2
        U, _, _ = prob.unpack(Y)
        if Uref is None:
            Uref = U
        if phase is None:
            phase = prob.phase_row(Uref)
        pa = prob.parts(Y, phase, Uref, np.zeros(prob.size), 0.0)
        return scipy.sparse.coo_matrix(sparse_matrix(prob, pa)), pa

    def evaluate(self, z: np.ndarray, phase: np.ndarray, Uref: np.ndarray) -> Evaluation:
        """Residual and Jacobian of (cycle rows, g) at z (module docstring)."""
        prob = self.prob
        full, pa = self._full(z, phase, Uref)
        Y, p2 = self.split(z)
        A = self.test_entries(full)
        v, g, w = self.bordered_solve(A, self.b, self.c)
        gz = self._g_gradient(Y, v, w)
        dp2 = prob.param_derivative(Y, prob.system.param_names[self.ipar2])[:-1] * self.scale2
        S = prob.size  # the cycle rows are 0..S-2, g is row S-1; columns 0..S-1, p2 is S
        keep = full.row < S - 1
        rows = np.concatenate([full.row[keep], np.arange(S - 1), np.full(S + 1, S - 1)])
        cols = np.concatenate([full.col[keep], np.full(S - 1, S), np.arange(S + 1)])
        vals = np.concatenate([full.data[keep], dp2, gz])
        jac = scipy.sparse.coo_matrix((vals, (rows, cols)), shape=(S, S + 1))
        resid = np.append(pa.resid[:-1], g)
        return Evaluation(resid=resid, jac=jac, g=g, v=v, w=w, blocks=pa.blocks)

    def _g_gradient(self, Y: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        """g_z = -w^T (A_z v) in the scaled unknowns z."""
        vT = float(v[self.prob.N * self.prob.n]) if self.kind == CurveKind.LPC else 0.0
        return -self._bilinear_gradient(Y, v, vT, w)

    def _bilinear_gradient(self, Y: np.ndarray, v: np.ndarray, vT: float, w: np.ndarray
                           ) -> np.ndarray:
        """w^T (C_z v), C the scaled collocation rows, over z = (Y, p2) (scaled); ``v``
        the profile part of a (scaled) vector, ``vT`` its scaled period part, ``w`` the
        collocation-row part of a left vector (real arrays)."""
        prob = self.prob
        ntst, m, n, N = prob.mesh.size - 1, prob.m, prob.n, prob.N
        U, T, p1 = prob.unpack(Y)
        p = prob.params(p1)
        sc = prob.scale
        idx = interval_nodes(ntst, m)
        Vs = v[:N * n].reshape(N, n) * sc
        vT = vT * prob.T_scale
        Wc = w[:ntst * m * n].reshape(ntst, m, n)
        gU, gT, gp = collocation_second_derivative(prob.system.rhs, m)(
            U[idx], T, p, Vs[idx], vT, np.zeros_like(p), Wc, np.diff(prob.mesh), sc)
        gradU = np.zeros((N, n))
        np.add.at(gradU, idx, np.asarray(gU))
        gp = np.asarray(gp)
        out = np.concatenate([(gradU * sc).ravel(), [float(gT) * prob.T_scale,
                                                      gp[prob.ipar] * prob.lam_scale,
                                                      gp[self.ipar2] * self.scale2]])
        return out
