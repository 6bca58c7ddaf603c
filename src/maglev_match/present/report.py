"""Self-contained HTML study reports: one HTML file per study.

A report is a list of *sections*. Each section is produced by a small function
``section(params, ctx) -> (html_fragment, figure_files, data)``; :func:`run_section` calls it
and, if the analysis it needs raises or is not available, renders a clear
"not available: <reason>" box instead (and logs the reason), so a report always renders.

The HTML comes from Jinja2 templates in ``maglev_match/templates/report/`` (the page, its
style sheet, the table/figure/note macros and the larger sections), rendered with
autoescaping, so a value can never inject markup. The file needs no network: figures are
embedded as base64 PNG (the SVG and PNG files are also written beside the report), styles
are inline, and no element refers to an ``http://`` or ``https://`` address. The footer
records the software version and the settings that produced the report.

:func:`study_report` assembles the report for one vehicle-beam pair: parameters with units,
stability and eigenvalues (models A and B), the root locus along omega1, the Hopf curve in
the (omega1, sigma) plane with the design point, the cycle bifurcation diagrams through the
design point, the time history after the typical disturbance (the vehicle pressed onto the
free beam, x5(0) = -w0) and the matching index h, w0, chi with its reading.
"""

from __future__ import annotations

import base64
import dataclasses
import datetime as _dt
import functools
import html
import json
import logging
import platform
import subprocess
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match.core.io import atomic_write_text
from maglev_match.core.params import PARAMETER_DOCS, Params
from maglev_match.core.units import label as unit_label
from maglev_match.maglev.catalog import model_info

log = logging.getLogger(__name__)

__all__ = [
    "ReportSettings",
    "ReportContext",
    "SectionResult",
    "SectionUnavailable",
    "ReportResult",
    "run_section",
    "figure_html",
    "table_html",
    "note_html",
    "assemble_html",
    "write_report",
    "software_version",
    "study_sections",
    "study_report",
    "fmt",
]


# ---------------------------------------------------------------------------------------
# data
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReportSettings:
    """How much work a report does.

    quick : coarse settings (few continuation steps, short simulations) for tests/previews.
    t_end : simulation horizon (s) of the time histories.
    hopf_omega1_range : (min, max) of omega1 (rad/s) for the Hopf curve chart.
    hopf_sigma_range : (min, max) of sigma (1/kg) for the Hopf curve chart.
    cycle_ntst, cycle_max_steps : collocation mesh intervals and continuation steps.
    include_vehicle : also analyse model B (full vehicle, 40 states).
    """

    quick: bool = False
    t_end: float = 3.0
    hopf_omega1_range: tuple[float, float] = (40.0, 400.0)
    hopf_sigma_range: tuple[float, float] = (0.0, 2e-3)
    cycle_ntst: int = 60
    cycle_max_steps: int = 200
    include_vehicle: bool = True

    @classmethod
    def quick_settings(cls) -> ReportSettings:
        return cls(quick=True, t_end=1.5, cycle_ntst=30, cycle_max_steps=60,
                   include_vehicle=False)

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass
class ReportContext:
    """What the section functions share: the output folder for figure files, the
    settings and a cache of intermediate results (e.g. Hopf points used by two sections)."""

    out_dir: Path
    settings: ReportSettings = field(default_factory=ReportSettings)
    cache: dict[str, Any] = field(default_factory=dict)
    prefix: str = ""

    def figure_path(self, stem: str) -> Path:
        """Where a figure named ``stem`` is written (suffix added by the saver)."""
        return self.out_dir / f"{self.prefix}{stem}"


class SectionUnavailable(Exception):
    """A section cannot be computed (a missing analysis module, a failed precondition)."""


@dataclass(frozen=True)
class SectionResult:
    """One rendered section of a report."""

    key: str
    title: str
    html: str
    figures: tuple[Path, ...]
    data: Any
    available: bool
    reason: str = ""
    seconds: float = 0.0


@dataclass(frozen=True)
class ReportResult:
    """A written report: the HTML file, its figure files and every section's data."""

    path: Path
    sections: tuple[SectionResult, ...]
    figures: tuple[Path, ...]
    seconds: float

    @property
    def unavailable(self) -> list[tuple[str, str]]:
        """(section key, reason) of the sections that could not be computed."""
        return [(s.key, s.reason) for s in self.sections if not s.available]


SectionFn = Callable[[Params, ReportContext], tuple[str, Sequence[Path], Any]]


