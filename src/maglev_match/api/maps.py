"""Design maps of the headline index over two parameters (`maglev-match map`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.api.compat import deprecated
from maglev_match.api.inputs import resolve_params
from maglev_match.api.progress import reported
from maglev_match.core.params import DEFAULT_PRESET, ParameterError, Params, load_params

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

__all__ = ['design_map', 'map_warnings', 'remove_tiles']


def map_axis(axis: Any, field: str) -> str:
    """A map axis as the command line writes it (NAME=START:STOP:COUNT), from that text or
    from the keyword form (name, start, stop, count). Validation (names, counts, order) is
    :func:`maglev_match.analyses.maps.parse_axis`'s."""
    if isinstance(axis, str):
        return axis
    try:
        name, start, stop, count = axis
    except (TypeError, ValueError):
        raise ParameterError(field, axis, "expected (name, start, stop, count), e.g. "
                             '("omega1", 40, 190, 100)') from None
    if isinstance(count, float) and count.is_integer():
        count = int(count)
    if not isinstance(count, int) or isinstance(count, bool):
        raise ParameterError(field, axis, "the count must be a whole number")
    try:
        return f"{name}={float(start)!r}:{float(stop)!r}:{count}"
    except (TypeError, ValueError):
        raise ParameterError(field, axis, "start and stop must be numbers") from None


