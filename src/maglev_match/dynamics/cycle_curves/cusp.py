"""The cusp of cycles (CPC) on an LPC curve, solved.

At a cusp of cycles the fold's quadratic normal-form coefficient vanishes; the LPC curve,
smooth in the space of (cycle, p1, p2), then has a vanishing tangent in the parameter
plane: its projection on (p1, p2) turns back with a cusp there. So the CPC is the zero of

    phi(s) = (t_p1(s), t_p2(s)) . d,

the parameter part of the curve's unit tangent (scaled as the continuation's arclength)
projected on d, the curve's direction in the scaled parameter plane before the cusp: phi
changes sign there and nowhere near (where the projected tangent does not vanish it keeps
pointing along +-d). It is solved by Illinois iterations (:mod:`.illinois`) on the arclength of the
step over which phi changes sign, each a point corrected onto the curve with its tangent from
the factorised Newton matrix; the solution is accepted where the whole projected tangent
(both components, relative to the tangent's norm) is below 1e-6.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from maglev_match.dynamics.cycle_curves.illinois import illinois

__all__ = ["solve_cusp"]


def solve_cusp(sp: Any, states: list, aug: Any, newton: Callable, make_point: Callable,
               W: np.ndarray, tol: float, tangent: Callable) -> Any:
    """The bracketed CPC ``sp`` (at point k = ``sp.step``, where the chord directions
    reverse) solved on the curve (module docstring), or ``sp`` unchanged if it cannot be.
    ``states`` the curve's (z, unit tangent, mesh) per point; ``tangent(lu, W, orient)``
    the driver's unit tangent from a factorised Newton matrix."""
    k = sp.step
    ip = [aug.i_p1, aug.i_p2]
    if k < 1 or k + 1 >= len(states):
        return sp
    d = states[k][0][ip] - states[k - 1][0][ip]
    if not np.any(d):
        return sp
    d = d / np.linalg.norm(d)
    phis = [float(states[j][1][ip] @ d) for j in (k - 1, k, k + 1)]
    j = next((k - 1 + i for i in (0, 1) if phis[i] * phis[i + 1] < 0), None)
    if j is None:
        return sp
    (za, ta, mesh_a), (zb, _, mesh_b) = states[j], states[j + 1]
    if not np.array_equal(mesh_a, mesh_b):
        return sp
    aug.prob.mesh = mesh_a.copy()
    aug.init_borders(za)
    Ua = aug.unpack(za)[0]
    row = W * ta

    def at(s):
        z0 = za + s * ta
        out = newton(z0, row, float(row @ z0), Ua)
        if out is None:
            return None, np.nan
        t = tangent(out[2], W, ta)
        return (out, float(np.linalg.norm(t[ip]))), float(t[ip] @ d)

    lo, hi = 0.0, float(row @ (zb - za))
    flo, fhi = at(lo)[1], at(hi)[1]
    if not (np.isfinite(flo) and np.isfinite(fhi)) or flo * fhi >= 0:
        return sp
    found, f, _ = illinois(at, lo, hi, flo, fhi, tol, 1e-12)
    if found is None or not np.isfinite(f):
        return sp
    best, size = found
    if not size < 1e-6:
        return sp
    pt = make_point(best[0], best[1], best[3], best[4], "CPC")
    return dataclasses.replace(sp, value=pt.values[0], values=pt.values, located="solved",
                               detail=f"projected tangent {size:.1e} there",
                               period=pt.period, point=pt)
