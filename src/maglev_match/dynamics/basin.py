"""The unstable limit cycle that bounds a stable equilibrium's basin, found by continuation.

Model-agnostic. At a design parameter point p, with the equilibrium stable:

1. locate the Hopf points of the equilibrium along each search parameter (the others held
   at their design values), nearest first by relative distance;
2. from each, continue the branch of periodic orbits in that parameter until it reaches the
   design value (directly: no special points other than the limit contact and the design
   value are located on the way, and the multipliers are computed only at the points kept).
   If the cycle there is unstable, it surrounds the equilibrium: that cycle bounds the
   basin (case ``unstable_cycle``). If the branch first touches a limit (the ``limits``
   callable) between the Hopf point and the design value, the surrounding cycle
   lies beyond the physical range (case ``beyond_limits``); a contact on the far side of
   the Hopf point (the branch heading away from the design) counts as turning away. If it
   turns away or leaves the search range, that Hopf point gives no
   surrounding cycle and the next is tried;
3. with no Hopf point's branch surrounding the equilibrium: case ``no_cycle``.

A branch that stops because Newton's method failed or the step became too small is reported
(``converged`` False) and never read as "no cycle".
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.cycles import CycleBranch, CyclePoint, CycleStop, cycle_branch
from maglev_match.dynamics.hopf import HopfPoint, locate_hopf_points
from maglev_match.dynamics.system import System

__all__ = ["CycleBound", "bounding_cycle"]

FAILED = (CycleStop.NEWTON_FAILED, CycleStop.STEP_TOO_SMALL)


@dataclass(frozen=True)
class CycleBound:
    """What bounds the basin of a stable equilibrium at one parameter point."""

    __repr__ = compact_repr

    case: str  # "unstable_cycle", "beyond_limits", "no_cycle"
    hopf: HopfPoint | None  # the Hopf point whose branch decided (or the nearest one)
    cycle: CyclePoint | None  # the surrounding unstable cycle (case unstable_cycle)
    branches: tuple[CycleBranch, ...]
    converged: bool
    design: Mapping[str, float]  # the design values of the search parameters
    message: str = ""
    warnings: tuple[str, ...] = ()

    @property
    def hopf_distance(self) -> float | None:
        """Relative distance |p_hopf - p_design| / |p_design| along the Hopf parameter."""
        if self.hopf is None:
            return None
        design = self.design[self.hopf.param]
        return abs(self.hopf.value - design) / abs(design) if design else abs(self.hopf.value)


def bounding_cycle(
    system: System,
    p: np.ndarray,
    search: Mapping[str, tuple[float, float]],
    *,
    limits: Callable | None = None,
    n_scan: int = 60,
    ntst: int = 60,
    ncol: int = 4,
    max_steps: int = 400,
    newton: str = "full",
) -> CycleBound:
    """The unstable cycle around the (stable) equilibrium at ``p``, by continuation.

    Parameters
    ----------
    system : the ODE system; ``p`` its design parameter vector.
    search : parameter name -> (lo, hi) range in which to look for Hopf points.
    limits : passed to :func:`~maglev_match.dynamics.cycles.cycle_branch`: the branch
        stops at the first contact with a limit.
    n_scan, ntst, ncol, max_steps : scan resolution and collocation/continuation settings.
    newton : the corrector of the cycle branch ("full" by default: the step sequence, and
        so the adapted mesh and h, stay those of the Newton-count rule; "chord" is faster
        and moves h by ~6e-8 relative through the other step sequence).
    """
    p = np.asarray(p, float)
    design = {name: float(p[system.param_index(name)]) for name in search}
    cands: list[tuple[float, HopfPoint]] = []
    warnings: list[str] = []
    for name, (lo, hi) in search.items():
        scan = locate_hopf_points(system, name, lo, hi, p=p, n_scan=n_scan)
        warnings.extend(f"Hopf search along {name}: {w}" for w in scan.warnings)
        v = design[name]
        for hp in scan.points:
            if hp.converged:
                cands.append((abs(hp.value - v) / (abs(v) or 1.0), hp))
            else:
                warnings.append(f"Hopf point near {name} = {hp.value:.6g} did not converge")
    cands.sort(key=lambda t: t[0])
    branches: list[CycleBranch] = []
    failed: list[str] = []
    limited: HopfPoint | None = None
    found: tuple[HopfPoint, CyclePoint] | None = None
    for _, hp in cands:
        target = design[hp.param]
        lo, hi = search[hp.param]
        # the direct route: only the limit contact and the design value end the branch, and
        # only the cycle solved at the design value is read, so no fold / PD / NS / BP is
        # located on the way (those solves changed nothing in h). The step sequence is the
        # Newton-count rule's (predictor_tol=None): the mesh is adapted every 3 steps, so a
        # different sequence ends on a different mesh and moves h by ~4e-8 relative.
        # The multipliers are computed only at the end point (the only one read), and a
        # limit contact is only bracketed: whether and on which side of the Hopf point the
        # branch meets a limit is all the index reads of it.
        br = cycle_branch(system, hp, hp.param, stop_at=target, ntst=ntst, ncol=ncol,
                          max_steps=max_steps, limits=limits, param_bounds=(lo, hi),
                          detect_special_points=False, predictor_tol=None, newton=newton,
                          multipliers_at="last", locate_limit=False)
        branches.append(br)
        last = br.last
        if last is not None and last.kind == "stop_at" and last.converged:
            if last.n_unstable >= 1:
                found = (hp, last)
                break
            warnings.append(f"the cycle born at {hp.param} = {hp.value:.6g} is stable at the "
                            "design point; it does not bound the basin")
            continue
        if br.stopped_reason == CycleStop.CONTACT:
            # only a contact between the Hopf point and the design point means that the
            # surrounding cycle leaves the range; a branch that touched a limit on the far
            # side of its Hopf point (heading away from the design) turned away
            v = last.value if last is not None else hp.value
            if (v - hp.value) * (target - hp.value) > 0:
                limited = limited or hp
            else:
                warnings.append(f"the cycle branch from {hp.param} = {hp.value:.6g} touched a "
                                f"limit at {v:.6g}, on the far side from the design point")
            continue
        if br.stopped_reason in FAILED:
            failed.append(f"branch from {hp.param} = {hp.value:.6g}: {br.stopped_reason}")
    nearest = cands[0][1] if cands else None
    if found is not None:
        res = CycleBound("unstable_cycle", found[0], found[1], tuple(branches), True, design,
                         warnings=tuple(warnings))
    elif failed and limited is None:
        res = CycleBound("no_cycle", nearest, None, tuple(branches), False, design,
                         message="cycle continuation failed: " + "; ".join(failed),
                         warnings=tuple(warnings))
    elif limited is not None:
        res = CycleBound("beyond_limits", limited, None, tuple(branches), True, design,
                         message="the surrounding cycle touches a limit before the design point",
                         warnings=tuple(warnings + failed))
    else:
        res = CycleBound("no_cycle", nearest, None, tuple(branches), True, design,
                         message="no Hopf point's cycle branch surrounds the equilibrium",
                         warnings=tuple(warnings))
    return res
