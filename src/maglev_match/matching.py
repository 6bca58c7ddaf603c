"""The vehicle-track beam matching index chi = h / w0 (SPEC.md section 6.6).

h, the size of the equilibrium's basin along the gap, is decided by one of three cases:

* ``unstable_equilibrium``: the equilibrium is unstable, h = 0 (so chi = 0 exactly);
* ``unstable_cycle``: the equilibrium is stable and an unstable limit cycle surrounds it;
  h = max over that cycle of the gap deviation c - c0 (smallest-amplitude cycle if several);
* ``no_cycle_within_limits``: the equilibrium is stable and no unstable cycle surrounds it
  within the physical gap range; h = gap_max - c0.

The cycle is found by continuation, never guessed: from the Hopf point nearest to the design
point (along omega1 at the design sigma, or along sigma at the design omega1), its branch of
periodic orbits is continued until it reaches the design value (then that cycle decides h),
touches a physical gap limit first (then the cycle leaves the range), or turns away (then that
Hopf point gives no surrounding cycle). A continuation that fails is reported as such.

Cycles are computed on the smooth model (no current clamp). When the coil current on the
cycle would reverse, ``current_reverses`` is set: the clamped system differs there.

A second reading, ``h_simulation``, is the beam-deflection disturbance x5(0) that separates
return from collision in simulations with the physical limits on. It measures a disturbance
size, not a cycle amplitude, so it is not expected to equal h.

This module is maglev glue: the numerics live in :mod:`maglev_match.dynamics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from maglev_match.dynamics.basin import bounding_cycle
from maglev_match.dynamics.cycles import CyclePoint
from maglev_match.dynamics.equilibria import StabilityResult, stability
from maglev_match.dynamics.system import System
from maglev_match.limits_check import cycle_limit_margins
from maglev_match.models.unit import unit_system
from maglev_match.params import Params

__all__ = ["MatchingIndex", "matching_index", "index_of_system", "reading", "search_ranges",
           "CASES",
           "cycle_settings"]

CASES = ("unstable_equilibrium", "unstable_cycle", "no_cycle_within_limits")

@dataclass(frozen=True)
class CycleSettings:
    """Collocation and continuation settings used for the index."""

    ntst: int = 30  # h agrees with NTST 60 to 1e-8 relative on model A (mesh adaptation on)
    ncol: int = 4
    max_steps: int = 400


cycle_settings = CycleSettings()


@dataclass(frozen=True)
class MatchingIndex:
    """The matching index at one parameter point, with what decided it.

    Lengths in metres, rates in 1/s.
    """

    chi: float
    h: float
    w0: float
    case: str
    stable: bool
    max_real_part: float
    omega1: float
    sigma: float
    reading: str
    hopf_param: str | None = None
    hopf_value: float | None = None
    hopf_distance: float | None = None  # relative distance to the Hopf point used
    l1: float | None = None
    cycle_period: float | None = None
    cycle_gap_max: float | None = None
    cycle_gap_min: float | None = None
    cycle_current_min: float | None = None
    cycle_unstable_multipliers: int | None = None
    current_reverses: bool = False
    h_simulation: float | None = None
    chi_simulation: float | None = None
    simulation: dict[str, Any] | None = None
    converged: bool = True
    message: str = ""
    warnings: tuple[str, ...] = ()
    cycle: CyclePoint | None = field(default=None, repr=False, compare=False)

    def as_json(self) -> dict[str, Any]:
        """The machine-readable form (SI units); the cycle's profile is left out."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "cycle"}
        out["warnings"] = list(self.warnings)
        return out


def reading(chi: float, case: str) -> str:
    """The paper's qualitative reading of chi. Thresholds are this project's choice:
    chi < 1 means the typical disturbance w0 already exceeds the basin."""
    if case == "unstable_equilibrium" or chi == 0:
        return "poor: no stable levitation (chi = 0)"
    if not math.isfinite(chi):
        return "unknown: the index could not be computed"
    if chi < 1:
        return "poor: stable, but a disturbance the size of the static deflection escapes"
    if case == "no_cycle_within_limits":
        return "best: stable for every disturbance within the physical gap range"
    if chi < 5:
        return "good: stable under small disturbances, unstable under large ones"
    return "very good: stable under disturbances several times the static deflection"


def search_ranges(params: Params) -> dict[str, tuple[float, float]]:
    """Where to look for the nearest Hopf point: omega1 within a factor 4 of the design
    value (sigma fixed), sigma within a factor 10 (omega1 fixed), inside the valid ranges."""
    w, s = float(params.omega1), float(params.sigma)  # type: ignore[arg-type]
    out = {"omega1": (w / 4.0, min(4.0 * w, 1e5))}
    if s > 0:
        out["sigma"] = (s / 10.0, min(10.0 * s, 0.1))
    return out


