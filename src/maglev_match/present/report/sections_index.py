"""The study report's sections on the matching index and its sensitivities: the index
h, w0, chi with its reading and, with the vehicle included, model B's index beside model
A's (:func:`section_matching`, :func:`matching_rows`, :func:`side_by_side_rows`), and the
exact derivatives of chi and of the stability margin with the nearest stability boundary
per parameter (:func:`section_sensitivity`, :func:`sensitivity_rows`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from maglev_match.core.params import Params
from maglev_match.present.report.html import formatted_rows, render, save_and_embed

if TYPE_CHECKING:
    from maglev_match.present.report.base import ReportContext

__all__ = [
    "matching_rows",
    "side_by_side_rows",
    "BASIS_TEXT",
    "section_matching",
    "sensitivity_rows",
    "section_sensitivity",
]


def matching_rows(mi: Any) -> list[tuple[str, Any, str]]:
    """(quantity, value, unit) rows of a MatchingIndex."""
    def mm(v: Any) -> Any:
        return None if v is None else float(v) * 1e3

    return [
        ("chi, the headline index (the one the reading uses)", mi.chi, "-"),
        ("chi = h / w0 by the paper's definition", _chi_paper(mi), "-"),
        ("chi_simulation (simulated critical disturbance / w0)", mi.chi_simulation, "-"),
        ("h (basin along the gap)", mm(mi.h), "mm"),
        ("w0 (static deflection, typical disturbance)", mm(mi.w0), "mm"),
        ("case that decided h", mi.case, ""),
        ("reading", mi.reading, ""),
        ("reading based on", getattr(mi, "reading_basis", "paper"), ""),
        ("equilibrium stable", mi.stable, ""),
        ("max Re(lambda)", mi.max_real_part, "1/s"),
        ("Hopf point used", None if mi.hopf_param is None
         else f"{mi.hopf_param} = {mi.hopf_value:.6g}", ""),
        ("l1 there", mi.l1, "1/s"),
        ("cycle period", mi.cycle_period, "s"),
        ("cycle max / min gap deviation",
         None if mi.cycle_gap_max is None
         else f"{mi.cycle_gap_max * 1e3:.4g} / {mi.cycle_gap_min * 1e3:.4g}", "mm"),
        ("coil current reverses on the cycle", mi.current_reverses, ""),
        ("critical disturbance, beam up / down",
         None if mi.h_simulation is None and getattr(mi, "h_simulation_up", None) is None
         else " / ".join("-" if v is None else f"{v * 1e3:.4g}"
                         for v in (mi.h_simulation_up, mi.h_simulation_down)), "mm"),
    ]


def side_by_side_rows(unit: Any, vehicle: Any) -> list[tuple[str, Any, Any]]:
    """(quantity, model A, model B) rows comparing the two indices for the same beam."""
    def mm(v: Any) -> Any:
        return None if v is None else float(v) * 1e3

    return [
        ("chi (headline)", unit.chi, vehicle.chi),
        ("chi (the paper's definition)", _chi_paper(unit), _chi_paper(vehicle)),
        ("h (mm)", mm(unit.h), mm(vehicle.h)),
        ("w0 (mm)", mm(unit.w0), mm(vehicle.w0)),
        ("case", unit.case, vehicle.case),
        ("chi_simulation", unit.chi_simulation, vehicle.chi_simulation),
        ("reading based on", unit.reading_basis, vehicle.reading_basis),
        ("reading", unit.reading, vehicle.reading),
    ]


BASIS_TEXT = {"paper": "the paper's definition", "simulation": "the simulation, the smaller "
              "index"}


def section_matching(params: Params, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """The headline index chi (the one the reading uses, with its basis), the paper's
    definition and the simulation beside it, the case, the reading and every warning; with
    the vehicle included, the full vehicle's index beside model A's for the same beam."""
    from maglev_match.analyses.matching import matching_index

    mi = ctx.cache.get("matching")
    if mi is None:
        mi = matching_index(params, simulate=not ctx.settings.quick)
        ctx.cache["matching"] = mi
    data = mi.as_json() if hasattr(mi, "as_json") else mi
    mv = None
    if ctx.settings.include_vehicle:
        mv = matching_index(params, model="vehicle", simulate=not ctx.settings.quick)
        ctx.cache["matching_vehicle"] = mv  # the sensitivity section differentiates it
        data = {"unit": data, "vehicle": mv.as_json()}
    basis = str(getattr(mi, "reading_basis", "paper"))
    frag = render("matching.html.j2", mi=mi, rows=formatted_rows(matching_rows(mi)),
                  chi_paper=_chi_paper(mi), basis_text=BASIS_TEXT.get(basis, basis),
                  vehicle=mv,
                  side_rows=formatted_rows(side_by_side_rows(mi, mv)) if mv is not None else [])
    return frag, [], data


def _chi_paper(mi: Any) -> float:
    """chi by the paper's definition (``chi_paper`` when the result carries it)."""
    v = getattr(mi, "chi_paper", None)
    return mi.chi if v is None or not np.isfinite(v) else v


def sensitivity_rows(sens: Any, top: int = 12) -> list[tuple[Any, ...]]:
    """(parameter, value, d chi/dp, elasticity, d margin/dp, stability boundary) rows of an
    :class:`~maglev_match.analyses.sensitivity.IndexSensitivity`, largest |elasticity| first."""
    rows = []
    for r in sens.sorted_rows()[:top]:
        unit = f" {r.unit}" if r.unit else ""
        bound = (None if r.boundary is None
                 else f"{r.boundary:.4g}{unit} ({r.boundary_relative:+.1%})")
        rows.append((r.name, f"{r.value:.5g}{unit}", r.dchi, r.elasticity, r.dmargin, bound))
    return rows


def section_sensitivity(params: Params, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """Exact d chi / d p (implicit differentiation of the bounding cycle), the elasticities,
    the margin's sensitivities and the nearest stability boundary per parameter."""
    from maglev_match.analyses.matching import matching_index
    from maglev_match.analyses.sensitivity import index_sensitivity
    from maglev_match.plots.design import tornado_figure

    mi = ctx.cache.get("matching")
    if mi is None:
        mi = matching_index(params, simulate=not ctx.settings.quick)
        ctx.cache["matching"] = mi
    sens = index_sensitivity(params, index=mi, boundaries=not ctx.settings.quick)
    html, files = save_and_embed(tornado_figure(sens), ctx, "sensitivity_tornado",
                                 "Elasticities of chi and of the stability margin")
    data = sens.as_json()
    mv = ctx.cache.get("matching_vehicle") if ctx.settings.include_vehicle else None
    sv = None
    if mv is not None:
        # model B's sensitivities at its own index (one implicit solve on the vehicle's
        # cycle; no stability boundaries: each would scan the 40-state equilibrium)
        sv = index_sensitivity(params, index=mv, boundaries=False, model="vehicle")
        data = {"unit": data, "vehicle": sv.as_json()}
    header = ["parameter", "value", "d chi / d p", "elasticity",
              "d margin / d p (1/s per unit)", "stability lost at"]
    frag = render("sensitivity.html.j2", sens=sens, mi=mi, header=header,
                  rows=formatted_rows(sensitivity_rows(sens)),
                  figure=html, vehicle_sens=sv, vehicle_index=mv,
                  vehicle_rows=formatted_rows(sensitivity_rows(sv)) if sv is not None else [])
    return frag, files, data
