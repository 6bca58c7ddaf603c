"""The vehicle-track beam matching index chi = h / w0 (Chen, Ma, Luo & Zou 2019).

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

A second reading, ``h_simulation``, is the disturbance along the paper's kind of initial
state (model A: the beam deflection x5(0); model B: the vehicle pressed onto the free beam,
scaled) that separates return from collision in simulations with the physical limits on,
in both directions (beam up, beam down; the smaller one counts). It measures a disturbance
size, not a cycle amplitude, so it is not expected to equal h.

**The headline index** ``chi`` is the one number the product stands behind: the smaller of
the paper's index ``chi_paper`` and ``chi_simulation`` when the simulation ran and was
conclusive, else ``chi_paper`` (``reading_basis`` says which of the two it is: "paper" or
"simulation"). The words a user reads (``reading``) are a monotone function of it, so the
reading never claims more robustness than the simulation shows. What decided h_simulation
in each direction (a grazing contact, a basin boundary, or the bisection alone;
:mod:`maglev_match.analyses.critical`) is ``mechanism_up`` / ``mechanism_down``.

Disagreement beyond :data:`DISAGREEMENT_FACTOR`, a cycle branch stopped
at a limit, closeness to the stability boundary or to a generalised-Hopf point, current
reversal on the cycle and an inconclusive simulation are warnings (``warnings``).

This module is maglev glue: the numerics live in :mod:`maglev_match.dynamics`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any

import numpy as np

from maglev_match.core.params import Params
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.basin import bounding_cycle
from maglev_match.dynamics.cycles import CyclePoint
from maglev_match.dynamics.equilibria import StabilityResult, stability
from maglev_match.dynamics.system import System
from maglev_match.maglev.base import MaglevModel
from maglev_match.maglev.models import maglev_model

__all__ = ["MatchingIndex", "matching_index", "index_of_system", "reading", "reading_rank",
           "search_ranges", "CASES", "Case", "Basis", "with_simulation", "cycle_settings",
           "DISAGREEMENT_FACTOR", "NEAR_HOPF", "NEAR_GH", "headline_text"]


class Case(StrEnum):
    """Which of the paper's three cases decided h."""

    UNSTABLE_EQUILIBRIUM = "unstable_equilibrium"
    UNSTABLE_CYCLE = "unstable_cycle"
    NO_CYCLE_WITHIN_LIMITS = "no_cycle_within_limits"


class Basis(StrEnum):
    """Which index the headline chi (and the reading) is."""

    PAPER = "paper"
    SIMULATION = "simulation"


CASES = tuple(c.value for c in Case)
# chi (paper) and chi_simulation differing by more than this factor is a warning
DISAGREEMENT_FACTOR = 1.5
# a design point closer than this (relative) to its Hopf point is a warning
NEAR_HOPF = 0.05
# |l2| r^2 / |l1| above this within the gap range: near a generalised-Hopf point (the
# quintic term of the normal form an order of magnitude above the cubic one; about 1 at the
# presets, 175 at alpha1 with omega1 = 158.8, sigma = 4.92e-5)
NEAR_GH = 10.0
# reading thresholds on the index used (this project's choice), with their words
READING_LEVELS = (
    (1.0, "poor: stable, but a disturbance the size of the static deflection escapes"),
    (5.0, "good: stable under disturbances up to a few times the static deflection"),
    (10.0, "very good: stable under disturbances several times the static deflection"),
    (math.inf, "best: stable under disturbances ten or more times the static deflection"),
)

@dataclass(frozen=True)
class CycleSettings:
    """Collocation and continuation settings used for the index."""

    ntst: int = 30  # h agrees with NTST 60 to 1e-8 relative on model A (mesh adaptation on)
    ncol: int = 4
    max_steps: int = 400


cycle_settings = CycleSettings()


