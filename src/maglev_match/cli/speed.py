"""`maglev-match speed`: the vehicle at speed over identical spans, swept over speed; the
run over N spans behind `simulate --speed V --spans N`; the map over (v, another parameter)
behind `map --x v=...`. Speeds on the command line are in km/h; JSON and files are SI."""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from rich import box
from rich.table import Table

from maglev_match.api.speed import KMH, speeds_kmh
from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    ConfigOpt,
    JsonOpt,
    PresetOpt,
    SetOpt,
    api_options,
    check_output_path,
    console,
    emit_json,
    output_target,
    params_from_options,
    preload,
    print_warnings,
    progress_report,
    scheduler_option,
    workers_option,
)
from maglev_match.core.params import ParameterError

SPEED_MODELS = ("unit", "vehicle", "force")
#: API keyword -> option, for `speed`, `simulate --speed` and `map --x v=...`
SPEED_OPTIONS = {"model": "--model", "speeds": "--from/--to/--step", "critical": "--critical",
                 "spans": "--spans", "workers": "--workers", "scheduler": "--scheduler",
                 "resume": "--resume", "config": "--config", "kmh": "--speed",
                 "x": "--x", "y": "--y", "irregularity": "--irregularity",
                 "irregular_spans": "--irregular-spans", "critical_delay": "--critical-delay"}

SpeedModelOpt = Annotated[str, typer.Option(
    "--model", help="'unit' (model A's unit, the vehicle's k units spread over its length), "
    "'vehicle' (model B, six levitation points) or 'force' (a constant moving force).")]
SpansOpt = Annotated[int, typer.Option(
    "--spans", help="Spans a disturbed run may take to return to the periodic response "
    "(the guideway's length in spans).")]
IrregularityOpt = Annotated[str | None, typer.Option(
    "--irregularity", help="A guideway irregularity under every levitation point, "
    "KIND:NAME=VALUE,... in m: sine:wavelength=W,amplitude=A; joint:step=S; "
    "settlement:depth=S[,support=J]; camber:amplitude=A; random:class=low|high[,seeds=N,"
    "seed0=K,lmin=..,lmax=..,waves=..] (the German track spectrum). Replaces a --config "
    "file's [irregularity] table.")]


def irregularity_option(irregularity: str | None, config: Path | None):
    """The guideway irregularity of a run: --irregularity if given (it replaces the
    config's), else the --config file's [irregularity] table, else None."""
    if irregularity is not None:
        return irregularity
    from maglev_match.api.speed import config_irregularity

    return config_irregularity(config)


def _check_model(model: str) -> str:
    if model not in SPEED_MODELS:
        raise ParameterError("--model", model, "must be 'unit', 'vehicle' or 'force'")
    return model


def _fmt(v: float, fmt: str) -> str:
    return "-" if v is None or not np.isfinite(v) else format(v, fmt)


def _side(p, direction: int) -> str:
    """The index at speed in one direction, the smallest over the positions, with how the
    search ended there."""
    if p.index is None:
        return "-"
    cs = [q.down if direction > 0 else q.up for q in p.index.positions]
    if any(c.size is None for c in cs):
        return "open"
    c = min(cs, key=lambda c: c.size)
    word = {"solved": "", "bracketed": " br", "all_return": " all ret.",
            "all_collide": " all coll.", "open": " open"}.get(c.status, "")
    return f"{c.size * 1e3:.3f}{word}"


def _decides(p) -> str:
    ix = p.index
    if ix is None or ix.fraction is None:
        return "-"
    return f"{ix.fraction:g} L {'down' if ix.direction > 0 else 'up'}"


