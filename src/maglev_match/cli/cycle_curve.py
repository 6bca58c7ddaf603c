"""`maglev-match cycle-curve`: the fold of cycles (LPC), the period doubling (PD) or the
Neimark-Sacker bifurcation (NS) continued in two parameters, from a special point of a
branch of cycles (located here, or read from a saved branch). Options parsed here, the
computation in :mod:`maglev_match.api.cycle_curves`, the answer printed and saved here
(table, CSV, netCDF, figure)."""

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
    OutOpt,
    PresetOpt,
    SetOpt,
    UserError,
    api_options,
    check_output_path,
    console,
    emit_json,
    finite,
    given,
    model_inputs,
    ncol_option,
    ntst_option,
    output_target,
    parse_range,
    print_error,
    print_warnings,
    progress_report,
    refuse_given,
    steps_option,
)
from maglev_match.cli.cycle_tables import at_values, write_csv

#: API keyword -> option, for `cycle-curve`
CYCLE_CURVE_OPTIONS = {"kind": "--kind", "x": "--params", "y": "--params",
                       "x/y": "--params", "at": "--at", "bounds": "--range",
                       "label": "--label", "restart": "--restart",
                       "restart/label": "--restart/--label", "start": "--from",
                       "stop": "--to", "ntst": "--ntst", "ncol": "--ncol",
                       "max_steps": "--max-steps", "marks": "--mark",
                       "ignore_current": "--stop-at-current", "model": "--model",
                       "config": "--config"}


def _pair(text: str) -> tuple[str, str]:
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 2 or not all(parts):
        raise UserError(f"--params '{text}': expected two parameter names P1,P2, e.g. "
                        "omega1,sigma")
    return parts[0], parts[1]


def _ranges(items: list[str] | None) -> dict[str, tuple[float, float]]:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise UserError(f"--range '{item}': expected NAME=LOW:HIGH, e.g. "
                            "sigma=3e-4:5e-4")
        name, text = item.split("=", 1)
        out[name.strip()] = parse_range(text, f"--range {name.strip()}")
    return out


@app.command("cycle-curve")
def cycle_curve_command(
    kind: Annotated[str, typer.Option(
        "--kind", help="LPC (fold of cycles), PD (period doubling) or NS (Neimark-Sacker, "
        "torus).")] = "LPC",
    params_: Annotated[str, typer.Option(
        "--params", help="The curve's two parameters P1,P2: cycles are continued in P1 to "
        "locate the start, then the curve in (P1, P2).")] = "omega1,sigma",
    at: Annotated[list[str] | None, typer.Option(
        "--at", help="Fix a parameter, NAME=VALUE (repeatable), e.g. --at sigma=4e-4 (the "
        "start's P2).")] = None,
    range_: Annotated[list[str] | None, typer.Option(
        "--range", help="NAME=LOW:HIGH for P1 or P2 (repeatable): the curve ends on it "
        "(default: P2 from 0.5 to 2 times its start value).")] = None,
    label: Annotated[str | None, typer.Option(
        "--label", help="The special point to start from (default: the first of --kind on "
        "the branch, e.g. LPC1); with --restart, required; GH1, GH2, ...: the LPC curve born "
        "at that generalised Hopf point of the Hopf curve in (P1, P2).")] = None,
    restart: Annotated[Path | None, typer.Option(
        "--restart", help="Start from the special point --label of a branch saved by "
        "`cycles --out` (netCDF): no Hopf search, the saved model, mesh and values.")] = None,
    start: Annotated[float | None, typer.Option(
        "--from", help="Search the start branch's Hopf point along P1 from this value.",
        callback=finite)] = None,
    stop: Annotated[float | None, typer.Option(
        "--to", help="... up to this value.", callback=finite)] = None,
    ntst: Annotated[int, typer.Option("--ntst", help="Mesh intervals (the curve keeps the "
                                      "start branch's mesh).", callback=ntst_option)] = 80,
    ncol: Annotated[int, typer.Option("--ncol", help="Collocation points (2-7).",
                                      callback=ncol_option)] = 4,
    max_steps: Annotated[int, typer.Option("--max-steps", help="Continuation steps each way.",
                                           callback=steps_option)] = 200,
    mark: Annotated[list[float] | None, typer.Option(
        "--mark", help="A value of P2 at which a point is solved exactly on the curve "
        "(repeatable).", callback=lambda v: [finite(x) for x in v or []])] = None,
    stop_at_current: Annotated[bool, typer.Option(
        "--stop-at-current", help="The start branch and the curve stop where the coil "
        "current reaches 0 (default: only the gap limits stop them, a fold usually lies "
        "beyond).")] = False,
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    json_out: JsonOpt = False,
    out: OutOpt = None,
) -> None:
    """The fold of cycles (LPC), period doubling (PD) or Neimark-Sacker bifurcation (NS)
    continued in two parameters, with its codimension-two points; writes CSV, netCDF and
    a figure."""
    check_output_path(out)
    x, y = _pair(params_)
    bounds = _ranges(range_)
    user = str(model).endswith(".py")
    if user:
        refuse_given({"stop_at_current": "--stop-at-current", "config": "--config",
                      "preset": "--preset"}, f"applies to the maglev models only; a user "
                      f"model ({model}) takes its values from --set/--at")
    if restart is not None:
        if label is None:
            raise UserError("--restart FILE and --label LABEL go together (e.g. --restart "
                            "branch.nc --label LPC1)")
        refuse_given({"start": "--from", "stop": "--to", "ntst": "--ntst", "ncol": "--ncol"},
                     "a restart searches no Hopf point and keeps the saved mesh; leave this "
                     "option out")
        if not given("model") and not user:
            from maglev_match import api
            from maglev_match.cli.restart import restart_error_context

            with restart_error_context():
                model = api.saved_model(restart) or model
    params, overrides = model_inputs(model, preset, config, set_,
                                     default_params=restart is None)
    from maglev_match import api
    from maglev_match.cli.restart import restart_error_context

    with progress_report("cycle-curve") as prog, api_options(CYCLE_CURVE_OPTIONS), \
            restart_error_context():
        st = api.cycle_curve(
            params, kind, x, y, model=model, at=at_values(at), bounds=bounds, label=label,
            restart=restart, start=start, stop=stop,
            ntst=ntst if restart is None else None, ncol=ncol if restart is None else None,
            max_steps=max_steps, marks=tuple(mark or ()),
            **({} if user else {"ignore_current": not stop_at_current}),
            stage=prog.stage, **overrides)
    files: list[Path] = []
    if out is not None or not json_out:
        with progress_report("cycle-curve") as prog:
            prog.stage("writing the curve files and the figure ...")
            files = _write_outputs(st, out)
    if json_out:
        result = st.as_json()
        result["files"] = [str(f) for f in files]
        emit_json(result)
    else:
        _print_text(st)
        for f in files:
            console.print(f"wrote {f}", highlight=False)
    if not st.curve.points:
        print_error(f"the {st.kind} curve could not start: {'; '.join(st.warnings)}")
        raise typer.Exit(1)


