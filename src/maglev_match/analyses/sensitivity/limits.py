"""The cycle-limit boundary: where the index's case changes between ``unstable_cycle`` and
``no_cycle_within_limits``.

The index's case rule looks at the whole branch of the bounding cycle, from its Hopf point
to the design point: the case boundary is where the largest (or smallest) gap deviation
over that branch reaches a gap limit. :func:`branch_extremes` gives those two extremes
(inside the branch by Brent's method on the branch parameter, their derivatives by every
parameter by the envelope theorem); :func:`limit_contact`, for a branch that cannot be
continued to the design point even without limits, the first contact of the branch with a
limit; :func:`unlimited_bound` the bounding-cycle search with the limits off. The
derivatives on each cycle are those of :mod:`maglev_match.analyses.sensitivity.cycle`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import scipy.optimize

from maglev_match.analyses.sensitivity.cycle import cycle_h_derivative
from maglev_match.dynamics.system import System

__all__ = ["branch_extremes", "unlimited_bound", "limit_contact"]


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
        val, dval, _, _ = cycle_h_derivative(system, pt.orbit, observable, sign)
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
    _, dval, _, _ = cycle_h_derivative(system, pt.orbit, observable, sign)
    return float(lam), dval, key, solved
