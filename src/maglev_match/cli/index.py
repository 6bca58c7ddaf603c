"""`maglev-match index` (the main job) and `maglev-match map`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    ConfigOpt,
    JsonOpt,
    ModelOpt,
    PresetOpt,
    SetOpt,
    api_options,
    check_index_params,
    check_model,
    check_output_path,
    console,
    emit_json,
    ntst_option,
    output_target,
    params_from_options,
    progress_report,
    refuse_given,
    rows_per_tile_option,
    scheduler_option,
    workers_option,
    write_result_json,
)
from maglev_match.cli.design import McOpt, ResumeOpt, ScatterOpt, SeedOpt, WorkersOpt
from maglev_match.cli.iso_curve import iso_overlay
from maglev_match.cli.models import is_model_file, refuse_model_file
from maglev_match.core.params import ParameterError
from maglev_match.maglev.catalog import model_info

#: API keyword -> option, for `map`
MAP_OPTIONS = {"x": "--x", "y": "--y", "workers": "--workers", "scheduler": "--scheduler",
               "resume": "--resume", "rows_per_tile": "--rows-per-tile", "ntst": "--ntst",
               "simulate": "--no-simulation", "config": "--config", "model": "--model"}
#: API keyword -> option, for `index`
INDEX_OPTIONS = {"model": "--model", "simulate": "--no-simulation", "scatter": "--scatter",
                 "monte_carlo": "--monte-carlo", "workers": "--workers", "resume": "--resume",
                 "seed": "--seed", "config": "--config"}

CASE_TEXT = {
    "unstable_equilibrium": "the equilibrium is unstable (h = 0)",
    "unstable_cycle": "an unstable limit cycle surrounds the stable equilibrium (h = its max gap "
    "deviation)",
    "no_cycle_within_limits": "no unstable cycle surrounds the equilibrium within the gap range "
    "(h = gap_max - c0)",
}


@app.command("index")
def index_command(
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    no_simulation: Annotated[
        bool, typer.Option("--no-simulation", help="Skip the simulation-based h_simulation.")
    ] = False,
    scatter: ScatterOpt = None,
    monte_carlo: McOpt = None,
    workers: WorkersOpt = None,
    resume: ResumeOpt = False,
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option(
        "--out", help="Folder for the result (index_MODEL.json, as --json prints it) and "
        "the --monte-carlo chunks (default: maglev-match-out/index/).")] = None,
    json_out: JsonOpt = False,
) -> None:
    """The headline matching index chi = min(chi_paper, chi_simulation) (model A or the full
    vehicle): the paper's chi = h / w0 with the case that decided h, the simulated critical
    disturbance in both directions with what decided it, and the reading; with --scatter,
    the spread of chi from parameter scatter."""
    if is_model_file(model):
        refuse_model_file(model, "index")
    from maglev_match.cli.design import (
        check_monte_carlo_folder,
        print_scatter,
        scatter_options,
        scatter_report,
    )

    model = check_model(model)
    params = params_from_options(preset, config, set_)
    check_index_params(params)
    sc = scatter_options(params, scatter, monte_carlo, model)
    check_monte_carlo_folder(out, "index", "index", monte_carlo)
    from maglev_match import api  # (after the checks: JAX loads here)

    with progress_report("index") as prog, api_options(INDEX_OPTIONS):
        prog.stage("computing the matching index ...")
        res = api.matching_index(params, model=model, simulate=not no_simulation,
                                 stage=prog.stage)
    sp = scatter_report(params, res, sc, monte_carlo, out, workers, resume, seed, model)
    data = res.as_json()
    if sc:
        data.update(sp.as_json())
    written = write_result_json(out, "index", f"index_{model}", data, json_out)
    if json_out:
        emit_json(data)
        return
    print_index(res, preset, config, set_)
    print_scatter(sp)
    for f in written:
        console.print(f"wrote {f}", highlight=False)


MECHANISM_WORDS = {
    "grazing": "grazing",
    "basin_boundary": "basin boundary",
    "bisection": "bisection only",
    "all_return": "every size returned",
    "all_collide": "even the smallest size collided",
    "unresolved": "unresolved",
}


def _direction_line(d: dict, size: float | None, mm: float) -> str:
    """One direction of the simulated critical disturbance: the size, what decided it and
    how it was found."""
    crit = d.get("critical")
    val = "unknown" if size is None else f"{size * mm:.6g} mm" if (
        crit and crit["mechanism"] in ("grazing", "basin_boundary")) else (
        "unknown" if size is None else f"{size * mm:.4g} mm")
    if crit and crit["mechanism"] == "grazing":
        where = crit["limit"] + " gap limit" + (f" of point {crit['point']}"
                                                if crit.get("point", 1) not in (None, 1) else "")
        return (f"{val}: grazing, the critical run touches the {where} tangentially at "
                f"t* = {crit['t_star']:.4g} s (solved, Newton {crit['iterations']} steps; "
                f"bisection bracket +/- {d['tolerance'] / 2 * mm:.2g} mm, {d['runs']} runs)")
    if crit and crit["mechanism"] == "basin_boundary":
        return (f"{val}: basin boundary, the critical run lands on a saddle cycle of the "
                f"clamped system (solved; bisection bracket +/- {d['tolerance'] / 2 * mm:.2g} "
                f"mm, {d['runs']} runs)")
    extra = ""
    ev = (crit or {}).get("evidence")
    ev_text = {"grazing": "; the runs point to a grazing contact, not solved",
               "basin_boundary": "; the runs point to a basin boundary, not solved",
               "mixed": "; the runs' evidence is mixed, neither condition solved"}.get(ev, "")
    if d["status"] == "bracketed":  # midpoint of a bracket no wider than the tolerance
        extra = (f" (bisection only: +/- {d['tolerance'] / 2 * mm:.2g} mm, {d['runs']} "
                 f"runs{ev_text})")
    elif d["status"] == "all_return":
        extra = " (every size returned: the whole gap range)"
    elif d["status"] == "all_collide":
        extra = " (even the smallest size collided)"
    elif d["status"] == "open":
        sc = d.get("smallest_collision")
        coll = "" if sc is None else f"; smallest size seen to collide {sc * mm:.4g} mm"
        extra = (" (inconclusive: largest size seen to return" if size is not None
                 else " (inconclusive: no size seen to return") + coll + ")"
    return f"{val}{extra}"


def _print_critical_delay(res) -> None:
    """The critical delay of the outer control loop (one line, issue 23)."""
    cd = getattr(res, "critical_delay", None)
    if not cd:
        return
    ms = 1e3
    at = (f"; at tau = {cd['tau'] * ms:.4g} ms the equilibrium is "
          + ("stable" if cd["stable_at_tau"] else "unstable") if cd["tau"] > 0 else "")
    if cd["value"] is None:
        text = (f"none up to {cd['tau_max']:g} s (stable for every delay of the controller)"
                if cd["stable_without_delay"] else "none (the equilibrium is unstable)")
    elif cd["value"] == 0:
        text = "0 (the equilibrium is unstable without delay)"
    else:
        text = (f"tau = {cd['value'] * ms:.4g} ms (omega = {cd['frequency']:.5g} rad/s, "
                f"{cd['kind']}, l1 = {cd['l1']:.3g}){at}")
    console.print(f"  critical delay of the controller: {text}", highlight=False)
    pr = cd.get("practical")
    if pr:
        if pr["value"] is None:
            console.print(f"  practical margin of the delay: not found ({pr['reason']})",
                          highlight=False)
        else:
            console.print(f"  practical margin of the delay: tau = {pr['value'] * ms:.4g} ms "
                          f"({pr['reason']})", highlight=False)


def print_index(res, preset: str, config, set_) -> None:
    """The text form of a :class:`~maglev_match.analyses.matching.MatchingIndex` (every warning
    of the JSON form is printed here too): the headline chi first, then the paper's
    definition, the simulation and the reading."""
    mm = 1e3
    verdict = "[bold green]stable[/]" if res.stable else "[bold red]unstable[/]"
    info = model_info(res.model)
    name = info.label
    console.print(f"[bold]maglev-match index[/] — {name}, preset {preset}"
                  + (f", config {config}" if config else "")
                  + (f", set {' '.join(set_)}" if set_ else ""), highlight=False)
    chi_text = "nan" if res.chi != res.chi else f"{res.chi:.4g}"
    console.print(f"  [bold]chi = {chi_text}[/] (headline: {res.headline})", highlight=False)
    console.print(f"  beam: omega1 = {res.omega1:.5g} rad/s, sigma = {res.sigma:.4g} 1/kg")
    console.print(f"  equilibrium: {verdict}, max Re(lambda) = {res.max_real_part:.4g} 1/s")
    if res.hopf_param is not None:
        dist = f" ({100 * res.hopf_distance:.3g} % away)" if res.hopf_distance is not None else ""
        kind = ("subcritical" if (res.l1 or 0) > 0 else "supercritical") if res.l1 else ""
        console.print(f"  nearest Hopf point: {res.hopf_param} = {res.hopf_value:.6g}{dist}"
                      + (f", {kind}, l1 = {res.l1:.3g}" if kind else ""))
    _print_critical_delay(res)
    console.print("  [bold]by the paper's definition[/]:")
    console.print(f"    h  = {res.h * mm:.4g} mm: {CASE_TEXT.get(res.case, res.case)}")
    w0_text = info.w0_text
    console.print(f"    w0 = {res.w0 * mm:.4g} mm ({w0_text})")
    console.print(f"    chi_paper = h / w0 = {res.chi_paper:.4g} (the paper's definition)")
    sim = res.simulation
    if sim is None:
        console.print("  by simulation: not run (--no-simulation); the headline chi is the "
                      "paper's number")
    elif sim.get("status") == "skipped":
        console.print(f"  by simulation: not run ({sim['reason']})")
    else:
        console.print("  [bold]by simulation[/] (critical disturbance along the paper's initial "
                      "state, both directions):")
        for key, size in (("up", res.h_simulation_up), ("down", res.h_simulation_down)):
            d = sim.get(key)
            if d is None:
                continue
            console.print(f"    {d['label']}: {_direction_line(d, size, mm)}", highlight=False)
        chi_s = "unknown" if res.chi_simulation is None else f"{res.chi_simulation:.4g}"
        h_s = "unknown" if res.h_simulation is None else f"{res.h_simulation * mm:.4g} mm"
        console.print(f"    h_simulation = {h_s} (the smaller), chi_simulation = {chi_s}")
        console.print(f"    rule: {sim.get('rule', '')}", markup=False, highlight=False)
    basis = ("the paper's definition" if res.reading_basis == "paper"
             else "the simulation")
    console.print(f"  [bold]reading[/] (of the headline chi, from {basis}): "
                  f"[bold]{res.reading}[/]", highlight=False)
    if res.warnings:
        console.print(f"  [yellow]warnings ({len(res.warnings)}):[/]")
        for w in res.warnings:
            console.print(f"    - {w}", style="yellow", markup=False, highlight=False)


@app.command("map")
def map_command(
    ctx: typer.Context,
    x: Annotated[str, typer.Option("--x", help="NAME=START:STOP:COUNT, e.g. omega1=40:190:100")],
    y: Annotated[str, typer.Option("--y", help="NAME=START:STOP:COUNT, e.g. sigma=2e-4:6e-4:100")],
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    out: Annotated[Path | None, typer.Option(
        "--out", help="netCDF file to write, or a folder for map_X_Y.nc (default: "
        "maglev-match-out/map/).")] = None,
    resume: Annotated[bool, typer.Option("--resume", help="Reuse finished tiles.")] = False,
    scheduler: Annotated[
        str | None, typer.Option("--scheduler", help="Existing Dask scheduler, tcp://host:port.",
                                 callback=scheduler_option)
    ] = None,
    workers: Annotated[
        int | None, typer.Option("--workers", help="Local workers (default: all cores; 0: none).",
                                 callback=workers_option)
    ] = None,
    rows_per_tile: Annotated[int, typer.Option(
        "--rows-per-tile", help="Rows per task; within a tile each row's critical "
        "disturbances start from the row below.", callback=rows_per_tile_option)] = 4,
    ntst: Annotated[int, typer.Option("--ntst", help="Collocation intervals for cycles.",
                                      callback=ntst_option)] = 30,
    no_simulation: Annotated[bool, typer.Option(
        "--no-simulation", help="The paper's index only: chi is then the paper's chi, and "
        "no critical disturbance is simulated.")] = False,
    keep_tiles: Annotated[bool, typer.Option(
        "--keep-tiles", help="Keep the checkpoint folder <out>.tiles/ after a successful "
        "map (default: removed once the map is saved).")] = False,
    json_out: JsonOpt = False,
    model: Annotated[str | None, typer.Option(
        "--model", help="unit (the default): a map of the standstill index is computed for "
        "model A; with a speed axis v=... also vehicle or force (see `speed`).")] = None,
    iso: Annotated[float | None, typer.Option(
        "--iso", help="Draw the level chi = VALUE on the figure, interpolated from the map "
        "grid (drawing only).")] = None,
    iso_curve: Annotated[Path | None, typer.Option(
        "--iso-curve", help="Draw this iso-chi curve (the netCDF file of `iso-curve`) on "
        "the figure, as solved (drawing only).")] = None,
) -> None:
    """The headline matching index chi = min(chi_paper, chi_simulation), its two parts,
    h, the simulated critical disturbances and stability over a grid of two parameters
    (netCDF + figure). An axis v=START:STOP:COUNT (km/h) maps the read-outs at speed instead
    (see `speed`)."""
    from maglev_match.cli.speed import has_speed_axis, speed_map_command

    if has_speed_axis(x, y):
        refuse_given({"iso": "--iso", "iso_curve": "--iso-curve"}, "the iso-chi overlay "
                     "is drawn on maps of the standstill index")
        return speed_map_command(x, y, preset, config, set_, out, resume, scheduler, workers,
                                 json_out, model)
    if model is not None and is_model_file(model):
        refuse_model_file(model, "map")
    check_output_path(out)
    if rows_per_tile < 1:
        raise ParameterError("--rows-per-tile", rows_per_tile, "must be at least 1")
    base = params_from_options(preset, config, set_)
    names = [a.split("=", 1)[0].strip() for a in (x, y)]
    overlay = iso_overlay(iso, iso_curve, names)
    folder, stem = output_target(out, "map", f"map_{names[0]}_{names[1]}")
    from maglev_match import api
    from maglev_match.core.io import atomic_write_netcdf

    out = folder / f"{stem}.nc"
    checkpoint = out.with_name(out.name + ".tiles")
    log = out.with_suffix(".log")
    debug = bool(ctx.find_root().params.get("debug", False))
    with progress_report("map") as prog, api_options(MAP_OPTIONS):
        ds = api.design_map(base, x, y, checkpoint=checkpoint, resume=resume,
                            scheduler=scheduler, workers=workers, rows_per_tile=rows_per_tile,
                            ntst=ntst, progress=prog.tiles, simulate=not no_simulation,
                            log=log, echo_dask=debug, check_fraction=0.1, stage=prog.stage,
                            model=model or "unit")
    warns = api.map_warnings(ds)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_netcdf(out, ds)
    from maglev_match.plots import plot as draw

    figs = draw(ds, out.with_suffix(""), design_point=(float(getattr(base, names[0])),
                                                       float(getattr(base, names[1]))),
                **overlay)
    tiles_left = keep_tiles or not api.remove_tiles(checkpoint)
    summary = _map_summary(ds, names, not no_simulation, out, figs, warns,
                           str(checkpoint) if tiles_left else None,
                           str(log) if log.exists() else None)
    if json_out:
        emit_json(summary)
        return
    _print_map(summary)


def _map_summary(ds, names, simulate, out, figs, warnings, tiles, log) -> dict:
    """The JSON form of a finished map (every number as stored in the netCDF file)."""
    import math

    import numpy as np

    stable = ds["stable"].values == 1
    resolved = ds["resolved"].values == 1

    def top(name):
        v = ds[name].values
        return float(np.nanmax(v)) if np.isfinite(v).any() else None

    a = ds.attrs
    spot = {"points": int(a["spot_check_points"]),
            "max_rel_diff": float(a["spot_check_max_rel_diff"]),
            "tolerance": float(a["spot_check_tolerance"]),
            "passed": bool(a["spot_check_passed"])}
    if simulate:
        spot.update({"simulation_max_diff": float(a["spot_check_simulation_max_diff"]),
                     "simulation_tolerance": float(a["spot_check_simulation_tolerance"]),
                     "headline_max_diff": float(a["spot_check_headline_max_diff"]),
                     "headline_passed": bool(a["spot_check_headline_passed"])})
    by_sim = int(np.sum((ds["chi_basis"].values == 1) & stable & resolved))
    return {
        "netcdf": str(out), "figures": [str(f) for f in figs], "x": names[0],
        "y": names[1], "shape": list(ds["stable"].shape),
        "index_definition": a["index_definition"], "simulation": bool(simulate),
        "stable_fraction": float(stable.mean()),
        "chi_max": top("chi"), "chi_paper_max": top("chi_paper"),
        "chi_simulation_max": top("chi_simulation"),
        "points_decided_by_simulation": by_sim,
        "unresolved": int((~resolved).sum()),
        "spot_check": spot,
        "hopf_curve": a.get("hopf_curve", ""),
        "tiles": tiles, "log": log,
        "warnings": warnings,
        "simulation_tolerance": (None if not simulate
                                 or not math.isfinite(a["simulation_tolerance"])
                                 else float(a["simulation_tolerance"])),
    }


def _print_map(summary: dict) -> None:
    """The text form of :func:`_map_summary` (every warning of the JSON form too)."""
    def num(v):
        return "-" if v is None else f"{v:.3g}"

    console.print(f"wrote {summary['netcdf']} and {', '.join(summary['figures'])}",
                  highlight=False)
    console.print(f"index: {summary['index_definition']}", highlight=False)
    console.print(f"stable at {summary['stable_fraction']:.0%} of the points (index NaN at "
                  f"unstable ones); chi up to {num(summary['chi_max'])} (paper's definition up "
                  f"to {num(summary['chi_paper_max'])}"
                  + (f", simulation up to {num(summary['chi_simulation_max'])}; the "
                     f"simulation gives the smaller index at "
                     f"{summary['points_decided_by_simulation']} point(s)"
                     if summary["simulation"] else "") + f"); {summary['unresolved']} "
                  "unresolved point(s)", highlight=False)
    sc = summary["spot_check"]
    text = (f"spot check: {sc['points']} point(s) recomputed one by one: paper's h within "
            f"{sc['max_rel_diff']:.3g} relative (tolerance {sc['tolerance']:g})")
    if summary["simulation"]:
        text += (f", critical disturbances within {sc['simulation_max_diff'] * 1e3:.3g} mm "
                 f"(search tolerance {sc['simulation_tolerance'] * 1e3:g} mm), headline chi "
                 f"within {sc['headline_max_diff']:.3g} "
                 f"({'passed' if sc['headline_passed'] else 'FAILED'})")
    console.print(text + ("" if sc["passed"] else " - FAILED"), highlight=False)
    console.print(f"stability boundary: Hopf curve {summary['hopf_curve']}", highlight=False)
    if summary["tiles"]:
        console.print(f"checkpoint tiles kept in {summary['tiles']}", highlight=False)
    if summary["log"]:
        console.print(f"Dask's messages: {summary['log']}", highlight=False)
    for w in summary["warnings"]:
        console.print(f"  - {w}", style="yellow", markup=False, highlight=False)