def _table(sweep) -> Table:
    t = Table(box=box.SIMPLE_HEAD, pad_edge=False)
    cols = ["km/h", "stable", "max|mu|", "DAF", "max|gap dev| mm", "min current A",
            "Wz", "acc m/s^2", "down mm", "up mm", "chi(v)", "decided at", "chi entry"]
    delay = sweep.options.critical_delay
    if delay:
        cols += ["tau_c ms"]
    for c in cols:
        t.add_column(c, justify="right")
    for p in sweep.points:
        stable = "-" if p.stable is None else ("yes" if p.stable else "NO")
        extra = [_fmt(p.tau_c * 1e3, ".6g")] if delay else []
        imin = min(p.current_min) if p.current_min else float("nan")
        t.add_row(f"{p.speed_kmh:g}", stable, _fmt(p.largest_multiplier, ".4f"),
                  _fmt(p.daf, ".4f"), _fmt(p.gap_dev_abs_max * 1e3, ".4f"),
                  _fmt(imin, ".2f"), _fmt(p.wz, ".3f"), _fmt(p.body_acc_peak, ".4f"),
                  _side(p, +1), _side(p, -1), _fmt(p.chi, ".3f"), _decides(p),
                  _fmt(p.chi_entry, ".3f"), *extra)
    return t


def _summary_lines(sweep) -> list[str]:
    from maglev_match.api.speed import ride_reading as sperling_reading

    out = []
    daf, v_daf = sweep.largest("daf")
    wz, v_wz = sweep.largest("wz")
    gap, v_gap = sweep.largest("gap_dev_abs_max")
    out.append(f"largest DAF {_fmt(daf, '.4f')} at {_fmt(v_daf / KMH, '.4g')} km/h; largest "
               f"|gap deviation| {_fmt(gap * 1e3, '.4f')} mm at {_fmt(v_gap / KMH, '.4g')} km/h")
    if np.isfinite(wz):
        out.append(f"largest Wz {wz:.3f} at {v_wz / KMH:.4g} km/h ({sperling_reading(wz)})")
    unstable = [p for p in sweep.points if p.stable is False]
    if unstable:
        out.append("the levitation LOSES STABILITY at " + ", ".join(
            f"{p.speed_kmh:g}" for p in unstable) + " km/h")
    elif sweep.model != "force":
        out.append(f"the periodic response is stable at every speed from "
                   f"{sweep.points[0].speed_kmh:g} to {sweep.points[-1].speed_kmh:g} km/h")
    for c in sweep.stability_changes:
        if c.converged:
            what = "loses" if c.becomes_unstable else "regains"
            out.append(f"  it {what} stability at {c.speed / KMH:.4f} km/h ({c.kind}, "
                       f"multiplier {complex(*c.multiplier):.4g})")
    cds = sweep.critical_delays()
    if cds:
        ok = [c for c in cds if c["status"] == "solved"]
        if ok:
            low = min(ok, key=lambda c: c["tau_c"])
            out.append(f"critical delay of the outer loop: smallest tau_c(v) "
                       f"{low['tau_c'] * 1e3:.6g} ms at {low['speed'] / KMH:g} km/h; its "
                       f"low-speed limit (position-averaged frozen roots) "
                       f"{cds[0]['frozen_limit'] * 1e3:.6g} ms")
        for c in cds:
            if c["status"] != "solved":
                out.append(f"  critical delay at {c['speed'] / KMH:g} km/h NOT SOLVED: "
                           f"{c['status']}")
    st = sweep.standstill
    if st:
        out.append(f"standstill headline index chi = {st['chi']:.3f} (h = {st['h'] * 1e3:.4f} "
                   f"mm, basis {st['basis']}): the value chi(v) tends to as v -> 0")
    best = sweep.smallest_chi()
    if best is not None:
        worst = sweep.at(best["speed"])
        side = "beam down" if best["direction"] == 1 else "beam up"
        out.append(f"smallest chi(v) {best['value']:.3f} at {worst.speed_kmh:g} km/h (h = "
                   f"{best['h'] * 1e3:.4f} mm, w0 = {worst.w0 * 1e3:.4f} mm), decided with the "
                   f"vehicle's centre at {best['fraction']:g} L, {side}"
                   + ("; every jump up to the gap range returned there (h = the gap range)"
                      if best["every_size_returned"] else ""))
        out.append(f"  at {worst.speed_kmh:g} km/h: {worst.index.status_text()}")
    return out