# ---------------------------------------------------------------------------------------
# small HTML helpers
# ---------------------------------------------------------------------------------------
def fmt(value: Any, digits: int = 5) -> str:
    """Numbers for tables: ``digits`` significant digits, '-' for None/NaN."""
    if value is None:
        return "-"
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        if not np.isfinite(value):
            return "-"
        return f"{float(value):.{digits}g}"
    if isinstance(value, complex | np.complexfloating):
        z = complex(value)
        sign = "+" if z.imag >= 0 else "-"
        return f"{z.real:.{digits}g} {sign} {abs(z.imag):.{digits}g}j"
    return str(value)


def esc(text: Any) -> str:
    return html.escape(str(text), quote=True)


TEMPLATES = Path(__file__).resolve().parents[1] / "templates" / "report"


@functools.cache
def environment():
    """The Jinja2 environment of the report templates: autoescaping on, the number format
    :func:`fmt` and ``mm`` (metres -> millimetres) available in every template."""
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)),
                             autoescape=True, trim_blocks=True, lstrip_blocks=True,
                             undefined=jinja2.StrictUndefined)
    env.globals.update(fmt=fmt, mm=lambda v: None if v is None else float(v) * 1e3)
    return env


def render(template: str, **context: Any) -> str:
    """Render one template of ``templates/report`` with ``context``."""
    return str(environment().get_template(template).render(**context))


def _macros():
    return environment().get_template("macros.html.j2").module


def table_html(
    header: Sequence[str],
    rows: Iterable[Sequence[Any]],
    css_class: str = "",
    raw_columns: Sequence[int] = (),
    row_classes: Sequence[str] | None = None,
    column_classes: dict[int, str] | None = None,
) -> str:
    """An HTML table (template macro ``table``); cells are formatted by :func:`fmt` and
    escaped, except the columns in ``raw_columns`` (already HTML); ``column_classes``
    gives a CSS class to the cells of some columns."""
    from markupsafe import Markup

    cells = [[Markup(str(c)) if j in raw_columns else fmt(c) for j, c in enumerate(row)]
             for row in rows]
    return str(_macros().table(list(header), cells, css_class, list(row_classes or []),
                               dict(column_classes or {})))


def figure_html(png_path: Path, caption: str, alt: str | None = None) -> str:
    """A figure embedded as a base64 PNG (no file reference in the HTML)."""
    data = base64.b64encode(Path(png_path).read_bytes()).decode("ascii")
    return str(_macros().figure(data, caption, alt or caption))


def note_html(text: str, kind: str = "note") -> str:
    """A highlighted paragraph (kind: 'note', 'warning' or 'unavailable')."""
    return str(_macros().note(text, kind))


def save_and_embed(fig: Any, ctx: ReportContext, stem: str, caption: str
                   ) -> tuple[str, list[Path]]:
    """Save a matplotlib figure as PNG + SVG in the report folder and return the embedded
    HTML and the written files."""
    from maglev_match.plots import save_figure

    files = save_figure(fig, ctx.figure_path(stem))
    png = next(f for f in files if f.suffix == ".png")
    return figure_html(png, caption), files


# ---------------------------------------------------------------------------------------
# sections and assembly
# ---------------------------------------------------------------------------------------
def run_section(key: str, title: str, fn: SectionFn, params: Params,
                ctx: ReportContext) -> SectionResult:
    """Run one section function; a failure becomes a "not available: <reason>" box."""
    t0 = time.perf_counter()
    try:
        fragment, figures, data = fn(params, ctx)
        return SectionResult(key, title, fragment, tuple(Path(f) for f in figures), data,
                             True, "", time.perf_counter() - t0)
    except SectionUnavailable as exc:
        reason = str(exc)
    except ImportError as exc:
        reason = f"analysis module not installed yet ({exc})"
    except Exception as exc:  # the report must always render; the reason is shown and logged
        reason = f"{type(exc).__name__}: {exc}"
        log.debug("section %s failed:\n%s", key, traceback.format_exc())
    log.warning("report section '%s' not available: %s", key, reason)
    box = note_html(f"not available: {reason}", "unavailable")
    return SectionResult(key, title, box, (), None, False, reason, time.perf_counter() - t0)


CSS = (TEMPLATES / "report.css").read_text()  # the page's inline style sheet


