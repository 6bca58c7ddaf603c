"""The critical normal-form coefficient of a Neimark-Sacker (torus) bifurcation of cycles,
from the Poincare map of the collocated cycle (the same map as the flip coefficient's,
:mod:`~maglev_match.dynamics.cycle_curves.flip`).

What it is. At an NS bifurcation the Poincare map P of the cycle has a simple pair of
multipliers e^{+-i theta}; restricted to its two-dimensional centre manifold it reads, in a
complex coordinate z, z -> e^{i theta} z (1 + d |z|^2) + ... (Kuznetsov 2004, Elements of
Applied Bifurcation Theory, sec. 4.7; the resonant terms aside, theta not 0, pi, 2 pi / 3,
pi / 2). For the map x -> A x + B(x, x) / 2 + C(x, x, x) / 6 (x the deviation from the
fixed point) the coefficient is (ibid., the invariant form of the critical coefficient)::

    d = Re{ e^{-i theta} [ <p, C(q, q, qbar)> + 2 <p, B(q, (I - A)^{-1} B(q, qbar))>
                           + <p, B(qbar, (e^{2 i theta} I - A)^{-1} B(q, q))> ] } / 2,

A q = e^{i theta} q, A^T p = e^{-i theta} p, <p, q> = pbar^T q = 1, with |q| = 1 (complex
Euclidean norm) in the system's scaled states (the state vector divided by
``system.state_scale``). d < 0: the NS is supercritical (a stable invariant torus is born
on the side where the cycle is unstable); d > 0: subcritical. A Chenciner point (CH) is a
zero of d on an NS curve.

How. A is the exact Jacobian of the RK4 Poincare map at its fixed point y
(:func:`~maglev_match.dynamics.cycle_curves.flip.poincare_map`); with q = a + i b (a, b
real), the fourth-order central differences of the matrix DP(x) along a and along b
(steps eps, 2 eps: eight Jacobians) give, applied to a vector v, B(v, a), B(v, b), C(v, a,
a) and C(v, b, b); then B(q, qbar) = B(q, a) - i B(q, b), B(q, q) = B(q, a) + i B(q, b),
C(q, q, qbar) = C(q, a, a) + C(q, b, b) (the trilinear form's polarisation), B(q, h) =
B(h, a) + i B(h, b) and B(qbar, h) = B(h, a) - i B(h, b). The same with the second-order
differences gives a second estimate; their distance, plus the rounding of a second
difference, is the error estimate (as for the flip coefficient). Cost: the fixed point's
Newton iterations (from the collocated cycle, one or two Jacobians) and eight Jacobians in
one batched (vmapped) evaluation; measured 6.8 ms CPU per point on the 6-state test
system of tests/systems.py (ns_system, 160 RK4 steps; 2 cores, load 0.6), its NS curve's
113 points 2.9 s instead of 2.0 s warm (the first curve of a model also compiles the map,
about 4 s).
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass

import numpy as np

from maglev_match.dynamics.cycle_curves.flip import (
    PoincareMap,
    difference_stencil,
    poincare_map,
)
from maglev_match.dynamics.cycles.orbits import PeriodicOrbit
from maglev_match.dynamics.system import System

__all__ = ["TorusCoefficient", "torus_coefficient"]


@dataclass(frozen=True)
class TorusCoefficient:
    """The NS coefficient ``d`` of the module docstring, the multiplier of the RK4 Poincare
    map nearest e^{i theta} (``multiplier``: a check of the integration against the
    collocation), the fixed point's residual, the RK4 steps and ``error``, the estimate of
    d's error. ``ok`` False (and ``message`` why) where it could not be computed; d is then
    nan."""

    d: float
    multiplier: complex
    residual: float
    steps: int
    ok: bool = True
    message: str = ""
    error: float = float("nan")


def torus_coefficient(system: System, orbit: PeriodicOrbit, angle: float | None = None, *,
                      per_interval: int = 8, tol: float = 1e-12) -> TorusCoefficient:
    """The NS coefficient d of the cycle ``orbit`` at (or near) a Neimark-Sacker
    bifurcation (module docstring); ``angle``: theta of the critical pair (default: the
    non-real multiplier of the map nearest the unit circle). Never raises on a numerical
    failure: ``ok`` False and ``message`` say what failed."""
    pm = poincare_map(system, orbit, per_interval=per_interval, tol=tol)
    if not isinstance(pm, PoincareMap):
        message, res, steps = pm
        return TorusCoefficient(math.nan, complex(math.nan), res, steps, False, message)
    A, n = pm.A, pm.A.shape[0]
    ev, V = np.linalg.eig(A)
    up = np.flatnonzero(ev.imag > 1e-8 * np.maximum(1.0, np.abs(ev)))
    if up.size == 0:
        return TorusCoefficient(math.nan, complex(math.nan), pm.residual, pm.steps, False,
                                "the Poincare map has no complex pair of multipliers")
    if angle is None or not math.isfinite(angle):
        i = int(up[np.argmin(np.abs(np.abs(ev[up]) - 1.0))])
    else:
        target = cmath.exp(1j * abs(angle))
        i = int(up[np.argmin(np.abs(ev[up] - target))])
    lam = complex(ev[i])
    theta = cmath.phase(lam)
    q = V[:, i] / np.linalg.norm(V[:, i])
    evl, Vl = np.linalg.eig(A.T)
    pv = Vl[:, int(np.argmin(np.abs(evl - lam.conjugate())))]
    pq = complex(np.vdot(pv, q))  # pbar^T q
    if abs(pq) < 1e-12:
        return TorusCoefficient(math.nan, lam, pm.residual, pm.steps, False,
                                "the critical pair is not simple (a Jordan block)")
    pv = pv / pq.conjugate()  # now <p, q> = 1
    y, eps = pm.y, pm.eps
    a, b = q.real, q.imag
    # DP(x) at y +- eps r, y +- 2 eps r for r = a, b (unit-free: |a|^2 + |b|^2 = 1)
    steps = np.array([1.0, -1.0, 2.0, -2.0])
    mats = pm.jacobians_at(np.concatenate([y + eps * steps[:, None] * a,
                                           y + eps * steps[:, None] * b]))
    sa, sb = difference_stencil(*mats[:4], A, eps), difference_stencil(*mats[4:], A, eps)
    I = np.eye(n)
    e2 = cmath.exp(2j * theta)
    ds = []
    for k1, k2 in ((0, 1), (2, 3)):  # the fourth-order, then the second-order differences
        Ba, Ca, Bb, Cb = sa[k1], sa[k2], sb[k1], sb[k2]
        Bq_a, Bq_b = Ba @ q, Bb @ q
        Bqqbar = Bq_a - 1j * Bq_b
        Bqq = Bq_a + 1j * Bq_b
        Cqqqbar = Ca @ q + Cb @ q
        try:
            h11 = np.linalg.solve(I - A, Bqqbar)
            h20 = np.linalg.solve(e2 * I - A, Bqq)
        except np.linalg.LinAlgError:
            return TorusCoefficient(math.nan, lam, pm.residual, pm.steps, False,
                                    "a strong resonance (I - A or e^(2 i theta) I - A is "
                                    "singular)")
        Bq_h11 = Ba @ h11 + 1j * (Bb @ h11)
        Bqbar_h20 = Ba @ h20 - 1j * (Bb @ h20)
        inner = np.vdot(pv, Cqqqbar + 2.0 * Bq_h11 + Bqbar_h20)
        ds.append(0.5 * float((cmath.exp(-1j * theta) * inner).real))
    d, d2 = ds
    rounding = 1e-15 * float(np.abs(pv) @ np.abs(A @ q)) / eps ** 2
    if not math.isfinite(d):
        return TorusCoefficient(math.nan, lam, pm.residual, pm.steps, False,
                                "the coefficient is not finite")
    return TorusCoefficient(d, lam, pm.residual, pm.steps, error=abs(d - d2) + rounding)
