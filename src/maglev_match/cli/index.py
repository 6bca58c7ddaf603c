"""`maglev-match index` (the main job) and `maglev-match map`."""

from __future__ import annotations

import time
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
    check_index_params,
    check_model,
    check_output_path,
    console,
    emit_json,
    ntst_option,
    output_target,
    params_from_options,
    progress_report,
    rows_per_tile_option,
    scheduler_option,
    workers_option,
)
from maglev_match.cli.design import McOpt, ResumeOpt, ScatterOpt, SeedOpt, WorkersOpt
from maglev_match.cli.models import MaglevOnlyModelOpt, is_model_file, refuse_model_file

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
        "--out", help="Folder for the --monte-carlo chunks (default: "
        "maglev-match-out/index/).")] = None,
    json_out: JsonOpt = False,
) -> None:
    """The matching index chi = h / w0 (model A or the full vehicle), with the case that
    decided h, the simulated critical disturbance in both directions and the reading;
    with --scatter, the spread of chi from parameter scatter."""
    if is_model_file(model):
        refuse_model_file(model, "index")
    from maglev_match.cli.design import print_scatter, scatter_options, scatter_report
    from maglev_match.matching import matching_index

    model = check_model(model)
    params = params_from_options(preset, config, set_)
    check_index_params(params)
    sc = scatter_options(params, scatter, monte_carlo, model)
    with progress_report("index") as prog:
        prog.stage("computing the matching index ...")
        res = matching_index(params, model=model, simulate=not no_simulation)
    spread, mc = scatter_report(params, res, sc, monte_carlo, out, workers, resume, seed, model)
    if json_out:
        data = res.as_json()
        if sc:
            data["spread"] = spread
            data["monte_carlo"] = None if mc is None else mc.as_json()
        emit_json(data)
        return
    print_index(res, preset, config, set_)
    print_scatter(spread, mc)


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


def print_index(res, preset: str, config, set_) -> None:
    """The text form of a :class:`~maglev_match.matching.MatchingIndex` (every warning
    of the JSON form is printed here too)."""
    mm = 1e3
    verdict = "[bold green]stable[/]" if res.stable else "[bold red]unstable[/]"
    name = "model A (one levitation unit)" if res.model == "unit" else \
        "model B (full vehicle, six levitation points)"
    console.print(f"[bold]maglev-match index[/] — {name}, preset {preset}"
                  + (f", config {config}" if config else "")
                  + (f", set {' '.join(set_)}" if set_ else ""), highlight=False)
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
    w0_text = ("static beam deflection" if res.model == "unit"
               else "static mid-span beam deflection under the vehicle")
    console.print(f"    w0 = {res.w0 * mm:.4g} mm ({w0_text})")
    console.print(f"    chi = {res.chi:.4g}")
    sim = res.simulation
    if sim is None:
        console.print("  by simulation: not run (--no-simulation); the reading rests on the "
                      "paper's definition alone")
    elif sim.get("status") == "skipped":
        console.print(f"  by simulation: not run ({sim['reason']})")
    else:
        console.print("  [bold]by simulation[/] (critical disturbance along the paper's initial "
                      "state, both directions):")
        for key, size in (("up", res.h_simulation_up), ("down", res.h_simulation_down)):
            d = sim.get(key)
            if d is None:
                continue
            val = "unknown" if size is None else f"{size * mm:.4g} mm"
            extra = ""
            if d["status"] == "bracketed":  # midpoint of a bracket no wider than the tolerance
                extra = f" (+/- {d['tolerance'] / 2 * mm:.2g} mm, {d['runs']} runs)"
            elif d["status"] == "all_return":
                extra = " (every size returned: the whole gap range)"
            elif d["status"] == "open":
                extra = " (inconclusive: largest size seen to return)"
            console.print(f"    {d['label']}: {val}{extra}", highlight=False)
        chi_s = "unknown" if res.chi_simulation is None else f"{res.chi_simulation:.4g}"
        h_s = "unknown" if res.h_simulation is None else f"{res.h_simulation * mm:.4g} mm"
        console.print(f"    h_simulation = {h_s} (the smaller), chi_simulation = {chi_s}")
        console.print(f"    rule: {sim.get('rule', '')}", markup=False, highlight=False)
    used = res.chi if res.reading_basis == "paper" else res.chi_simulation
    basis = ("the paper's definition" if res.reading_basis == "paper"
             else "the simulation, the smaller index")
    used_text = "" if used is None else f", index {used:.4g}"
    console.print(f"  [bold]reading[/] (from {basis}{used_text}): [bold]{res.reading}[/]",
                  highlight=False)
    if res.warnings:
        console.print(f"  [yellow]warnings ({len(res.warnings)}):[/]")
        for w in res.warnings:
            console.print(f"    - {w}", style="yellow", markup=False, highlight=False)