def _print_text(st) -> None:
    cv = st.curve
    start = st.restart_of or f"{st.start_label} of the branch along {st.x}"
    console.print(f"{st.kind} curve of cycles in ({st.x}, {st.y}), model {st.model}, from "
                  f"{start}: {len(cv.points)} points; {cv.message or cv.stopped_reason}",
                  highlight=False, markup=False)
    rows = st.rows()
    step = max(1, len(rows) // 15)
    shown = rows[::step] + ([rows[-1]] if rows and (len(rows) - 1) % step else [])
    ns = st.kind == "NS"  # the critical pair's kappa = cos theta as one more column
    pd = st.kind == "PD"  # the flip coefficient c (c > 0 supercritical) as one more
    head = f"  {st.x:>14}  {st.y:>14}  {'T (s)':>10}  {'amplitude':>10}  {'max|mu|':>9}  " \
        + (f"{'kappa':>10}  {'ns coefficient':>14}  " if ns else "") \
        + (f"{'flip c':>11}  " if pd else "") + "kind"
    console.print(head, highlight=False, markup=False)
    for r in shown:
        console.print(f"  {r[st.x]:>14.8g}  {r[st.y]:>14.8g}  {r['period']:>10.6g}  "
                      f"{r['amplitude']:>10.4g}  {r['max_abs_multiplier']:>9.4g}  "
                      + (f"{r['kappa']:>10.6f}  {r['ns_coefficient']:>14.4g}  " if ns
                         else "")
                      + (f"{r['flip_coefficient']:>11.4g}  " if pd else "") + r["kind"],
                      highlight=False, markup=False)
    for s in st.special_rows():
        console.print(f"  {s['label']}: {s['type']} at {st.x} = {s[st.x]:.10g}, {st.y} = "
                      f"{s[st.y]:.10g} ({s['located']})", highlight=False, markup=False)
    if not cv.ok:
        console.print(f"  the curve stopped early: {cv.stopped_reason}", highlight=False,
                      markup=False)
    print_warnings(st.warnings)


def _write_outputs(st, out) -> list[Path]:
    from maglev_match.core.io import atomic_write_netcdf

    folder, stem = output_target(out, "cycle-curve",
                                 f"cycle_curve_{st.model}_{st.kind}_{st.x}_{st.y}")
    files = [folder / f"{stem}.csv", folder / f"{stem}_special_points.csv"]
    write_csv(files[0], st.rows(), st.x)
    write_csv(files[1], st.special_rows(), st.x)
    if st.curve.points:
        nc = folder / f"{stem}.nc"
        atomic_write_netcdf(nc, st.to_xarray())
        files.append(nc)
    files += st.plot(folder / f"{stem}.png")
    return files