@dataclass(frozen=True)
class MatchingIndex(Plottable):
    """The matching index at one parameter point, with what decided it.

    Lengths in metres, rates in 1/s. ``chi`` is the HEADLINE index: min(chi_paper,
    chi_simulation) when the simulation ran and was conclusive, else chi_paper;
    ``reading_basis`` says which of the two it is ("paper" or "simulation").
    ``chi_paper`` is the index by the paper's definition (h from the cycle or the case rule,
    over w0); ``chi_simulation`` the simulated critical disturbance over w0 (the smaller of
    the two directions); ``reading`` the words for the headline. ``mechanism_up`` /
    ``mechanism_down``: what decided the critical disturbance of each direction
    (:class:`maglev_match.analyses.critical.Mechanism`); ``critical_up`` / ``critical_down`` the
    solved results (:class:`maglev_match.analyses.critical.CriticalSize`, in JSON as
    ``simulation.up.critical``); ``simulation_derivative``: whether chi_simulation has a
    derivative here (its deciding direction was solved).
    """

    __repr__ = compact_repr

    chi: float
    h: float
    w0: float
    case: str
    stable: bool
    max_real_part: float
    omega1: float
    sigma: float
    reading: str
    model: str = "unit"
    chi_paper: float = float("nan")
    reading_basis: str = Basis.PAPER
    hopf_param: str | None = None
    hopf_value: float | None = None
    hopf_distance: float | None = None  # relative distance to the Hopf point used
    l1: float | None = None
    gh_ratio: float | None = None  # |l2| r^2 / |l1| at the gap range (near GH when large)
    cycle_period: float | None = None
    cycle_gap_max: float | None = None
    cycle_gap_min: float | None = None
    cycle_current_min: float | None = None
    cycle_unstable_multipliers: int | None = None
    current_reverses: bool = False
    h_simulation: float | None = None
    h_simulation_up: float | None = None
    h_simulation_down: float | None = None
    chi_simulation: float | None = None
    simulation: dict[str, Any] | None = None
    converged: bool = True
    message: str = ""
    warnings: tuple[str, ...] = ()
    mechanism_up: str | None = None
    mechanism_down: str | None = None
    simulation_derivative: bool = False
    headline: str = ""
    cycle: CyclePoint | None = field(default=None, repr=False, compare=False)
    critical_up: Any = field(default=None, repr=False, compare=False)
    critical_down: Any = field(default=None, repr=False, compare=False)
    critical_delay: dict[str, Any] | None = None  # see critical_delay_info

    @property
    def h_headline(self) -> float:
        """The disturbance size (m) of the headline: ``h`` (the paper's, from the cycle or
        the case rule) when the reading basis is the paper, the simulated critical
        disturbance ``h_simulation`` when it is the simulation; ``h_headline / w0`` is
        ``chi``. (``h`` alone is always the paper's: ``h / w0`` is ``chi_paper``.)"""
        if self.reading_basis == Basis.SIMULATION and self.h_simulation is not None:
            return float(self.h_simulation)
        return float(self.h)

    def as_json(self) -> dict[str, Any]:
        """The machine-readable form (SI units); the cycle's profile is left out."""
        skip = ("cycle", "critical_up", "critical_down")
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k not in skip}
        out["case"] = str(self.case)
        out["reading_basis"] = str(self.reading_basis)
        out["warnings"] = list(self.warnings)
        for k in ("mechanism_up", "mechanism_down"):
            out[k] = None if out[k] is None else str(out[k])
        return out

    def to_xarray(self) -> Any:
        """The index as an :class:`xarray.Dataset` of 0-d variables (SI units, NaN where a
        part was not computed): ``chi``, ``chi_paper``, ``chi_simulation``, ``h``,
        ``h_simulation`` (``_up``, ``_down``), ``w0``, ``stable``, ``max_real_part``,
        ``omega1``, ``sigma``, the Hopf point used (``hopf_value``, ``hopf_distance``,
        ``l1``, ``gh_ratio``), the deciding cycle (``cycle_period``, ``cycle_gap_max``,
        ``cycle_gap_min``, ``cycle_current_min``, ``cycle_unstable_multipliers``),
        ``current_reverses``, ``converged`` and ``simulation_derivative``, each with
        ``units`` and ``long_name``. The words are attributes: ``case``, ``reading``,
        ``reading_basis``, ``headline``, ``model``, ``hopf_param``, ``mechanism_up`` /
        ``mechanism_down``, ``message``, and as JSON ``warnings``, ``simulation`` and
        ``critical_delay``. (The cycle's profile is left out, as in :meth:`as_json`.)"""
        import json

        import xarray as xr

        from maglev_match.core.datasets import annotate
        from maglev_match.core.params import PARAMETER_DOCS

        def num(v: Any) -> float:
            return float("nan") if v is None else float(v)

        hopf_unit = PARAMETER_DOCS.get(self.hopf_param or "", ("1",))[0]
        fields = {  # name: (value, units, long name)
            "chi": (self.chi, "1", f"headline matching index ({self.reading_basis})"),
            "chi_paper": (self.chi_paper, "1", "matching index by the paper's definition, "
                          "h / w0"),
            "chi_simulation": (self.chi_simulation, "1", "h_simulation / w0 (NaN: not "
                               "simulated or inconclusive)"),
            "h": (self.h, "m", "basin size by the paper's definition"),
            "h_simulation": (self.h_simulation, "m", "simulated critical disturbance, the "
                             "smaller of the two directions"),
            "h_simulation_up": (self.h_simulation_up, "m", "simulated critical "
                                "disturbance, beam up"),
            "h_simulation_down": (self.h_simulation_down, "m", "simulated critical "
                                  "disturbance, beam down"),
            "w0": (self.w0, "m", "static beam deflection"),
            "stable": (self.stable, "1", "equilibrium stable (1) or unstable (0)"),
            "max_real_part": (self.max_real_part, "1/s", "largest real part of the "
                              "eigenvalues of the equilibrium"),
            "omega1": (self.omega1, "", ""),
            "sigma": (self.sigma, "", ""),
            "hopf_value": (self.hopf_value, hopf_unit, "value of hopf_param at the Hopf "
                           "point used for h"),
            "hopf_distance": (self.hopf_distance, "1", "relative distance to the Hopf point "
                              "used"),
            "l1": (self.l1, "1/s", "first Lyapunov coefficient at the Hopf point used"),
            "gh_ratio": (self.gh_ratio, "1", "|l2| r^2 / |l1| at the gap range (near a "
                         "generalised-Hopf point when large)"),
            "cycle_period": (self.cycle_period, "s", "period of the deciding cycle"),
            "cycle_gap_max": (self.cycle_gap_max, "m", "largest gap deviation on the "
                              "deciding cycle"),
            "cycle_gap_min": (self.cycle_gap_min, "m", "smallest gap deviation on the "
                              "deciding cycle"),
            "cycle_current_min": (self.cycle_current_min, "A", "smallest coil current on "
                                  "the deciding cycle"),
            "cycle_unstable_multipliers": (self.cycle_unstable_multipliers, "1", "Floquet "
                                           "multipliers of the deciding cycle outside the "
                                           "unit circle"),
            "current_reverses": (self.current_reverses, "1", "coil current on the deciding "
                                 "cycle would reverse (1) or not (0)"),
            "converged": (self.converged, "1", "index computed (1) or a part failed (0)"),
            "simulation_derivative": (self.simulation_derivative, "1", "chi_simulation has "
                                      "a derivative here (1) or not (0)"),
        }
        flags = ("stable", "current_reverses", "converged", "simulation_derivative")
        data = {k: ((), np.int8(bool(v)) if k in flags else num(v))
                for k, (v, _, _) in fields.items()}

        def text(v: Any) -> str:
            return "" if v is None else str(v)

        ds = xr.Dataset(data, attrs={
            "title": "maglev-match matching index chi = h / w0",
            "case": str(self.case), "reading": self.reading,
            "reading_basis": str(self.reading_basis), "headline": self.headline,
            "model": self.model, "hopf_param": text(self.hopf_param),
            "mechanism_up": text(self.mechanism_up),
            "mechanism_down": text(self.mechanism_down), "message": self.message,
            "warnings": json.dumps(list(self.warnings)),
            "simulation": json.dumps(self.simulation, default=str),
            "critical_delay": json.dumps(self.critical_delay, default=str)})
        return annotate(ds, units={k: u for k, (_, u, _) in fields.items() if u},
                        long_names={k: n for k, (_, _, n) in fields.items() if n})


