"""`maglev-match sensitivity` (d chi / d p for every parameter) and `maglev-match design`
(the cheapest beam or the best gains meeting requirements on chi, the margin and
chi_simulation)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    ConfigOpt,
    JsonOpt,
    ModelOpt,
    OutOpt,
    PresetOpt,
    SetOpt,
    api_options,
    bounded,
    check_index_params,
    check_model,
    console,
    emit_json,
    monte_carlo_option,
    output_target,
    params_from_options,
    print_warnings,
    progress_report,
    seed_option,
    workers_option,
)
from maglev_match.core.options import SCATTER_PCT_MAX, check_scatter_percent
from maglev_match.core.params import FIELD_NAMES, INTEGER_FIELDS, ParameterError
from maglev_match.maglev.catalog import model_info

#: API keyword -> option, for `sensitivity`, `design` and the scatter of `index`
SCATTER_OPTIONS = {"scatter": "--scatter", "monte_carlo": "--monte-carlo",
                   "workers": "--workers", "resume": "--resume", "seed": "--seed",
                   "model": "--model"}
SENSITIVITY_OPTIONS = {"model": "--model", "boundaries": "--boundaries/--no-boundaries",
                       "simulate": "--no-simulation", "config": "--config"}
DESIGN_OPTIONS = {"vary": "--vary", "minimize/maximize": "--minimize/--maximize",
                  "require": "--require", "model": "--model", "grid": "--grid",
                  "starts": "--starts", "simulate": "--no-simulation", "config": "--config"}

# `design` exits with this code when no candidate meets the requirements (the best one found
# is still printed): distinct from 1 (a failure or a bug) and 2 (a usage error).
NO_FEASIBLE_DESIGN = 3
# bounds of the search's counts: the start grid has GRID^d points (d varied parameters), and
# each optimiser run takes tens of index evaluations
DESIGN_GRID_MAX = 50
DESIGN_STARTS_MAX = 100

ScatterOpt = Annotated[
    list[str] | None,
    typer.Option("--scatter", help="NAME=PCT: relative standard deviation of a parameter "
                 f"in percent, 0 to {SCATTER_PCT_MAX:g} (repeatable); prints the linearised "
                 "spread of chi."),
]


McOpt = Annotated[
    int | None,
    typer.Option("--monte-carlo", help="N: also sample chi at N parameter sets drawn with "
                 "the --scatter spreads (Dask, resumable), beside the linearised estimate.",
                 callback=monte_carlo_option),
]
WorkersOpt = Annotated[
    int | None, typer.Option("--workers", help="Local Dask workers for --monte-carlo "
                             "(default: all cores; 0: none).", callback=workers_option)]
ResumeOpt = Annotated[bool, typer.Option("--resume", help="Reuse finished Monte Carlo "
                                         "chunks in the output folder.")]
SeedOpt = Annotated[int, typer.Option("--seed", help="Random seed of the Monte Carlo samples.",
                                      callback=seed_option)]
NoSimOpt = Annotated[bool, typer.Option(
    "--no-simulation", help="The paper's chi only: no simulated critical disturbance, so the "
    "headline chi is the paper's number.")]


def _spread(params, scatter: dict[str, float], n: int | None, folder, workers: int | None,
            resume: bool, seed: int, model: str, command: str, *, index=None,
            sensitivity=None):
    """The linearised spread of chi (and, with ``n``, the Monte Carlo study in
    ``<folder>/monte-carlo``) through the API: an IndexSpread, or None without --scatter."""
    if not scatter:
        return None
    from maglev_match import api

    with progress_report(command) as prog, api_options(SCATTER_OPTIONS):
        return api.index_spread(params, scatter, model=model, index=index,
                                sensitivity=sensitivity, monte_carlo=n,
                                checkpoint=None if n is None else folder / "monte-carlo",
                                seed=seed, resume=resume, workers=workers, stage=prog.stage,
                                progress=lambda d, t: prog.tiles(d, t, "chunks"))


def _print_sampled(mc, bound: float | None = None) -> None:
    if mc is None:
        return
    q = mc.quantiles
    console.print(f"  sampled ({mc.n} sets): chi mean {mc.mean:.4g}, sd {mc.sd:.3g}, 5% "
                  f"{q['5%']:.4g}, median {q['50%']:.4g}, 95% {q['95%']:.4g}"
                  + (f"; {mc.fraction_below(bound):.1%} below chi = {bound:g}"
                     if bound is not None else ""))
    if mc.linearised is not None:
        console.print(f"  linearised vs sampled sd: {mc.linearised['sd']:.3g} vs {mc.sd:.3g}"
                      " (they differ where chi is not linear over the spread: case changes, "
                      "the Hopf curve)")
    if mc.failed or mc.invalid:
        console.print(f"  [yellow]{mc.failed} samples failed (index not converged), "
                      f"{mc.invalid} broke a parameter rule; both left out[/]")


def parse_scatter(items: list[str] | None) -> dict[str, float]:
    """NAME=PCT pairs -> {name: percent}."""
    out: dict[str, float] = {}
    for text in items or []:
        if "=" not in text:
            raise ParameterError("--scatter", text, "expected NAME=PCT, e.g. EI=5")
        name, raw = (s.strip() for s in text.split("=", 1))
        if name not in FIELD_NAMES:
            raise ParameterError("--scatter", name, "unknown parameter")
        if name in INTEGER_FIELDS:
            raise ParameterError("--scatter", name, "a whole-number parameter has no "
                                 "continuous scatter")
        try:
            pct = float(raw.rstrip("%"))
        except ValueError:
            raise ParameterError("--scatter", text, "the percentage must be a number") from None
        if name in out:
            raise ParameterError("--scatter", name, "given twice")
        out[name] = check_scatter_percent(name, pct)
    return out


def check_scatter_names(params, scatter: dict[str, float], model: str) -> None:
    """Every --scatter name must have a row in the sensitivity table of ``model`` (checked
    before any computation, so a typo costs no index)."""
    if not scatter:
        return  # (no import of the sensitivity module, ~0.2 s, when there is nothing to check)
    from maglev_match import api

    with api_options(SCATTER_OPTIONS):
        api.check_scatter(params, scatter, model=model)


def scatter_options(params, items: list[str] | None, monte_carlo: int | None,
                    model: str) -> dict[str, float]:
    """--scatter and --monte-carlo of ``sensitivity``, ``design`` and ``index``, checked
    before any computation: {name: percent} (names with a row in ``model``'s sensitivity
    table), and --monte-carlo only with at least one --scatter."""
    sc = parse_scatter(items)
    check_scatter_names(params, sc, model)
    if monte_carlo is not None and not sc:
        raise ParameterError("--monte-carlo", monte_carlo, "needs at least one --scatter NAME=PCT")
    if monte_carlo is None:  # options of the Monte Carlo study would do nothing
        from maglev_match.cli.common import refuse_given

        refuse_given({"resume": "--resume", "seed": "--seed", "workers": "--workers"},
                     "applies to a Monte Carlo study only; add --monte-carlo N (with "
                     "--scatter NAME=PCT)")
    return sc


def check_monte_carlo_folder(out, command: str, stem: str, monte_carlo: int | None) -> None:
    """Before any work: the --out of a Monte Carlo study can be written, and its checkpoint
    folder (``<out>/monte-carlo``) is not in use by another run (the lock is tried and let
    go; the study holds it while it runs, see
    :func:`maglev_match.analyses.sensitivity.sampled_spread`).
    A second run on the same folder is thus refused at once, not after its index."""
    if monte_carlo is None:
        return
    from maglev_match.cli.common import check_output_path
    from maglev_match.core.checkpoint import lock_folder

    check_output_path(out)
    folder, _ = output_target(out, command, stem)
    with lock_folder(folder / "monte-carlo", "Monte Carlo run"):
        pass


def scatter_report(params, index, scatter: dict[str, float], monte_carlo: int | None,
                   out, workers: int | None, resume: bool, seed: int, model: str):
    """The spread of chi at an already computed ``index`` for `index --scatter` (and
    --monte-carlo, in ``<out>/monte-carlo``, resumable): an IndexSpread, or None without
    --scatter."""
    folder, _ = output_target(out, "index", "index")
    return _spread(params, scatter, monte_carlo, folder, workers, resume, seed, model, "index",
                   index=index)


def print_scatter(sp) -> None:
    """The text lines of `index --scatter` (and --monte-carlo)."""
    if sp is None:
        return
    _print_spread(sp.linearised)
    _print_sampled(sp.sampled)


def _print_spread(spread: dict | None) -> None:
    if spread is None:
        return
    parts = ", ".join(f"{k} {v:.3g}" for k, v in spread["contributions"].items())
    console.print(f"  linearised spread: chi = {spread['chi']:.4g} +- {spread['sd']:.3g} "
                  f"(one standard deviation; contributions {parts})")


def _fmt(v: float | None, spec: str = ".4g") -> str:
    if v is None or not math.isfinite(v):
        return "-"
    return format(v, spec)


@app.command("sensitivity")
def sensitivity_command(
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    boundaries: Annotated[bool, typer.Option(
        "--boundaries/--no-boundaries",
        help="Also solve each parameter's value at the stability boundary.")] = True,
    scatter: ScatterOpt = None,
    monte_carlo: McOpt = None,
    workers: WorkersOpt = None,
    resume: ResumeOpt = False,
    seed: SeedOpt = 0,
    out: OutOpt = None,
    no_simulation: NoSimOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Exact d chi / d p of the headline index (the smaller of the paper's chi and
    chi_simulation; --no-simulation: the paper's chi), the elasticity (p / chi) d chi / d p
    and the margin's sensitivity for every parameter of model A or of the vehicle
    (--model vehicle), sorted by magnitude, with a tornado figure."""
    model = check_model(model)
    params = params_from_options(preset, config, set_)
    check_index_params(params)
    sc = scatter_options(params, scatter, monte_carlo, model)
    check_monte_carlo_folder(out, "sensitivity", "tornado", monte_carlo)
    from maglev_match import api  # (the numerics and JAX, once the options are good)

    with progress_report("sensitivity") as prog, api_options(SENSITIVITY_OPTIONS):
        sens = api.index_sensitivity(params, model=model, boundaries=boundaries,
                                     simulate=not no_simulation, stage=prog.stage)
    folder, stem = output_target(out, "sensitivity", "tornado")
    figs = sens.plot(folder / stem)
    sp = _spread(params, sc, monte_carlo, folder, workers, resume, seed, model,
                 "sensitivity", sensitivity=sens)
    spread, mc = (None, None) if sp is None else (sp.linearised, sp.sampled)
    if json_out:
        data = sens.as_json()
        data["figures"] = [str(f) for f in figs]
        data["spread"] = spread
        data["monte_carlo"] = None if mc is None else mc.as_json()
        emit_json(data)
        return
    idx = sens.index
    console.print(f"[bold]maglev-match sensitivity[/] — {model_info(model).label}, preset {preset}"
                  + (f", config {config}" if config else "")
                  + (f", set {' '.join(set_)}" if set_ else ""))
    console.print(f"  chi = {idx.chi:.5g} (headline: {idx.headline})", highlight=False)
    sim_part = ("" if idx.chi_simulation is None
                else f", chi_simulation = {idx.chi_simulation:.5g}")
    console.print(f"  chi_paper = {idx.chi_paper:.5g} ({idx.case}, the paper's definition)"
                  f"{sim_part}, h = {idx.h * 1e3:.4g} mm, w0 = {idx.w0 * 1e3:.4g} mm, "
                  f"margin = {-idx.max_real_part:.4g} 1/s"
                  + (f", Hopf point {idx.hopf_param} = {idx.hopf_value:.6g} "
                     f"({idx.hopf_distance:.1%} away)" if idx.hopf_param else ""))
    status_text = {
        "exact": "exact: implicit differentiation of the converged unstable "
                                "cycle",
        "zero": "zero: the equilibrium is unstable, chi = 0 on a whole "
                               "neighbourhood",
        "rule": "case rule: h = gap_max - c0, chi moves only through w0 "
                               "(and gap_max, c0)",
        "undefined": "undefined: the index did not converge",
        "solved": "exact: implicit function theorem on the solved critical "
                                 "disturbance of chi_simulation",
        "unavailable": "not available: chi_simulation's critical size is only "
                                      "bracketed by bisection here",
    }[sens.status]
    console.print(f"  derivatives of the headline: {status_text}")
    if sens.simulation_status:
        console.print(f"  chi_simulation: {sens.simulation_status}", highlight=False)
    if sens.switch_note:
        console.print(f"  [yellow]{sens.switch_note}[/] (columns 'left' and 'right': for a "
                      "decrease and an increase of the parameter)")
    if sens.status == "undefined":
        console.print(f"[bold red]numerical failure:[/] {idx.message}")
    table = Table(show_edge=False, header_style="bold")
    cols = ["parameter", "value", "unit", "d chi/dp", "elasticity", "d chi_paper/dp"]
    if idx.chi_simulation is not None:
        cols.append("d chi_sim/dp")
    if sens.switch_note:
        cols += ["left", "right"]
    cols += ["d margin/dp", "d hopf dist/dp", "stability boundary", "cycle-limit boundary"]
    for col in cols:
        table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    for r in sens.sorted_rows():
        b = ("-" if r.boundary is None else f"{r.boundary:.4g} ({r.boundary_relative:+.0%})")
        lb = ("-" if r.limit_boundary is None or r.limit_boundary <= 0 else
              f"{r.limit_boundary:.4g} ({r.limit_boundary / r.value - 1:+.0%})")
        row = [r.name, _fmt(r.value), r.unit, _fmt(r.dchi), _fmt(r.elasticity, "+.3f"),
               _fmt(r.dchi_paper)]
        if idx.chi_simulation is not None:
            row.append(_fmt(r.dchi_simulation))
        if sens.switch_note:
            row += [_fmt(r.dchi_left), _fmt(r.dchi_right)]
        row += [_fmt(r.dmargin), _fmt(r.dhopf_distance), b, lb]
        table.add_row(*row)
    console.print(table)
    if sens.limit_boundary_note:
        console.print(f"  note: {sens.limit_boundary_note}")
    _print_spread(spread)
    _print_sampled(mc)
    for f in figs:
        console.print(f"wrote {f}", highlight=False)
    print_warnings(sens.warnings + idx.warnings)


