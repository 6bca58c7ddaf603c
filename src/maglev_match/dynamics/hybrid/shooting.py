"""Periodic orbits of a hybrid system by single shooting: an independent method.

:func:`shoot_hybrid_orbit` computes the orbits of :mod:`maglev_match.dynamics.hybrid.orbits`
by single shooting on the flow (Newton on the return to a section, with the sensitivities
of :func:`~maglev_match.dynamics.hybrid.flow.hybrid_flow`, saltations included, as in
Leine & Nijmeijer 2004, *Dynamics and Bifurcations of Non-smooth Mechanical Systems*): used
to start the collocation and to check it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.hybrid.flow import FlowOptions, FlowStatus, hybrid_flow
from maglev_match.dynamics.hybrid.system import HybridSystem

__all__ = ["ShotOrbit", "shoot_hybrid_orbit"]


# ---------------------------------------------------------------------------------------
# single shooting (independent method)
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ShotOrbit:
    """A hybrid periodic orbit by single shooting: the point x on the section
    n . (x - x_s) = 0, the period T, the monodromy matrix there (with every saltation),
    its eigenvalues, and the Newton record."""

    __repr__ = compact_repr

    x: np.ndarray
    s: np.ndarray
    period: float
    monodromy: np.ndarray
    multipliers: np.ndarray
    converged: bool
    iterations: int
    residual: float
    message: str = ""


def shoot_hybrid_orbit(hs: HybridSystem, x_guess: np.ndarray, s: np.ndarray, T_guess: float,
                       *, p: np.ndarray | None = None, tol: float = 1e-11,
                       max_iter: int = 20, options: FlowOptions | None = None) -> ShotOrbit:
    """A hybrid periodic orbit by single shooting on the flow with sensitivities: unknowns
    (x, T) with x on the hyperplane through ``x_guess`` normal to the flow there, equations
    x(T; x) - x = 0 and n . (x - x_guess) = 0, Jacobian [[M - I, f(x(T))], [n^T, 0]] with M
    the sensitivity of the end state to the start state (saltations included). ``x_guess``
    must lie inside a segment (away from switches), in mode ``s``."""
    opts = options or FlowOptions()
    pp = np.asarray(hs.p if p is None else p, float)
    n = hs.dim
    x = np.asarray(x_guess, float).copy()
    s = np.asarray(s, float)
    T = float(T_guess)
    f0 = hs.f(x, s, pp)
    nrm = f0 / np.linalg.norm(f0 / hs.state_scale)
    xs = x.copy()
    sc = np.asarray(hs.state_scale, float)
    conv = False
    msg = ""
    res = math.inf
    M = np.full((n, n), np.nan)
    it = 0
    while it < max_iter:
        it += 1
        fl = hybrid_flow(hs, x, T, s0=s, p=pp, tangents=np.eye(n), options=opts)
        if fl.status[0] != FlowStatus.REACHED:
            msg = "the flow failed over one period"
            break
        if not np.array_equal(fl.s[0], s):
            msg = "the run ends in another mode after one period"
            break
        xe, M = fl.x[0], fl.phi[0]
        fe = hs.f(xe, s, pp)
        r = np.concatenate([(xe - x) / sc, [float(nrm @ (x - xs))]])
        res = float(np.max(np.abs(r)))
        Jm = np.zeros((n + 1, n + 1))
        Jm[:n, :n] = (M - np.eye(n)) / sc[:, None]
        Jm[:n, n] = fe / sc
        Jm[n, :n] = nrm
        try:
            dz = np.linalg.solve(Jm, -r)
        except np.linalg.LinAlgError:
            msg = "the shooting Jacobian is singular"
            break
        x = x + dz[:n]
        T = T + dz[n]
        if float(np.max(np.abs(dz[:n] / sc))) <= tol and abs(dz[n]) <= tol * T:
            conv = True
            fl = hybrid_flow(hs, x, T, s0=s, p=pp, tangents=np.eye(n), options=opts)
            M = fl.phi[0]
            break
    if not conv and not msg:
        msg = f"shooting did not converge in {max_iter} iterations (residual {res:.3g})"
    mu = np.linalg.eigvals(M) if np.all(np.isfinite(M)) else np.full(n, np.nan)
    mu = mu[np.argsort(-np.abs(mu))]
    return ShotOrbit(x=x, s=s, period=T, monodromy=M, multipliers=mu, converged=conv,
                     iterations=it, residual=res, message=msg)
