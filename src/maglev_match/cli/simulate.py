"""`maglev-match simulate`: a time simulation with the physical limits (current clamp,
gap collision), of a user model file, or at speed over N spans. Options parsed here, the
computation in :mod:`maglev_match.api.simulation`, the answer printed and saved here."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    ConfigOpt,
    JsonOpt,
    ModelOpt,
    PresetOpt,
    SetOpt,
    UserError,
    api_options,
    check_model,
    check_output_path,
    console,
    console_err,
    displacement_option,
    emit_json,
    horizon_option,
    is_file_name,
    model_inputs,
    n_save_option,
    output_target,
    params_from_options,
    print_error,
    print_warnings,
    progress_report,
    refuse_given,
    tolerance_option,
)
from maglev_match.cli.models import is_model_file
from maglev_match.maglev.catalog import model_info

#: API keyword -> option, for `simulate`
SIMULATE_OPTIONS = {"t_end": "--t", "x5": "--x5", "initial": "--initial", "q1": "--q1",
                    "x0": "--x0", "limits": "--limits/--no-limits", "n_save": "--n-save",
                    "rtol": "--rtol", "atol": "--atol", "rtol/atol": "--rtol/--atol",
                    "model": "--model", "config": "--config", "kmh": "--speed",
                    "spans": "--spans", "irregularity": "--irregularity", "seed": "--seed"}


def _read_state(text: str) -> np.ndarray:
    """An explicit state: a file (whitespace/comma separated numbers, or a JSON list) or
    the numbers themselves separated by commas."""
    path = Path(text)
    if path.is_file():
        try:
            raw = path.read_bytes()[:10_000_000].decode("utf-8").strip()
        except (OSError, UnicodeDecodeError) as exc:
            raise UserError(f"--x0 {text}: not a readable UTF-8 text file ({exc})") from None
        if raw.startswith("["):
            try:
                return np.asarray(json.loads(raw), dtype=float).ravel()
            except (ValueError, TypeError):
                raise UserError(f"--x0 {text}: not a JSON list of numbers") from None
        try:
            return np.asarray(raw.replace(",", " ").split(), dtype=float)
        except ValueError:
            raise UserError(f"--x0 {text}: expected numbers separated by spaces or commas") \
                from None
    try:
        return np.asarray([float(v) for v in text.split(",") if v.strip()], dtype=float)
    except ValueError:
        raise UserError(f"--x0 '{text}': neither a file nor comma-separated numbers") from None


@app.command("simulate")
def simulate_command(
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    t: Annotated[float, typer.Option("--t", help="Horizon (s).", callback=horizon_option)] = 5.0,
    x5: Annotated[float | None, typer.Option(
        "--x5", help="Model A: initial beam deflection x5(0) (m); negative opens the gap.",
        callback=displacement_option)
    ] = None,
    initial: Annotated[str, typer.Option(
        "--initial", help="'equilibrium' or 'pressed' (model B: vehicle pressed onto the "
        "free beam, beam undeflected).")] = "equilibrium",
    q1: Annotated[float | None, typer.Option(
        "--q1", help="Model B: absolute first modal coordinate q1(0) (m), set on top of "
        "--initial (undeflected beam = 0).", callback=displacement_option)] = None,
    x0: Annotated[str | None, typer.Option(
        "--x0", help="Explicit initial state: a file of numbers (or JSON list) or "
        "comma-separated values; overrides --initial/--x5/--q1.")] = None,
    limits: Annotated[bool, typer.Option(
        "--limits/--no-limits", help="Physical limits (current clamp, gap collision).")
    ] = True,
    rtol: Annotated[float, typer.Option("--rtol", help="Relative tolerance.",
                                        callback=tolerance_option)] = 1e-8,
    atol: Annotated[float, typer.Option(
        "--atol", help="Absolute tolerance, in units of each state's typical size.",
        callback=tolerance_option)] = 1e-8,
    n_save: Annotated[int, typer.Option("--n-save", help="Saved time points.",
                                        callback=n_save_option)] = 5001,
    out: Annotated[Path | None, typer.Option(
        "--out", help="History file (.nc or .csv; the figure is written beside it), or a "
        "folder for simulation_MODEL.nc/.png/.svg (default: maglev-match-out/simulate/).")
    ] = None,
    plot: Annotated[Path | None, typer.Option(
        "--plot", help="Figure file (PNG; an SVG is written beside it), or a folder for "
        "simulation_MODEL.png, instead of beside the history.")] = None,
    json_out: JsonOpt = False,
    speed: Annotated[float | None, typer.Option(
        "--speed", help="Run at this speed (km/h) over --spans identical spans from rigid "
        "ground and off again (--model unit|vehicle|force), the periodic response "
        "overlaid; --t, --x5, --q1, --initial and --x0 do not apply.")] = None,
    spans: Annotated[int | None, typer.Option(
        "--spans", help="With --speed: the number of spans (default 10).")] = None,
    irregularity: Annotated[str | None, typer.Option(
        "--irregularity", help="With --speed: a guideway irregularity under every "
        "levitation point, KIND:NAME=VALUE,... in m (as for `speed --irregularity`; "
        "replaces a --config file's [irregularity] table).")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", help="With --speed and a random --irregularity: its seed.")] = None,
) -> None:
    """Simulate model A or B from a named or explicit initial state; report collision
    (time, limit, levitation point), convergence or neither by the horizon. With --speed V
    --spans N: the vehicle at speed over N spans."""
    if speed is not None or spans is not None or irregularity is not None or seed is not None:
        from maglev_match.cli.speed import irregularity_option, simulate_at_speed

        if speed is None:
            raise UserError("--spans, --irregularity and --seed go with --speed V (km/h)")
        params = params_from_options(preset, config, set_)
        return simulate_at_speed(params, model, speed, spans, limits, out, plot, json_out,
                                 irregularity_option(irregularity, config), seed)

    if not is_model_file(model):
        check_model(model)
    check_output_path(out, suffixes=(".csv", ".nc"))
    check_output_path(plot, "--plot")
    if not t > 0:
        raise UserError(f"--t {t}: the horizon must be > 0 s")
    if n_save < 2:
        raise UserError(f"--n-save {n_save}: need at least 2 saved points")
    if not (rtol > 0 and atol > 0):
        raise UserError("--rtol and --atol must be > 0")
    if out is not None and is_file_name(out) and out.suffix not in (".csv", ".nc"):
        raise UserError(f"--out {out}: the history file must end in .csv or .nc (or give "
                        "a folder)")
    state = _read_state(x0) if x0 is not None else None
    if is_model_file(model):  # a user model file: no maglev limits or initial states
        refuse_given({"x5": "--x5", "q1": "--q1", "initial": "--initial",
                      "limits": "--limits/--no-limits", "plot": "--plot", "config": "--config",
                      "preset": "--preset"},
                     f"applies to the maglev models (unit, vehicle) only; a user model "
                     f"({model}) starts from --x0 (default: its X0), runs without physical "
                     "limits and writes its history with --out FILE.csv")
        if out is not None and is_file_name(out) and out.suffix != ".csv":
            raise UserError(f"--out {out}: for a user model the history file must end in "
                            ".csv (or give a folder)")
    params, overrides = model_inputs(model, preset, config, set_)
    # the numerics (and JAX) once the options are known to be good
    from maglev_match import api

    with progress_report("simulate") as prog, api_options(SIMULATE_OPTIONS):
        what = Path(model).stem if is_model_file(model) else model_info(model).short
        prog.stage(f"simulating {what} for {t:g} s ...")
        sim = api.simulate(params, model=model, t_end=t, x5=x5, initial=initial, q1=q1,
                           x0=state, limits=limits, n_save=n_save, rtol=rtol, atol=atol,
                           **overrides)
        prog.stage(f"simulation done: {sim.outcome}")
    if is_model_file(model):
        return _user_outputs(sim, model, out, json_out)
    written: list[str] = []
    if out is not None or plot is not None or not json_out:
        # the history and its figure go to --out (default maglev-match-out/simulate/);
        # --plot puts the figure elsewhere. With --json and neither option, nothing is
        # written (the JSON on stdout is the result).
        folder, stem = output_target(out, "simulate", f"simulation_{model}")
        suffix = out.suffix if out is not None and out.suffix else ".nc"
        if out is not None or not json_out:
            written.append(str(sim.save_history(folder / (stem + suffix))))
        if plot is not None:
            folder, stem = output_target(plot, "simulate", f"simulation_{model}")
        written += [str(p) for p in sim.plot(folder / f"{stem}.png")]
    summary = sim.summary()
    if json_out:
        emit_json(summary)
        for w in written:
            console_err.print(f"wrote {w}", highlight=False)
        print_warnings(sim.warnings)
        _fail_if_failed(sim.result)
        return
    res = sim.result
    info = model_info(model)
    console.print(f"Model {info.letter} ({info.title}), "
                  f"omega1 = {params.omega1:.4g} rad/s, sigma = {params.sigma:.4g} 1/kg, "
                  f"limits {'on' if limits else 'off'}", highlight=False)
    if sim.outcome == "collision":
        console.print(f"[bold red]collision[/] at t = {sim.collision_time:.6f} s: "
                      f"{sim.limit} gap limit at levitation point {sim.point}")
    elif sim.outcome == "converged":
        console.print(f"[bold green]converged[/]: within tolerance of the equilibrium from "
                      f"t = {res.converged_time:.3f} s on")
    elif sim.outcome == "running":
        console.print(f"[bold yellow]running[/]: neither collided nor settled by {t:g} s")
        print_warnings(sim.warnings)  # e.g. close to the equilibrium but not decaying
    else:
        console.print(f"[bold red]failed[/]: {'; '.join(sim.warnings)}")
    gd = np.atleast_1d(sim.final_gap_deviation)
    console.print("final gap deviation (mm): " + ", ".join(f"{v * 1e3:.4g}" for v in gd),
                  highlight=False)
    console.print(f"steps: {res.accepted} accepted, {res.rejected} rejected", highlight=False)
    for w in written:
        console.print(f"wrote {w}", highlight=False)
    _fail_if_failed(res)


def _user_outputs(sim, model: str, out: Path | None, json_out: bool) -> None:
    """A user model's run: its history as CSV (with --out), the JSON or the text."""
    written = []
    if out is not None:
        folder, stem = output_target(out, "simulate", f"simulation_{sim.model}")
        path = folder / f"{stem}.csv"
        t, x = sim.history()
        header = ",".join(["t", *sim.state_names])
        from maglev_match.core.io import atomic_write

        atomic_write(path, lambda tmp: np.savetxt(tmp, np.column_stack([t, x]),
                                                  delimiter=",", header=header, comments=""))
        written.append(str(path))
    summary = sim.summary() | {"model_file": str(model), "files": written}
    if json_out:
        emit_json(summary)
        print_warnings(sim.warnings)
        _fail_if_failed(sim.result)
        return
    res = sim.result
    console.print(f"Model {sim.model} ({model}): {res.outcome} at t = {res.final_time:.6g} s",
                  highlight=False)
    console.print("final state: " + ", ".join(
        f"{n} = {v:.6g}" for n, v in zip(sim.state_names, res.final_state, strict=True)),
        highlight=False)
    console.print(f"steps: {res.accepted} accepted, {res.rejected} rejected", highlight=False)
    for w in written:
        console.print(f"wrote {w}", highlight=False)
    print_warnings(sim.warnings)
    _fail_if_failed(res)


def _fail_if_failed(res) -> None:
    """A run that failed (a non-finite state, the step limit reached) is a numerical
    failure: exit code 1 after the result was printed, never a silent exit 0."""
    if str(res.outcome) == "failed":
        print_error(f"the simulation failed at t = {res.final_time:.6g} s (a non-finite "
                    "state, or the step limit was reached): the history up to there is all "
                    "there is")
        raise typer.Exit(1)
