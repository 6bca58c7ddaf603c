"""What a design map is: its two axes (:class:`Axis`, :func:`parse_axis`), the spec of a map
(:class:`MapSpec`: base parameters, axes, numerical settings, the checks of every grid point
before any work, the fingerprint of its checkpoint tiles), the variables a map stores and
the codes they use (case, basis, reason), and the search settings of the map's simulated
critical disturbances (:func:`simulation_settings`, part of the fingerprint)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from maglev_match.core.params import FIELD_NAMES, ParameterError, Params, make_params

__all__ = ["Axis", "MapSpec", "parse_axis", "simulation_settings", "MAP_VARIABLES",
           "REASON_CODES", "CASE_CODES", "BASIS_CODES", "MAP_MODELS"]

CASE_CODES = {"unstable_equilibrium": 0, "unstable_cycle": 1, "no_cycle_within_limits": 2}
# which part decided the headline index chi (variable ``chi_basis``)
BASIS_CODES = {"paper": 0, "simulation": 1}
# the variables of a tile (each of shape (rows, nx)); ``hopf_x`` holds a row's Hopf points
# (x values) in its first entries, NaN after them
MAP_VARIABLES = ("chi", "chi_paper", "chi_simulation", "h", "h_simulation_up",
                 "h_simulation_down", "chi_basis", "w0", "stable", "max_real_part",
                 "hopf_distance", "case", "omega1_point", "sigma_point", "current_reverses",
                 "resolved", "reason", "hopf_x")
# why a point is unresolved (variable ``reason``; 0 for resolved points)
REASON_FAILED = 1
REASON_MAX_STEPS = 2
REASON_NO_HOPF = 3
REASON_NO_BRANCH = 4
REASON_SIM_UNDECIDED = 5
REASON_SIM_ROUNDS = 6
REASON_CODES = {
    0: "",
    REASON_FAILED: "the cycle continuation failed (Newton or step size) before the point",
    REASON_MAX_STEPS: "the cycle branch reached its step limit before the point",
    REASON_NO_HOPF: "max Re(lambda) changes sign next to the stable stretch without a Hopf "
                    "point, even on a refined scan",
    REASON_NO_BRANCH: "no cycle branch could be started at the Hopf point",
    REASON_SIM_UNDECIDED: "the simulated critical disturbance could not be bracketed: runs "
                          "near it neither collided nor converged within the longest horizon",
    REASON_SIM_ROUNDS: "the simulated critical disturbance search reached its round limit "
                       "without a bracket",
}
#: the maglev models whose map rows this module computes (model A: its rows are written on
#: model A's parameter vector and its limited system)
MAP_MODELS = ("unit",)
#: the beam and vehicle data from which model A's omega1 and sigma derive
BEAM_QUANTITIES = ("L", "EI", "mbar", "l", "k")
# Largest grid accepted (points); beyond it the result arrays alone would not fit.
MAX_POINTS = 4_000_000
# the checkpoint's format: part of every tile's fingerprint, so that tiles written before a
# change of the stored variables are never reused
TILE_FORMAT = 2


@dataclass(frozen=True)
class Axis:
    """One swept parameter: ``count`` values from ``start`` to ``stop`` inclusive."""

    name: str
    start: float
    stop: float
    count: int

    @property
    def values(self) -> np.ndarray:
        return np.linspace(self.start, self.stop, self.count)


def parse_axis(text: str, option: str) -> Axis:
    """'NAME=START:STOP:COUNT' -> Axis, with errors that name the option, value and rule."""
    if "=" not in text:
        raise ParameterError(option, text, "expected NAME=START:STOP:COUNT, e.g. omega1=40:190:100")
    name, rng = (s.strip() for s in text.split("=", 1))
    if name not in FIELD_NAMES or name in ("n_modes",):
        raise ParameterError(option, text, f"unknown parameter '{name}'; sweepable names are: "
                             + ", ".join(n for n in FIELD_NAMES if n != "n_modes"))
    parts = rng.split(":")
    if len(parts) != 3:
        raise ParameterError(option, text, "expected NAME=START:STOP:COUNT with three numbers")
    try:
        start, stop = float(parts[0]), float(parts[1])
        count = int(parts[2])
    except ValueError:
        raise ParameterError(option, text, "START and STOP must be numbers, COUNT a whole number")\
            from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise ParameterError(option, text, "START and STOP must be finite")
    if count < 2:
        raise ParameterError(option, text, "COUNT must be at least 2")
    if not start < stop:
        raise ParameterError(option, text, "the range is empty or reversed: START must be < STOP")
    return Axis(name, start, stop, count)


#: grids up to this many points have every point's parameter set checked before any tile
FULL_CHECK_POINTS = 20_000


@dataclass(frozen=True)
class MapSpec:
    """What to map: base parameters, the two axes and the numerical settings.

    ``simulate`` (default True): also the simulated critical disturbances, so that ``chi``
    is the headline index min(chi_paper, chi_simulation); False: the paper's index only
    (``chi`` = ``chi_paper``, the simulation variables NaN)."""

    base: dict[str, Any]  # Params.as_input_dict() of the base point
    x: Axis
    y: Axis
    rows_per_tile: int = 4
    ntst: int = 30
    ncol: int = 4
    max_steps: int = 300
    simulate: bool = True

    def key(self) -> str:
        """A fingerprint of the spec, stored with checkpoints so a resume can't mix maps
        (it names the stored variables and the simulation's search settings too)."""
        d = {"base": {k: self.base[k] for k in sorted(self.base)}, "x": self.x.__dict__,
             "y": self.y.__dict__, "rows_per_tile": self.rows_per_tile, "ntst": self.ntst,
             "ncol": self.ncol, "max_steps": self.max_steps, "simulate": self.simulate,
             "format": TILE_FORMAT, "variables": list(MAP_VARIABLES)}
        if self.simulate:
            d["simulation"] = simulation_settings().__dict__
        return json.dumps(d, sort_keys=True, default=float)

    def point(self, xv: float, yv: float) -> Params:
        values = dict(self.base)
        values[self.x.name] = float(xv)
        values[self.y.name] = float(yv)
        return make_params(values)

    def validate(self) -> None:
        """Every grid point must be a valid parameter set; the grid must fit in memory."""
        n = self.x.count * self.y.count
        if n > MAX_POINTS:
            raise ParameterError("grid", f"{self.x.count} x {self.y.count}",
                                 f"at most {MAX_POINTS} points fit in memory here")
        if self.x.name == self.y.name:
            raise ParameterError("--y", self.y.name, "must differ from the --x parameter")
        for xv in (self.x.start, self.x.stop):
            for yv in (self.y.start, self.y.stop):
                self.point(xv, yv)  # raises ParameterError naming the field
        for yv, xv in self._points_to_check():
            self.point(xv, yv)
        self._check_axes_move_the_model()
        if "tau" in (self.x.name, self.y.name):  # the delay must be resolvable (its rule)
            from maglev_match.maglev.unit import unit_system

            for xv in (self.x.start, self.x.stop):
                for yv in (self.y.start, self.y.stop):
                    p = self.point(xv, yv)
                    if p.tau > 0:
                        unit_system(p)  # raises ParameterError naming tau and its bound

    def _points_to_check(self):
        """The grid points whose parameter sets :meth:`validate` builds: all of them up to
        :data:`FULL_CHECK_POINTS`; on a larger grid (a 2000 x 2000 map took minutes to
        check point by point, silently) its four edges and every point of a sub-grid of
        at most 100 x 100 values. A parameter's rule is a range of that parameter or of a
        value derived monotonically from two of them (omega1, sigma, w0 from L, EI, mbar),
        so a grid that breaks a rule breaks it on an edge."""
        import numpy as np

        xs, ys = np.asarray(self.x.values), np.asarray(self.y.values)
        if xs.size * ys.size <= FULL_CHECK_POINTS:
            return [(yv, xv) for yv in ys for xv in xs]
        sub_x = xs[np.unique(np.linspace(0, xs.size - 1, min(xs.size, 100)).round().astype(int))]
        sub_y = ys[np.unique(np.linspace(0, ys.size - 1, min(ys.size, 100)).round().astype(int))]
        edges = [(ys[0], xv) for xv in xs] + [(ys[-1], xv) for xv in xs] + \
            [(yv, xs[0]) for yv in ys] + [(yv, xs[-1]) for yv in ys]
        return edges + [(yv, xv) for yv in sub_y for xv in sub_x]

    def _check_axes_move_the_model(self) -> None:
        """Each axis must change the map model's parameters (a model-B quantity such as s
        on a map of model A, or L while omega1 and sigma are set explicitly, would give a
        flat map)."""
        import numpy as np

        from maglev_match.maglev.models import maglev_model

        def vector(xv: float, yv: float) -> np.ndarray:
            # the model's parameters, its delay and its gap limits (a map's simulated part)
            p = self.point(xv, yv)
            return np.concatenate([maglev_model(p, MAP_MODELS[0]).param_vector(),
                                   [p.tau, p.gap_min, p.gap_max]]).astype(float)

        v0 = vector(self.x.start, self.y.start)
        for ax, option, other in ((self.x, "--x", vector(self.x.stop, self.y.start)),
                                  (self.y, "--y", vector(self.x.start, self.y.stop))):
            if np.array_equal(v0, other):
                fixed = sorted(set(self.point(self.x.start, self.y.start).explicit)
                               & {"omega1", "sigma"} - {self.x.name, self.y.name}
                               ) if ax.name in BEAM_QUANTITIES else []
                why = (f"{', '.join(fixed)} set explicitly override it; use a preset that "
                       "derives them from the beam, e.g. turnout-soft" if fixed else
                       "it does not enter this model")
                raise ParameterError(option, ax.name, f"changes no parameter of model "
                                     f"'{MAP_MODELS[0]}' over the map: {why}")

    @property
    def tiles(self) -> list[tuple[int, int]]:
        r = self.rows_per_tile
        return [(a, min(a + r, self.y.count)) for a in range(0, self.y.count, r)]


# runs per batched kernel call. Most calls of a map's rows are far from full (a 20-point
# tile of 4 rows: 715 runs in ~300 calls), and a wider chunk pays for the lanes of the
# runs that finished early while its slowest run goes on: that tile took 11.3 s CPU with
# 32, 10.4 s with 16, 13.4 s with 64 and 16.3 s with 128, the same sizes to the last bit
# (a 100-point row fills its chunks: there 16 and 32 are within the run-to-run spread)
SIM_CHUNK = 16
_SETTINGS: list = []


def simulation_settings():
    """The search settings of the map's critical disturbances
    (:class:`~maglev_match.dynamics.integrate.threshold.ThresholdOptions`): those of the point-wise
    search :func:`maglev_match.analyses.simulation.critical_disturbance` on model A (its
    :attr:`~maglev_match.maglev.models.UnitModel.critical_search`: the tolerance, first
    horizon, horizon doublings and sizes per round, hence the largest size it tries), so
    that the map and the point-wise index agree within the tolerance."""
    if not _SETTINGS:
        from maglev_match.dynamics.integrate.threshold import ThresholdOptions
        from maglev_match.maglev.models import UnitModel

        search = UnitModel.critical_search
        batch = int(search.batch)
        _SETTINGS.append(ThresholdOptions(
            tol=float(search.tol), t_max=float(search.t_max),
            max_extend=int(search.max_extend), cold_sizes=batch,
            top_fraction=batch / (batch + 1), chunk=SIM_CHUNK))
    return _SETTINGS[0]