@app.command("speed")
def speed_command(
    model: SpeedModelOpt = "unit",
    from_: Annotated[float, typer.Option("--from", help="First speed (km/h).")] = 0.0,
    to: Annotated[float, typer.Option("--to", help="Last speed (km/h).")] = 150.0,
    step: Annotated[float, typer.Option("--step", help="Speed step (km/h).")] = 5.0,
    spans: SpansOpt = 40,
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    critical: Annotated[bool, typer.Option(
        "--critical/--no-critical", help="Compute the index at speed chi(v), the entry "
        "disturbance and the standstill headline; off is faster.")] = True,
    out: Annotated[Path | None, typer.Option(
        "--out", help="Folder for speed_MODEL.nc and .png/.svg, or a file name whose stem "
        "names them (default: maglev-match-out/speed/).")] = None,
    resume: Annotated[bool, typer.Option(
        "--resume", help="Reuse the finished speeds of an interrupted sweep and its "
        "finished runs over an irregular guideway (<out>.tiles/).")] = False,
    workers: Annotated[int | None, typer.Option(
        "--workers", help="Local Dask workers for the speeds and the runs over an "
        "irregular guideway (default: one per core; 0: in this process).",
        callback=workers_option)] = None,
    scheduler: Annotated[str | None, typer.Option(
        "--scheduler", help="Existing Dask scheduler, tcp://host:port.",
        callback=scheduler_option)] = None,
    json_out: JsonOpt = False,
    irregularity: IrregularityOpt = None,
    irregular_spans: Annotated[int, typer.Option(
        "--irregular-spans", help="With --irregularity: spans per run over the irregular "
        "guideway (the distance of the probability of contact).")] = 20,
    critical_delay: Annotated[bool, typer.Option(
        "--critical-delay", help="Also solve at every speed for the critical delay of the "
        "outer loop tau_c(v), the smallest delay at which the periodic response loses "
        "stability (at 0 km/h: the vehicle standing at mid-span), with its low-speed "
        "limit.")] = False,
) -> None:
    """The vehicle at speed over identical simply supported spans: the periodic response at
    every speed from --from to --to (km/h), its stability (span-map multipliers), gap
    deviation, current, DAF, car-body acceleration and Sperling's Wz, the index at speed
    chi(v) = h(v) / w0 (the span under the vehicle suddenly displaced; the standstill index
    as v -> 0) next to the standstill headline, and the entry disturbance; resonance speeds
    and stability changes marked. Writes a netCDF sweep and a figure. With --irregularity:
    also runs over that irregular guideway (limits on, one per seed) at every speed above
    0, with gap, current, ride, DAF and contact-probability read-outs (their own netCDF,
    CSV and figure)."""
    _check_model(model)
    check_output_path(out)
    params = params_from_options(preset, config, set_)
    kmh = speeds_kmh(from_, to, step)
    from maglev_match import api  # (the numerics, and JAX, once the options are good)

    irregularity = irregularity_option(irregularity, config)

    folder, stem = output_target(out, "speed", f"speed_{model}")
    nc = folder / f"{stem}.nc"
    tiles = nc.with_name(nc.name + ".tiles")
    if out is not None or not json_out:
        preload("xarray", "matplotlib.pyplot", "h5netcdf")
    with progress_report("speed") as prog, api_options(SPEED_OPTIONS):
        started = time.perf_counter()
        sweep = api.speed_sweep(params, model=model, speeds=list(kmh * KMH),
                                critical=critical, spans=spans, checkpoint=tiles,
                                resume=resume, scheduler=scheduler, workers=workers,
                                progress=lambda d, t: prog.tiles(d, t, "speeds"),
                                stage=prog.stage, irregularity=irregularity,
                                irregular_spans=irregular_spans,
                                critical_delay=critical_delay,
                                runs_progress=lambda d, t: prog.tiles(d, t, "irregular runs"))
        elapsed = time.perf_counter() - started
        prog.stage(f"sweep done in {elapsed:.1f} s; writing files ...")
        files = _write_sweep(sweep, folder, stem)
        if sweep.irregular is not None:
            files += _write_irregular(sweep.irregular, folder, f"{stem}_irregular")
    shutil.rmtree(tiles, ignore_errors=True)  # the sweep is complete: its tiles are spent
    summary = sweep.summary() | {"files": [str(f) for f in files]}
    if sweep.irregular is not None:
        summary["irregular"] = sweep.irregular.summary()
    if json_out:
        emit_json(summary)
        print_warnings(sweep.warnings)
        if sweep.irregular is not None:
            print_warnings(sweep.irregular.warnings)
        return
    console.print(f"maglev-match speed — model {model}, preset {preset}, L = {params.L:g} m, "
                  f"omega1 = {params.omega1:.4g} rad/s"
                  + (f", outer-loop delay tau = {params.tau * 1e3:g} ms" if params.tau > 0
                     else ""), highlight=False)
    console.print(_table(sweep))
    if sweep.resonances:
        console.print("resonance speeds (an excitation frequency meets a natural frequency):",
                      highlight=False)
        for r in sweep.resonances:
            console.print(f"  {r.label}", highlight=False, markup=False)
    for line in _summary_lines(sweep):
        console.print(line, highlight=False, markup=False)
    print_warnings(sweep.warnings)
    if sweep.irregular is not None:
        _print_irregular(sweep.irregular)
    for f in files:
        console.print(f"wrote {f}", highlight=False)


