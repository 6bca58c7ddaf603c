"""The vehicle at speed over identical spans, swept over speed (`maglev-match speed`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.analyses.speed.grid import KMH, speeds_kmh
from maglev_match.api.inputs import resolve_params
from maglev_match.api.progress import reported
from maglev_match.core.params import Params

if TYPE_CHECKING:  # pragma: no cover
    from maglev_match.analyses.speed.sweep import SpeedSweep

__all__ = ['speed_sweep', 'speed_map', 'ride_reading', 'speeds_kmh', 'KMH',
           'config_irregularity']

#: the folder inside a sweep's checkpoint that keeps its runs over an irregular guideway
IRREGULAR_FOLDER = "irregular"


@reported("speeds")
def speed_sweep(params: Params | str | None = None, *, model: str = "unit",
                speeds: Sequence[float] | None = None,
                kmh: tuple[float, float, float] = (0.0, 150.0, 5.0), critical: bool = True,
                spans: int = 40, workers: int | None = 0, scheduler: str | None = None,
                checkpoint: str | Path | None = None, resume: bool = False,
                progress: Callable[[int, int], None] | None = None,
                config: str | Path | None = None,
                stage: Callable[[str], None] | None = None,
                irregularity: str | None = None, irregular_spans: int = 20,
                critical_delay: bool = False,
                runs_progress: Callable[[int, int], None] | None = None,
                **overrides: Any) -> SpeedSweep:
    """The vehicle at speed over identical spans, swept over speed (`maglev-match speed`).

    At every speed the periodic response (one span passage, found as the fixed point of
    the span map), its multipliers and verdict, the gap deviation and current per
    levitation point, the mid-span deflection and DAF, the car body's peak acceleration and
    Sperling's Wz, the index at speed chi(v) = h(v) / w0 (the span under the vehicle
    suddenly displaced in its first mode, the mean deflection under the vehicle jumping by
    h; the smaller direction at the worst position of the vehicle in the span; the
    standstill index as v -> 0) and the entry disturbance (the span being entered deflected
    before the vehicle reaches it, a second read-out); then the resonance speeds in the
    range and the speeds where the periodic response changes stability, located by solving.
    With `critical` the result also carries the standstill headline index of the same model
    (`standstill`).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    model : str
        `'unit'`, `'vehicle'` or `'force'` (a constant moving force).
    speeds : sequence of float, optional
        The speeds in m/s; without them, `kmh` = (from, to, step) in km/h as on the
        command line (from 0 to 150 by 5 by default; v = 0 gives the standstill values).
    critical : bool
        Compute the index at speed, the entry disturbance and the standstill headline
        (slower).
    spans : int
        Spans a disturbed run may take to return to the periodic response.
    workers, scheduler, checkpoint, resume, progress
        As for [`design_map`][maglev_match.api.maps.design_map]: 0 computes here, n > 0 on a
        local Dask cluster, None one worker per core; `checkpoint` keeps a tile per speed
        (then `resume` reuses them). The runs over an irregular guideway go the same way,
        one task per (speed, seed), each kept in the folder `irregular` inside
        `checkpoint`; `progress` counts them too unless `runs_progress` is given.
    config : str or Path, optional
        A TOML file applied on top of the preset (its `[irregularity]` table, if any, is
        the guideway irregularity unless `irregularity` is given).
    stage : callable, optional
        Called with a line of text once the inputs are checked and the work starts.
    irregularity : str, optional
        A guideway irregularity, `KIND:NAME=VALUE,...` (lengths in m; `sine:wavelength=..,
        amplitude=..`, `joint:step=..`, `settlement:depth=..[,support=J]`,
        `camber:amplitude=..`, `random:class=low|high[,seeds=N,seed0=K,lmin=..,lmax=..,
        waves=..]`; see docs/speed.md). Then at every speed above 0 the vehicle also runs
        over `irregular_spans` spans of that guideway with the limits on, once per seed,
        and the result's `irregular` holds the read-outs (gap deviation, current, ride,
        DAF, the probability of contact with its interval, the linear rms of the unit).
        Without it, the `config` file's `[irregularity]` table if it has one.
    irregular_spans : int
        The length of those runs in spans (the distance of the probability of contact).
    critical_delay : bool
        Also compute at every speed the critical delay of the outer loop tau_c(v): the
        smallest delay at which the periodic response loses stability, solved in tau
        (`SpeedPoint.tau_c`; at v = 0 the vehicle standing at mid-span), and its low-speed
        limit (`tau_c_frozen`). A delay of its own (`tau=...` in the overrides) gives the
        periodic response and multipliers of the delayed model at every speed.
    runs_progress : callable, optional
        Called as `runs_progress(done, total)` before the first run over the irregular
        guideway and after each (default: `progress`).
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    SpeedSweep
        One [`SpeedPoint`][maglev_match.analyses.speed.sweep.SpeedPoint] per speed, the resonance
        speeds
        and the stability changes; `.to_xarray()` and `.plot()` give the netCDF dataset and
        the figure of the command line.
    """
    from maglev_match.analyses.speed.grid import KMH, speeds_kmh
    from maglev_match.analyses.speed.sweep import SpeedOptions, check_speed_setup
    from maglev_match.analyses.speed.sweep import speed_sweep as _speed_sweep

    p = resolve_params(params, config=config, **overrides)
    if speeds is None:
        speeds = list(speeds_kmh(*kmh) * KMH)
    opts = SpeedOptions(critical=critical, spans=spans, critical_delay=critical_delay)
    check_speed_setup(p, model, list(speeds), spans)
    prof = None
    if irregularity is None and config is not None:
        from maglev_match.maglev.irregularity import irregularity_in_config

        irregularity = irregularity_in_config(config)
    if irregularity is not None:
        from maglev_match.analyses.speed.irregular import check_irregular_setup

        prof = check_irregular_setup(p, model, list(speeds), irregularity, irregular_spans,
                                     warmup=_warmup(irregular_spans))
    if stage is not None:
        stage(f"{len(speeds)} speeds, model {model}, "
              f"{'with' if critical else 'without'} chi(v) and the entry disturbance ...")
    if prof is None:
        return _speed_sweep(p, model, list(speeds), opts,
                            checkpoint=None if checkpoint is None else Path(checkpoint),
                            resume=resume, scheduler=scheduler, workers=workers,
                            progress=progress)
    import dataclasses

    from maglev_match.analyses.speed.irregular import irregular_sweep
    from maglev_match.core.jobs import shared_cluster

    # both stages on one cluster: its workers keep their compiled kernels in between
    with shared_cluster(scheduler, workers) as address:
        sweep = _speed_sweep(p, model, list(speeds), opts,
                             checkpoint=None if checkpoint is None else Path(checkpoint),
                             resume=resume, scheduler=address, workers=workers,
                             progress=progress)
        moving = [v for v in speeds if v > 0]
        if stage is not None:
            stage(f"{len(moving)} speeds over the irregular guideway ({prof.describe()}), "
                  f"{len(prof.seed_list)} run(s) of {irregular_spans} spans each per speed, "
                  f"{len(moving) * len(prof.seed_list)} runs ...")
        irr = irregular_sweep(p, model, moving, prof, spans=irregular_spans,
                              warmup=_warmup(irregular_spans),
                              progress=progress if runs_progress is None else runs_progress,
                              checkpoint=None if checkpoint is None
                              else Path(checkpoint) / IRREGULAR_FOLDER,
                              resume=resume, scheduler=address, workers=workers)
    return dataclasses.replace(sweep, irregular=irr)


def _warmup(spans) -> int:
    """The run-in left out of the irregular read-outs: one span, none in a run of one."""
    return 1 if isinstance(spans, int) and spans > 1 else 0


@reported("map at speed")
def speed_map(params: Params | str | None = None, x: str = "v=0:150:16",
              y: str = "L=15:25:5", *, model: str = "unit", workers: int | None = 0,
              scheduler: str | None = None, checkpoint: str | Path | None = None,
              resume: bool = False, progress: Callable[[int, int], None] | None = None,
              config: str | Path | None = None, stage: Callable[[str], None] | None = None,
              **overrides: Any) -> Any:
    """The read-outs at speed over a grid of the speed v (km/h) and another parameter
    (`maglev-match map --x v=START:STOP:COUNT --y NAME=...`): at every grid point the
    periodic response with its stability, DAF, ride index and chi(v). With the delay `tau`
    (s) on the other axis: the stability of the delayed periodic response (largest
    |multiplier|; chi(v) is not computed) and the critical delay tau_c(v) at every speed,
    solved from the grid's first crossing (variables `tau_c`, `tau_c_grid`).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    x, y : str
        The axes as `NAME=START:STOP:COUNT`, one of them the speed `v` in km/h.
    model : str
        `'unit'`, `'vehicle'` or `'force'`.
    workers, scheduler, checkpoint, resume, progress
        As for [`speed_sweep`][maglev_match.api.speed.speed_sweep] (a tile per row).
    config : str or Path, optional
        A TOML file applied on top of the preset (its `[irregularity]` table, if any, is
        the guideway irregularity unless `irregularity` is given).
    stage : callable, optional
        Called with a line of text once the axes are checked and the work starts, and
        (over the delay) before each speed's critical-delay solve, after the tiles.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    xarray.Dataset
        The map (speeds in m/s in the file); `maglev_match.plots.plot(ds)` draws it.
    """
    import tempfile

    from maglev_match.analyses.speed.maps import DELAY_AXIS, parse_speed_axes, run_speed_map
    from maglev_match.analyses.speed.sweep import SpeedOptions

    p = resolve_params(params, config=config, **overrides)
    over_delay = DELAY_AXIS in (a.split("=", 1)[0].strip() for a in (x, y))
    # over the delay: the stability of the delayed periodic response and tau_c(v), no chi(v)
    spec = parse_speed_axes(p, model, x, y, SpeedOptions(critical=not over_delay))
    if stage is not None:
        nx, ny = (a.split("=", 1)[0].strip() for a in (x, y))
        stage(f"map {nx} x {ny} at speed, model {model} ...")
    if checkpoint is None:
        with tempfile.TemporaryDirectory(prefix="maglev-match-speed-map-") as tmp:
            return run_speed_map(spec, Path(tmp) / "tiles", resume=False,
                                 scheduler=scheduler, workers=workers, progress=progress,
                                 stage=stage)
    return run_speed_map(spec, Path(checkpoint), resume=resume, scheduler=scheduler,
                         workers=workers, progress=progress, stage=stage)


def config_irregularity(config: str | Path | None) -> Any:
    """The guideway irregularity of a `--config` TOML file's `[irregularity]` table,
    validated like `--irregularity` (None without a file or a table)."""
    from maglev_match.maglev.irregularity import irregularity_in_config

    return irregularity_in_config(config)


def ride_reading(wz: float) -> str:
    """Sperling's words for a ride index Wz ("just noticeable", ...;
    :func:`maglev_match.analyses.speed.ride.sperling_reading`)."""
    from maglev_match.analyses.speed.ride import sperling_reading

    return sperling_reading(wz)
