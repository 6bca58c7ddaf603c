"""The study report's sections on the design point's equilibrium: the parameter table with
units (:func:`section_parameters`), stability and eigenvalues of model A and B
(:func:`section_stability`, with :func:`stability_summary` which the reproduction shares)
and the root locus along omega1 (:func:`section_root_locus`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from maglev_match.core.params import PARAMETER_DOCS, Params
from maglev_match.maglev.catalog import model_info
from maglev_match.present.report.html import fmt, render, save_and_embed, table_html

if TYPE_CHECKING:
    from maglev_match.present.report.base import ReportContext

__all__ = [
    "params_table_html",
    "section_parameters",
    "stability_summary",
    "eigen_rows",
    "eigen_table_html",
    "EIGEN_ROWS",
    "section_stability",
    "section_root_locus",
]


def params_table_html(params: Params) -> str:
    """Every parameter with its unit and meaning, derived values marked."""
    values = params.as_dict()
    rows = []
    for name, v in values.items():
        unit, meaning = PARAMETER_DOCS.get(name, ("", ""))
        if name == "i0":
            unit, meaning = "A", "levitation current (derived)"
        if name == "w0":
            unit, meaning = "m", "static beam deflection (derived; the typical disturbance)"
        if name in ("omega1", "sigma", "s", "s0") and name not in params.explicit:
            meaning += " (derived from the beam/vehicle geometry)"
        rows.append((name, v, unit, meaning))
    return table_html(["name", "value", "unit", "meaning"], rows, "params")


def section_parameters(params: Params, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """Parameter table with units."""
    return params_table_html(params), [], params.as_dict()


def stability_summary(params: Params, model: str = "unit") -> dict[str, Any]:
    """Equilibrium stability of model A ('unit') or B ('vehicle')."""
    from maglev_match.dynamics.equilibria import stability
    from maglev_match.maglev.models import maglev_model

    res = stability(maglev_model(params, model).system())
    return {"model": model, "stable": res.stable, "max_real_part": res.max_real_part,
            "eigenvalues": res.eigenvalues, "converged": res.equilibrium.converged,
            "warnings": list(res.warnings)}


def eigen_rows(eigenvalues: np.ndarray, limit: int | None = None) -> list[tuple]:
    """(Re, Im, f in Hz, damping ratio) of each conjugate pair (Im >= 0) and real
    eigenvalue, at most ``limit`` of them."""
    rows = []
    for z in eigenvalues:
        if z.imag < -1e-12:
            continue
        zeta = -z.real / abs(z) if abs(z) > 0 else float("nan")
        rows.append((fmt(z.real), fmt(z.imag), fmt(abs(z.imag) / (2 * np.pi)), fmt(zeta)))
    return rows if limit is None else rows[:limit]


def eigen_table_html(eigenvalues: np.ndarray, limit: int | None = None) -> str:
    return table_html(["Re (1/s)", "Im (rad/s)", "f (Hz)", "damping ratio"],
                      eigen_rows(eigenvalues, limit), "eig")


#: eigenvalue rows shown per model (the rightmost; a 40-state model shows 12 of its pairs)
EIGEN_ROWS = 12


def section_stability(params: Params, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """Stability verdict and eigenvalues, model A and (optionally) model B."""
    models = ["unit"] + (["vehicle"] if ctx.settings.include_vehicle else [])
    shown, data = [], {}
    for model in models:
        s = stability_summary(params, model)
        data[model] = s
        info = model_info(model)
        rows = eigen_rows(s["eigenvalues"])
        shown.append({
            "label": f"Model {info.letter} ({info.title}, {len(s['eigenvalues'])} states)",
            "stable": s["stable"], "max_real_part": s["max_real_part"],
            "rows": rows[:EIGEN_ROWS], "truncated": len(rows) > EIGEN_ROWS,
            "warnings": s["warnings"]})
    return render("stability.html.j2", models=shown), [], data


def section_root_locus(params: Params, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """Root locus of model A along omega1 through the design point."""
    from maglev_match.dynamics.equilibria import root_locus
    from maglev_match.maglev.models import build_system
    from maglev_match.plots.rootlocus import root_locus_figure

    lo, hi = ctx.settings.hopf_omega1_range
    values = np.linspace(lo, hi, 61 if ctx.settings.quick else 181)
    res = root_locus(build_system(params, "unit"), "omega1", values)
    fig = root_locus_figure(values, res.eigenvalues, "omega1", "(rad/s)")
    fig.axes[1].axvline(float(params.omega1), color="C3", ls="--", lw=1)
    figure, files = save_and_embed(
        fig, ctx, "root_locus_omega1",
        f"Model A: eigenvalues along omega1 at sigma = {params.sigma:.4g} 1/kg; the dashed "
        f"line marks the design point omega1 = {params.omega1:.5g} rad/s.")
    mr = res.max_real_part
    changes = [float(values[k] - mr[k] * (values[k + 1] - values[k]) / (mr[k + 1] - mr[k]))
               for k in range(len(values) - 1) if np.sign(mr[k]) != np.sign(mr[k + 1])]
    return (render("root_locus.html.j2", figure=figure, changes=changes), files,
            {"stability_changes": changes})