def reading_rank(chi: float) -> int:
    """The rank of the reading of an index value: 0 (chi = 0, or not computable) up to
    len(READING_LEVELS) ("best"). Non-decreasing in chi by construction."""
    if not (math.isfinite(chi) or chi == math.inf) or chi <= 0:
        return 0
    for k, (upper, _) in enumerate(READING_LEVELS):
        if chi < upper:
            return k + 1
    return len(READING_LEVELS)


def reading(chi: float, case: str = "", stable: bool = True) -> str:
    """The qualitative reading of the index used (the paper: 0 poor, small poor, large good,
    very large best). A function of chi alone (monotone: a larger chi never reads worse);
    the thresholds 1, 5 and 10 are this project's choice: chi < 1 means a disturbance the
    size of the static deflection w0 already escapes. ``case``/``stable`` only choose the
    words for chi = 0."""
    if math.isnan(chi):
        return "unknown: the index could not be computed"
    rank = reading_rank(chi)
    if rank == 0:
        if case == Case.UNSTABLE_EQUILIBRIUM or not stable:
            return "poor: no stable levitation (chi = 0)"
        return "poor: stable, but even the smallest disturbance tried escapes (chi = 0)"
    return READING_LEVELS[rank - 1][1]


def search_ranges(params: Params) -> dict[str, tuple[float, float]]:
    """Where model A looks for the nearest Hopf point (its
    :meth:`~maglev_match.maglev.base.MaglevModel.hopf_search`): omega1 within a factor 4 of
    the design value (sigma fixed), sigma within a factor 10 (omega1 fixed), inside the
    valid ranges."""
    return maglev_model(params, "unit").hopf_search()