def software_version() -> dict[str, str]:
    """Package version, git commit (when run from a checkout), Python, NumPy, JAX."""
    import maglev_match

    info = {"maglev-match": maglev_match.__version__, "python": platform.python_version(),
            "numpy": np.__version__}
    try:
        import jax
        import scipy

        info["jax"] = jax.__version__
        info["scipy"] = scipy.__version__
    except ImportError:  # pragma: no cover
        pass
    try:
        here = Path(__file__).resolve().parent
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here,
                             capture_output=True, text=True, timeout=5)
        if rev.returncode == 0 and rev.stdout.strip():
            info["git commit"] = rev.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    info["platform"] = platform.platform()
    return info


def assemble_html(title: str, intro_html: str, sections: Sequence[SectionResult],
                  settings: dict[str, Any], params: Params | None = None) -> str:
    """The complete self-contained HTML document (template ``page.html.j2``)."""
    from markupsafe import Markup

    version = software_version()
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    footer_rows = [(k, v) for k, v in version.items()]
    footer_rows.append(("generated", stamp))
    footer_rows += [(f"setting: {k}", json.dumps(v)) for k, v in settings.items()]
    if params is not None:
        changed = ", ".join(sorted(params.explicit)) or "none"
        footer_rows.append(("explicitly set derivable values", changed))
    footer_rows.append(("section run times (s)", ", ".join(
        f"{s.key} {s.seconds:.1f}" for s in sections)))
    footer = table_html(["item", "value"], footer_rows, "footer-table")
    return render("page.html.j2", title=title, intro=Markup(intro_html),
                  sections=sections, footer=Markup(footer)) + "\n"