#: the CSV table of a sweep: (header with unit, value of a point)
_CSV_COLUMNS = (
    ("speed (m/s)", lambda p, st: p.speed),
    ("speed (km/h)", lambda p, st: p.speed_kmh),
    ("stable", lambda p, st: "" if p.stable is None else int(p.stable)),
    ("largest_multiplier", lambda p, st: p.largest_multiplier),
    ("daf", lambda p, st: p.daf),
    ("gap_dev_abs_max (m)", lambda p, st: p.gap_dev_abs_max),
    ("wz", lambda p, st: p.wz),
    ("h (m)", lambda p, st: p.h),
    ("chi", lambda p, st: p.chi),
    ("chi_standstill", lambda p, st: "" if not st else st["chi"]),
    ("index_fraction", lambda p, st: "" if p.index is None else p.index.fraction),
    ("index_direction", lambda p, st: "" if p.index is None else p.index.direction),
    ("status_down", lambda p, st: _status_at(p, +1)),
    ("status_up", lambda p, st: _status_at(p, -1)),
    ("every_size_returned", lambda p, st: int(p.every_size_returned)),
    ("h_entry (m)", lambda p, st: p.h_entry),
    ("chi_entry", lambda p, st: p.chi_entry),
    ("tau (s)", lambda p, st: p.tau),
    ("tau_c (s)", lambda p, st: p.tau_c),
    ("tau_c_frozen (s)", lambda p, st: p.tau_c_frozen),
)


def _status_at(p, direction: int) -> str:
    """How the index's search ended in one direction at the deciding position."""
    ix = p.index
    if ix is None or ix.fraction is None:
        return ""
    q = next(q for q in ix.positions if q.fraction == ix.fraction)
    return (q.down if direction > 0 else q.up).status


