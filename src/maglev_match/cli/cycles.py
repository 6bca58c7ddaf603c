"""`maglev-match cycles`: periodic orbits born at Hopf points, continued in one parameter
(paper Fig. 5): max/min gap deviation, period, Floquet stability, folds and limit contacts.
Options parsed here, the computation in :mod:`maglev_match.api.cycles` (maglev models, user
model files, restarts of a saved branch), the answer printed and saved here."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    PARAM_HELP,
    SCAN_MAX,
    ConfigOpt,
    JsonOpt,
    ModelOpt,
    OutOpt,
    PresetOpt,
    SetOpt,
    UserError,
    api_options,
    bounded,
    check_output_path,
    console,
    emit_json,
    finite,
    given,
    model_inputs,
    ncol_option,
    ntst_option,
    output_target,
    preload,
    print_error,
    progress_report,
    refuse_given,
    set_items,
    steps_option,
)
from maglev_match.cli.cycle_tables import at_values, print_summary, print_user_branch, write_csv
from maglev_match.core.params import ParameterError

AtOpt = Annotated[
    list[str] | None,
    typer.Option("--at", help="Fix another parameter, NAME=VALUE (repeatable), e.g. "
                 "--at sigma=4e-4. Applied after --preset/--config/--set."),
]

#: API keyword -> option, for `cycles`
CYCLES_OPTIONS = {"param": "--param", "at": "--at", "start": "--from", "stop": "--to",
                  "start/stop": "--from/--to", "all_hopf": "--all", "n_scan": "--scan",
                  "ntst": "--ntst", "ncol": "--ncol", "max_steps": "--max-steps",
                  "ignore_current": "--ignore-current", "model": "--model",
                  "config": "--config", "restart": "--restart", "label": "--label",
                  "restart/label": "--restart"}
#: Options of `cycles` that only steer the Hopf search a restart does not do.
HOPF_SEARCH_OPTIONS = {"start": "--from", "stop": "--to", "all_hopf": "--all", "n_scan": "--scan"}


@app.command("cycles")
def cycles_command(
    param: Annotated[str, typer.Option("--param", help=PARAM_HELP)] = "omega1",
    at: AtOpt = None,
    start: Annotated[float | None, typer.Option(
        "--from", help="Search Hopf points from this value (default: design value / 4).",
        callback=finite)] = None,
    stop: Annotated[float | None, typer.Option(
        "--to", help="... up to this value (default: design value x 4).",
        callback=finite)] = None,
    all_hopf: Annotated[bool, typer.Option(
        "--all", help="Continue from every Hopf point in the range (default: the one "
        "nearest the design value).")] = False,
    n_scan: Annotated[int, typer.Option(
        "--scan", help="Sampling of the equilibrium branch searched for Hopf points (steps "
        "at most 1/scan of the range).", callback=bounded(3, SCAN_MAX, integer=True))] = 100,
    ntst: Annotated[int, typer.Option("--ntst", help="Mesh intervals.",
                                      callback=ntst_option)] = 80,
    ncol: Annotated[int, typer.Option("--ncol", help="Collocation points (2-7).",
                                      callback=ncol_option)] = 4,
    max_steps: Annotated[int, typer.Option("--max-steps", help="Continuation steps.",
                                           callback=steps_option)] = 300,
    ignore_current: Annotated[bool, typer.Option(
        "--ignore-current", help="Do not stop where the coil current reaches 0 (only the "
        "gap limits stop the branch).")] = False,
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    json_out: JsonOpt = False,
    out: OutOpt = None,
    restart: Annotated[Path | None, typer.Option(
        "--restart", help="Continue from a point of a branch saved by --out (netCDF) instead "
        "of from a Hopf point: no Hopf search (--from/--to/--all/--scan are refused), the "
        "saved model, mesh and parameter values (give no --preset/--config/--set/--at, or the "
        "saved ones). With another --param the saved cycle is continued in that "
        "parameter.")] = None,
    label: Annotated[str | None, typer.Option(
        "--label", help="With --restart: the point to continue from, P<k> for the k-th "
        "branch point or a special point's label (LPC1, PD1, ...).")] = None,
) -> None:
    """Cycles born at Hopf points, continued in --param until a physical limit (Fig. 5)."""
    check_output_path(out)
    if not 2 <= ncol <= 7:
        raise ParameterError("--ncol", ncol, "must be between 2 and 7")
    if ntst < 4:
        raise ParameterError("--ntst", ntst, "must be at least 4")
    if n_scan < 3:
        raise ParameterError("--scan", n_scan, "must be at least 3")
    user = str(model).endswith(".py")
    restarting = restart is not None or label is not None
    if user:  # a user model file: no maglev limits or read-outs
        refuse_given({"ignore_current": "--ignore-current", "config": "--config",
                      "preset": "--preset"},
                     f"applies to the maglev models only; a user model ({model}) has no coil "
                     "current limit and takes its values from --set/--at")
    if restarting:
        if restart is None or label is None:
            raise UserError("--restart FILE and --label LABEL go together (e.g. --restart "
                            "branch.nc --label P12)")
        refuse_given(HOPF_SEARCH_OPTIONS, "a restart searches no Hopf point: it continues the "
                     "saved branch from --label; leave this option out")
        if not given("model") and not user:  # the model the file was saved for
            from maglev_match import api
            from maglev_match.cli.restart import restart_error_context

            with restart_error_context():
                model = api.saved_model(restart) or model
    params, overrides = model_inputs(model, preset, config, set_,
                                     default_params=not restarting)
    if restarting and params is not None and set_:
        # (checked above) the --set values go as overrides, so that the API can tell a
        # value given for the parameter the saved branch is continued in
        overrides = {n: float(v) for n, v in set_items(set_).items()}
        params, _ = model_inputs(model, preset, config, None, default_params=False)
    at_vals = at_values(at)
    if not user and (out is not None or not json_out):  # files at the end: load writers now
        preload("maglev_match.plots.cycles", "maglev_match.core.datasets", "xarray",
                "h5netcdf")
    from maglev_match import api
    from maglev_match.cli.restart import restart_error_context

    with progress_report("cycles") as prog, api_options(CYCLES_OPTIONS), \
            restart_error_context():
        def report(step, pt):
            if user:
                return
            prog.update(f"cycles along {param}: step {step}, {param} = {pt.value:.6g}, max "
                        f"gap dev {pt.extrema['gap_deviation'][0] * 1e3:.3f} mm")

        st = api.cycle_study(
            params, param if (given("param") or not restarting) else None, model=model,
            at=at_vals, start=start, stop=stop, all_hopf=all_hopf, n_scan=n_scan,
            ntst=ntst if (given("ntst") or not restarting) else None,
            ncol=ncol if (given("ncol") or not restarting) else None, max_steps=max_steps,
            ignore_current=ignore_current, restart=restart, label=label, stage=prog.stage,
            progress=report, **overrides)
    if user:
        return _user_outputs(st, model, out, json_out)
    result = st.as_json()
    param = st.param
    if json_out:
        if out is not None:
            result["files"] = [str(f) for f in _write_outputs(st, out)]
        emit_json(result)
        return _fail_if_nothing_continued(st)
    # The answer first, the files after: writing the netCDF and the figure costs about a
    # second (xarray, HDF5 and two renderings), which the reader need not wait for.
    first = None
    if st.restart is not None:
        br = st.branches[0]
        header = st.restart.describe() + (f", continued in {param}"
                                          if param != st.restart.param else "")
        first = (f"cycles: {header}; no Hopf search; branch stopped: {br.stopped_reason} "
                 f"after {br.steps} steps")
    print_summary(st.branches, st.chosen, param, [], first_line=first)
    with progress_report("cycles") as prog:
        prog.stage("writing the branch files and the figure ...")
        files = _write_outputs(st, out)
    for f in files:
        console.print(f"wrote {f}")
    _fail_if_nothing_continued(st)


def _write_outputs(st, out) -> list[Path]:
    """The branches as CSV (points and special points), the restartable netCDF of each
    branch and the figure."""
    from maglev_match.api.cycles import branch_label
    from maglev_match.core.io import atomic_write_netcdf

    param = st.param
    restart = st.restart
    stem0 = f"cycles_{st.model}_{param}" + ("_restart" if restart is not None else "")
    folder, stem = output_target(out, "cycles", stem0)
    rows, specials = [], []
    for k, br in enumerate(st.branches):
        extra = ({"restart_of": f"{restart.label} of {restart.path}"} if restart is not None
                 else {"hopf": br.hopf.value})
        for r in st.branch_rows(k):
            rows.append({"branch": branch_label(k), **extra, **r})
        for r in st.special_rows(k):
            specials.append({"branch": branch_label(k), **r})
    write_csv(folder / f"{stem}.csv", rows, param)
    write_csv(folder / f"{stem}_special_points.csv", specials, param)
    files = [folder / f"{stem}.csv", folder / f"{stem}_special_points.csv"]
    for k, br in enumerate(st.branches):
        if not br.points:
            continue
        nc = folder / (f"{stem}.nc" if k == 0 else f"{stem}_{k}.nc")
        atomic_write_netcdf(nc, st.branch_dataset(k))
        files.append(nc)
    files += st.plot(folder / f"{stem}.png")
    return files


def _user_outputs(st, model: str, out, json_out: bool) -> None:
    """A user model's branches: the CSV of every point and each restartable branch, the
    JSON or the text summary."""
    import csv

    from maglev_match.core.io import atomic_open, atomic_write_netcdf

    result = st.as_json()
    param = st.param
    result["model_file"] = str(model)
    if out is not None:
        tail = "_restart" if st.restart is not None else ""
        folder, stem = output_target(out, "cycles", f"cycles_{st.model}_{param}{tail}")
        path = folder / f"{stem}.csv"
        if st.restart is not None:
            allrows = st.branch_rows(0)
        else:
            allrows = [{"branch": k, **r} for k in range(len(st.branches))
                       for r in st.branch_rows(k)]
        with atomic_open(path, "w", newline="") as fh:
            if allrows:
                w = csv.DictWriter(fh, fieldnames=list(allrows[0]))
                w.writeheader()
                w.writerows(allrows)
        result["files"] = [str(path)]
        for k, br in enumerate(st.branches):  # the full branches, restartable (--restart)
            if not br.points:
                continue
            nc = folder / (f"{stem}.nc" if k == 0 else f"{stem}_{k}.nc")
            atomic_write_netcdf(nc, st.branch_dataset(k))
            result["files"].append(str(nc))
    if json_out:
        emit_json(result)
        return _fail_if_nothing_continued(st)
    if st.restart is not None:
        header = st.restart.describe() + (f", continued in {param}"
                                          if param != st.restart.param else "")
        console.print(f"cycles: {header}; no Hopf search", highlight=False, markup=False)
    for h, br in zip(st.chosen, st.branches, strict=True):
        print_user_branch(h, br, param, restarted=st.restart is not None)
    for f in result.get("files", []):
        console.print(f"wrote {f}", highlight=False)
    from maglev_match.cli.common import print_warnings

    print_warnings(st.warnings)
    _fail_if_nothing_continued(st)


def _fail_if_nothing_continued(st) -> None:
    """A restart whose first point does not converge continued nothing: a numerical
    failure, exit code 1 (after the result was printed), never a silent exit 0."""
    rs = st.restart
    if rs is None or st.branches[0].points:
        return
    br = st.branches[0]
    why = "; ".join(br.warnings) or str(br.stopped_reason)
    print_error(f"the restart from {rs.label} of {rs.path} continued nothing: {why} "
                f"(stopped: {br.stopped_reason}); the saved point does not solve the "
                "periodic problem of this model with these values")
    raise typer.Exit(1)