@app.command("design")
def design_command(
    vary: Annotated[list[str], typer.Option("--vary", help="NAME=LO:HI (repeatable), e.g. "
                                            "EI=5e9:4e10")],
    minimize: Annotated[str | None, typer.Option("--minimize", help="A varied parameter to "
                                                 "make as small as possible.")] = None,
    maximize: Annotated[str | None, typer.Option("--maximize", help="'chi'.")] = None,
    require: Annotated[list[str] | None, typer.Option(
        "--require", help="chi>=X, margin>=Y (1/s) or chi_simulation>=Z (repeatable).")] = None,
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    grid: Annotated[int | None, typer.Option(
        "--grid", help="Start-grid points per varied parameter (default 9 for one, 5 for "
        "two).", callback=bounded(2, DESIGN_GRID_MAX, integer=True,
                                  why="each point is one index computation"))] = None,
    starts: Annotated[int, typer.Option("--starts", help="Optimiser runs.",
                                        callback=bounded(1, DESIGN_STARTS_MAX,
                                                         integer=True))] = 2,
    scatter: ScatterOpt = None,
    monte_carlo: McOpt = None,
    workers: WorkersOpt = None,
    resume: ResumeOpt = False,
    seed: SeedOpt = 0,
    out: OutOpt = None,
    no_simulation: NoSimOpt = False,
    json_out: JsonOpt = False,
    iso_curve: Annotated[Path | None, typer.Option(
        "--iso-curve", help="Draw this iso-chi curve (the netCDF file of `iso-curve`, in "
        "the two varied parameters) on the design figure.")] = None,
) -> None:
    """The cheapest design (or the largest chi) meeting the requirements on the headline
    chi (both the paper's chi and chi_simulation; --no-simulation: the paper's chi alone):
    SLSQP with exact gradients from several grid starts, every candidate the full index."""
    model = check_model(model)
    if (minimize is None) == (maximize is None):
        raise ParameterError("--minimize/--maximize", minimize or maximize,
                             "give exactly one of them")
    if starts < 1:
        raise ParameterError("--starts", starts, "must be at least 1")
    if grid is not None and grid < 2:
        raise ParameterError("--grid", grid, "must be at least 2")
    from maglev_match import api

    with api_options(DESIGN_OPTIONS):
        reqs = api.check_requirements(require or [], simulate=not no_simulation,
                                      field="--require", switch="--no-simulation")
    base = params_from_options(preset, config, set_)
    check_index_params(base)
    sc = scatter_options(base, scatter, monte_carlo, model)
    check_monte_carlo_folder(out, "design", "design-path", monte_carlo)
    overlay = {}
    if iso_curve is not None:  # checked before the search: a curve in the varied pair
        from maglev_match.cli.iso_curve import iso_overlay

        got = iso_overlay(None, iso_curve, [v.split("=", 1)[0].strip() for v in vary],
                          what="design")
        overlay = {"iso": got["iso_curve"], "iso_source": got["iso_source"]}
    with api_options(DESIGN_OPTIONS):  # every input checked before the progress starts
        api.design_problem(base, vary=list(vary), minimize=minimize, maximize=maximize,
                           require=list(require or []), simulate=not no_simulation,
                           starts=starts, grid=grid)
    with progress_report("design") as prog, api_options(DESIGN_OPTIONS):
        prog.stage("searching ...")
        res = api.design_search(base, vary=list(vary), minimize=minimize, maximize=maximize,
                                require=list(require or []), model=model, grid=grid,
                                starts=starts, simulate=not no_simulation,
                                stage=prog.stage)
    design_params = base.replace(**{n: float(v) for n, v in res.values.items()})
    folder, stem = output_target(out, "design", "design-path")
    figs = res.plot(folder / stem, **overlay)
    sp = _spread(design_params, sc, monte_carlo, folder, workers, resume, seed, model,
                 "design", index=res.index)
    spread, mc = (None, None) if sp is None else (sp.linearised, sp.sampled)
    chi_req = next((r.bound for r in reqs if r.quantity == "chi"), None)
    goal, objective = ("minimize", minimize) if minimize is not None else ("maximize", maximize)
    if json_out:
        data = res.as_json()
        data["figures"] = [str(f) for f in figs]
        data["spread"] = spread
        data["monte_carlo"] = None if mc is None else dict(
            mc.as_json(), fraction_below_requirement=None if chi_req is None
            else mc.fraction_below(chi_req))
        emit_json(data)
        if res.status != "feasible":
            raise typer.Exit(NO_FEASIBLE_DESIGN)
        return
    idx = res.index
    console.print(f"[bold]maglev-match design[/] — {model_info(model).label}, preset {preset}: "
                  f"{goal} {objective}"
                  + (" subject to " + ", ".join(str(r) for r in reqs) if reqs else ""))
    ok = res.status == "feasible"
    console.print(("  [bold green]feasible[/]: " if ok else "  [bold red]no feasible design"
                   "[/]: ") + res.message)
    for var in res.problem.variables:
        console.print(f"  [bold]{var.name} = {res.values[var.name]:.6g}[/] (range "
                      f"{var.lo:g} .. {var.hi:g})")
    console.print(f"  full index there: chi = {idx.chi:.5g} (headline: {idx.headline}); "
                  f"chi_paper = {idx.chi_paper:.5g} ({idx.case}, the paper's definition)"
                  + (f", chi_simulation = {idx.chi_simulation:.5g}"
                     if idx.chi_simulation is not None else "")
                  + f"; h = {idx.h * 1e3:.4g} mm, w0 = {idx.w0 * 1e3:.4g} mm, margin = "
                  f"{-idx.max_real_part:.4g} 1/s, omega1 = {idx.omega1:.5g} rad/s"
                  + (f", sigma = {idx.sigma:.4g} 1/kg"
                     if "sigma" in model_info(model).beam_params else ""),
                  highlight=False)
    console.print("  active: " + (", ".join(res.active) if res.active else "none"))
    if goal == "maximize" and idx.case == "no_cycle_within_limits":
        console.print("  note: chi is at the ceiling (gap_max - c0) / w0 of the case rule (no "
                      "unstable cycle within the gap range); it grows further only through "
                      "w0, so the optimum is not unique")
    console.print(f"  search: {len(res.grid_chi)} grid points, {len(res.candidates)} optimiser "
                  f"runs, {res.iterations} SLSQP iterations, {res.evaluations} index "
                  f"evaluations, {res.seconds:.1f} s")
    for k, c in enumerate(res.candidates, 1):
        d = ", ".join(f"{n} = {v:.5g}" for n, v in zip(res.problem.names, c.values,
                                                          strict=True))
        console.print(f"    run {k}: {d}: chi = {c.chi:.5g} (paper {c.chi_paper:.5g}), "
                      f"margin = {c.margin:.4g}"
                      + (f", chi_simulation = {c.chi_simulation:.4g}"
                         if c.chi_simulation is not None else "")
                      + (" (meets the requirements)" if c.feasible
                         else f" (misses by {c.violation:.2%})") + f"; {c.message}")
    if not idx.converged:
        console.print(f"[bold red]numerical failure at the design:[/] {idx.message}")
    _print_spread(spread)
    _print_sampled(mc, chi_req)
    for f in figs:
        console.print(f"wrote {f}", highlight=False)
    print_warnings(res.warnings + idx.warnings)
    if not ok:
        raise typer.Exit(NO_FEASIBLE_DESIGN)


__all__ = ["NO_FEASIBLE_DESIGN", "sensitivity_command", "design_command", "parse_scatter",
           "check_scatter_names", "scatter_options", "scatter_report", "print_scatter",
           "check_monte_carlo_folder",
           "ScatterOpt", "McOpt", "WorkersOpt", "ResumeOpt", "SeedOpt", "NoSimOpt"]
