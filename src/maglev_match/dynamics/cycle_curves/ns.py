"""The minimally augmented collocation system of a Neimark-Sacker (torus) bifurcation of
cycles in two parameters, with its exact Jacobian.

Unknowns (scaled as in :class:`~maglev_match.dynamics.collocation.CollocationProblem`):
z = (U_0, ..., U_{N-1}, T, p1, p2, theta). Equations: the cycle's collocation, periodicity
and phase rows (N n + 1, p2 free), the real and imaginary parts of one complex test
function g(z, theta) = 0, and the linear condition of the continuation.

The test function (a complex bordered matrix, as BifurcationKit.jl's minimally augmented NS
of periodic orbits and Govaerts 2000, ch. 4, for the Hopf/NS case): A(z, theta) is the
collocation rows with respect to the profile at the fixed period (N n - n rows, real) with
the boundary condition v(1) - e^{i theta} v(0) = 0 in place of periodicity, a complex
N n x N n matrix whose kernel is the Floquet solution of the multiplier e^{i theta};
bordered with complex vectors b, c::

    M = [ A  b ],   M [v; g] = [0; 1],   M^H [w; h] = [0; 1]:   A v = -g b,
        [ c^H 0]

so g = 0 exactly where e^{i theta} is a Floquet multiplier (the PD system is the case
theta = pi). Its derivatives: g_z = -w^H (A_z v) (four real forward-over-reverse products
of the collocation rows, :meth:`AugmentedCycleSystem._bilinear_gradient`), and
g_theta = -w^H (A_theta v) = i e^{i theta} sum_a conj(w_a) v_a(0) over the boundary rows.
The borders are the singular vectors of the previous point.

kappa = cos theta is what the resonance tests read (:mod:`codim2`). theta is an unknown of
the system, not restricted to (0, pi), and the system is regular where the pair meets -1
(R2: the curve turns back in the parameter plane there, the conjugate pair giving the same
points again); the driver ends the NS curve there, where theta reaches pi (solved with
theta fixed at pi), or where it reaches 0 (R1). At theta = 0 the trivial multiplier makes
A singular anyway: an R1 point is a singular point of this system, reported only as
bracketed.
"""

from __future__ import annotations

import cmath

import numpy as np
import scipy.sparse

from maglev_match.dynamics.collocation import CollocationProblem, factorize
from maglev_match.dynamics.cycle_curves.augmented import (
    AugmentedCycleSystem,
    CurveKind,
    Evaluation,
)

__all__ = ["NSCycleSystem", "critical_angle"]


def critical_angle(mult: np.ndarray) -> float | None:
    """theta in (0, pi) of the non-real multiplier pair nearest the unit circle (None if
    there is no non-real multiplier)."""
    mult = np.asarray(mult, complex)
    up = mult[mult.imag > 1e-8 * np.maximum(1.0, np.abs(mult))]
    if up.size == 0:
        return None
    mu = up[int(np.argmin(np.abs(np.abs(up) - 1.0)))]
    return float(np.angle(mu))


