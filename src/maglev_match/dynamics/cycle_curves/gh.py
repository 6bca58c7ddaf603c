"""Branch switching at a generalised Hopf (Bautin, GH) point: the fold-of-cycles curve that
is born there.

Near a GH point the normal form r' = r (beta1 + l1 r^2 + l2 r^4) has its fold of cycles at
r^2 = -l1 / (2 l2), beta1 = l1^2 / (4 l2), on the side of the Hopf curve where l1 l2 < 0
(Kuznetsov 2004, sec. 8.3). :func:`lpc_from_generalised_hopf` takes one small step
``offset`` from the GH point along the second parameter to that side, refines the Hopf
point there (:func:`~maglev_match.dynamics.hopf.refine_hopf_point`, from the GH point's
equilibrium and frequency), continues its (small) cycles in the first parameter until the
fold, which lies at a distance of order offset^2 from the Hopf point, and continues that
fold in two parameters (:func:`~maglev_match.dynamics.cycle_curves.cycle_curve`). The
offset is a trade: small enough for the fold to be the one born at GH, large enough for
its cycle (amplitude of order offset^(1/2)) to be resolved by the collocation.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from maglev_match.dynamics.cycle_curves.curve import cycle_curve
from maglev_match.dynamics.cycle_curves.results import CycleCurve
from maglev_match.dynamics.system import System

__all__ = ["lpc_from_generalised_hopf"]


def lpc_from_generalised_hopf(system: System, x: np.ndarray, p: np.ndarray, frequency: float,
                              params: tuple[str, str], *, offset: float,
                              l2: float | None = None, ntst: int = 40, ncol: int = 4,
                              branch_steps: int = 200, **curve_options: Any
                              ) -> tuple[CycleCurve, Any]:
    """The LPC curve born at a GH point (module docstring).

    Parameters
    ----------
    x, p, frequency : the GH point's equilibrium, parameter vector and frequency (rad/s),
        e.g. from a GH special point of a Hopf curve (``sp.x``, the system's parameters
        with ``sp.values``, ``sp.frequency``).
    params : (p1, p2): the cycles are continued in p1; the step ``offset`` is taken in p2.
    offset : the step in p2 from the GH point (its sign chooses the side); with ``l2``
        given, a step to the side where l1 l2 > 0 (no fold there) is refused.
    ntst, ncol, branch_steps : mesh and steps of the one-parameter branch that locates the
        fold (the curve keeps its mesh).
    **curve_options : passed to :func:`cycle_curve` (``ranges``, ``direction``, ...).

    Returns
    -------
    (the :class:`CycleCurve`, the one-parameter branch the fold was located on). A
    refused side, a Hopf point that does not converge or a branch without a fold raise
    ``ValueError`` naming what failed.
    """
    from maglev_match.dynamics.cycles import cycle_branch
    from maglev_match.dynamics.hopf import refine_hopf_point

    p1, p2 = params
    pv = np.array(p, float)
    pv[system.param_index(p2)] += float(offset)
    v1 = float(pv[system.param_index(p1)])
    h = refine_hopf_point(system, p1, v1, np.asarray(x, float), float(frequency), p=pv,
                          value_scale=abs(v1) if abs(v1) > 1e-12 else 1.0)
    if not h.converged:
        raise ValueError(f"offset = {offset!r}: the Hopf point at {p2} = "
                         f"{pv[system.param_index(p2)]:.10g} did not converge ({h.message})")
    if l2 is not None and np.isfinite(h.l1) and h.l1 * l2 > 0:
        raise ValueError(f"offset = {offset!r}: on this side of the GH point l1 = {h.l1:.4g} "
                         f"has the sign of l2 = {l2:.4g}: no fold of cycles is born there; "
                         "step to the other side")
    br = cycle_branch(system, h, p1, ntst=ntst, ncol=ncol, max_steps=branch_steps)
    folds = [sp for sp in br.special_points if sp.type == "LPC" and sp.point is not None]
    if not folds:
        raise ValueError(f"offset = {offset!r}: the cycles of the Hopf point at {p2} = "
                         f"{pv[system.param_index(p2)]:.10g} have no fold within "
                         f"{branch_steps} steps (the branch ended: {br.stopped_reason})")
    return cycle_curve(system, folds[0].point.orbit, "LPC", params, **curve_options), br
