"""The headline index's sensitivities: d chi / d p, the elasticity, d margin / d p, the
derivative of the relative Hopf distance and the two case boundaries for every parameter
of model A or model B (:func:`index_sensitivity`, :class:`IndexSensitivity`).

Where h is set by a case rule the derivative is not a cycle derivative:
``unstable_equilibrium`` gives chi = 0 on an open set, so its derivative is exactly zero;
``no_cycle_within_limits`` gives h = gap_max - c0, so h moves only with those two values and
chi only through w0; a failed continuation leaves it undefined. For each parameter two case
boundaries are given: the stability boundary (max Re lambda = 0), bracketed by a scan and
solved by Newton's method with the exact slope of
:func:`~maglev_match.analyses.sensitivity.cycle.margin_derivative`
(:func:`_stability_boundaries`); and, to first order, the cycle-limit boundary between
``unstable_cycle`` and ``no_cycle_within_limits``
(:mod:`maglev_match.analyses.sensitivity.limits`).

The maglev layer (:func:`index_sensitivity`) chains these model-parameter derivatives with
exact derivatives of the derived values omega1 = (pi/L)^2 sqrt(EI/mbar),
sigma = 8 k L / (pi^2 l^2 mbar) sin^2(pi l / (2 L)) and w0 = sigma (m + M) g / omega1^2
(Euler-Bernoulli beam, simply supported), so that engineering parameters (L, EI, mbar, l, k)
and the gains (kP, kD, ke, xi0, omega0) all get d chi / d p. For the full vehicle (model B)
the beam enters through the modal frequencies omega_n = n^2 omega1 of its modes and through
L and mbar directly (mode shapes at the six levitation points, modal mass); w0 is the static
mid-span deflection sum_n q_n* sin(n pi / 2), differentiated through the same formulas
(:func:`derived_map`), and h is the largest gap deviation over the six points on the cycle.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.analyses.matching import MatchingIndex, matching_index
from maglev_match.analyses.sensitivity.cycle import (
    SystemSensitivity,
    margin_derivative,
    system_sensitivity,
)
from maglev_match.analyses.sensitivity.limits import (
    branch_extremes,
    limit_contact,
    unlimited_bound,
)
from maglev_match.analyses.sensitivity.status import DerivativeStatus
from maglev_match.core import jax_setup  # noqa: F401  (float64)
from maglev_match.core.params import PARAMETER_DOCS, Params, refuse_delay
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.equilibria import find_equilibrium
from maglev_match.dynamics.system import System
from maglev_match.maglev.base import MaglevModel
from maglev_match.maglev.beam import LIMITS as _LIMITS
from maglev_match.maglev.models import maglev_model

__all__ = [
    "ParameterSensitivity",
    "IndexSensitivity",
    "index_sensitivity",
    "engineering_names",
    "derived_map",
    "SWITCH_TOL",
]


# ---------------------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ParameterSensitivity:
    """One row of the sensitivity table (SI units of the parameter)."""

    name: str
    value: float
    unit: str
    dchi: float  # d chi / d p of the headline index (NaN where not available)
    elasticity: float  # (p / chi) d chi / d p (dimensionless); nan when chi = 0
    dmargin: float  # d (-max Re lambda) / d p (1/s per unit)
    dhopf_distance: float | None  # d (relative Hopf distance) / d p
    boundary: float | None = None  # value of p at the nearest stability boundary
    boundary_relative: float | None = None  # (boundary - p) / p
    # first-order value of p where the bounding cycle's gap maximum reaches gap_max - c0
    # (the boundary between cases unstable_cycle and no_cycle_within_limits)
    limit_boundary: float | None = None
    note: str = ""
    dchi_paper: float = float("nan")  # d chi_paper / d p (the paper's definition)
    dchi_simulation: float | None = None  # d chi_simulation / d p (None: not available)
    # one-sided derivatives of the headline where it switches between its parts (or
    # h_simulation between directions): (for a decrease of p, for an increase of p)
    dchi_left: float | None = None
    dchi_right: float | None = None


@dataclass(frozen=True)
class IndexSensitivity(Plottable):
    """Sensitivities of chi, the margin and the Hopf distance of model A at one point."""

    __repr__ = compact_repr

    index: MatchingIndex
    status: DerivativeStatus
    rows: tuple[ParameterSensitivity, ...]
    system: SystemSensitivity
    limit_boundary_note: str = ""
    warnings: tuple[str, ...] = ()
    paper_status: DerivativeStatus | None = None  # how d chi_paper / dp was obtained
    simulation_status: str = ""  # how d chi_simulation / dp was obtained (or why not)
    switch_note: str = ""  # the headline at a switch between its parts: one-sided values
    _by_name: dict[str, ParameterSensitivity] = field(default_factory=dict, repr=False,
                                                     compare=False)

    def __post_init__(self) -> None:
        self._by_name.update({r.name: r for r in self.rows})

    def dchi(self, name: str) -> float:
        return self._by_name[name].dchi

    def dmargin(self, name: str) -> float:
        return self._by_name[name].dmargin

    def row(self, name: str) -> ParameterSensitivity:
        return self._by_name[name]

    def has_row(self, name: str) -> bool:
        """Whether ``name`` has a row (is a parameter of the model's index)."""
        return name in self._by_name

    def sorted_rows(self) -> list[ParameterSensitivity]:
        """Rows by |elasticity| (|d chi/dp| where chi = 0), largest first."""
        def key(r: ParameterSensitivity) -> float:
            e = r.elasticity if math.isfinite(r.elasticity) else 0.0
            return -abs(e) if self.index.chi else -abs(r.dmargin * r.value)
        return sorted(self.rows, key=key)

    def as_json(self) -> dict[str, Any]:
        return {
            "chi": self.index.chi, "chi_paper": self.index.chi_paper,
            "chi_simulation": self.index.chi_simulation,
            "reading_basis": str(self.index.reading_basis), "headline": self.index.headline,
            "paper_status": None if self.paper_status is None else str(self.paper_status),
            "simulation_status": self.simulation_status, "switch_note": self.switch_note,
            "h": self.index.h, "w0": self.index.w0,
            "case": self.index.case, "status": str(self.status),
            "max_real_part": self.index.max_real_part,
            "hopf_param": self.index.hopf_param, "hopf_value": self.index.hopf_value,
            "hopf_distance": self.index.hopf_distance,
            "t_star": self.system.t_star, "solve_residual": self.system.solve_residual,
            "limit_boundary_note": self.limit_boundary_note,
            "rows": [dict(r.__dict__) for r in self.sorted_rows()],
            "warnings": list(self.warnings),
        }

    def to_xarray(self) -> Any:
        """The derivative table as an :class:`xarray.Dataset` over ``parameter`` (the rows'
        names, in the table's order): ``value`` and ``parameter_unit`` of each parameter,
        ``dchi``, ``dchi_paper``, ``dchi_simulation``, ``dchi_left`` / ``dchi_right``
        (per unit of the parameter), ``elasticity``, ``dmargin`` (1/s per unit),
        ``dhopf_distance``, the stability ``boundary`` (and ``boundary_relative``), the
        ``limit_boundary`` and the row's ``note`` (NaN or '' where not available); and the
        0-d ``chi``, ``chi_paper``, ``chi_simulation``, ``h``, ``w0`` and
        ``max_real_part`` of the index it differentiates. How the derivatives were
        obtained (``status``, ``paper_status``, ``simulation_status``), the notes and the
        warnings (JSON list) are attributes."""
        import json

        import xarray as xr

        from maglev_match.core.datasets import annotate

        rows = self.rows

        def col(name: str) -> np.ndarray:
            return np.array([float("nan") if getattr(r, name) is None
                             else float(getattr(r, name)) for r in rows], float)

        per = "1 per unit of the parameter (see parameter_unit)"
        columns = {  # name: (units, long name)
            "value": ("SI (see parameter_unit)", "parameter value"),
            "dchi": (per, "d chi / d p of the headline index"),
            "dchi_paper": (per, "d chi_paper / d p (the paper's definition)"),
            "dchi_simulation": (per, "d chi_simulation / d p (NaN: not available)"),
            "dchi_left": (per, "one-sided d chi / d p for a decrease of p (at a switch)"),
            "dchi_right": (per, "one-sided d chi / d p for an increase of p (at a switch)"),
            "elasticity": ("1", "elasticity of chi, (p / chi) d chi / d p"),
            "dmargin": ("1/s per unit of the parameter", "d margin / d p, margin = "
                        "-max Re(lambda)"),
            "dhopf_distance": (per, "d (relative Hopf distance) / d p"),
            "boundary": ("SI (see parameter_unit)", "value of p at the nearest stability "
                         "boundary"),
            "boundary_relative": ("1", "(boundary - p) / p"),
            "limit_boundary": ("SI (see parameter_unit)", "first-order value of p where the "
                               "bounding cycle reaches the gap limit"),
        }
        data: dict[str, Any] = {k: ("parameter", col(k)) for k in columns}
        data["parameter_unit"] = ("parameter", np.array([r.unit for r in rows], dtype=str))
        data["note"] = ("parameter", np.array([r.note for r in rows], dtype=str))
        ix = self.index
        head = {"chi": ix.chi, "chi_paper": ix.chi_paper, "chi_simulation": ix.chi_simulation,
                "h": ix.h, "w0": ix.w0, "max_real_part": ix.max_real_part}
        data.update({k: ((), float("nan") if v is None else float(v))
                     for k, v in head.items()})
        ds = xr.Dataset(data, coords={"parameter": ("parameter", [r.name for r in rows])},
                        attrs={
            "title": "maglev-match sensitivities of the matching index",
            "status": str(self.status),
            "paper_status": "" if self.paper_status is None else str(self.paper_status),
            "simulation_status": self.simulation_status, "switch_note": self.switch_note,
            "limit_boundary_note": self.limit_boundary_note, "case": str(ix.case),
            "model": ix.model, "reading_basis": str(ix.reading_basis),
            "warnings": json.dumps(list(self.warnings))})
        return annotate(ds, units={k: u for k, (u, _) in columns.items()}
                        | {"chi_simulation": "1", "parameter_unit": "1", "note": "1",
                           "parameter": "1"},
                        long_names={k: n for k, (_, n) in columns.items()}
                        | {"chi_paper": "matching index by the paper's definition",
                           "chi_simulation": "h_simulation / w0 (NaN: not simulated)",
                           "parameter_unit": "SI unit of the parameter",
                           "note": "how the row's derivative was obtained",
                           "parameter": "parameter name"})


# ---------------------------------------------------------------------------------------
# beam and vehicle data -> model parameters, w0, h_max (the model's own map)
# ---------------------------------------------------------------------------------------
_FAR = 4.0  # boundaries are looked for within a factor 4 of the design value


def engineering_names(params: Params, model: str = "unit") -> tuple[str, ...]:
    """The parameters with a d chi / d p row (the model's
    :meth:`~maglev_match.maglev.base.MaglevModel.engineering_names`): its own parameters,
    with the derived modal values replaced by the beam's where they are derived, and
    gap_max. Model A: omega1 and sigma become L, EI, mbar, l, k; model B: omega1 becomes EI
    (:mod:`maglev_match.maglev.beam`)."""
    return maglev_model(params, model).engineering_names()


def derived_map(params: Params, model: str = "unit") -> Callable:
    """q (values of :func:`engineering_names`) -> (model parameter vector, w0, h_max), a
    JAX function so its Jacobian is exact (the model's
    :meth:`~maglev_match.maglev.base.MaglevModel.derived_map`, formulas in
    :mod:`maglev_match.maglev.beam`)."""
    return maglev_model(params, model).derived_map()


def _values(params: Params, names: tuple[str, ...]) -> np.ndarray:
    return np.array([float(getattr(params, n)) for n in names])


def index_sensitivity(params: Params, index: MatchingIndex | None = None, *,
                      boundaries: bool = True, model: str | None = None,
                      simulate: bool = True) -> IndexSensitivity:
    """d chi / d p, the elasticity (p / chi) d chi / d p, d margin / d p and the derivative of
    the relative Hopf distance for every parameter of model A or model B at ``params``.

    Parameters
    ----------
    params : the parameter set.
    index : the index at ``params`` (computed, without simulation, when not given).
    boundaries : also solve, for each parameter, the value where the equilibrium changes
        stability (Newton's method with the exact slope of max Re lambda), and the first-order
        cycle-limit boundary.
    model : 'unit' (model A) or 'vehicle' (model B); default: the model of ``index``, else
        'unit'. For the vehicle, h is the largest gap deviation over the six levitation
        points on the cycle (the envelope theorem picks the point and the time of the
        maximum) and w0 the static mid-span deflection (:func:`derived_map`).

    simulate : when ``index`` is not given, compute it with the simulation (the headline is
        then the smaller of chi_paper and chi_simulation) or without (the paper's chi).

    Raises :class:`~maglev_match.core.params.ParameterError` (naming tau) for a delay:
    the sensitivities are of the delay-free models.

    The derivative is that of the headline ``index.chi``. chi_paper = h / w0 gives
    d chi_paper = (dh - chi_paper dw0) / w0 with dh = (dh/dp_model)(dp_model/dq) in the
    cycle case and dh = d(gap_max - c0) in case ``no_cycle_within_limits``; the vehicle's
    take one implicit solve on its cycle. chi_simulation = h_simulation / w0 with
    h_simulation the solved critical size of the deciding direction: its derivative comes
    from the implicit function theorem on the solved grazing or basin-boundary condition
    (:func:`maglev_match.analyses.critical.critical_derivative`), so it exists only where that
    direction was solved. Where the headline sits at a switch between its two parts (or
    h_simulation between its two directions) the one-sided derivatives are given
    (``dchi_left``, ``dchi_right``).
    """
    from maglev_match.core.threads import blas_threads

    # the maps from the beam data to the model parameters are of the delay-free models
    refuse_delay(params, "the sensitivities of the index")
    m = maglev_model(params, model or (index.model if index is not None else "unit"))
    # small dense blocks: BLAS threads only contend (as in matching_index)
    with blas_threads(m.blas_threads):
        return _index_sensitivity(m, index, boundaries, simulate)


#: two parts of the headline (or two directions of h_simulation) within this relative
#: distance are treated as a switch: one-sided derivatives
SWITCH_TOL = 1e-6


def _simulation_derivative(m: MaglevModel, idx: MatchingIndex, Pq: np.ndarray,
                           names: tuple[str, ...]) -> tuple[dict[str, np.ndarray], str]:
    """d h_simulation / dq of each direction whose critical size was solved (keys 'up',
    'down'), in the engineering parameters q, and a text on how (or why not)."""
    from maglev_match.analyses.critical import critical_derivative

    out: dict[str, np.ndarray] = {}
    why = []
    for key, crit in (("up", idx.critical_up), ("down", idx.critical_down)):
        if crit is None or not crit.solved:
            if crit is not None:
                why.append(f"{key}: {crit.mechanism} (no derivative)")
            continue
        c = crit if crit.dsize_dp is not None else critical_derivative(m, crit)
        if c.dsize_dp is None:
            why.append(f"{key}: {c.mechanism}, derivative run failed")
            continue
        dq = c.dsize_dp @ Pq
        if c.limit == "upper" and "gap_max" in names:
            dq = dq + (c.dsize_dlimit or 0.0) * np.array([1.0 if n == "gap_max" else 0.0
                                                          for n in names])
        out[key] = dq
        why.append(f"{key}: implicit function theorem on the solved {c.mechanism} condition")
    return out, "; ".join(why)


def _index_sensitivity(m: MaglevModel, index: MatchingIndex | None, boundaries: bool,
                       simulate: bool = True) -> IndexSensitivity:
    params = m.params
    idx = index if index is not None else matching_index(m, simulate=simulate)
    system = m.system()
    search = m.hopf_search()
    names = m.engineering_names()
    q = _values(params, names)
    fmap = m.derived_map()
    jac = _map_jacobian(fmap)
    (pm, w0, hmax), (Pq, W0q, Hq) = jac(jnp.asarray(q))
    Pq, W0q, Hq = np.asarray(Pq), np.asarray(W0q), np.asarray(Hq)
    w0 = float(w0)
    sens = system_sensitivity(system, idx, np.asarray(pm))
    warnings = list(sens.warnings)
    if abs(w0 - idx.w0) > 1e-8 * abs(idx.w0):
        warnings.append(f"the static deflection of the beam formulas, {w0:.10g} m, differs "
                        f"from the index's w0 {idx.w0:.10g} m")
    status = sens.h_status
    paper_status = status
    if status == DerivativeStatus.RULE:
        dh_q = Hq
    else:
        dh_q = sens.dh_dp @ Pq
    chi_p = idx.chi_paper
    if status == DerivativeStatus.ZERO:
        dchi_paper = np.zeros(len(names))
    else:
        dchi_paper = (dh_q - chi_p * W0q) / w0
    # the headline: chi_paper, chi_simulation, or a switch between them
    chi = idx.chi
    dchi = dchi_paper
    dchi_sim = None
    left = right = None
    sim_status = ""
    switch_note = ""
    if idx.chi_simulation is not None and idx.h_simulation is not None:
        dh_sims, sim_status = _simulation_derivative(m, idx, Pq, names)
        sizes = {"up": idx.h_simulation_up, "down": idx.h_simulation_down}
        near = [k for k, v in sizes.items() if v is not None
                and abs(v - idx.h_simulation) <= SWITCH_TOL * idx.h_simulation]
        if all(k in dh_sims for k in near):
            parts = [(dh_sims[k] - idx.chi_simulation * W0q) / w0 for k in near]
            dchi_sim = parts[0] if len(parts) == 1 else np.minimum(parts[0], parts[1])
            if len(parts) == 2:
                switch_note = ("h_simulation is at a switch between its two directions: "
                               "one-sided derivatives")
                left, right = np.maximum(parts[0], parts[1]), np.minimum(parts[0], parts[1])
        tie = (math.isfinite(chi_p) and abs(chi_p - idx.chi_simulation)
               <= SWITCH_TOL * max(abs(chi_p), 1e-300))
        if tie:
            switch_note = ("the headline is at a switch between chi_paper and chi_simulation: "
                           "one-sided derivatives")
            if dchi_sim is not None and status != DerivativeStatus.UNDEFINED:
                left = np.maximum(dchi_paper, dchi_sim if left is None else left)
                right = np.minimum(dchi_paper, dchi_sim if right is None else right)
                dchi = right
            else:
                dchi = np.full(len(names), np.nan)
                status = DerivativeStatus.UNAVAILABLE
        elif idx.reading_basis == "simulation":
            if dchi_sim is not None:
                dchi = dchi_sim if right is None else right
                status = DerivativeStatus.SOLVED
            else:
                dchi = np.full(len(names), np.nan)
                status = DerivativeStatus.UNAVAILABLE
            if left is not None and right is not None and not switch_note:
                switch_note = "one-sided derivatives"
        elif left is not None:  # the switch is in the non-deciding part: headline smooth
            left = right = None
            switch_note = ""
    dmargin = -(sens.dmax_re_dp @ Pq)
    ddist = None
    if sens.dhopf_dp is not None and idx.hopf_param is not None:
        k = system.param_index(idx.hopf_param)
        v = float(np.asarray(pm)[k])
        a = float(sens.hopf_value)
        # distance = |a - v| / |v| with a = alpha_H(p), v the design value of that parameter
        sgn = math.copysign(1.0, a - v)
        dd_dp = sgn * sens.dhopf_dp / abs(v)
        dd_dp[k] += -sgn / abs(v) - abs(a - v) * math.copysign(1.0, v) / v**2
        ddist = dd_dp @ Pq
    bounds: dict[str, tuple[float | None, str]] = {}
    if boundaries:
        bounds = _stability_boundaries(system, fmap, q, names)
    # the other case boundary: the branch's extreme gap deviation reaching a gap limit
    limit_b = np.full(len(names), np.nan)
    limit_note = ""
    if boundaries and paper_status in (DerivativeStatus.EXACT, DerivativeStatus.RULE):
        ubound = unlimited_bound(system, np.asarray(pm), search)
        ext = branch_extremes(system, np.asarray(pm), search, bound=ubound)
        lo_lim = params.gap_min - params.c0
        contact = (limit_contact(system, ubound, float(hmax), lo_lim)
                   if ext is None and paper_status == DerivativeStatus.RULE else None)
        if ext is None and contact is None:
            limit_note = "no surrounding cycle without the gap limit either: no cycle-limit " \
                         "boundary"
        elif ext is None:
            # the branch cannot reach the design point: the case changes where its contact
            # with the limit, lambda_c(q), meets the design value of the branch parameter.
            # E(lambda_c, p) = limit(q)  =>  d lambda_c / dq = -(dE/dp Pq - dlimit/dq) / E_lam
            lam_c, dE, which, solved = contact
            k = system.param_index(idx.hopf_param)
            e_lam = dE[k]
            dE_other = dE.copy()
            dE_other[k] = 0.0
            c0_k = np.array([1.0 if n == "c0" else 0.0 for n in names])
            dlimit = Hq if which == "max" else -c0_k
            dlam_c = -(dE_other @ Pq - dlimit) / e_lam
            G = lam_c - float(np.asarray(pm)[k])
            dG = dlam_c - Pq[k]
            with np.errstate(divide="ignore", invalid="ignore"):
                pick = np.where(dG != 0, -G / dG, np.nan)
            limit_b = q + pick
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = limit_b / q
            limit_b = np.where((ratio >= 1.0 / _FAR) & (ratio <= _FAR), limit_b, np.nan)
            lim_v = float(hmax) if which == "max" else lo_lim
            limit_note = (f"the cycle branch from the Hopf point at {idx.hopf_param} = "
                          f"{idx.hopf_value:.6g} reaches the gap-deviation limit "
                          f"{lim_v * 1e3:.4g} mm at {idx.hopf_param} = {lam_c:.6g} and cannot "
                          "be continued to the design point"
                          + ("" if solved else " (contact bracketed between two branch points, "
                             "not solved: the cycle is near-singular at gap 0)")
                          + "; 'cycle-limit boundary': where that contact meets the design "
                          "point, to first order")
        else:
            (hi_v, hi_d, hi_l), (lo_v, lo_d, lo_l) = ext["max"], ext["min"]
            c0_k = np.array([1.0 if n == "c0" else 0.0 for n in names])
            # margins to the limits of the gap deviation: (gap_max - c0) - max, min - (gap_min - c0)
            margins = [(float(hmax) - hi_v, Hq - hi_d @ Pq),
                       (lo_v - (params.gap_min - params.c0), lo_d @ Pq + c0_k)]
            with np.errstate(divide="ignore", invalid="ignore"):
                deltas = np.array([np.where(d != 0, -m / d, np.nan) for m, d in margins])
            short = [i for i, (m, _) in enumerate(margins) if m < 0]
            if short:  # case rule in force: every short margin must be made good
                dd = deltas[short]
                same = np.all(np.sign(dd) == np.sign(dd[0]), axis=0)
                pick = np.where(same, dd[np.argmax(np.abs(np.nan_to_num(dd)), axis=0),
                                         np.arange(len(names))], np.nan)
            else:  # the nearest of the two contacts
                pick = deltas[np.argmin(np.abs(np.nan_to_num(deltas, nan=np.inf)), axis=0),
                              np.arange(len(names))]
            limit_b = q + pick
            # a first-order extrapolation far from the design point says nothing: keep it
            # within the factor the stability scan uses
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = limit_b / q
            limit_b = np.where((ratio >= 1.0 / _FAR) & (ratio <= _FAR), limit_b, np.nan)
            limit_note = (f"along the cycle branch from the Hopf point to the design point the "
                          f"gap deviation reaches {hi_v * 1e3:.4g} mm (at {idx.hopf_param} = "
                          f"{hi_l:.5g}) and {lo_v * 1e3:.4g} mm (at {lo_l:.5g}); the limits are "
                          f"{float(hmax) * 1e3:.4g} mm and "
                          f"{(params.gap_min - params.c0) * 1e3:.4g} mm. 'cycle-limit "
                          "boundary': where the first of them is reached, to first order")
    rows = []
    for i, n in enumerate(names):
        note = ""
        if status == DerivativeStatus.ZERO:
            note = "chi = 0 throughout the unstable region: derivative exactly 0"
        elif status == DerivativeStatus.RULE and n not in ("gap_max", "c0"):
            note = "h = gap_max - c0 by the case rule: chi moves only through w0"
        elif status == DerivativeStatus.UNDEFINED:
            note = "undefined: the index did not converge"
        b, bnote = bounds.get(n, (None, ""))
        if bnote:
            note = (note + "; " if note else "") + bnote
        ela = q[i] / chi * dchi[i] if chi and math.isfinite(chi) else float("nan")
        if status == DerivativeStatus.UNAVAILABLE and not note:
            note = "d chi_simulation not available: its critical size is only bracketed"
        rows.append(ParameterSensitivity(
            name=n, value=float(q[i]), unit=PARAMETER_DOCS.get(n, ("", ""))[0],
            dchi=float(dchi[i]), elasticity=float(ela), dmargin=float(dmargin[i]),
            dchi_paper=float(dchi_paper[i]),
            dchi_simulation=None if dchi_sim is None else float(dchi_sim[i]),
            dchi_left=None if left is None else float(left[i]),
            dchi_right=None if right is None else float(right[i]),
            dhopf_distance=None if ddist is None else float(ddist[i]),
            boundary=b, boundary_relative=None if b is None else (b - q[i]) / q[i], note=note,
            limit_boundary=float(limit_b[i]) if np.isfinite(limit_b[i]) else None,
        ))
    return IndexSensitivity(index=idx, status=status, rows=tuple(rows), system=sens,
                            limit_boundary_note=limit_note, warnings=tuple(warnings),
                            paper_status=paper_status, simulation_status=sim_status,
                            switch_note=switch_note)


@cache
def _map_jacobian(fmap: Callable) -> Callable:
    """(values, Jacobians) of the derived map at q, compiled once per map."""

    def fun(q):
        return fmap(q), jax.jacfwd(fmap)(q)

    return jax.jit(fun)


def _stability_boundaries(system: System, fmap: Callable, q: np.ndarray,
                          names: tuple[str, ...], factor: float = _FAR, n_scan: int = 33,
                          max_iter: int = 30) -> dict[str, tuple[float | None, str]]:
    """For each parameter q_k alone: the nearest value where max Re lambda changes sign.

    A log-spaced scan of max Re lambda over [q_k / factor, q_k factor] brackets the sign
    changes; the one nearest q_k is refined by Newton's method with the exact slope of the
    rightmost eigenvalue (eigenvalue perturbation), safeguarded by bisection."""
    out: dict[str, tuple[float | None, str]] = {}
    jac = _map_jacobian(fmap)

    def mre(qv: np.ndarray, k: int, x0):
        (pm, _, _), (Pq, _, _) = jac(jnp.asarray(qv))
        pm, col = np.asarray(pm), np.asarray(Pq)[:, k:k + 1]
        mr, d, x, _ = margin_derivative(system, pm, x0, directions=col)
        return mr, float(d[0]), x

    for k, name in enumerate(names):
        if name in _LIMITS:
            out[name] = (None, "does not affect stability")
            continue
        grid = q[k] * np.geomspace(1.0 / factor, factor, n_scan)
        vals, x = [], None
        for v in grid:
            qv = q.copy()
            qv[k] = v
            try:
                eq = find_equilibrium(system, np.asarray(jac(jnp.asarray(qv))[0][0]), x)
            except np.linalg.LinAlgError:
                vals.append(np.nan)
                continue
            x = eq.x if eq.converged else None
            J = system.jacobian(eq.x, eq.p)
            vals.append(float(np.max(np.linalg.eigvals(J).real)) if eq.converged else np.nan)
        vals_a = np.asarray(vals)
        brackets = [i for i in range(n_scan - 1)
                    if np.isfinite(vals_a[i]) and np.isfinite(vals_a[i + 1])
                    and np.sign(vals_a[i]) != np.sign(vals_a[i + 1])]
        if not brackets:
            out[name] = (None, f"no stability boundary within a factor {factor:g}")
            continue
        i = min(brackets, key=lambda i: abs(math.log(grid[i] * grid[i + 1]) / 2
                                            - math.log(q[k])))
        lo, hi = float(grid[i]), float(grid[i + 1])
        flo = vals_a[i]
        v = 0.5 * (lo + hi)
        found = None
        for _ in range(max_iter):
            qv = q.copy()
            qv[k] = v
            mr, slope, _ = mre(qv, k, None)
            if np.sign(mr) == np.sign(flo):
                lo = v
            else:
                hi = v
            if abs(mr) < 1e-12 or abs(hi - lo) < 1e-13 * abs(v):
                found = v
                break
            nv = v - mr / slope if slope else 0.5 * (lo + hi)
            if not min(lo, hi) < nv < max(lo, hi):
                nv = 0.5 * (lo + hi)
            v = nv
        out[name] = (found if found is not None else v,
                     "" if found is not None else "boundary located to the bracket only")
    return out
