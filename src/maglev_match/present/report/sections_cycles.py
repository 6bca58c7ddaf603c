"""The study report's sections on limit cycles and the Hopf curve of model A, shared with
the reproduction of the paper's Figs. 4 and 5: the Hopf points along omega1 or sigma and
the cycle branch born at each (:class:`CycleDiagram`, :func:`cycle_diagram`, its figure
and table, :func:`section_bifurcation_diagrams`), and the Hopf curve in the
(omega1, sigma) plane with the stability region on an eigenvalue grid (:func:`hopf_curves`,
:func:`stability_region`, its figure and table, :func:`section_hopf_curve`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from maglev_match.core.params import Params
from maglev_match.present.report.html import render, save_and_embed, table_html

if TYPE_CHECKING:
    from maglev_match.present.report.base import ReportContext, ReportSettings

__all__ = [
    "CycleDiagram",
    "cycle_diagram",
    "PARAM_LABEL",
    "cycle_diagram_figure",
    "cycle_diagram_table",
    "section_bifurcation_diagrams",
    "hopf_curves",
    "stability_region",
    "hopf_curve_figure",
    "hopf_curve_table",
    "section_hopf_curve",
]


# ---------------------------------------------------------------------------------------
# Hopf points and cycle bifurcation diagrams through the design point
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CycleDiagram:
    """Equilibrium stability along one parameter, its Hopf points and the cycle branches
    born there (model A): the data of one panel of the paper's Fig. 5."""

    param: str
    fixed: dict[str, float]
    scan: Any  # dynamics.hopf.HopfScan
    branches: tuple[Any, ...]  # (HopfPoint, CycleBranch) pairs
    gap_limits: tuple[float, float]  # allowed gap deviations (m): gap_min - c0, gap_max - c0

    def limit_contacts(self) -> list[tuple[float, float, float]]:
        """(Hopf value, parameter value, max gap deviation) where an unstable cycle first
        touches a physical gap limit."""
        out = []
        for hp, br in self.branches:
            for sp in br.special_points:
                if sp.type == "contact":
                    out.append((hp.value, sp.value, sp.extrema["gap_deviation"][0]))
        return out


def cycle_diagram(params: Params, param: str, lo: float, hi: float,
                  settings: ReportSettings, n_scan: int | None = None) -> CycleDiagram:
    """Hopf points of model A along ``param`` in [lo, hi] (the other of omega1/sigma fixed
    at its value in ``params``) and the cycle branch from each, continued until it touches
    a physical gap limit or leaves [lo, hi]."""
    from maglev_match.dynamics.cycles import cycle_branch
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.maglev.limits import cycle_limit_margins
    from maglev_match.maglev.models import build_system

    system = build_system(params, "unit")
    n = n_scan or (60 if settings.quick else 160)
    scan = locate_hopf_points(system, param, lo, hi, n_scan=n)
    limits = (params.gap_min - params.c0, params.gap_max - params.c0)
    margins = cycle_limit_margins(params, include_current=False)
    branches = []
    for hp in scan.points:
        if not hp.converged:
            continue
        br = cycle_branch(system, hp, param, ntst=settings.cycle_ntst,
                          max_steps=settings.cycle_max_steps, limits=margins,
                          param_bounds=(lo, hi))
        branches.append((hp, br))
    other = "sigma" if param == "omega1" else "omega1"
    return CycleDiagram(param=param, fixed={other: float(getattr(params, other))}, scan=scan,
                        branches=tuple(branches), gap_limits=limits)


PARAM_LABEL = {"omega1": "omega1 (rad/s)", "sigma": "sigma (1/kg)"}


def _runs(mask: np.ndarray) -> list[slice]:
    """Consecutive runs of equal values in a boolean array, as slices overlapping by one
    point so the drawn pieces join."""
    out, start = [], 0
    for k in range(1, len(mask) + 1):
        if k == len(mask) or mask[k] != mask[start]:
            out.append(slice(start, min(k + 1, len(mask))))
            start = k
    return out


