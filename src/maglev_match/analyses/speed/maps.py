"""Maps at speed: the read-outs of :mod:`maglev_match.analyses.speed.sweep` over a grid of the
speed v and
another parameter (behind ``maglev-match map --x v=START:STOP:COUNT``), row by row on Dask
with checkpoint tiles."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match.analyses.speed.grid import KMH
from maglev_match.analyses.speed.options import SpeedOptions, check_speed_setup
from maglev_match.analyses.speed.point import speed_point
from maglev_match.analyses.speed.sweep import SWEEP_NAMES, run_tiles
from maglev_match.core.params import ParameterError, Params
from maglev_match.maglev.moving import MovingModel

__all__ = ["MAP_SPEED_VARIABLES", "SpeedMapSpec", "parse_speed_axes", "run_speed_map",
           "compute_speed_map_tile"]


# ---------------------------------------------------------------------------------------
#: the delay axis of a map at speed: then the stability of the delayed periodic response
#: (chi(v) is not computed) and the critical delay tau_c(v) per speed
DELAY_AXIS = "tau"
MAP_SPEED_VARIABLES = ("converged", "stable", "largest_multiplier", "daf", "gap_dev_abs_max",
                       "wz", "body_acc_peak", "h", "every_size_returned", "chi")


@dataclass(frozen=True)
class SpeedMapSpec:
    """A map of read-outs at speed over two axes, one of them the speed ``v`` (m/s; km/h on
    the command line): the base parameters, the model, the axes
    (:class:`maglev_match.analyses.maps.Axis`) and the settings. Tiles are rows (fixed y)."""

    base: dict[str, Any]
    model: str
    x: Any
    y: Any
    options: dict[str, Any]

    def key(self) -> str:
        d = {"kind": "speed-map", "base": {k: self.base[k] for k in sorted(self.base)},
             "model": self.model, "x": self.x.__dict__, "y": self.y.__dict__,
             "options": self.options}
        return json.dumps(d, sort_keys=True, default=float)

    @property
    def tiles(self) -> list[tuple[int, int]]:
        return [(i, i + 1) for i in range(self.y.count)]

    @property
    def tau_max(self) -> float | None:
        """The longest delay of a map over the delay ``tau`` (s; one discretisation sized
        for it serves every point), None without a delay axis."""
        for ax in (self.x, self.y):
            if ax.name == DELAY_AXIS:
                return float(np.max(ax.values))
        return None

    def point(self, xv: float, yv: float) -> tuple[Params, float]:
        """(parameters, speed in m/s) of a grid point."""
        from maglev_match.core.params import make_params

        values = dict(self.base)
        v = None
        for ax, val in ((self.x, xv), (self.y, yv)):
            if ax.name == "v":
                v = float(val)
            else:
                values[ax.name] = float(val)
        return make_params(values), float(v)  # type: ignore[arg-type]


def parse_speed_axes(params: Params, model: str, x: str, y: str,
                     options: SpeedOptions) -> SpeedMapSpec:
    """Both axes of a map with the speed on one of them: ``v=START:STOP:COUNT`` in km/h (0 <=
    START < STOP), the other ``NAME=START:STOP:COUNT`` as for ``map``; every grid point is
    validated (parameters and speed) before any work."""
    from maglev_match.analyses.maps.spec import Axis, parse_axis

    axes = []
    for text, option in ((x, "--x"), (y, "--y")):
        name = text.split("=", 1)[0].strip()
        if name != "v":
            axes.append(parse_axis(text, option))
            continue
        parts = text.split("=", 1)[1].split(":")
        try:
            a, b, c = float(parts[0]), float(parts[1]), int(parts[2])
        except (ValueError, IndexError):
            raise ParameterError(option, text, "expected v=START:STOP:COUNT (km/h)") from None
        if not (math.isfinite(a) and math.isfinite(b)) or not 0 <= a < b:
            raise ParameterError(option, text, "the speed range must satisfy 0 <= START < STOP "
                                 "(km/h)")
        if c < 2:
            raise ParameterError(option, text, "COUNT must be at least 2")
        axes.append(Axis("v", a * KMH, b * KMH, c))
    ax, ay = axes
    if ax.name == ay.name:
        raise ParameterError("--y", y, "the two axes must be different parameters")
    spec = SpeedMapSpec(base=params.as_input_dict(), model=MovingModel(model).value, x=ax,
                        y=ay, options=options.key())
    if spec.x.count * spec.y.count > 100_000:
        raise ParameterError("--x", x, "the grid has more than 100000 points")
    for yv in ay.values:
        for xv in ax.values:
            p, v = spec.point(xv, yv)
            check_speed_setup(p, model, [v], options.spans)
    return spec


def compute_speed_map_tile(spec: SpeedMapSpec, rows: tuple[int, int]
                           ) -> dict[str, np.ndarray]:
    """Rows rows[0]..rows[1]-1 of a speed map: (rows, nx) arrays of
    :data:`MAP_SPEED_VARIABLES`."""
    opts = SpeedOptions(**spec.options)
    out = {k: np.full((rows[1] - rows[0], spec.x.count), np.nan) for k in MAP_SPEED_VARIABLES}
    tau_max = spec.tau_max
    for r in range(*rows):
        for c, xv in enumerate(spec.x.values):
            p, v = spec.point(xv, spec.y.values[r])
            pt = speed_point(p, spec.model, v, opts,
                             tau_max=tau_max if tau_max and p.tau > 0 else None)
            for k in MAP_SPEED_VARIABLES:
                val = getattr(pt, k)
                out[k][r - rows[0], c] = (np.nan if val is None else float(val))
    return out


def run_speed_map(spec: SpeedMapSpec, checkpoint: Path | None = None, *, resume: bool = False,
                  scheduler: str | None = None, workers: int | None = 0,
                  progress: Callable[[int, int], None] | None = None,
                  stage: Callable[[str], None] | None = None):
    """The speed map as an :class:`xarray.Dataset` over (y, x), computed row by row here or
    on Dask with checkpoint tiles (:func:`run_tiles`); ``stage`` is told when the
    critical-delay solves that follow the tiles start, one line per speed."""
    import xarray as xr

    from maglev_match.core.datasets import annotate
    from maglev_match.core.params import PARAMETER_DOCS

    tiles = run_tiles(spec, compute_speed_map_tile, checkpoint, MAP_SPEED_VARIABLES,
                       spec.x.count, resume=resume, scheduler=scheduler, workers=workers,
                       progress=progress)
    data = {k: np.concatenate([t[k] for t in tiles], axis=0) for k in MAP_SPEED_VARIABLES}
    dims = (spec.y.name, spec.x.name)
    units = {"converged": "1", "stable": "1", "largest_multiplier": "1", "daf": "1",
             "gap_dev_abs_max": "m", "wz": "1", "body_acc_peak": "m/s^2", "h": "m",
             "every_size_returned": "1", "chi": "1", "v": "m/s"}
    names = {"converged": SWEEP_NAMES["converged"], "stable": SWEEP_NAMES["stable"],
             "largest_multiplier": SWEEP_NAMES["largest_multiplier"],
             "daf": SWEEP_NAMES["daf"],
             "gap_dev_abs_max": "largest |gap deviation| over the levitation points",
             "wz": SWEEP_NAMES["wz"], "body_acc_peak": SWEEP_NAMES["body_acc_peak"],
             "h": SWEEP_NAMES["h"],
             "every_size_returned": SWEEP_NAMES["every_size_returned"],
             "chi": SWEEP_NAMES["chi"], "v": "vehicle speed"}

    def coord(ax):
        unit = "m/s" if ax.name == "v" else PARAMETER_DOCS.get(ax.name, ("",))[0]
        return (ax.name, ax.values, {"units": unit})

    ds = xr.Dataset({k: (dims, data[k]) for k in MAP_SPEED_VARIABLES},
                    coords={spec.x.name: coord(spec.x), spec.y.name: coord(spec.y)})
    ds["stable"] = xr.where(np.isfinite(ds["stable"]), ds["stable"], -1).astype(np.int8)
    ds["converged"] = ds["converged"].fillna(0).astype(np.int8)
    ds.attrs.update({"title": "maglev-match map at speed", "model": spec.model,
                     "spec": spec.key()})
    if spec.tau_max is not None:
        _add_critical_delay(ds, spec, units, names, stage)
    from maglev_match.core.params import make_params

    return annotate(ds, make_params(dict(spec.base)), units=units, long_names=names)


def _add_critical_delay(ds, spec: SpeedMapSpec, units: dict, names: dict,
                        stage: Callable[[str], None] | None = None) -> None:
    """The critical delay tau_c(v) at every speed of a map over (v, tau), solved
    (:func:`~maglev_match.analyses.speed.delay.critical_delay_at_speed`) from the grid's
    first crossing of the unit circle in tau (linear in ln max|mu| between rows) or, without
    one, the low-speed limit; 1-D over v, with how each solve ended."""
    from maglev_match.analyses.speed.delay import critical_delay_at_speed
    from maglev_match.core.params import make_params

    if DELAY_AXIS not in ds.dims or "v" not in ds.dims:
        return
    lm = np.log(ds["largest_multiplier"].transpose(DELAY_AXIS, "v").values)
    taus = ds[DELAY_AXIS].values.astype(float)
    base = make_params(dict(spec.base))
    opts = SpeedOptions(**spec.options)
    vals, status, grid = [], [], []
    speeds = ds["v"].values.astype(float)
    for j, v in enumerate(speeds):
        if stage is not None:
            stage(f"solving the critical delay tau_c(v) at {v * 3.6:g} km/h "
                  f"({j + 1} of {speeds.size}) ...")
        col = lm[:, j]
        guess = None
        for k in range(taus.size - 1):
            a, b = col[k], col[k + 1]
            if np.isfinite(a) and np.isfinite(b) and a < 0 <= b:
                guess = float(taus[k] + (taus[k + 1] - taus[k]) * (-a) / (b - a))
                break
        grid.append(np.nan if guess is None else guess)
        cd = critical_delay_at_speed(base.replace(tau=0.0), spec.model, float(v), opts,
                                     guess=guess)
        vals.append(cd.value)
        status.append(cd.status)
    ds["tau_c"] = (("v",), np.array(vals, float))
    ds["tau_c_grid"] = (("v",), np.array(grid, float))
    ds["tau_c"].attrs.update({"units": "s", "long_name": SWEEP_NAMES["tau_c"]})
    ds["tau_c_grid"].attrs.update({"units": "s", "long_name": "first crossing of max|mu| = 1 "
                                   "in tau on the grid (linear in ln max|mu|), the solve's "
                                   "start"})
    ds.attrs["tau_c_status"] = json.dumps(status)
