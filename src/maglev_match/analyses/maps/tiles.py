"""A map computed tile by tile and stored: :func:`compute_tile` (rows of the paper's index
and of the simulated critical disturbances, combined into the headline index),
:func:`run_map` (every tile through the package's job runner,
:mod:`maglev_match.core.jobs`: here or on Dask, checkpointed, resumable),
:func:`assemble`, the dataset of a map with its units, codes and self-check
(:func:`map_dataset`), its warnings (:func:`map_warnings`) and the Hopf curve continued in
the map's plane."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match.analyses.maps.check import SPOT_CHECK_FRACTION, SPOT_CHECK_MAX, spot_check
from maglev_match.analyses.maps.rows import compute_row
from maglev_match.analyses.maps.simulated import simulate_rows
from maglev_match.analyses.maps.spec import (
    BASIS_CODES,
    CASE_CODES,
    MAP_VARIABLES,
    REASON_CODES,
    MapSpec,
    simulation_settings,
)
from maglev_match.core import checkpoint as checkpoint_mod
from maglev_match.core.jobs import Job, run_job
from maglev_match.core.options import CollocationMesh
from maglev_match.core.params import make_params

__all__ = ["compute_tile", "run_map", "assemble", "map_dataset", "map_warnings"]


def compute_tile(spec: MapSpec, rows: tuple[int, int]) -> dict[str, np.ndarray]:
    """Rows [a, b) of the map stacked: the arrays of :data:`MAP_VARIABLES`, shape
    (b - a, nx). The paper's index by :func:`compute_row`; with ``spec.simulate`` the
    critical disturbances by :func:`simulate_rows` and the headline index
    chi = min(chi_paper, chi_simulation)."""
    paper = [compute_row(spec, r) for r in range(*rows)]
    nx = spec.x.count
    sim = (simulate_rows(spec, rows, paper) if spec.simulate
           else [{"h_up": np.full(nx, np.nan), "h_down": np.full(nx, np.nan),
                  "reason": np.zeros(nx, np.int8)} for _ in paper])
    out = [_combine(pr, sr, spec.simulate) for pr, sr in zip(paper, sim, strict=True)]
    return {k: np.stack([o[k] for o in out]) for k in MAP_VARIABLES}


def _combine(pr: dict[str, np.ndarray], sr: dict[str, np.ndarray], simulate: bool
             ) -> dict[str, np.ndarray]:
    """The map's variables of one row from the paper's row and the simulated sizes:
    index variables NaN at unstable points and where a part is unresolved."""
    stable = np.asarray(pr["stable"], bool)
    w0 = pr["w0"]
    paper_ok = np.asarray(pr["resolved"], bool)
    h = np.where(stable, pr["h"], np.nan)
    chi_paper = h / w0
    h_sim = np.minimum(sr["h_up"], sr["h_down"])  # NaN if either is NaN
    chi_sim = np.where(stable, h_sim / w0, np.nan)
    sim_ok = ~stable | np.isfinite(h_sim) if simulate else np.ones_like(stable)
    resolved = paper_ok & sim_ok
    reason = np.where(pr["reason"] != 0, pr["reason"], sr["reason"]).astype(np.int8)
    if simulate:
        chi = np.fmin(chi_paper, chi_sim)  # NaN only if both are
        chi = np.where(resolved & stable, chi, np.nan)
        basis = np.where(stable & resolved & (chi_sim < chi_paper), BASIS_CODES["simulation"],
                         BASIS_CODES["paper"])
    else:
        chi = np.where(paper_ok, chi_paper, np.nan)
        basis = np.full(stable.shape, BASIS_CODES["paper"])
    return {
        "chi": chi, "chi_paper": chi_paper, "chi_simulation": chi_sim, "h": h,
        "h_simulation_up": np.where(stable, sr["h_up"], np.nan),
        "h_simulation_down": np.where(stable, sr["h_down"], np.nan),
        "chi_basis": basis.astype(np.int8), "w0": w0, "stable": stable,
        "max_real_part": pr["max_real_part"], "hopf_distance": pr["hopf_distance"],
        "case": pr["case"], "omega1_point": pr["omega1_point"],
        "sigma_point": pr["sigma_point"], "current_reverses": pr["current_reverses"],
        "resolved": resolved, "reason": reason, "hopf_x": pr["hopf_x"],
    }


def run_map(
    spec: MapSpec,
    checkpoint: Path | None,
    *,
    resume: bool = False,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    max_tiles: int | None = None,
    log: Path | None = None,
    echo_dask: bool = False,
) -> dict[str, np.ndarray]:
    """Compute the map tile by tile, here or on Dask (the package's job runner,
    :func:`maglev_match.core.jobs.run_job`), checkpointing every finished tile.

    Parameters
    ----------
    checkpoint : folder for the tiles (created); with ``resume`` its tiles are reused.
        None: nothing is kept (the tiles are computed in memory here, or through a
        temporary folder on Dask).
        The folder is locked for the duration of the run (a second run on it raises
        :class:`~maglev_match.core.checkpoint.CheckpointLocked`); tiles of another map or
        unreadable tiles are named in a warning and recomputed.
    scheduler : address of an existing Dask scheduler (tcp://host:port); default a local
        cluster with ``workers`` processes (default: all cores), or no cluster at all when
        ``workers == 0`` (compute in this process).
    max_tiles : compute at most this many new tiles, then stop (for tests of resuming).
    log : file that receives Dask's own messages (its logging and warnings: a port in use,
        workers killed at shutdown) instead of the terminal; created only when there is
        one (None: dropped). echo_dask : show them on the terminal too (``--debug``).
    Returns the assembled arrays, shape (ny, nx); raises RuntimeError when tiles are missing
    and :class:`~maglev_match.core.checkpoint.MapStopped` (with the resume hint) on Ctrl-C or a
    lost scheduler.
    """
    spec.validate()
    CollocationMesh(spec.ntst, spec.ncol, spec.max_steps)  # raises ParameterError
    job = Job(pieces=spec.tiles, compute=compute_tile, args_of=lambda rows: (spec, rows),
              store=lambda folder: checkpoint_mod.tile_checkpoint(
                  folder, spec.key(), MAP_VARIABLES, spec.x.count))
    out = run_job(job, None if checkpoint is None else Path(checkpoint), resume=resume,
                  scheduler=scheduler, workers=workers, progress=progress, limit=max_tiles,
                  log=log, echo_dask=echo_dask,
                  finish=lambda store: assemble(spec, store.folder))
    if isinstance(out, list):  # computed in memory: the tiles in order
        return {k: np.concatenate([p[k] for p in out], axis=0) for k in out[0]}
    return out


def assemble(spec: MapSpec, checkpoint: Path) -> dict[str, np.ndarray]:
    """Stack the checkpointed tiles into (ny, nx) arrays (each tile checked first)."""
    key = spec.key()
    missing = [t for t in spec.tiles
               if not checkpoint_mod.check_tile(checkpoint, t, key, MAP_VARIABLES,
                                                spec.x.count).ok]
    if missing:
        raise RuntimeError(f"{len(missing)} of {len(spec.tiles)} tiles not computed yet "
                           f"(checkpoint {checkpoint}); run again with --resume")
    parts = [checkpoint_mod.load_tile(checkpoint, t) for t in spec.tiles]
    return {k: np.concatenate([p[k] for p in parts], axis=0) for k in parts[0]}


def map_warnings(ds) -> list[str]:
    """Every warning of a map dataset: the spot check's and the unresolved points by
    reason."""
    out = list(json.loads(ds.attrs.get("warnings", "[]")))
    if "reason" in ds:
        codes, counts = np.unique(ds["reason"].values, return_counts=True)
        for c, k in zip(codes, counts, strict=True):
            if c != 0:
                out.append(f"{k} unresolved point(s): {REASON_CODES.get(int(c), str(c))}")
    return out


# units and long names of the map's variables (``chi`` depends on the simulation)
_VARIABLE_DOCS: dict[str, tuple[str, str]] = {
    "chi_paper": ("1", "matching index by the paper's definition, h / w0 (NaN where unstable "
                       "or unresolved)"),
    "chi_simulation": ("1", "h_simulation / w0 with h_simulation the smaller simulated "
                            "critical disturbance of the two directions"),
    "h": ("m", "basin size by the paper's definition: the unstable cycle's largest gap "
               "deviation, or the gap range"),
    "h_simulation_up": ("m", "simulated critical beam-deflection disturbance, beam up "
                             "(x5(0) < 0), physical limits on"),
    "h_simulation_down": ("m", "simulated critical beam-deflection disturbance, beam down "
                               "(x5(0) > 0), physical limits on"),
    "chi_basis": ("code", "which part decided chi (codes in the basis_codes attribute)"),
    "w0": ("m", "static beam deflection under one levitation unit"),
    "stable": ("bool", "equilibrium stable (1) or unstable (0)"),
    "max_real_part": ("1/s", "largest real part of the eigenvalues of the equilibrium"),
    "case": ("code", "case that decided h (codes in the case_codes attribute)"),
    "omega1_point": ("rad/s", "beam first modal circular frequency at the grid point"),
    "sigma_point": ("1/kg", "force gain coefficient at the grid point"),
    "current_reverses": ("bool", "coil current on the deciding cycle would reverse (1) or "
                                 "not (0)"),
    "resolved": ("bool", "point resolved (1), or a part of its index could not be computed "
                         "(0; the reason in 'reason')"),
    "reason": ("code", "why the point is unresolved (0: resolved; codes in the reason_codes "
                       "attribute)"),
}


def map_dataset(spec: MapSpec, data: dict[str, np.ndarray], *, check: bool = True,
                seed: int = 0, budget: float | None = None, hopf_curve: bool = True,
                fraction: float = SPOT_CHECK_FRACTION, max_points: int = SPOT_CHECK_MAX):
    """The map as an xarray Dataset over coordinates named after the swept parameters.

    Variables: ``chi`` (the headline index min(chi_paper, chi_simulation), or chi_paper
    when the map was computed without the simulation: the attribute ``index_definition``
    says which), ``chi_paper``, ``chi_simulation``, ``h``, ``h_simulation_up``,
    ``h_simulation_down`` (m), ``chi_basis``, ``w0``, ``stable``, ``max_real_part``,
    ``hopf_distance``, ``case``, ``omega1_point``, ``sigma_point``, ``current_reverses``,
    ``resolved``, ``reason``, ``hopf_x`` (the Hopf points of each row, over the dimension
    ``hopf``) and, with ``hopf_curve`` when both axes are parameters of model A, the Hopf
    curve continued in the map's plane (``hopf_curve_x``, ``hopf_curve_y``,
    ``hopf_curve_l1`` over ``hopf_curve_point``, branches separated by NaN;
    :func:`maglev_match.dynamics.hopf_curve.hopf_curves_from_scans` inside the map's
    ranges). Index variables are NaN at unstable points (``stable`` = 0) and at
    unresolved ones (``resolved`` = 0, ``reason`` a code of ``reason_codes``).

    With ``check`` (default) a seeded sample of points (``fraction`` of them, at most
    ``max_points``) is recomputed point-wise (:func:`spot_check`, within ``budget``
    seconds) and the result stored in the attributes ``spot_check_*`` and ``warnings`` (a
    JSON list)."""
    import xarray as xr

    from maglev_match.core.params import PARAMETER_DOCS

    data = dict(data)
    dims = (spec.y.name, spec.x.name)
    docs = dict(_VARIABLE_DOCS)
    x_unit = PARAMETER_DOCS.get(spec.x.name, ("",))[0] or "1"
    docs["hopf_distance"] = (x_unit, "distance to the nearest Hopf point along the row "
                                     f"(in {spec.x.name})")
    if spec.simulate:
        definition = ("chi = min(chi_paper, chi_simulation): the headline index, the one the "
                      "reading of 'maglev-match index' uses")
        docs["chi"] = ("1", "headline matching index min(chi_paper, chi_simulation) (NaN "
                            "where unstable or unresolved)")
        sim_text = (f"critical disturbances by simulation with the physical limits on, both "
                    f"directions, bracketed to {simulation_settings().tol * 1e3:g} mm (the "
                    "point-wise search's tolerance)")
    else:
        definition = ("chi = chi_paper: the paper's definition only (map computed without "
                      "the simulation, --no-simulation)")
        docs["chi"] = ("1", "matching index by the paper's definition, h / w0 (map without "
                            "simulation; NaN where unstable or unresolved)")
        sim_text = "not run (--no-simulation): chi_simulation and h_simulation_* are NaN"
    attrs: dict[str, Any] = {
        "title": "maglev-match design map",
        "index_definition": definition,
        "simulation": sim_text,
        "simulation_tolerance": simulation_settings().tol if spec.simulate else math.nan,
        "case_codes": json.dumps(CASE_CODES),
        "basis_codes": json.dumps(BASIS_CODES),
        "reason_codes": json.dumps({str(k): v for k, v in REASON_CODES.items()}),
        "unstable_points": "index variables are NaN where the equilibrium is unstable "
                           "(stable = 0); the paper assigns chi = 0 there",
        "spec": spec.key(),
    }
    if check:
        attrs.update(spot_check(spec, data, seed=seed, budget=budget, fraction=fraction,
                                max_points=max_points))
    else:
        attrs["warnings"] = json.dumps(["no spot check was run"])
    variables = {}
    for k in MAP_VARIABLES:
        if k == "hopf_x":
            continue
        unit, long_name = docs.get(k, ("", k))
        variables[k] = (dims, data[k], {"units": unit, "long_name": long_name})
    hx = np.asarray(data["hopf_x"], float)
    width = max(1, int(np.max(np.sum(np.isfinite(hx), axis=1))) if hx.size else 1)
    variables["hopf_x"] = ((spec.y.name, "hopf"), hx[:, :width], {
        "units": x_unit, "long_name": f"Hopf points of each row ({spec.x.name} values inside "
        "the grid), solved on the row's path; NaN after the last"})
    coords = {
        spec.x.name: (spec.x.name, spec.x.values,
                      {"units": PARAMETER_DOCS.get(spec.x.name, ("",))[0]}),
        spec.y.name: (spec.y.name, spec.y.values,
                      {"units": PARAMETER_DOCS.get(spec.y.name, ("",))[0]}),
        "hopf": ("hopf", np.arange(width), {"units": "1", "long_name": "Hopf point number"}),
    }
    if hopf_curve:
        curve, note = _hopf_curve_in_plane(spec, hx)
        attrs["hopf_curve"] = note
        if curve is not None:
            y_unit = PARAMETER_DOCS.get(spec.y.name, ("",))[0] or "1"
            for name, col, unit, what in (
                    ("hopf_curve_x", 0, x_unit, spec.x.name),
                    ("hopf_curve_y", 1, y_unit, spec.y.name),
                    ("hopf_curve_l1", 2, "1/s", "first Lyapunov coefficient l1")):
                variables[name] = (("hopf_curve_point",), curve[:, col], {
                    "units": unit, "long_name": f"Hopf curve continued in the map's plane: "
                    f"{what} (branches separated by NaN)"})
    ds = xr.Dataset(variables, coords=coords, attrs=attrs)
    for k in ("stable", "current_reverses", "resolved", "reason", "chi_basis", "case"):
        ds[k] = ds[k].astype(np.int8)
    return ds


def _hopf_curve_in_plane(spec: MapSpec, hopf_x: np.ndarray) -> tuple[np.ndarray | None, str]:
    """The Hopf curve in the map's plane by continuation of the Hopf defining system
    (:func:`~maglev_match.dynamics.hopf_curve.hopf_curves_from_scans`), when both axes are
    parameters of model A: rows (x, y, l1) with NaN rows between branches, and a note
    saying how it was computed (or why not)."""
    from maglev_match.dynamics.hopf_curve import hopf_curves_from_scans
    from maglev_match.maglev.unit import PARAM_NAMES, unit_system

    names = (spec.x.name, spec.y.name)
    if not all(n in PARAM_NAMES for n in names):
        return None, ("not continued: the axes are not both parameters of model A (beam or "
                      "vehicle data); hopf_x holds each row's Hopf points, solved on the row")
    rows = np.flatnonzero(np.isfinite(hopf_x).any(axis=1))
    if rows.size == 0:
        return None, "no Hopf point inside the grid"
    # start branches from Hopf scans at the rows where the number of Hopf points changes
    # (a branch enters or leaves), and at the first, middle and last such row
    counts = np.sum(np.isfinite(hopf_x), axis=1)
    picks = {rows[0], rows[-1], rows[rows.size // 2]}
    picks |= {int(r) for r in np.flatnonzero(np.diff(counts) != 0) + 1 if counts[r] > 0}
    picks = sorted(picks)[:8]
    system = unit_system(make_params(spec.base))
    bounds = {spec.x.name: (spec.x.start, spec.x.stop), spec.y.name: (spec.y.start, spec.y.stop)}
    try:
        curves, _ = hopf_curves_from_scans(system, names, bounds,
                                           [float(spec.y.values[r]) for r in picks])
    except Exception as exc:  # noqa: BLE001 - a failed curve is reported, not raised
        return None, f"the continuation failed ({type(exc).__name__}: {exc})"
    parts = []
    for c in curves:
        v = c.values()
        if len(v):
            parts.append(np.column_stack([v, c.l1()]))
            parts.append(np.full((1, 3), np.nan))
    if not parts:
        return None, "the continuation gave no points"
    stalled = [c.message for c in curves if not c.converged]
    note = (f"{len(curves)} branch(es) continued by pseudo-arclength on the Hopf defining "
            "system inside the map's ranges")
    if stalled:
        note += "; stalled: " + "; ".join(stalled)
    return np.concatenate(parts[:-1]), note