@reported("map")
def design_map(params: Params | str | None = None,
               x: tuple | str = ("omega1", 40.0, 190.0, 100),
               y: tuple | str = ("sigma", 2e-4, 6e-4, 100), *,
               config: str | Path | None = None, workers: int | None = 0,
               scheduler: str | None = None, checkpoint: str | Path | None = None,
               resume: bool = False, rows_per_tile: int = 4, ntst: int = 30,
               progress: Callable[[int, int], None] | None = None,
               simulate: bool = True, preset: str | None = None,
               log: str | Path | None = None, echo_dask: bool = False,
               check_fraction: float | None = None,
               stage: Callable[[str], None] | None = None, model: str = "unit",
               **overrides: Any) -> xr.Dataset:
    """The headline index chi = min(chi_paper, chi_simulation), its parts and stability
    over a grid of two parameters (`maglev-match map`).

    Parameters
    ----------
    params : Params | str | None
        The base point: a [`Params`][maglev_match.core.params.Params], a preset name or None
        for the default preset.
    x, y : tuple
        The axes, `(name, start, stop, count)`, e.g. `("omega1", 40, 190, 100)`; name is
        any parameter, including the beam data L, EI, mbar, l, k (omega1 and sigma are then
        derived at every point). (The command-line strings `"omega1=40:190:100"` still
        work, with a DeprecationWarning.)
    config : str or Path, optional
        A TOML file applied on top of a preset `params` (`--config`).
    workers : int or None
        0 (default): compute in this process; n > 0: a local Dask cluster of n
        single-threaded worker processes; None: one per core.
    scheduler : str, optional
        Address of an existing Dask scheduler, `tcp://host:port`.
    checkpoint : str or Path, optional
        Folder for finished tiles (then `resume` reuses them); without it the map is
        assembled in memory and nothing is written.
    resume : bool
        Reuse the finished tiles of `checkpoint`.
    rows_per_tile : int
        Rows of the grid per task.
    ntst : int
        Collocation intervals of the cycles.
    progress : callable, optional
        Called as `progress(done_tiles, total_tiles)`.
    simulate : bool
        Simulate the critical disturbances (default), so that chi is the headline index;
        False: the paper's index only (`--no-simulation`; chi is then chi_paper).
    preset : str, optional
        Deprecated: the preset name, now given as `params`.
    log : str or Path, optional
        A file for Dask's own messages (created on the first one; with a checkpoint).
    echo_dask : bool
        Show Dask's messages on the terminal too.
    check_fraction : float, optional
        The share of the map's time its self-check (points recomputed one by one) may take
        (default: the check's own default budget).
    stage : callable, optional
        Called with a line of text when a stage starts (the tiles, the self-check).
    model : str
        The maglev model; maps of the standstill index are computed for model A ("unit")
        and any other model is refused (ParameterError naming ``model``), never ignored.
    **overrides : float
        Parameter values applied on top of the base point (`--set`).

    Returns
    -------
    xarray.Dataset
        Variables chi (the headline index), chi_paper, chi_simulation, h,
        h_simulation_up, h_simulation_down, chi_basis, w0, stable, max_real_part,
        hopf_distance, case, omega1_point, sigma_point, current_reverses, resolved, reason
        over the dimensions (y, x) (index variables NaN where unstable or unresolved), the
        rows' Hopf points hopf_x and, for two model parameters as axes, the continued Hopf
        curve; units and long names, the base parameter set and the package version as
        attributes. Equal, value for value, to the netCDF file `maglev-match map` writes
        for the same grid (see `maglev_match.analyses.maps.map_dataset`);
        `maglev_match.plots.plot(ds)` draws the map figure.
    """
    if isinstance(params, str) and "=" in params:  # design_map("NAME=A:B:N", "NAME=...", p)
        deprecated('design_map("X=A:B:N", "Y=A:B:N", preset)',
                    'design_map(params, x=("X", A, B, N), y=("Y", A, B, N))')
        old_preset = y if isinstance(y, str) and "=" not in y else None
        params, x, y = None, params, x
        preset = preset or old_preset
    if preset is not None:
        if params is not None and not isinstance(params, str):
            pass  # a ready Params wins, as before
        else:
            deprecated("design_map(..., preset=NAME)", "design_map(NAME, ...)")
            params = preset
    from maglev_match.analyses.maps.spec import MAP_MODELS

    if model not in MAP_MODELS:
        raise ParameterError("model", model, "maps of the standstill index are computed for "
                             f"{', '.join(MAP_MODELS)} only (a map with a speed axis "
                             "v=... takes the vehicle)")
    x, y = map_axis(x, "x"), map_axis(y, "y")
    if params is None or isinstance(params, str):
        base = load_params(params or DEFAULT_PRESET, config, dict(overrides))
    else:
        base = resolve_params(params, **overrides)
    from maglev_match.analyses.maps import MapSpec, map_dataset, parse_axis, run_map
    from maglev_match.core.datasets import annotate_map

    ax, ay = parse_axis(x, "x"), parse_axis(y, "y")
    if rows_per_tile < 1:
        raise ParameterError("rows_per_tile", rows_per_tile, "must be at least 1")
    spec = MapSpec(base=base.as_input_dict(), x=ax, y=ay, rows_per_tile=rows_per_tile,
                   ntst=ntst, simulate=simulate)
    if stage is not None and ax.count * ay.count > 20_000:
        stage(f"checking the parameter sets of the {ax.count} x {ay.count} grid ...")
    spec.validate()
    if stage is not None:
        what = "headline index" if simulate else "paper's index only (--no-simulation)"
        stage(f"map {ax.name} x {ay.name}, {what}: {len(spec.tiles)} tiles ...")
    started = time.perf_counter()
    data = run_map(spec, None if checkpoint is None else Path(checkpoint), resume=resume,
                   scheduler=scheduler, workers=workers, progress=progress,
                   log=None if log is None else Path(log), echo_dask=echo_dask)
    elapsed = time.perf_counter() - started
    if stage is not None:
        stage("spot check: recomputing sample points one by one ...")
    if check_fraction is None:
        ds = map_dataset(spec, data)
    else:  # the self-check gets this fraction of the map's time (at least one point)
        ds = map_dataset(spec, data, budget=check_fraction * elapsed)
    return annotate_map(ds, base)


def map_warnings(ds: xr.Dataset) -> list[str]:
    """What a map's own checks found (unresolved points, a failed spot check, stability
    changing without a Hopf point ...), one sentence each."""
    from maglev_match.analyses.maps import map_warnings as _map_warnings

    return _map_warnings(ds)


def remove_tiles(checkpoint: str | Path) -> bool:
    """Remove the checkpoint folder of a finished map (True when it is gone)."""
    from maglev_match.analyses.maps import remove_checkpoint

    return remove_checkpoint(Path(checkpoint))