def matching_index(
    params: Params | MaglevModel,
    *,
    model: str = "unit",
    simulate: bool = True,
    stability_result: StabilityResult | None = None,
    simulation_kwargs: dict[str, Any] | None = None,
    solve: bool = True,
    stage: Callable[[str], None] | None = None,
    near: MatchingIndex | None = None,
) -> MatchingIndex:
    """The headline index chi at ``params`` (the smaller of the paper's chi = h / w0 and
    chi_simulation), with the case that decided h, the simulated critical disturbance in
    both directions and what decided it, and the reading.

    Parameters
    ----------
    params : the parameter set (omega1 and sigma as given or derived from the beam), with
        ``model`` naming the model, or a :class:`~maglev_match.maglev.base.MaglevModel`.
    model : 'unit' (model A, 9 states) or 'vehicle' (model B, 34 + 2 n_modes states). For
        the vehicle, h is the largest gap deviation over the six levitation points on the
        cycle, w0 the static mid-span beam deflection under the whole vehicle, and the
        Hopf points are looked for along omega1 (the beam stiffness): each model's
        :attr:`~maglev_match.maglev.base.MaglevModel.w0` and
        :meth:`~maglev_match.maglev.base.MaglevModel.hopf_search`.
    simulate : also compute h_simulation (both directions) by bracketing on simulations
        with the limits on; the equilibrium must be stable for this to be meaningful.
    stability_result : reuse an already computed stability result.
    simulation_kwargs : passed to the critical-disturbance search of the model.
    solve : also solve the critical disturbance of each direction where a grazing contact or
        a basin boundary decides it (:mod:`maglev_match.analyses.critical`); False keeps the
        bisection's midpoints.
    stage : called with a line of text as each stage starts.
    near : the index at a neighbouring design (of the same model): each direction it
        solved is continued to this design
        (:func:`maglev_match.analyses.continued.continue_critical`: predictor, Newton on the
        same condition, two check runs) instead of searched again; where that does not
        hold, the full search runs. ``simulation[key]["continuation"]`` says which, and why.
        Where the neighbour's h was an unstable cycle, that cycle is continued too
        (:func:`maglev_match.analyses.continued.continue_cycle`: its Hopf point refined and
        the cycle corrected by collocation Newton at the new parameters, within stretch
        rules), not found again from a Hopf point; h then agrees with the point-wise
        index's to ~1e-8 relative (the point-wise branch ends on another adapted mesh).
        Where the rules do not hold, the full search runs.
    """
    from maglev_match.core.threads import blas_threads

    say = stage if stage is not None else (lambda text: None)
    m = maglev_model(params, model)
    say(f"the paper's index of {m.info.short}: equilibrium, Hopf point, cycle branch ...")
    params = m.params
    system = m.system()
    if simulate:  # (not imported by a paper-only index: a map row's, --no-simulation)
        from maglev_match.analyses.continued import simulated_part
    beside = None
    if simulate and _beside_allowed(m):
        # the simulated part does not need the paper's: it runs beside it, in a second
        # thread, once the equilibrium is known to be stable (core/beside.py)
        from maglev_match.core.beside import Beside

        stability_result = stability_result or stability(system, system.p)
        if stability_result.stable:
            beside = Beside(simulated_part, m, near, simulation_kwargs or {}, solve, say)
    try:
        with blas_threads(m.blas_threads):
            res = None if near is None else _paper_near(m, system, near, stability_result)
            res = res if res is not None else index_of_system(
                system, system.p, w0=m.w0, h_max=params.gap_max - params.c0,
                search=m.hopf_search(),
                limits=m.cycle_limits(include_current=False),
                stability_result=stability_result,
                omega1=float(params.omega1), sigma=float(params.sigma),  # type: ignore[arg-type]
                newton=m.cycle_newton,
            )
        if m.params.tau > 0:
            say("the critical delay of the controller ...")
        res = replace(res, model=m.name, critical_delay=critical_delay_info(m))
        if not simulate:
            return replace(res, headline=headline_text(res))
        if not res.stable:
            if beside is not None:  # (started only for a stable equilibrium)
                beside.stop()
            res = replace(res, simulation={"status": "skipped",
                                           "reason": "the equilibrium is unstable"})
            return replace(res, headline=headline_text(res))
        up, down, solved, cont = (
            beside.result() if beside is not None
            else simulated_part(m, near, simulation_kwargs or {}, solve, say))
    except BaseException:
        if beside is not None:  # an error or a Ctrl-C here: the thread stops first
            beside.stop()
        raise
    out = with_simulation(res, up, down, labels=m.info.disturbance_labels, rule=SIM_RULE,
                          solved=solved)
    if near is None or not solve:
        return out
    info = dict(out.simulation)
    for d, key in ((-1, "up"), (1, "down")):
        how = cont.get(d, (None, None, "the neighbour's size was not solved"))
        info[key] = {**info[key], "continuation": (
            {"continued": True} if how[1] is not None
            else {"continued": False, "reason": how[2]})}
    return replace(out, simulation=info)