def matching_index(
    params: Params,
    *,
    simulate: bool = True,
    stability_result: StabilityResult | None = None,
    simulation_kwargs: dict[str, Any] | None = None,
) -> MatchingIndex:
    """chi = h / w0 for model A at ``params`` (SPEC.md 6.6), with the case that decided h.

    Parameters
    ----------
    params : the parameter set (omega1 and sigma as given or derived from the beam).
    simulate : also compute h_simulation by bisection on simulations with the limits on.
    stability_result : reuse an already computed stability result.
    simulation_kwargs : passed to :func:`maglev_match.simulation.critical_disturbance`.
    """
    system = unit_system(params)
    res = index_of_system(
        system, system.p, w0=params.w0, h_max=params.gap_max - params.c0,
        search=search_ranges(params),
        limits=cycle_limit_margins(params, include_current=False),
        stability_result=stability_result,
        omega1=float(params.omega1), sigma=float(params.sigma),  # type: ignore[arg-type]
    )
    return _with_simulation(res, params, simulate, simulation_kwargs)


def index_of_system(
    system: System,
    p: np.ndarray,
    *,
    w0: float,
    h_max: float,
    search: dict[str, tuple[float, float]],
    limits: Any = None,
    stability_result: StabilityResult | None = None,
    omega1: float = float("nan"),
    sigma: float = float("nan"),
) -> MatchingIndex:
    """The index for any System with observables "gap_deviation" and "current": h from the
    stability of the equilibrium and the bounding cycle (SPEC.md 6.6), chi = h / w0.

    ``h_max`` is h when no unstable cycle bounds the basin within the limits (m);
    ``search`` gives the parameter ranges in which Hopf points are looked for.
    """
    stab = stability_result or stability(system, p)
    base = dict(w0=w0, stable=stab.stable, max_real_part=stab.max_real_part,
                omega1=omega1, sigma=sigma)
    warnings = list(stab.warnings)
    if not stab.stable:
        return MatchingIndex(chi=0.0, h=0.0, case="unstable_equilibrium",
                             reading=reading(0.0, "unstable_equilibrium"),
                             warnings=tuple(warnings), **base)
    bound = bounding_cycle(system, p, search, limits=limits, ntst=cycle_settings.ntst,
                           ncol=cycle_settings.ncol, max_steps=cycle_settings.max_steps)
    warnings.extend(bound.warnings)
    hp = bound.hopf
    hopf = dict(hopf_param=hp.param if hp else None, hopf_value=hp.value if hp else None,
                hopf_distance=bound.hopf_distance, l1=hp.l1 if hp else None)
    if bound.case == "unstable_cycle":
        cyc = bound.cycle
        assert cyc is not None
        g_hi, g_lo = cyc.extrema["gap_deviation"]
        i_lo = cyc.extrema["current"][1]
        h = float(g_hi)
        case = "unstable_cycle"
        return MatchingIndex(
            chi=h / w0, h=h, case=case, reading=reading(h / w0, case),
            cycle_period=cyc.period, cycle_gap_max=float(g_hi), cycle_gap_min=float(g_lo),
            cycle_current_min=float(i_lo), cycle_unstable_multipliers=cyc.n_unstable,
            current_reverses=bool(i_lo < 0), warnings=tuple(warnings), cycle=cyc,
            **hopf, **base,
        )
    if not bound.converged:
        return MatchingIndex(
            chi=float("nan"), h=float("nan"), case="no_cycle_within_limits",
            reading=reading(float("nan"), ""), converged=False, message=bound.message,
            warnings=tuple(warnings), **hopf, **base,
        )
    case = "no_cycle_within_limits"
    return MatchingIndex(
        chi=h_max / w0, h=h_max, case=case, reading=reading(h_max / w0, case),
        message=bound.message, warnings=tuple(warnings), **hopf, **base,
    )


def _with_simulation(res: MatchingIndex, params: Params, simulate: bool,
                     kwargs: dict[str, Any] | None) -> MatchingIndex:
    if not simulate:
        return res
    from dataclasses import replace

    from maglev_match.simulation import critical_disturbance

    cd = critical_disturbance(params, **(kwargs or {}))
    if cd.status == "all_return":
        h_sim: float | None = cd.gap_range
    elif cd.status == "all_collide":
        h_sim = 0.0
    else:
        h_sim = cd.critical
    info = {
        "status": cd.status, "largest_return": cd.largest_return,
        "smallest_collision": cd.smallest_collision, "runs": cd.runs,
        "unresolved": cd.unresolved, "direction": cd.direction,
        "tolerance": cd.tol, "warnings": list(getattr(cd, "warnings", ())),
    }
    chi_sim = None if h_sim is None or not np.isfinite(h_sim) else float(h_sim) / res.w0
    return replace(res, h_simulation=None if h_sim is None else float(h_sim),
                   chi_simulation=chi_sim, simulation=info)