def write_report(path: Path, title: str, intro_html: str, sections: Sequence[SectionResult],
                 settings: dict[str, Any], params: Params | None = None,
                 t_start: float | None = None) -> ReportResult:
    """Write the HTML file and return a :class:`ReportResult`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, assemble_html(title, intro_html, sections, settings, params))
    figures = tuple(f for s in sections for f in s.figures)
    seconds = time.perf_counter() - t_start if t_start is not None else 0.0
    return ReportResult(path=path, sections=tuple(sections), figures=figures, seconds=seconds)


# ---------------------------------------------------------------------------------------
# analyses shared by the study report and the reproduction (maglev glue; numerics live
# in maglev_match.dynamics and the other analysis modules)
# ---------------------------------------------------------------------------------------
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
# time histories
# ---------------------------------------------------------------------------------------
def run_time_history(params: Params, model: str, t_end: float, *, x5: float | None = None,
                     initial: str = "equilibrium", q1: float | None = None):
    """One simulation with the physical limits on, and its history as an xarray Dataset."""
    from maglev_match.analyses.simulation import history_dataset, simulate_maglev
    from maglev_match.maglev.models import maglev_model

    m = maglev_model(params, model)
    x0 = m.initial_state(initial, x5=x5, q1=q1)
    # 10001 saved points (0.3-0.5 ms apart): smooth phase portraits of 20 Hz oscillations
    sim = simulate_maglev(m, x0=x0, t_end=t_end, n_save=10001)
    return sim, history_dataset(sim)


def late_amplitude(sim: Any, window: float = 1.0) -> tuple[float, float]:
    """Largest |gap deviation| (m, over all levitation points) in the first and in the last
    ``window`` seconds of a run."""
    from maglev_match.analyses.simulation import history_dataset

    ds = history_dataset(sim)
    t = ds["time"].values
    g = np.abs(ds["gap_deviation"].values).max(axis=1)
    if len(t) == 0:
        return float("nan"), float("nan")
    early = g[t <= t[0] + window].max()
    late = g[t >= t[-1] - window].max()
    return float(early), float(late)


def converges(sim: Any) -> bool:
    """The run returned to the equilibrium, or had not collided by the horizon with the
    gap oscillation in its last second below half of that in its first second."""
    if sim.outcome == "converged":
        return True
    if sim.outcome != "running":
        return False
    early, late = late_amplitude(sim)
    return bool(late < 0.5 * early)


def outcome_text(sim: Any) -> str:
    """The outcome of a run in words."""
    if sim.outcome == "collision":
        where = f" at levitation point {sim.point}" if model_info(sim.model).points > 1 else ""
        return f"collision with the {sim.limit} gap limit{where} at t = {sim.collision_time:.4g} s"
    if sim.outcome == "running":
        early, late = late_amplitude(sim)
        trend = "decaying" if late < 0.5 * early else "not decaying"
        return (f"no collision by t = {sim.t_end:g} s; max |c - c0| {early * 1e3:.3g} mm in "
                f"the first second, {late * 1e3:.3g} mm in the last ({trend})")
    return {"converged": "returns to the equilibrium", "running": "still moving at the horizon",
            "failed": "integration failed"}.get(sim.outcome, sim.outcome)


#: A gap oscillation below this fraction of its peak counts as died out (the same rule as
#: the simulation figure, :data:`maglev_match.plots.simulate.SETTLED_FRACTION`).
SETTLED_FRACTION = 0.02


def fitted_window(histories: Sequence[Any]) -> tuple[float, float]:
    """(end of the fitted time axis, horizon) in s for history datasets: 25 % past the
    latest time any gap deviation exceeds 2 % of its run's peak (a collision ends its run
    there), at least 0.1 s, at most the horizon."""
    horizon, latest = 0.0, 0.0
    for ds in histories:
        t = ds["time"].values
        if len(t) == 0:
            continue
        horizon = max(horizon, float(t[-1]))
        g = np.abs(ds["gap_deviation"].values).reshape(len(t), -1).max(axis=1)
        if not np.any(g > 0):
            continue
        above = np.nonzero(g > SETTLED_FRACTION * g.max())[0]
        latest = max(latest, float(t[min(above[-1] + 1, len(t) - 1)]))
    horizon = horizon or 1.0
    return float(min(horizon, max(0.1, 1.25 * latest))), horizon


def time_history_figure(runs: Sequence[tuple[str, Any]], params: Params, title: str,
                        points: Sequence[int] | None = None):
    """Left: gap deviation (mm) against time, the axis fitted to the motion
    (:func:`fitted_window`) with the whole run in an inset when the motion ends early;
    right: phase portrait gap deviation against gap rate (mm/s). ``runs`` = (label, history
    Dataset) pairs; model B histories show the given levitation points."""
    from maglev_match.plots import new_figure

    fig, (ax1, ax2) = new_figure(1, 2, figsize=(11, 4.2))
    styles = ["-", "--", "-.", ":"]
    t_fit, horizon = fitted_window([ds for _, ds in runs])
    inset = None
    if t_fit < 0.8 * horizon:  # the motion is over early: the whole run in an inset
        inset = ax1.inset_axes([0.58, 0.62, 0.4, 0.34])
    for k, (label, ds) in enumerate(runs):
        t = ds["time"].values
        gd = ds["gap_deviation"].values
        rate = ds["gap_rate"].values
        pts = list(points) if points is not None else list(range(gd.shape[1]))
        for j, pidx in enumerate(pts):
            lab = label if len(pts) == 1 else f"{label}, point {pidx + 1}"
            color = f"C{(k * len(pts) + j) % 10}"
            ax1.plot(t, gd[:, pidx] * 1e3, color=color, ls=styles[k % 4], lw=1.2, label=lab)
            if inset is not None:
                inset.plot(t, gd[:, pidx] * 1e3, color=color, ls=styles[k % 4], lw=0.8)
            ax2.plot(gd[:, pidx] * 1e3, rate[:, pidx] * 1e3, color=color, ls=styles[k % 4],
                     lw=0.9)
    for g in (params.gap_min - params.c0, params.gap_max - params.c0):
        ax1.axhline(g * 1e3, color="k", ls=":", lw=1)
        ax2.axvline(g * 1e3, color="k", ls=":", lw=1)
    ax1.set_xlim(0.0, t_fit)
    ax1.set_xlabel("time (s)" if inset is None else
                   f"time (s); shown: 0 to {t_fit:.3g} s, the whole {horizon:g} s run inset")
    ax1.set_ylabel("gap deviation c - c0 (mm)")
    ax1.set_title(title)
    ax1.legend(fontsize=7, loc="lower right" if inset is not None else "best")
    if inset is not None:
        inset.set_xlim(0.0, horizon)
        inset.axvspan(0.0, t_fit, color="0.85", lw=0)
        inset.set_title(f"whole run, 0 to {horizon:g} s", fontsize=7)
        inset.tick_params(labelsize=6)
        inset.grid(alpha=0.3)
    ax2.set_xlabel("gap deviation c - c0 (mm)")
    ax2.set_ylabel(unit_label("gap_rate", "gap rate dc/dt"))
    ax2.set_title("phase portrait")
    return fig


def section_time_history(params: Params, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """The typical disturbance: model A with the beam at its undeflected position,
    x5(0) = -w0 (and model B pressed onto the free beam), limits on."""
    t_end = ctx.settings.t_end
    sim, ds = run_time_history(params, "unit", t_end, x5=-params.w0)
    runs = [(f"model A, x5(0) = -w0 = {-params.w0 * 1e3:.3g} mm", ds)]
    figure, files = save_and_embed(
        time_history_figure(runs, params, "Model A after the typical disturbance"), ctx,
        "time_history_unit", "Model A with the physical limits on, from x5(0) = -w0; the "
        "dotted lines are the gap limits.")
    figures = [figure]
    rows = [("model A", f"x5(0) = {-params.w0 * 1e3:.4g} mm", outcome_text(sim))]
    data = {"unit": sim.summary()}
    if ctx.settings.include_vehicle:
        simb, dsb = run_time_history(params, "vehicle", t_end, initial="pressed")
        fb, filesb = save_and_embed(
            time_history_figure([("model B pressed", dsb)], params,
                                "Model B pressed onto the free beam", points=[0, 2, 4]),
            ctx, "time_history_vehicle",
            "Model B: the vehicle pressed onto the free beam (all q_n = 0), gaps at the "
            "first point of each levitation frame.")
        figures.append(fb)
        files += filesb
        rows.append(("model B", "pressed onto the free beam", outcome_text(simb)))
        data["vehicle"] = simb.summary()
    return (render("time_history.html.j2", figures=figures, rows=_formatted(rows)), files,
            data)


# ---------------------------------------------------------------------------------------
# matching index
# ---------------------------------------------------------------------------------------
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
    frag = render("matching.html.j2", mi=mi, rows=_formatted(matching_rows(mi)),
                  chi_paper=_chi_paper(mi), basis_text=BASIS_TEXT.get(basis, basis),
                  vehicle=mv,
                  side_rows=_formatted(side_by_side_rows(mi, mv)) if mv is not None else [])
    return frag, [], data


def _formatted(rows: Iterable[Sequence[Any]]) -> list[tuple[str, ...]]:
    """Table rows with every cell formatted by :func:`fmt` (the templates' tables escape
    but do not format)."""
    return [tuple(fmt(c) for c in r) for r in rows]


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
                  rows=_formatted(sensitivity_rows(sens)),
                  figure=html, vehicle_sens=sv, vehicle_index=mv,
                  vehicle_rows=_formatted(sensitivity_rows(sv)) if sv is not None else [])
    return frag, files, data


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


# ---------------------------------------------------------------------------------------
# the study report of one vehicle-beam pair
# ---------------------------------------------------------------------------------------
def study_sections() -> list[tuple[str, str, SectionFn]]:
    """(key, title, function) of the study report's sections, in order."""
    return [
        ("parameters", "Parameters", section_parameters),
        ("stability", "Stability and eigenvalues", section_stability),
        ("root-locus", "Root locus along omega1", section_root_locus),
        ("hopf-curve", "Hopf curve in (omega1, sigma)", section_hopf_curve),
        ("cycles", "Bifurcation diagrams through the design point",
         section_bifurcation_diagrams),
        ("time-history", "Time history after the typical disturbance", section_time_history),
        ("matching", "Matching index h, w0, chi", section_matching),
        ("sensitivity", "Sensitivities of the index", section_sensitivity),
    ]