def _beside_allowed(m: MaglevModel) -> bool:
    """May the simulated part run beside the paper's (:mod:`maglev_match.core.beside`)?
    Where the model's code may run in a second thread and the process has two cores."""
    from maglev_match.core.beside import two_cores

    return m.parts_beside and two_cores()


SIM_RULE = ("limits on: the coil current is clamped at zero (force from max(i, 0), di/dt held "
            "at 0 while i <= 0 and falling) and a gap leaving [gap_min, gap_max] is a "
            "collision; sizes are searched inside the gap range, so a direction where every "
            "size returns counts as the whole range (h_simulation = the size that puts the "
            "gap on its limit at t = 0)")


def _gh_ratio(system: System, hp: Any, h_max: float) -> float | None:
    """|l2| r^2 / |l1| at the amplitude r (normal-form coordinate) whose gap deviation is
    ``h_max``: the size of the quintic term of the Hopf normal form
    r' = r (alpha + l1 r^2 + l2 r^4) against the cubic one within the gap range
    (Kuznetsov 2004, section 8.3). Large means near a generalised-Hopf (Bautin) point,
    where the cubic truncation fails and h changes fast with the parameters. The ratio does
    not depend on the eigenvector normalisation (l1 ~ |q|^-2, l2 ~ |q|^-4, r ~ |q|)."""
    from maglev_match.dynamics.hopf import second_lyapunov_coefficient

    try:
        l1, l2 = second_lyapunov_coefficient(system, hp.x, hp.p, hp.frequency, hp.q, hp.p_adj)
        g = np.atleast_2d(system.observable_gradient("gap_deviation", hp.x, hp.p))
        amp = 2.0 * float(np.max(np.abs(g @ np.asarray(hp.q, complex))))
    except Exception:  # noqa: BLE001 - a diagnostic only; its failure must not stop the index
        return None
    if not (amp > 0 and l1 != 0 and np.isfinite(l2)):
        return None
    r = h_max / amp
    return float(abs(l2) * r * r / abs(l1))


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
    newton: str = "full",
) -> MatchingIndex:
    """The index for any System with observables "gap_deviation" and "current": h from the
    stability of the equilibrium and the bounding cycle, chi = h / w0.

    ``h_max`` is h when no unstable cycle bounds the basin within the limits (m);
    ``search`` gives the parameter ranges in which Hopf points are looked for. The result
    carries the paper-only reading (``reading_basis`` "paper") and the warnings that do not
    need a simulation (case message, near Hopf, near generalised Hopf, current reversal).
    ``newton`` is the cycle corrector (:func:`~maglev_match.dynamics.basin.bounding_cycle`):
    model A keeps "full" (h then stays that of the Newton-count step sequence); the vehicle
    uses "chord" (2.2x less CPU for its 40-state cycles, measured on turnout-soft).
    """
    stab = stability_result or stability(system, p)
    base = dict(w0=w0, stable=stab.stable, max_real_part=stab.max_real_part,
                omega1=omega1, sigma=sigma)
    warnings = list(stab.warnings)
    if not stab.stable:
        return MatchingIndex(chi=0.0, chi_paper=0.0, h=0.0, case=Case.UNSTABLE_EQUILIBRIUM,
                             reading=reading(0.0, Case.UNSTABLE_EQUILIBRIUM, False),
                             warnings=tuple(warnings), **base)
    bound = bounding_cycle(system, p, search, limits=limits, ntst=cycle_settings.ntst,
                           ncol=cycle_settings.ncol, max_steps=cycle_settings.max_steps,
                           newton=newton)
    warnings.extend(bound.warnings)
    hp = bound.hopf
    hopf = _hopf_info(system, hp, bound.hopf_distance, h_max, warnings)
    if bound.case == "unstable_cycle":
        assert bound.cycle is not None
        return _cycle_index(bound.cycle, w0, warnings, {**hopf, **base})
    if not bound.converged:
        warnings.append(bound.message)
        return MatchingIndex(
            chi=float("nan"), chi_paper=float("nan"), h=float("nan"),
            case=Case.NO_CYCLE_WITHIN_LIMITS, reading=reading(float("nan")), converged=False,
            message=bound.message, warnings=tuple(warnings), **hopf, **base,
        )
    if bound.message:
        warnings.append(f"{bound.message}: by the paper's rule h = gap_max - c0 = "
                        f"{h_max * 1e3:.4g} mm")
    return MatchingIndex(
        chi=h_max / w0, chi_paper=h_max / w0, h=h_max, case=Case.NO_CYCLE_WITHIN_LIMITS,
        reading=reading(h_max / w0, Case.NO_CYCLE_WITHIN_LIMITS),
        message=bound.message, warnings=tuple(warnings), **hopf, **base,
    )