@app.command("map")
def map_command(
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
    rows_per_tile: Annotated[int, typer.Option("--rows-per-tile",
                                               callback=rows_per_tile_option)] = 2,
    ntst: Annotated[int, typer.Option("--ntst", help="Collocation intervals for cycles.",
                                      callback=ntst_option)] = 30,
    json_out: JsonOpt = False,
    model: MaglevOnlyModelOpt = None,
) -> None:
    """Stability, h, w0 and chi over a grid of two parameters (netCDF + figure)."""
    refuse_model_file(model, "map")
    from maglev_match.io import atomic_write
    from maglev_match.maps import MapSpec, map_dataset, map_warnings, parse_axis, run_map
    from maglev_match.params import ParameterError
    from maglev_match.plots import save_figure
    from maglev_match.plots.maps import map_figure

    check_output_path(out)
    base = params_from_options(preset, config, set_)
    ax, ay = parse_axis(x, "--x"), parse_axis(y, "--y")
    folder, stem = output_target(out, "map", f"map_{ax.name}_{ay.name}")
    if rows_per_tile < 1:
        raise ParameterError("--rows-per-tile", rows_per_tile, "must be at least 1")
    spec = MapSpec(base=base.as_input_dict(), x=ax, y=ay, rows_per_tile=rows_per_tile,
                   ntst=ntst)
    spec.validate()  # every grid point, before any work starts
    out = folder / f"{stem}.nc"
    checkpoint = out.with_name(out.name + ".tiles")
    with progress_report("map") as prog:
        prog.stage(f"map {ax.name} x {ay.name}: {len(spec.tiles)} tiles ...")
        started = time.perf_counter()
        data = run_map(spec, checkpoint, resume=resume, scheduler=scheduler, workers=workers,
                       progress=prog.tiles)
        elapsed = time.perf_counter() - started
        # the self-check gets 10 % of the map's time (at least one point is checked)
        prog.stage("spot check: recomputing sample points one by one ...")
        ds = map_dataset(spec, data, budget=0.1 * elapsed)
    from maglev_match.datasets import annotate_map

    ds = annotate_map(ds, base)
    warnings = map_warnings(ds)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, lambda tmp: ds.to_netcdf(tmp, engine="h5netcdf"))
    figs = save_figure(map_figure(ds, design_point=(float(getattr(base, ax.name)),
                                                    float(getattr(base, ay.name)))),
                       out.with_suffix(""))
    summary = {
        "netcdf": str(out), "figures": [str(f) for f in figs], "x": ax.name, "y": ay.name,
        "shape": [ay.count, ax.count], "stable_fraction": float(ds["stable"].mean()),
        "chi_max": float(ds["chi"].max()), "unresolved": int((ds["resolved"] == 0).sum()),
        "spot_check": {"points": int(ds.attrs["spot_check_points"]),
                       "max_rel_diff": float(ds.attrs["spot_check_max_rel_diff"]),
                       "tolerance": float(ds.attrs["spot_check_tolerance"]),
                       "passed": bool(ds.attrs["spot_check_passed"])},
        "warnings": warnings,
    }
    if json_out:
        emit_json(summary)
        return
    console.print(f"wrote {out} and {', '.join(str(f) for f in figs)}")
    console.print(f"stable at {summary['stable_fraction']:.0%} of the points; chi up to "
                  f"{summary['chi_max']:.3g}; {summary['unresolved']} unresolved points")
    sc = summary["spot_check"]
    console.print(f"spot check: {sc['points']} point(s) recomputed one by one, largest relative "
                  f"difference of h {sc['max_rel_diff']:.3g} (tolerance {sc['tolerance']:g})")
    for w in warnings:
        console.print(f"  - {w}", style="yellow", markup=False, highlight=False)
