"""The reproduction's sections: the paper's figures redrawn with the printed defaults
(Fig. 4, the Hopf curve; Fig. 5, the cycle bifurcation diagrams; Figs. 6-8, model A at
alpha1..alpha3; Figs. 11 and 13, model B on the turnout beams; Fig. 12, the unstable cycle
that decides h) and the variants section (which single parameter change would reconcile
the differences, with the variant presets written and model A run at alpha1..alpha3)."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match.core.io import atomic_write_text
from maglev_match.core.params import load_preset
from maglev_match.present.report.base import ReportContext, SectionUnavailable
from maglev_match.present.report.html import render, save_and_embed, table_html
from maglev_match.present.report.sections_cycles import (
    cycle_diagram_figure,
    cycle_diagram_table,
    hopf_curve_figure,
    hopf_curve_table,
    stability_region,
)
from maglev_match.present.report.sections_history import (
    outcome_text,
    run_time_history,
    time_history_figure,
)
from maglev_match.present.reproduce.paper import PAPER
from maglev_match.present.reproduce.study import Study
from maglev_match.present.reproduce.variants import (
    VARIANT_TARGET,
    shipped_variant_value,
    variant_preset_text,
)

__all__ = [
    "section_fig4",
    "section_fig5",
    "section_fig6_8",
    "section_fig11_13",
    "section_fig12",
    "section_variants",
]


def _mark_alphas() -> list[tuple[str, float, float]]:
    return [(f"alpha{k}", *PAPER[f"alpha{k}"]) for k in (1, 2, 3)] + [
        ("turnout-soft", PAPER["omega1_soft"], PAPER["sigma"]),
        ("turnout-stiff", PAPER["omega1_stiff"], PAPER["sigma"])]


def section_fig4(st: Study, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """Fig. 4: the Hopf curve of model A in (omega1, sigma), the paper's points marked."""
    curves = st.curves()
    frag, files = save_and_embed(
        hopf_curve_figure(curves, _mark_alphas(), st.settings,
                          "Fig. 4: Hopf curve of model A (printed defaults)",
                          region=stability_region(st.preset("alpha1"), st.settings)),
        ctx, "fig4_hopf_curve",
        "Fig. 4 recomputed: the Hopf curve in (omega1, sigma), subcritical red, supercritical "
        "blue, generalised Hopf points as squares; the paper's parameter points marked; "
        "shaded: the equilibrium is unstable (eigenvalues on a grid, an independent check).")
    return frag + hopf_curve_table(curves), files, None