def _hopf_info(system: System, hp: Any, distance: float | None, h_max: float,
               warnings: list[str]) -> dict[str, Any]:
    """The index's Hopf fields of the Hopf point ``hp`` (None: none) at relative
    ``distance`` from the design, and its warnings (near Hopf, near generalised Hopf)."""
    gh = _gh_ratio(system, hp, h_max) if hp is not None else None
    if distance is not None and distance < NEAR_HOPF:
        warnings.append(
            f"the design point is only {100 * distance:.2g} % from the Hopf point at "
            f"{hp.param} = {hp.value:.6g}: a small change of the parameters loses stability")
    if gh is not None and gh > NEAR_GH:
        warnings.append(
            f"near a generalised-Hopf point: l1 = {hp.l1:.3g} is small (the quintic term of "
            f"the normal form is {gh:.3g} times the cubic one within the gap range), so h "
            "changes fast with the parameters here")
    return dict(hopf_param=hp.param if hp else None, hopf_value=hp.value if hp else None,
                hopf_distance=distance, l1=hp.l1 if hp else None, gh_ratio=gh)


def _cycle_index(cyc: CyclePoint, w0: float, warnings: list[str], fields: dict[str, Any]
                 ) -> MatchingIndex:
    """The paper's index where the unstable cycle ``cyc`` bounds the basin: h its largest
    gap deviation (``fields``: the Hopf and equilibrium fields)."""
    g_hi, g_lo = cyc.extrema["gap_deviation"]
    i_lo = cyc.extrema["current"][1]
    h = float(g_hi)
    if i_lo < 0:
        warnings.append(
            f"the coil current on the cycle would reverse (min {i_lo:.3g} A): the cycle is "
            "of the smooth model, the clamped system differs there")
    return MatchingIndex(
        chi=h / w0, chi_paper=h / w0, h=h, case=Case.UNSTABLE_CYCLE,
        reading=reading(h / w0, Case.UNSTABLE_CYCLE),
        cycle_period=cyc.period, cycle_gap_max=float(g_hi), cycle_gap_min=float(g_lo),
        cycle_current_min=float(i_lo), cycle_unstable_multipliers=cyc.n_unstable,
        current_reverses=bool(i_lo < 0), warnings=tuple(warnings), cycle=cyc, **fields,
    )


def _paper_near(m: MaglevModel, system: System, near: MatchingIndex,
                stability_result: StabilityResult | None) -> MatchingIndex | None:
    """The paper's index with the bounding cycle continued from the neighbouring design's
    (:func:`maglev_match.analyses.continued.continue_cycle`), or None where that does not
    hold (then :func:`index_of_system` searches it)."""
    from maglev_match.analyses.continued import continue_cycle

    if (near.case != Case.UNSTABLE_CYCLE or near.cycle is None or near.hopf_param is None
            or near.hopf_value is None or near.model != m.name or m.params.tau > 0):
        return None
    stab = stability_result or stability(system, system.p)
    if not stab.stable:
        return None
    params = m.params
    out = continue_cycle(system, system.p, near.cycle, near.hopf_param, near.hopf_value,
                         stab.equilibrium.x, limits=m.cycle_limits(include_current=False))
    if isinstance(out, str):
        return None
    cyc, hp = out
    v = float(np.asarray(system.p)[system.param_index(hp.param)])
    warnings = list(stab.warnings)
    h_max = params.gap_max - params.c0
    hopf = _hopf_info(system, hp, abs(hp.value - v) / abs(v) if v else abs(hp.value), h_max,
                      warnings)
    base = dict(w0=m.w0, stable=stab.stable, max_real_part=stab.max_real_part,
                omega1=float(params.omega1), sigma=float(params.sigma))
    return _cycle_index(cyc, m.w0, warnings, {**hopf, **base})


def supported_size(cd: Any, crit: Any = None) -> float | None:
    """The disturbance size a simulation search supports (m): a solved critical size (the
    grazing or basin-boundary condition, inside a bracket whose lower end returned), else
    the bracket's midpoint,
    the whole range when every size returned, 0 when every size collided, and for an open
    search the largest size seen to return (a lower bound; None if none returned)."""
    if (crit is not None and getattr(crit, "solved", False) and crit.size is not None
            and cd.status == "bracketed"):
        return float(crit.size)
    if cd.status == "all_return":
        return float(cd.gap_range)
    if cd.status == "all_collide":
        return 0.0
    if cd.status == "bracketed":
        return float(cd.critical)
    return None if cd.largest_return is None else float(cd.largest_return)