def study_report(
    params: Params,
    out: str | Path,
    settings: ReportSettings | None = None,
    label: str = "",
    only: Sequence[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> ReportResult:
    """Write the self-contained HTML study report of one vehicle-beam pair.

    Parameters
    ----------
    params : the parameter set.
    out : the HTML file; figures (PNG + SVG) are written to ``<stem>_figures/`` beside it.
    settings : :class:`ReportSettings` (``ReportSettings.quick_settings()`` for previews).
    label : a name for the study (e.g. the preset name), shown in the title.
    only : keys of the sections to include (default: all of :func:`study_sections`).
    progress : called with each section's title before it runs.
    """
    t0 = time.perf_counter()
    settings = settings or ReportSettings()
    out = Path(out)
    fig_dir = out.parent / f"{out.stem}_figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    ctx = ReportContext(out_dir=fig_dir, settings=settings)
    results = []
    for key, title, fn in study_sections():
        if only is not None and key not in only:
            continue
        if progress is not None:
            progress(title)
        results.append(run_section(key, title, fn, params, ctx))
    name = label or "parameter set"
    intro = render("study_intro.html.j2", name=name, params=params)
    return write_report(out, f"maglev-match study report: {name}", intro, results,
                        {"label": name, **settings.as_dict()}, params, t0)