class NSCycleSystem(AugmentedCycleSystem):
    """The NS curve's system (module docstring); the unknown vector is
    z = (Y, p2 / scale2, theta)."""

    def __init__(self, prob: CollocationProblem, ipar2: int, scale2: float, theta: float):
        super().__init__(prob, ipar2, scale2, CurveKind.NS)
        self.theta0 = float(theta)

    @property
    def size(self) -> int:
        return self.prob.size + 2

    def angle(self, z: np.ndarray) -> float:
        return float(z[-1])

    def border_size(self) -> int:
        return self.prob.N * self.prob.n

    def join(self, Y: np.ndarray, p2: float) -> np.ndarray:
        """z at the start angle ``theta0``."""
        return np.concatenate([Y, [p2 / self.scale2, self.theta0]])

    def weights(self) -> np.ndarray:
        return np.append(self.prob.W(), [1.0, 1.0])

    def test_entries(self, full: scipy.sparse.coo_matrix, theta: float = 0.0):
        p = self.prob
        Nn, n = p.N * p.n, p.n
        nc = Nn - n
        r, c, v = full.row, full.col, full.data
        keep = (r < nc) & (c < Nn)
        a = np.arange(n)
        vals = np.concatenate([v[keep].astype(complex), np.full(n, -cmath.exp(1j * theta)),
                               np.ones(n, complex)])
        return (np.concatenate([r[keep], nc + a, nc + a]),
                np.concatenate([c[keep], a, Nn - n + a]), vals, Nn)

    def bordered_solve(self, A, b, c):
        r, cc, vals, k = A
        ar = np.arange(k)
        M = scipy.sparse.csc_matrix(
            (np.concatenate([vals, b, np.conj(c)]),
             (np.concatenate([r, ar, np.full(k, k)]), np.concatenate([cc, np.full(k, k), ar]))),
            shape=(k + 1, k + 1))
        lu = factorize(M)
        e = np.zeros(k + 1, complex)
        e[-1] = 1.0
        x = lu.solve(e)
        y = lu.solve(e, trans="H")
        return x[:-1], complex(x[-1]), y[:-1]

    def init_borders(self, z: np.ndarray, c0: np.ndarray | None = None) -> None:
        k = self.border_size()
        rng = np.random.default_rng(0)
        b = rng.standard_normal(k) + 1j * rng.standard_normal(k)
        c = (rng.standard_normal(k) + 1j * rng.standard_normal(k) if c0 is None
             else np.asarray(c0, complex))
        A = self.test_entries(self._full(z)[0], self.angle(z))
        for _ in range(3):
            v, _, w = self.bordered_solve(A, b / np.linalg.norm(b), c / np.linalg.norm(c))
            b, c = w, v
        self.b, self.c = b / np.linalg.norm(b), c / np.linalg.norm(c)

    def evaluate(self, z: np.ndarray, phase: np.ndarray, Uref: np.ndarray) -> Evaluation:
        """Residual (cycle rows, Re g, Im g) and Jacobian (columns Y, p2, theta)."""
        prob = self.prob
        full, pa = self._full(z, phase, Uref)
        Y, _ = self.split(z)
        theta = self.angle(z)
        v, g, w = self.bordered_solve(self.test_entries(full, theta), self.b, self.c)
        Nn, n = prob.N * prob.n, prob.n
        nc = Nn - n
        # w^H (C_z v) = [B(vr, wr) + B(vi, wi)] + i [B(vi, wr) - B(vr, wi)], B bilinear
        bl = self._bilinear_gradient
        vr, vi, wr, wi = v.real, v.imag, w[:nc].real, w[:nc].imag
        gz = -((bl(Y, vr, 0.0, wr) + bl(Y, vi, 0.0, wi))
               + 1j * (bl(Y, vi, 0.0, wr) - bl(Y, vr, 0.0, wi)))
        gth = 1j * cmath.exp(1j * theta) * complex(np.sum(np.conj(w[nc:]) * v[:n]))
        dp2 = prob.param_derivative(Y, prob.system.param_names[self.ipar2])[:-1] * self.scale2
        S = prob.size  # cycle rows 0..S-2; Re g row S-1, Im g row S; p2 column S, theta S+1
        keep = full.row < S - 1
        cols_g = np.arange(S + 2)
        rows = np.concatenate([full.row[keep], np.arange(S - 1), np.full(S + 2, S - 1),
                               np.full(S + 2, S)])
        cols = np.concatenate([full.col[keep], np.full(S - 1, S), cols_g, cols_g])
        gfull = np.append(gz, gth)
        vals = np.concatenate([full.data[keep], dp2, gfull.real, gfull.imag])
        jac = scipy.sparse.coo_matrix((vals, (rows, cols)), shape=(S + 1, S + 2))
        resid = np.concatenate([pa.resid[:-1], [g.real, g.imag]])
        return Evaluation(resid=resid, jac=jac, g=abs(g), v=v, w=w, blocks=pa.blocks)