def cycle_diagram_figure(d: CycleDiagram, design: float | None = None, title: str = ""):
    """Max/min gap deviation (mm) of the cycles against the parameter: stable solid,
    unstable dashed, Hopf points '*', first contact with a gap limit 'o'; the equilibrium
    (gap deviation 0) solid where stable, dashed where unstable."""
    from maglev_match.plots import new_figure

    fig, ax = new_figure()
    vals, mr = np.asarray(d.scan.scan_values), np.asarray(d.scan.max_real_part)
    stable = mr < 0
    for sl in _runs(stable):
        ax.plot(vals[sl], np.zeros_like(vals[sl]), color="k", lw=1.6,
                ls="-" if stable[sl.start] else "--")
    for k, (hp, br) in enumerate(d.branches):
        color = f"C{k}"
        if br.points:
            v = br.values
            gmax, gmin = br.observable_max("gap_deviation"), br.observable_min("gap_deviation")
            st = br.stable
            for sl in _runs(st):
                ls = "-" if st[sl.start] else "--"
                ax.plot(v[sl], gmax[sl] * 1e3, color=color, ls=ls, lw=1.4)
                ax.plot(v[sl], gmin[sl] * 1e3, color=color, ls=ls, lw=1.4)
        ax.plot([hp.value], [0.0], marker="*", ms=13, color=color, ls="none",
                label=f"Hopf {hp.value:.4g} ({hp.kind})")
        for sp in br.special_points:
            if sp.type == "contact":
                gx, gn = sp.extrema["gap_deviation"]
                ax.plot([sp.value, sp.value], [gx * 1e3, gn * 1e3], "o", color=color, mfc="none",
                        ms=8)
    for g in d.gap_limits:
        ax.axhline(g * 1e3, color="k", ls=":", lw=1)
    if design is not None:
        ax.axvline(design, color="C3", ls="-.", lw=1, label=f"design point {design:.4g}")
    ax.set_xlabel(PARAM_LABEL.get(d.param, d.param))
    ax.set_ylabel("gap deviation c - c0 (mm)")
    fixed = ", ".join(f"{k} = {v:.4g}" for k, v in d.fixed.items())
    ax.set_title(title or f"Cycles of model A along {d.param} ({fixed})")
    ax.legend(fontsize=8, loc="best")
    ax.set_xlim(vals.min(), vals.max())
    return fig


def cycle_diagram_table(d: CycleDiagram) -> str:
    """One row per Hopf point of a diagram: the point, its branch's first contact with a
    limit, its other cycle bifurcations and how the branch ended (an HTML table)."""
    rows = []
    for hp, br in d.branches:
        contact = next((sp for sp in br.special_points if sp.type == "contact"), None)
        others = [f"{sp.type} at {sp.value:.5g}" for sp in br.special_points
                  if sp.type != "contact"]
        rows.append((hp.value, hp.frequency, hp.l1, hp.kind, hp.crossing_speed,
                     contact.value if contact else None,
                     "; ".join(others) or "-", br.stopped_reason))
    return table_html([f"Hopf {d.param}", "omega (rad/s)", "l1", "kind", "d Re/d param",
                       f"limit contact at {d.param}", "other cycle bifurcations",
                       "branch stopped"], rows, "hopf")


def section_bifurcation_diagrams(params: Params, ctx: ReportContext
                                 ) -> tuple[str, list[Path], Any]:
    """Cycle bifurcation diagrams through the design point: along omega1 at the design
    sigma and along sigma at the design omega1 (cf. the paper's Fig. 5)."""
    s = ctx.settings
    diagrams, files, data = [], [], {}
    w_lo, w_hi = s.hopf_omega1_range
    s_lo, s_hi = s.hopf_sigma_range
    for param, lo, hi in (("omega1", w_lo, w_hi), ("sigma", max(s_lo, 1e-6), s_hi)):
        d = cycle_diagram(params, param, lo, hi, s)
        ctx.cache[f"diagram_{param}"] = d
        design = float(getattr(params, param))
        figure, fl = save_and_embed(
            cycle_diagram_figure(d, design), ctx, f"cycles_{param}",
            f"Model A: equilibrium and limit cycles along {param}; solid stable, dashed "
            "unstable, * Hopf point, o first contact of the cycle with a gap limit (dotted).")
        diagrams.append({"figure": figure, "table": cycle_diagram_table(d)})
        files += fl
        data[param] = {"hopf": [(hp.value, hp.l1, hp.kind) for hp, _ in d.branches],
                       "limit_contacts": d.limit_contacts()}
    return render("cycles.html.j2", diagrams=diagrams), files, data


# ---------------------------------------------------------------------------------------
# Hopf curve in the (omega1, sigma) plane
# ---------------------------------------------------------------------------------------
def hopf_curves(params: Params, settings: ReportSettings) -> list[Any]:
    """Branches of the Hopf curve of model A in the (omega1, sigma) plane, continued from
    the Hopf points found along omega1 at the design sigma and along sigma at the design
    omega1 (duplicates of one branch are kept once)."""
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.dynamics.hopf_curve import hopf_curve
    from maglev_match.maglev.models import build_system

    system = build_system(params, "unit")
    w_lo, w_hi = settings.hopf_omega1_range
    s_lo, s_hi = settings.hopf_sigma_range
    n = 60 if settings.quick else 120
    seeds = list(locate_hopf_points(system, "omega1", w_lo, w_hi, n_scan=n).points)
    seeds += list(locate_hopf_points(system, "sigma", max(s_lo, 1e-6), s_hi, n_scan=n).points)
    bounds = {"omega1": (w_lo, w_hi), "sigma": (s_lo, s_hi)}
    curves: list[Any] = []
    for hp in seeds:
        if not hp.converged:
            continue
        if any(_on_curve(c, system, hp) for c in curves):
            continue
        curves.append(hopf_curve(system, ("omega1", "sigma"), hp, bounds=bounds,
                                 max_steps=400 if settings.quick else 5000))
    return curves


def _on_curve(curve: Any, system: Any, hp: Any) -> bool:
    """Whether a Hopf point lies on an already computed branch (within 1 % of the span)."""
    v = curve.values()
    if len(v) == 0:
        return False
    i_w, i_s = system.param_index("omega1"), system.param_index("sigma")
    pt = np.array([hp.p[i_w], hp.p[i_s]])
    span = np.maximum(np.ptp(v, axis=0), 1e-12)
    return bool(np.min(np.max(np.abs(v - pt) / span, axis=1)) < 0.01)