def section_fig5(st: Study, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """Fig. 5: the cycle bifurcation diagrams along omega1 and along sigma."""
    parts, files = [], []
    for param, tag, design in (("omega1", "a", 100.0), ("sigma", "b", 4e-4)):
        d = st.diagram(param)
        fixed = "sigma = 4e-4" if param == "omega1" else "omega1 = 100 rad/s"
        frag, fl = save_and_embed(
            cycle_diagram_figure(d, design, f"Fig. 5{tag}: cycles along {param}, {fixed}"),
            ctx, f"fig5{tag}_cycles_{param}",
            f"Fig. 5{tag} recomputed: max/min gap deviation of the cycles; solid stable, "
            "dashed unstable, * Hopf points, o first contact with a gap limit (dotted); the "
            "dash-dotted line is alpha1.")
        parts += [frag, cycle_diagram_table(d)]
        files += fl
    return "".join(parts), files, None


def section_fig6_8(st: Study, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """Figs. 6-8: model A at alpha1..alpha3 from the paper's initial beam deflections."""
    parts, files, rows = [], [], []
    cases = [("6", "alpha1", list(PAPER["x5_alpha1"])), ("7", "alpha2", [PAPER["x5_alpha2"]]),
             ("8", "alpha3", [PAPER["x5_alpha3"]])]
    for fig, name, x5s in cases:
        runs = []
        for x5 in x5s:
            sim, ds = st.unit_run(name, x5)
            runs.append((f"x5(0) = {x5 * 1e3:g} mm", ds))
            rows.append((f"Fig. {fig}", name, f"{x5 * 1e3:g} mm", outcome_text(sim)))
        p = st.preset(name)
        frag, fl = save_and_embed(
            time_history_figure(runs, p, f"Fig. {fig}: {name} = [{p.omega1:g}, {p.sigma:g}]"),
            ctx, f"fig{fig}_{name}",
            f"Fig. {fig} recomputed: model A with the physical limits on at {name}, from the "
            "paper's initial beam deflections; dotted lines are the gap limits.")
        parts.append(frag)
        files += fl
    parts.append(table_html(["figure", "point", "x5(0)", "outcome"], rows))
    return "".join(parts), files, rows


def section_fig11_13(st: Study, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """Figs. 11 and 13: model B pressed onto the free stiff and soft turnout beams."""
    if not st.settings.include_vehicle:
        raise SectionUnavailable("model B left out by the settings (--quick)")
    parts, files, rows = [], [], []
    sim, ds = st.vehicle_run("turnout-stiff", None)
    rows.append(("Fig. 11", "turnout-stiff", "pressed onto the free beam", outcome_text(sim)))
    frag, fl = save_and_embed(
        time_history_figure([("pressed", ds)], st.preset("turnout-stiff"),
                            "Fig. 11: turnout-stiff, model B", points=[0, 2, 4]),
        ctx, "fig11_turnout_stiff",
        "Fig. 11 recomputed: model B pressed onto the free stiff turnout beam (all q_n = 0); "
        "gaps at the first point of each levitation frame.")
    parts.append(frag)
    files += fl
    for tag, q1 in (("a", None), ("b", PAPER["q1_fig13b"])):
        sim, ds = st.vehicle_run("turnout-soft", q1)
        label = "q1(0) = 0" if q1 is None else f"q1(0) = {q1 * 1e3:g} mm"
        rows.append((f"Fig. 13{tag}", "turnout-soft", f"pressed, {label}", outcome_text(sim)))
        frag, fl = save_and_embed(
            time_history_figure([(label, ds)], st.preset("turnout-soft"),
                                f"Fig. 13{tag}: turnout-soft, model B, {label}",
                                points=[0, 2, 4]),
            ctx, f"fig13{tag}_turnout_soft",
            f"Fig. 13{tag} recomputed: model B pressed onto the free soft turnout beam, {label}.")
        parts.append(frag)
        files += fl
    parts.append(table_html(["figure", "beam", "initial state", "outcome"], rows))
    return "".join(parts), files, rows


def section_fig12(st: Study, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """Fig. 12: the unstable cycle of model A that decides h on the soft turnout beam."""
    from maglev_match.plots import new_figure

    mi = st.matching("turnout-soft")
    if mi.cycle is None:
        raise SectionUnavailable(f"no unstable cycle decides h for turnout-soft (case "
                                 f"{mi.case}: {mi.message})")
    orbit = mi.cycle.orbit
    from maglev_match.maglev.models import build_system

    p = st.preset("turnout-soft")
    system = build_system(p, "unit")
    gap = np.asarray(system.observe("gap_deviation", orbit.states, orbit.p))
    # d(c - c0)/dt = x2 - x6 (model A: gap deviation x1 - x5)
    rate = np.asarray(orbit.states)[:, 1] - np.asarray(orbit.states)[:, 5]
    t = np.asarray(orbit.times)  # s
    fig, (ax1, ax2) = new_figure(1, 2, figsize=(11, 4.2))
    ax1.plot(t, gap * 1e3)
    ax1.axhline(mi.h * 1e3, color="C3", ls="--", label=f"h = {mi.h * 1e3:.3g} mm")
    ax1.set_xlabel("time (s)")
    ax1.set_ylabel("gap deviation c - c0 (mm)")
    ax1.set_title(f"Fig. 12: unstable cycle, period {mi.cycle.period:.4g} s")
    ax1.legend(fontsize=8)
    ax2.plot(gap * 1e3, rate * 1e3)
    ax2.set_xlabel("gap deviation c - c0 (mm)")
    ax2.set_ylabel("gap rate (mm/s)")
    ax2.set_title("phase portrait")
    frag, files = save_and_embed(
        fig, ctx, "fig12_unstable_cycle",
        "Fig. 12 recomputed: the unstable limit cycle of model A on the soft turnout beam "
        "(omega1 = 97.33 rad/s, sigma = 4.72e-4) that decides h.")
    return frag, files, None


def section_variants(st: Study, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """The variants table, the variant presets written (those for which every paper
    statement holds) and model A run at alpha1..alpha3 with them."""
    results = st.variants()
    rows = []
    for v in results:
        checks = ", ".join(f"{k}: {'yes' if ok else 'no'}" for k, ok in v.checks.items())
        if v.window is None:
            window = None
        elif v.window[1] - v.window[0] <= 1e-6 * abs(v.window[1]):
            window = "none: this boundary does not move with omega1 (not the Hopf point A1)"
        else:
            window = f"{v.window[0]:.5g} .. {v.window[1]:.5g}"
        rows.append((v.param, v.default, v.value, window, v.a1, checks or v.message))
    table = table_html(["parameter", "printed value", f"value for A1 = {VARIANT_TARGET}",
                        "values with A1 in (100, 105)", "A1 with it (rad/s)",
                        "paper statements that then hold (model A)"], rows, "variants")
    full = [v for v in results if v.checks and all(v.checks.values())]
    written = []
    for v in full:
        path = ctx.out_dir / f"paper-variant-{v.param}.toml"
        atomic_write_text(path, variant_preset_text(v))
        written.append(path)
    sim_rows: list[tuple[Any, ...]] = []
    if full:
        t_end = 3.0 if st.settings.quick else 5.0
        for v in full:
            shipped = shipped_variant_value(v.param)
            base = load_preset("turnout-soft").replace(**{v.param: float(v.value)})
            for name, x5s in (("alpha1", PAPER["x5_alpha1"]), ("alpha2", (PAPER["x5_alpha2"],)),
                              ("alpha3", (PAPER["x5_alpha3"],))):
                w, sg = PAPER[name]
                for x5 in x5s:
                    sim, _ = run_time_history(base.replace(omega1=w, sigma=sg), "unit", t_end,
                                              x5=x5)
                    sim_rows.append((f"{v.param} = {v.value:.5g}" + (
                        "" if shipped is None else f" (shipped preset: {shipped:.6g})"),
                        name, f"{x5 * 1e3:g} mm", outcome_text(sim)))
    frag = render("reproduce_variants.html.j2", target=VARIANT_TARGET, full=full, table=table,
                  sim_table=table_html(["variant", "point", "x5(0)", "outcome"], sim_rows)
                  if sim_rows else "")
    return frag, written, [asdict(v) for v in results]