def _sim_info(cd: Any, label: str, crit: Any = None) -> dict[str, Any]:
    out = {
        "label": label, "status": cd.status, "largest_return": cd.largest_return,
        "smallest_collision": cd.smallest_collision, "collision_time": cd.collision_time,
        "gap_range": cd.gap_range, "runs": cd.runs, "unresolved": cd.unresolved,
        "largest_undecided": getattr(cd, "largest_undecided", None),
        "direction": cd.direction, "tolerance": cd.tol, "horizon": cd.horizon,
        "warnings": list(cd.warnings),
    }
    out["critical"] = None if crit is None else crit.as_json()
    return out


def headline_text(res: MatchingIndex) -> str:
    """One sentence saying what the headline chi is (text output, report)."""
    if res.simulation is None:
        return ("the paper's chi: the simulation was not run (--no-simulation), so the "
                "headline is the paper's number")
    if res.simulation.get("status") == "skipped":
        return f"the paper's chi: the simulation was skipped ({res.simulation['reason']})"
    if res.chi_simulation is None:
        return ("the paper's chi: the simulation was inconclusive, so the headline is the "
                "paper's number")
    which = "simulation" if res.reading_basis == Basis.SIMULATION else "the paper's chi"
    return f"the smaller of the paper's chi and chi_simulation; here: {which}"


def with_simulation(res: MatchingIndex, up: Any, down: Any | None = None, *,
                    labels: tuple[str, str] = ("up", "down"), rule: str = "",
                    factor: float = DISAGREEMENT_FACTOR,
                    solved: tuple[Any, Any] | None = None) -> MatchingIndex:
    """Combine the paper's index with simulated critical disturbances into the headline.

    ``up``/``down`` are :class:`~maglev_match.analyses.simulation.CriticalDisturbance` results of
    the
    two directions (``down`` may be None); ``solved`` the matching
    :class:`~maglev_match.analyses.critical.CriticalSize` results (None: the bisection alone).
    h_simulation is the smaller supported size, chi_simulation = h_simulation / w0. The
    headline chi is min(chi_paper, chi_simulation) (``reading_basis`` "simulation" when the
    simulation's is smaller), else chi_paper, and the reading follows it, so it never
    claims more than the simulation shows. Warnings: an inconclusive search, a collision
    inside the gap range where the paper's rule gives the whole range (the contradiction),
    chi_paper and chi_simulation differing by more than ``factor``, and a critical size that
    could not be solved.
    """
    mm = 1e3
    warnings = list(res.warnings)
    sizes: list[float | None] = []
    info: dict[str, Any] = {"rule": rule}
    collisions: list[str] = []
    unconfirmed = False  # a direction where no size was seen to return at all
    chi_paper = res.chi_paper
    crits = solved if solved is not None else (None, None)
    for cd, label, key, crit in ((up, labels[0], "up", crits[0]),
                                 (down, labels[1], "down", crits[1])):
        if cd is None:
            sizes.append(None)
            continue
        info[key] = _sim_info(cd, label, crit)
        size = supported_size(cd, crit)
        sizes.append(size)
        warnings.extend(f"simulation ({label}): {w}" for w in cd.warnings)
        if cd.status == "open":
            lr = "none" if cd.largest_return is None else f"{cd.largest_return * mm:.4g} mm"
            sc = ("none" if cd.smallest_collision is None
                  else f"{cd.smallest_collision * mm:.4g} mm")
            if crit is not None and crit.solved:
                sc += (f" (the collision boundary solved at {crit.size * mm:.6g} mm, "
                       f"{crit.mechanism})")
            slow = ""
            if res.max_real_part < 0 and -1.0 / res.max_real_part > cd.horizon / 4:
                slow = (f"; the slowest decay time of the equilibrium, "
                        f"{-1.0 / res.max_real_part:.3g} s, is long against the horizon "
                        f"{cd.horizon:g} s")
            warnings.append(
                f"simulation ({label}) inconclusive: {cd.unresolved} run(s) undecided, largest "
                f"return {lr}, smallest collision {sc}{slow}")
            unconfirmed = unconfirmed or cd.largest_return is None
        if (crit is not None and not crit.solved and cd.status in ("bracketed", "open")
                and crit.reason):
            warnings.append(f"simulation ({label}): critical size not solved, the bisection "
                            f"stays and no derivative is available: {crit.reason}")
        if (res.case == Case.NO_CYCLE_WITHIN_LIMITS and res.stable
                and cd.smallest_collision is not None and cd.smallest_collision < cd.gap_range):
            collisions.append(f"{cd.smallest_collision * mm:.4g} mm ({label})")
    if collisions:
        warnings.append(
            f"contradiction: by the paper's rule the basin covers the whole gap range "
            f"(h = {res.h * mm:.4g} mm, no unstable cycle within the limits), but disturbances "
            f"inside the gap range collide in simulation: {'; '.join(collisions)}; the reading "
            "does not claim that range")
    known = [s for s in sizes if s is not None]
    h_sim = None if unconfirmed or not known else min(known)
    chi_sim = None if h_sim is None else h_sim / res.w0
    chi_used, basis = chi_paper, Basis.PAPER
    if chi_sim is not None and math.isfinite(chi_paper) and chi_sim < chi_paper:
        chi_used, basis = chi_sim, Basis.SIMULATION
    if chi_sim is not None and math.isfinite(chi_paper) and chi_paper > 0:
        hi, lo = max(chi_paper, chi_sim), min(chi_paper, chi_sim)
        if lo == 0 or hi / lo > factor:
            warnings.append(
                f"chi (paper) = {chi_paper:.4g} and chi_simulation = {chi_sim:.4g} differ by "
                f"more than a factor {factor:g}; the headline and the reading use the smaller "
                f"({basis})")
    text = reading(chi_used, res.case, res.stable)
    if unconfirmed:
        # nothing was seen to return: the simulation supports no claim at all
        text = ("unknown: no simulated disturbance was seen to return within the horizon, so "
                f"no robustness is claimed (the paper's definition alone gives chi = "
                f"{chi_paper:.4g}: {reading(chi_paper, res.case, res.stable).split(':')[0]})")
    every = (res.case == Case.NO_CYCLE_WITHIN_LIMITS and down is not None
             and all(cd is not None and cd.status == "all_return" for cd in (up, down)))
    if every:
        text += "; every disturbance tried within the gap range returned"
    mech = [None if c is None else str(c.mechanism) for c in crits]
    # chi_simulation has a derivative where the direction deciding h_simulation was solved
    deriv = False
    if h_sim is not None:
        k = 0 if (sizes[0] is not None and sizes[0] == h_sim) else 1
        c = crits[k]
        deriv = bool(c is not None and c.solved and c.derivative_available)
    out = replace(res, chi=chi_used, h_simulation=h_sim, h_simulation_up=sizes[0],
                  h_simulation_down=sizes[1], chi_simulation=chi_sim, simulation=info,
                  reading=text, reading_basis=basis, warnings=tuple(warnings),
                  mechanism_up=mech[0], mechanism_down=mech[1], simulation_derivative=deriv,
                  critical_up=crits[0], critical_down=crits[1])
    return replace(out, headline=headline_text(out))