def stability_region(params: Params, settings: ReportSettings
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """max Re(lambda) of model A on a grid of (omega1, sigma) (batched Newton and
    eigenvalues): an independent picture of the regions the Hopf curve separates.
    Returns (omega1 values, sigma values, max real part shaped (n_sigma, n_omega1))."""
    from maglev_match.dynamics.hopf_curve import stability_grid
    from maglev_match.maglev.models import build_system

    n1, n2 = (50, 40) if settings.quick else (120, 90)
    w = np.linspace(*settings.hopf_omega1_range, n1)
    s = np.linspace(max(settings.hopf_sigma_range[0], 1e-7), settings.hopf_sigma_range[1], n2)
    mr, _ = stability_grid(build_system(params, "unit"), ("omega1", "sigma"), w, s)
    return w, s, mr


def hopf_curve_figure(curves: Sequence[Any], marks: Sequence[tuple[str, float, float]],
                      settings: ReportSettings, title: str = "",
                      region: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None):
    """The Hopf curve(s) in (omega1, sigma): subcritical (l1 > 0) red, supercritical blue,
    codimension-two points labelled, and the marked parameter points. With ``region``
    (from :func:`stability_region`) the unstable region U is shaded, S left white."""
    from maglev_match.plots import new_figure

    fig, ax = new_figure(figsize=(7.5, 5.0))
    if region is not None:
        w, s, mr = region
        unstable = np.where(np.isfinite(mr), (mr > 0).astype(float), np.nan)
        ax.contourf(w, s * 1e4, unstable, levels=[0.5, 1.5], colors=["#fde2e2"])
        ax.fill_between([], [], color="#fde2e2", label="U: unstable (eigenvalue grid)")
    for c in curves:
        v = c.values()
        if len(v) == 0:
            continue
        l1 = c.l1()
        sub = l1 > 0
        for sl in _runs(sub):
            ax.plot(v[sl, 0], v[sl, 1] * 1e4, color="C3" if sub[sl.start] else "C0", lw=1.8)
        for sp in c.special_points:
            ax.plot(sp.values[0], sp.values[1] * 1e4, "ks", ms=6)
            ax.annotate(sp.type, (sp.values[0], sp.values[1] * 1e4), textcoords="offset points",
                        xytext=(5, 5), fontsize=8)
    ax.plot([], [], color="C3", label="Hopf, subcritical (l1 > 0)")
    ax.plot([], [], color="C0", label="Hopf, supercritical (l1 < 0)")
    for k, (label, w, s) in enumerate(marks):
        ax.plot(w, s * 1e4, marker="o^vDP"[k % 5], ls="none", ms=8, label=label)
    ax.set_xlim(*settings.hopf_omega1_range)
    ax.set_ylim(settings.hopf_sigma_range[0] * 1e4, settings.hopf_sigma_range[1] * 1e4)
    ax.set_xlabel("omega1 (rad/s)")
    ax.set_ylabel("sigma (1e-4 1/kg)")
    ax.set_title(title or "Hopf curve of model A")
    ax.legend(fontsize=8, loc="best")
    return fig


def hopf_curve_table(curves: Sequence[Any]) -> str:
    """One row per codimension-two point of the Hopf curves: branch, type, where, the
    frequency, l2 and a note (an HTML table, or a sentence when there is none)."""
    rows = [(k + 1, sp.type, sp.values[0], sp.values[1], sp.frequency, sp.l2, sp.note)
            for k, c in enumerate(curves) for sp in c.special_points]
    if not rows:
        return "<p>No codimension-two points on the computed branches.</p>"
    return table_html(["branch", "type", "omega1 (rad/s)", "sigma (1/kg)", "omega (rad/s)",
                       "l2", "note"], rows, "codim2")


def section_hopf_curve(params: Params, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """The Hopf curve in (omega1, sigma) with the design point marked (cf. paper Fig. 4)."""
    curves = ctx.cache.get("hopf_curves")
    if curves is None:
        curves = hopf_curves(params, ctx.settings)
        ctx.cache["hopf_curves"] = curves
    marks = [(f"design point ({params.omega1:.4g}, {params.sigma:.3g})", float(params.omega1),
              float(params.sigma))]
    figure, files = save_and_embed(
        hopf_curve_figure(curves, marks, ctx.settings,
                          region=stability_region(params, ctx.settings)), ctx, "hopf_curve",
        "Hopf curve of model A in the (omega1, sigma) plane, continued from the Hopf points "
        "through the design point; squares are codimension-two points; shaded: unstable "
        "equilibrium on an eigenvalue grid (an independent check of the curve).")
    data = [{"values": c.values().tolist(), "l1": c.l1().tolist(),
             "special_points": [(sp.type, sp.values) for sp in c.special_points]}
            for c in curves]
    frag = render("hopf_curve.html.j2", figure=figure, curves=curves,
                  table=hopf_curve_table(curves))
    return frag, files, data