def _write_sweep(sweep, folder: Path, stem: str) -> list[Path]:
    import csv

    from maglev_match.core.io import atomic_open, atomic_write_netcdf

    folder.mkdir(parents=True, exist_ok=True)
    nc = folder / f"{stem}.nc"
    atomic_write_netcdf(nc, sweep.to_xarray())
    table = folder / f"{stem}.csv"
    with atomic_open(table, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([h for h, _ in _CSV_COLUMNS])
        w.writerows([[f(p, sweep.standstill) for _, f in _CSV_COLUMNS] for p in sweep.points])
    return [nc, table, *sweep.plot(folder / f"{stem}.png")]


def _irregular_table(ir) -> Table:
    t = Table(box=box.SIMPLE_HEAD, pad_edge=False)
    cols = ["km/h", "gap rms mm", "gap max mm", "profile rms mm", "linear rms mm",
            "i rms A", "i max A", "reverses", "acc rms m/s^2", "Wz", "DAF", "contacts",
            "P(contact)", "95% Wilson", "s"]
    for c in cols:
        t.add_column(c, justify="right")
    for k, row in enumerate(ir.rows()):
        t.add_row(f"{row['speed'] / KMH:g}", _fmt(row["gap_rms"] * 1e3, ".4f"),
                  _fmt(row["gap_max"] * 1e3, ".4f"),
                  _fmt(row["gap_rms_profile"] * 1e3, ".4f")
                  + ("" if not np.isfinite(row["gap_rms_profile_se"])
                     else f" ± {row['gap_rms_profile_se'] * 1e3:.4f}"),
                  _fmt(row["gap_rms_linear"] * 1e3, ".4f"), _fmt(row["current_rms"], ".3f"),
                  _fmt(row["current_max"], ".2f"), "YES" if row["reverses"] > 0.5 else "no",
                  _fmt(row["acc_rms"], ".4f"), _fmt(row["wz"], ".3f"), _fmt(row["daf"], ".4f"),
                  f"{int(row['contacts'])}/{int(row['runs'])}", _fmt(row["p_contact"], ".3f"),
                  f"[{row['p_contact_low']:.3f}, {row['p_contact_high']:.3f}]",
                  f"{ir.seconds[k]:.1f}")
    return t


def _print_irregular(ir) -> None:
    console.print(f"over an irregular guideway: {ir.profile.describe()}; runs of {ir.spans} "
                  f"spans ({ir.distance:g} m) with the limits on, read-outs after "
                  f"{ir.warmup} span(s) of run-in, means over {len(ir.seeds)} run(s) per "
                  "speed (largest values: the largest); P(contact) = runs that hit a gap "
                  f"limit / runs over {ir.distance:g} m, 95 % Wilson score interval",
                  highlight=False, markup=False)
    console.print(_irregular_table(ir))
    print_warnings(ir.warnings)


def _write_irregular(ir, folder: Path, stem: str) -> list[Path]:
    import csv

    from maglev_match.core.io import atomic_open, atomic_write_netcdf

    nc = folder / f"{stem}.nc"
    atomic_write_netcdf(nc, ir.to_xarray())
    table = folder / f"{stem}.csv"
    header, rows = ir.table()
    with atomic_open(table, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return [nc, table, *ir.plot(folder / f"{stem}.png")]


# ---------------------------------------------------------------------------------------
# simulate --speed V --spans N
# ---------------------------------------------------------------------------------------
def simulate_at_speed(params, model: str, speed_kmh: float, spans: int | None, limits: bool,
                      out: Path | None, plot: Path | None, json_out: bool,
                      irregularity: str | None = None, seed: int | None = None) -> None:
    """`simulate --speed V --spans N`: the run over N spans from rigid ground and off again,
    with the periodic response overlaid (called by the simulate command)."""
    _check_model(model)
    n = 10 if spans is None else spans
    check_output_path(out, suffixes=(".nc",))
    check_output_path(plot, "--plot")
    from maglev_match import api

    with progress_report("simulate") as prog, api_options(SPEED_OPTIONS):
        run = api.simulate_over_spans(params, model=model, kmh=speed_kmh, spans=n,
                                      limits=limits, stage=prog.stage,
                                      irregularity=irregularity, seed=seed)
        prog.stage(f"run done: {run.outcome}")
        folder, stem = output_target(out, "simulate", f"simulation_{model}_speed")
        folder.mkdir(parents=True, exist_ok=True)
        from maglev_match.core.io import atomic_write_netcdf

        nc = folder / f"{stem}.nc"
        atomic_write_netcdf(nc, run.to_xarray())
        written = [nc]
        pfolder, pstem = output_target(plot if plot is not None else out, "simulate",
                                       f"simulation_{model}_speed")
        written += run.plot(pfolder / f"{pstem}.png")
    summary: dict[str, Any] = run.summary() | {"files": [str(w) for w in written]}
    if json_out:
        emit_json(summary)
        print_warnings(run.warnings)
        return
    console.print(f"model {model} over {n} spans of L = {params.L:g} m at {speed_kmh:g} km/h "
                  f"({run.speed:.4g} m/s), limits {'on' if limits else 'off'}: {run.outcome}",
                  highlight=False)
    if run.irregularity is not None:
        console.print(f"guideway irregularity: {run.irregularity}", highlight=False,
                      markup=False)
    if run.outcome == "collision":
        console.print(f"[bold red]collision[/] at t = {run.collision_time:.6f} s: "
                      f"{run.collision_limit} gap limit at levitation point "
                      f"{run.collision_point}")
    spans_txt = ", ".join(f"{v * 1e3:.4f}" for v in run.per_span_midspan_max)
    console.print(f"largest mid-span deflection per span (mm): {spans_txt}", highlight=False)
    gaps_txt = ", ".join(_fmt(v * 1e3, ".4f") for v in run.per_passage_gap_max)
    console.print(f"largest |gap deviation| per span passage (mm): {gaps_txt}",
                  highlight=False)
    print_warnings(run.warnings)
    for w in written:
        console.print(f"wrote {w}", highlight=False)


# ---------------------------------------------------------------------------------------
# map --x v=... (km/h) --y NAME=...
# ---------------------------------------------------------------------------------------
def has_speed_axis(*axes: str) -> bool:
    """Whether a map axis is the speed ``v=START:STOP:COUNT`` (km/h)."""
    return any(a.split("=", 1)[0].strip() == "v" for a in axes)


def speed_map_command(x: str, y: str, preset: str, config, set_, out: Path | None,
                      resume: bool, scheduler: str | None, workers: int | None,
                      json_out: bool, model: str | None) -> None:
    """`map` with the speed v (km/h) on one axis: every grid point a periodic response at
    speed with its read-outs (netCDF + figure)."""
    kind = _check_model(model or "unit")
    check_output_path(out)
    params = params_from_options(preset, config, set_)
    names = [a.split("=", 1)[0].strip() for a in (x, y)]
    folder, stem = output_target(out, "map", f"map_{names[0]}_{names[1]}")
    nc = folder / f"{stem}.nc"
    tiles = nc.with_name(nc.name + ".tiles")
    from maglev_match import api

    with progress_report("map") as prog, api_options(SPEED_OPTIONS):
        ds = api.speed_map(params, x, y, model=kind, checkpoint=tiles, resume=resume,
                           scheduler=scheduler, workers=workers, progress=prog.tiles,
                           stage=prog.stage)
        from maglev_match.core.io import atomic_write_netcdf
        from maglev_match.plots import save_figure
        from maglev_match.plots.speed import speed_map_figure

        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_netcdf(nc, ds)
        files = [nc, *save_figure(speed_map_figure(ds), folder / f"{stem}.png")]
    shutil.rmtree(tiles, ignore_errors=True)
    stable = ds["stable"].values
    summary = {"netcdf": str(nc), "figures": [str(f) for f in files[1:]], "x": names[0],
               "y": names[1], "model": kind, "shape": list(stable.shape),
               "stable_fraction": float(np.mean(stable == 1)),
               "chi_min": float(np.nanmin(ds["chi"].values))
               if np.isfinite(ds["chi"].values).any() else None,
               "speed_units_on_command_line": "km/h", "speed_units_in_file": "m/s"}
    if json_out:
        emit_json(summary)
        return
    console.print(f"wrote {', '.join(str(f) for f in files)}", highlight=False)
    console.print(f"periodic response stable at {summary['stable_fraction']:.0%} of the "
                  "points", highlight=False)