# ---------------------------------------------------------------------------------------
# the critical delay of the controller (issue 23)
# ---------------------------------------------------------------------------------------
def critical_delay_info(params: Params | MaglevModel, model: str = "unit"
                        ) -> dict[str, Any]:
    """The critical delay of the outer control loop at ``params`` (or of a maglev model):
    the smallest tau (s) at
    which the equilibrium loses stability, with the frequency (rad/s) of the crossing pair,
    l1 (1/s, |q| = 1 on the state; > 0 subcritical) and whether ``params.tau`` lies below
    it. From the characteristic equation of the delay system
    (:func:`maglev_match.dynamics.delay.critical_delay`), over the valid range of tau.

    Keys: value (s, None when stable for every delay in the range, 0 when unstable without
    delay), frequency, l1, kind, crossing_speed, tau (the set delay), stable_at_tau,
    tau_max, practical (with a delay set: the practical margin beyond the critical delay,
    :func:`maglev_match.analyses.delay_margin.practical_delay_margin`; None otherwise),
    warnings."""
    from maglev_match.core.params import RANGES
    from maglev_match.dynamics.delay import critical_delay
    from maglev_match.dynamics.equilibria import find_equilibrium

    m = maglev_model(params, model)
    params = m.params
    dde = m.dde()
    eq = find_equilibrium(dde.ode_system(), dde.ode_params(dde.p))
    tau_max = RANGES["tau"][1]
    cd = critical_delay(dde, "tau", eq.x, dde.p, tau_max=tau_max)
    warnings = list(cd.warnings)
    if not eq.converged:
        warnings.append(f"equilibrium not converged: {eq.message}")
    tau = float(params.tau)
    stable_at_tau = None if cd.value is None and not cd.stable_without_delay else (
        cd.value is None or tau < cd.value)
    practical = None
    if tau > 0 and cd.value is not None and cd.value > 0:  # a study of the delay
        from maglev_match.analyses.delay_margin import practical_delay_margin

        practical = practical_delay_margin(m, cd.value, cd.kind)
        if practical["value"] is None:
            warnings.append(f"practical margin of the delay not found: {practical['reason']}")
    return {"value": cd.value, "frequency": cd.frequency, "l1": cd.l1, "kind": cd.kind,
            "crossing_speed": cd.crossing_speed, "tau": tau, "stable_at_tau": stable_at_tau,
            "stable_without_delay": cd.stable_without_delay, "tau_max": tau_max,
            "practical": practical, "warnings": warnings}
