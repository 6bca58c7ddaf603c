"""The vehicle at speed over a guideway of identical spans: the periodic response, its
stability from the span map, and what a track-beam designer reads off it at every speed.

Models (:mod:`maglev_match.maglev.moving`): ``unit`` (model A's levitation unit, the
vehicle's k units spread over its length l), ``vehicle`` (model B's six levitation points),
``force`` (a constant point force, the textbook moving-load case).

The subject, one module each (this module re-exports their public names, as the command
line and the documentation import them from here):

* :mod:`~maglev_match.analyses.speed.options`: the numerical settings
  (:class:`SpeedOptions`), the checks before any work, w0;
* :mod:`~maglev_match.analyses.speed.passage`: one span passage (the problem of the
  periodic response, its samples and read-outs);
* :mod:`~maglev_match.analyses.speed.critical`: the critical disturbance at speed;
* :mod:`~maglev_match.analyses.speed.point`: everything at one speed (:class:`SpeedPoint`,
  :func:`speed_point`, the periodic response and its multipliers);
* this module: the sweep over speed.

Sweeps over speed run point by point, here or on Dask like maps, through the package's job
runner (:mod:`maglev_match.core.jobs`) with checkpoint tiles
(:mod:`maglev_match.core.checkpoint`); resonance speeds are listed (:func:`resonance_speeds`)
and speeds where a multiplier leaves the unit circle are located by solving
(:func:`locate_stability_change`). Runs over N spans are in
:mod:`maglev_match.analyses.speed.spans`,
maps over the speed and another parameter in :mod:`maglev_match.analyses.speed.maps`.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match.analyses.speed.critical import (
    CriticalStatus,
    SpeedCritical,
    critical_disturbance_at_speed,
)
from maglev_match.analyses.speed.delay import with_critical_delay
from maglev_match.analyses.speed.grid import KMH, SPEED_MAX, speeds_kmh
from maglev_match.analyses.speed.options import SpeedOptions, check_speed_setup, w0_of
from maglev_match.analyses.speed.passage import (
    CHUNK,
    PassageReadouts,
    PassageSamples,
    integrate_saving,
    observe_all,
    observe_samples,
    passage_problem,
    passage_readouts,
    passage_states,
    quasi_static_state,
    sample_passage,
    sample_times,
    slot_flags,
)
from maglev_match.analyses.speed.point import (
    SpeedPoint,
    adiabatic_rate,
    periodic_response,
    speed_point,
    standstill_point,
)
from maglev_match.core.checkpoint import tile_checkpoint
from maglev_match.core.jobs import Job, run_job
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.maglev import moving as mv
from maglev_match.maglev.moving import MovingModel

__all__ = [
    "KMH",
    "MovingModel",
    "SpeedOptions",
    "SpeedPoint",
    "SpeedCritical",
    "SpeedSweep",
    "Resonance",
    "StabilityChange",
    "check_speed_setup",
    "passage_problem",
    "passage_readouts",
    "passage_states",
    "observe_all",
    "quasi_static_state",
    "periodic_response",
    "speed_point",
    "speed_sweep",
    "speeds_kmh",
    "resonance_speeds",
    "locate_stability_change",
    "standstill_point",
    "adiabatic_rate",
    "w0_of",
    # the names of the modules of the subject, re-exported (see the module docstring)
    "SPEED_MAX",
    "CHUNK",
    "CriticalStatus",
    "critical_disturbance_at_speed",
    "slot_flags",
    "integrate_saving",
    "observe_samples",
    "sample_passage",
    "sample_times",
    "PassageSamples",
    "PassageReadouts",
    "SweepSpec",
    "compute_speed_tile",
    "run_tiles",
    "run_speed_sweep",
    "natural_frequencies",
    "sweep_dataset",
]


# ---------------------------------------------------------------------------------------
# resonance speeds and the loss of stability
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Resonance:
    """A speed (m/s) at which an excitation frequency of the moving vehicle meets a natural
    frequency: ``harmonic`` times the span-passing frequency v / L, or v / d for a spacing d
    of neighbouring levitation points, equals ``frequency`` (Hz) of ``source``."""

    speed: float
    frequency: float
    source: str
    excitation: str
    harmonic: int

    @property
    def label(self) -> str:
        return (f"{self.speed / KMH:.1f} km/h: {self.excitation} meets {self.source} "
                f"({self.frequency:.3g} Hz)")


def natural_frequencies(params: Params, model: str, max_damping: float = 0.3
                        ) -> list[tuple[str, float]]:
    """(name, frequency in Hz) of the beam modes (n^2 omega1 / 2 pi) and of the vehicle's
    lightly damped modes (damping ratio below ``max_damping``) on a rigid guideway: the
    eigenvalues of the vehicle part of the Jacobian at its rigid-guideway equilibrium."""
    kind = MovingModel(model)
    out = [(f"beam mode {n}", n**2 * float(params.omega1) / (2 * math.pi))
           for n in range(1, params.n_modes + 1)]
    nv = mv.n_vehicle_states(kind)
    if nv == 0:
        return out
    p = mv.moving_param_vector(params, kind, v=0.0, x_front=params.L, active=(0.0, 0.0))
    system = mv.moving_system(params, kind, p)
    J = system.jacobian(mv.rigid_equilibrium(params, kind), p)[:nv, :nv]
    lam = np.linalg.eigvals(J)
    seen: list[float] = []
    for z in sorted(lam[lam.imag > 0], key=lambda z: z.imag):
        zeta = -z.real / abs(z)
        f = z.imag / (2 * math.pi)
        if zeta < max_damping and f > 0.05 and all(abs(f - s) > 1e-6 * f for s in seen):
            seen.append(f)
            out.append((f"vehicle mode (damping ratio {zeta:.2f})", float(f)))
    return out


def resonance_speeds(params: Params, model: str, v_min: float, v_max: float,
                     harmonics: int = 3) -> tuple[Resonance, ...]:
    """The resonance speeds in [v_min, v_max] (m/s): for every natural frequency f of
    :func:`natural_frequencies`, v = f L / i (the i-th harmonic of the span-passing
    frequency, i = 1..``harmonics``) and, for the full vehicle, v = f d for each distinct
    spacing d of neighbouring levitation points (their passing frequency v / d). Sorted by
    speed."""
    kind = MovingModel(model)
    freqs = natural_frequencies(params, kind)
    bases: list[tuple[str, float, int]] = [
        (f"span passing (harmonic {i}, L / v)", float(params.L) / i, i)
        for i in range(1, harmonics + 1)]
    if kind is MovingModel.VEHICLE:
        off = np.sort(mv.vehicle_point_offsets(params))
        for d in np.unique(np.round(np.diff(off), 9)):
            if d > 0:
                bases.append((f"levitation point spacing d = {d:.3g} m", float(d), 1))
    out = []
    for src, f in freqs:
        for what, length, i in bases:
            v = f * length
            if v_min <= v <= v_max:
                out.append(Resonance(float(v), float(f), src, what, i))
    return tuple(sorted(out, key=lambda r: r.speed))


class LossKind(StrEnum):
    """How a multiplier leaves the unit circle."""

    PD = "PD"  # a real multiplier through -1: period doubling of the periodic response
    NS = "NS"  # a complex pair: torus (Neimark-Sacker)
    LP = "LP"  # a real multiplier through +1: fold of the periodic response


@dataclass(frozen=True)
class StabilityChange:
    """A speed where the periodic response changes stability, located by solving
    ln max|mu|(v) = 0 (Brent's method on the speed, a periodic solve per trial).

    speed (m/s) ; kind : PD, NS or LP ; multiplier (re, im) there ; becomes_unstable :
    stable below, unstable above ; converged ; bracket : the final bracket (m/s)."""

    speed: float
    kind: str
    multiplier: tuple[float, float]
    becomes_unstable: bool
    converged: bool
    bracket: tuple[float, float]
    message: str = ""


def _log_largest(params: Params, kind: MovingModel, v: float, opts: SpeedOptions
                 ) -> tuple[float, complex]:
    sol = periodic_response(params, kind, v, opts)
    if not sol.converged or sol.multipliers is None:
        raise FloatingPointError(f"no periodic response at {v / KMH:.4g} km/h: {sol.message}")
    return float(sol.multipliers.log_abs[0]), sol.multipliers.critical


def locate_stability_change(params: Params, model: str, v_a: float, v_b: float,
                            options: SpeedOptions | None = None, xtol: float = 1e-4
                            ) -> StabilityChange:
    """The speed in [v_a, v_b] (m/s) where the largest multiplier crosses the unit circle
    (the two ends on either side), by Brent's method on ln max|mu| to ``xtol`` m/s; its
    kind from the critical multiplier there."""
    import scipy.optimize

    opts = options or SpeedOptions()
    kind = MovingModel(model)
    cache_: dict[float, tuple[float, complex]] = {}

    def g(v: float) -> float:
        if v not in cache_:
            cache_[v] = _log_largest(params, kind, v, opts)
        return cache_[v][0]

    try:
        ga, gb = g(v_a), g(v_b)
        if ga * gb > 0:
            return StabilityChange(float("nan"), "", (float("nan"),) * 2, gb > 0, False,
                                   (v_a, v_b), "the largest multiplier does not cross the "
                                   "unit circle between these speeds")
        v = scipy.optimize.brentq(g, v_a, v_b, xtol=xtol, rtol=1e-10, maxiter=60)
        _, mu = cache_.get(v) or _log_largest(params, kind, v, opts)
    except (FloatingPointError, ValueError, RuntimeError) as exc:
        return StabilityChange(float("nan"), "", (float("nan"),) * 2, False, False,
                               (v_a, v_b), str(exc))
    if abs(mu.imag) > 1e-6 * abs(mu):
        k = LossKind.NS
    else:
        k = LossKind.PD if mu.real < 0 else LossKind.LP
    return StabilityChange(float(v), k.value, (float(mu.real), float(mu.imag)), bool(gb > 0),
                           True, (v_a, v_b))


# ---------------------------------------------------------------------------------------
# sweeps over speed (Dask, checkpoints)
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SweepSpec:
    """What a speed sweep computes: the base parameters, the model, the speeds (m/s) and the
    numerical settings. One tile per speed; ``key()`` fingerprints the checkpoint tiles."""

    base: dict[str, Any]
    model: str
    speeds: tuple[float, ...]
    options: dict[str, Any]

    def key(self) -> str:
        d = {"kind": "speed-sweep", "base": {k: self.base[k] for k in sorted(self.base)},
             "model": self.model, "speeds": list(self.speeds), "options": self.options}
        return json.dumps(d, sort_keys=True, default=float)

    @property
    def tiles(self) -> list[tuple[int, int]]:
        return [(i, i + 1) for i in range(len(self.speeds))]

    def params(self) -> Params:
        from maglev_match.core.params import make_params

        return make_params(dict(self.base))


def compute_speed_tile(spec: SweepSpec, rows: tuple[int, int]) -> dict[str, np.ndarray]:
    """The speeds rows[0]..rows[1]-1 of a sweep: ``speed`` (rows, 1) and ``point``, each
    :class:`SpeedPoint` as JSON (a checkpoint tile)."""
    params = spec.params()
    opts = SpeedOptions(**spec.options)
    pts = [speed_point(params, spec.model, spec.speeds[i], opts) for i in range(*rows)]
    if opts.critical_delay and MovingModel(spec.model) is not MovingModel.FORCE:
        pts = [with_critical_delay(p, params, spec.model, opts) for p in pts]
    return {"speed": np.array([[p.speed] for p in pts]),
            "point": np.array([json.dumps(p.to_json()) for p in pts])}


def run_tiles(spec, compute: Callable, checkpoint: Path | None, variables: tuple[str, ...],
               nx: int, *, resume: bool, scheduler: str | None, workers: int | None,
               progress: Callable[[int, int], None] | None) -> list[dict[str, np.ndarray]]:
    """Every tile of ``spec`` (which has ``tiles`` and ``key()``), made by
    ``compute(spec, rows)``, through the package's job runner
    (:func:`maglev_match.core.jobs.run_job`): in this process (``workers == 0`` and no
    scheduler) or on Dask (a local cluster of ``workers`` processes, None: one per core, or
    an existing ``scheduler``), each tile written to the checkpoint folder as it finishes
    (:mod:`maglev_match.core.checkpoint`: locked, fingerprinted; ``resume`` reuses them).
    Without a folder the tiles are kept in memory here, and a Dask run uses a temporary
    folder. Dask's own messages (its workers' shutdown, "killing", port warnings) are kept
    off the terminal (:func:`maglev_match.core.jobs.dask_log_capture`); a failing task
    still ends the sweep with its own error."""
    job = Job(pieces=spec.tiles, compute=compute, args_of=lambda rows: (spec, rows),
              store=lambda folder: tile_checkpoint(folder, spec.key(), variables, nx))
    return run_job(job, checkpoint, resume=resume, scheduler=scheduler, workers=workers,
                   progress=progress, scratch_prefix="maglev-match-speed-")


def run_speed_sweep(spec: SweepSpec, checkpoint: Path | None = None, *, resume: bool = False,
                    scheduler: str | None = None, workers: int | None = 0,
                    progress: Callable[[int, int], None] | None = None
                    ) -> list[SpeedPoint]:
    """Every speed of ``spec``, point by point, here or on Dask, with checkpoint tiles
    (:func:`run_tiles`)."""
    tiles = run_tiles(spec, compute_speed_tile, checkpoint, ("speed",), 1, resume=resume,
                       scheduler=scheduler, workers=workers, progress=progress)
    return [SpeedPoint.from_json(json.loads(str(s))) for t in tiles for s in t["point"]]


@dataclass(frozen=True)
class SpeedSweep(Plottable):
    """A sweep over speed: one :class:`SpeedPoint` per speed, the resonance speeds in the
    range, the located stability changes and the sweep's warnings."""

    __repr__ = compact_repr

    params: Params
    model: str
    points: tuple[SpeedPoint, ...]
    resonances: tuple[Resonance, ...]
    stability_changes: tuple[StabilityChange, ...]
    options: SpeedOptions
    warnings: tuple[str, ...] = field(default=())
    #: the standstill headline index of the same model, chi(v)'s limit as v -> 0 (keys chi,
    #: h, w0, chi_paper, chi_simulation, basis, reading; None when not computed)
    standstill: dict[str, Any] | None = None
    #: the read-outs over an irregular guideway per speed
    #: (:class:`~maglev_match.analyses.speed.irregular.IrregularSweep`), or None
    irregular: Any = None

    @property
    def speeds(self) -> np.ndarray:
        return np.array([p.speed for p in self.points])

    def column(self, name: str) -> np.ndarray:
        return np.array([getattr(p, name) for p in self.points], float)

    def largest(self, name: str) -> tuple[float, float]:
        """(largest value, its speed in m/s) of a scalar read-out; NaN if none is finite."""
        vals = self.column(name)
        ok = np.isfinite(vals)
        if not ok.any():
            return float("nan"), float("nan")
        k = int(np.nanargmax(np.where(ok, vals, -np.inf)))
        return float(vals[k]), float(self.points[k].speed)

    def at(self, v: float) -> SpeedPoint:
        """The point nearest to speed v (m/s)."""
        return self.points[int(np.argmin(np.abs(self.speeds - v)))]

    @property
    def loses_stability(self) -> bool:
        return any(p.stable is False for p in self.points)

    def to_xarray(self):
        """The sweep as an :class:`xarray.Dataset` over ``speed`` (m/s) and ``point``, with
        units and long names, the parameter set, the resonance speeds, the stability changes
        and the warnings as (JSON) attributes."""
        return sweep_dataset(self)

    def summary(self) -> dict[str, Any]:
        """Machine-readable summary (SI units)."""
        def best(name):
            val, v = self.largest(name)
            return {"value": val, "speed": v}

        return {
            "model": self.model,
            "speeds": [float(v) for v in self.speeds],
            "points": [p.to_json() for p in self.points],
            "resonances": [dataclasses.asdict(r) | {"label": r.label} for r in self.resonances],
            "stability_changes": [dataclasses.asdict(c) for c in self.stability_changes],
            "loses_stability": self.loses_stability,
            "largest_daf": best("daf"),
            "largest_wz": best("wz"),
            "largest_gap_deviation": best("gap_dev_abs_max"),
            "largest_multiplier": best("largest_multiplier"),
            "smallest_chi": self.smallest_chi(),
            "standstill": self.standstill,
            "tau": float(self.params.tau),
            "critical_delay": self.critical_delays(),
            "warnings": list(self.warnings),
        }

    def critical_delays(self) -> list[dict[str, Any]] | None:
        """The critical delay per speed (speed m/s, tau_c s, status, low-speed limit s);
        None when not computed."""
        if not self.options.critical_delay:
            return None
        return [{"speed": float(p.speed), "tau_c": float(p.tau_c), "status": p.tau_c_status,
                 "frozen_limit": float(p.tau_c_frozen)} for p in self.points]

    def smallest_chi(self) -> dict[str, Any] | None:
        """The smallest chi(v) of the sweep: value, speed (m/s), the position of the
        vehicle's centre in the span that decides it (fraction of L), the direction (+1
        beam down, -1 beam up), whether every size up to the gap range returned there; None
        when no chi(v) was computed."""
        pts = [p for p in self.points if np.isfinite(p.chi)]
        if not pts:
            return None
        w = min(pts, key=lambda p: p.chi)
        ix = w.index
        return {"value": float(w.chi), "speed": float(w.speed), "h": float(w.h),
                "fraction": None if ix is None else ix.fraction,
                "direction": None if ix is None else ix.direction,
                "every_size_returned": w.every_size_returned}


def _check_speeds(speeds) -> tuple[float, ...]:
    vals = tuple(float(v) for v in speeds)
    if not vals:
        raise ParameterError("speeds", "[]", "give at least one speed")
    if len(set(vals)) != len(vals):
        raise ParameterError("speeds", vals, "the speeds must be distinct")
    return tuple(sorted(vals))


def speed_sweep(params: Params, model: str = "unit", speeds: Sequence[float] = (),
                options: SpeedOptions | None = None, *, checkpoint: Path | None = None,
                resume: bool = False, scheduler: str | None = None,
                workers: int | None = 0, locate: bool = True,
                progress: Callable[[int, int], None] | None = None) -> SpeedSweep:
    """Every read-out at every speed (m/s), then the resonance speeds in the range and, with
    ``locate``, every speed between two sweep points where the periodic response changes
    stability, located by solving (:func:`locate_stability_change`). Inputs are checked
    before any work (:func:`check_speed_setup`)."""
    opts = options or SpeedOptions()
    kind = check_speed_setup(params, model, list(speeds), opts.spans)
    vals = _check_speeds(speeds)
    spec = SweepSpec(base=params.as_input_dict(), model=kind.value, speeds=vals,
                     options=opts.key())
    pts = run_speed_sweep(spec, checkpoint, resume=resume, scheduler=scheduler,
                          workers=workers, progress=progress)
    warnings: list[str] = []
    for p in pts:
        for w in p.warnings:
            if p.speed > 0:
                warnings.append(f"{p.speed / KMH:.4g} km/h: {w}")
    changes = []
    if locate and kind is not MovingModel.FORCE:
        for a, b in zip(pts[:-1], pts[1:], strict=True):
            if a.speed > 0 and a.stable is not None and b.stable is not None \
                    and a.stable != b.stable:
                ch = locate_stability_change(params, kind, a.speed, b.speed, opts)
                changes.append(ch)
                if not ch.converged:
                    warnings.append(f"a stability change between {a.speed / KMH:.4g} and "
                                    f"{b.speed / KMH:.4g} km/h could not be located: "
                                    f"{ch.message}")
    every = [p for p in pts if p.every_size_returned]
    if every:
        warnings.append(
            f"at {len(every)} of {len(pts)} speeds (" + ", ".join(
                f"{p.speed / KMH:.4g}" for p in every[:6]) + (", ..." if len(every) > 6
                                                               else "")
            + " km/h) every jump up to the gap range returned in the direction that decides "
            "chi(v): h(v) there is the gap range, as the standstill index counts it")
    standstill = None
    if opts.critical and kind is not MovingModel.FORCE:
        standstill = standstill_headline(params, kind)
    res = resonance_speeds(params, kind, min(vals), max(vals)) if max(vals) > 0 else ()
    return SpeedSweep(params=params, model=kind.value, points=tuple(pts), resonances=res,
                      stability_changes=tuple(changes), options=opts,
                      warnings=tuple(warnings), standstill=standstill)


def standstill_headline(params: Params, kind: MovingModel) -> dict[str, Any]:
    """The standstill headline index of the same model (:func:`maglev_match.analyses.
    matching.matching_index`): the value chi(v) tends to as v -> 0."""
    from maglev_match.analyses.matching import matching_index

    res = matching_index(params, model=kind.value)
    return {"chi": float(res.chi), "h": float(res.h_headline), "w0": float(res.w0),
            "chi_paper": float(res.chi_paper),
            "chi_simulation": None if res.chi_simulation is None else float(res.chi_simulation),
            "basis": str(res.reading_basis), "reading": res.reading}


# ---------------------------------------------------------------------------------------
# the dataset
# ---------------------------------------------------------------------------------------
SWEEP_UNITS = {
    "speed": "m/s", "speed_kmh": "km/h", "period": "s", "converged": "1", "stable": "1",
    "largest_multiplier": "1", "critical_multiplier_real": "1",
    "critical_multiplier_imag": "1", "max_real_part": "1/s", "gap_dev_max": "m",
    "gap_dev_min": "m", "current_max": "A", "current_min": "A", "current_reverses": "1",
    "midspan_max": "m", "static_deflection": "m", "daf": "1", "body_acc_peak": "m/s^2",
    "wz": "1", "h": "m", "h_down": "m", "h_up": "m", "every_size_returned": "1", "w0": "m",
    "chi": "1", "index_fraction": "1", "index_direction": "1", "h_entry": "m",
    "h_entry_down": "m", "h_entry_up": "m", "entry_at_ceiling": "1", "chi_entry": "1",
    "integration_error": "1", "point": "1", "tau_c": "s", "tau_c_frozen": "s",
}
SWEEP_NAMES = {
    "speed": "vehicle speed",
    "speed_kmh": "vehicle speed in km/h",
    "period": "span passage time L / v",
    "converged": "periodic response found (1) or not (0)",
    "stable": "periodic response stable (1), unstable (0); at v = 0 the standstill verdict",
    "largest_multiplier": "largest |multiplier| of the span map",
    "critical_multiplier_real": "real part of the multiplier of largest modulus",
    "critical_multiplier_imag": "imaginary part of the multiplier of largest modulus",
    "max_real_part": "largest real part of the eigenvalues at v = 0 (standstill)",
    "gap_dev_max": "largest gap deviation c - c0 over a passage",
    "gap_dev_min": "smallest gap deviation c - c0 over a passage",
    "current_max": "largest coil current over a passage",
    "current_min": "smallest coil current over a passage",
    "current_reverses": "coil current would reverse on the periodic response (1) or not (0)",
    "midspan_max": "largest mid-span deflection of a span under the vehicle (downward)",
    "static_deflection": "largest static mid-span deflection under the vehicle's weights",
    "daf": "dynamic amplification factor midspan_max / static_deflection",
    "body_acc_peak": "peak vertical acceleration of the car body",
    "wz": "Sperling ride index Wz (vertical)",
    "h": "critical jump of the mean deflection under the vehicle, the span under it "
         "displaced in its first mode (smaller direction, worst position in the span)",
    "h_down": "critical jump, beam down (gaps close), smallest over the positions",
    "h_up": "critical jump, beam up (gaps open), smallest over the positions",
    "every_size_returned": "the direction deciding chi(v) returned at every jump up to the "
                           "gap range (1; h is then that range) or h was measured (0)",
    "index_fraction": "position of the vehicle's centre in the span that decides chi(v) "
                      "(fraction of L)",
    "index_direction": "direction that decides chi(v) (+1 beam down, -1 beam up)",
    "h_entry": "entry disturbance: critical initial deflection of the span being entered "
               "(smaller direction)",
    "h_entry_down": "entry disturbance, beam down (gaps close)",
    "h_entry_up": "entry disturbance, beam up (gaps open)",
    "entry_at_ceiling": "h_entry is its search's ceiling (1: every deflection up to the gap "
                        "range returned) or a measured margin (0)",
    "chi_entry": "entry disturbance over w0, h_entry / w0",
    "w0": "static deflection of the standstill index (same model)",
    "chi": "matching index at speed chi(v) = h(v) / w0 (the standstill index as v -> 0)",
    "integration_error": "variational solve against state run, scaled",
    "tau_c": "critical delay of the outer loop: smallest tau at which the periodic response "
             "loses stability (v = 0: standing at mid-span)",
    "tau_c_frozen": "low-speed limit of tau_c: position-averaged frozen spectral abscissa "
                    "crosses 0",
    "point": "levitation point number (1-based)",
}


def sweep_dataset(sweep: SpeedSweep):
    """The sweep as an :class:`xarray.Dataset` (see :meth:`SpeedSweep.to_xarray`)."""
    import xarray as xr

    from maglev_match.core.datasets import annotate

    pts = sweep.points
    n_pts = max((len(p.gap_dev_max) for p in pts), default=0)

    def per_point(name):
        arr = np.full((len(pts), n_pts), np.nan)
        for i, p in enumerate(pts):
            v = getattr(p, name)
            arr[i, :len(v)] = v
        return (("speed", "point"), arr)

    def crit(p, side):
        c = getattr(p, side)
        s = c.supported() if c is not None else None
        return float("nan") if s is None else float(s)

    def index_side(p, direction):
        if p.index is None:
            return float("nan")
        sizes = [(q.down if direction > 0 else q.up).size for q in p.index.positions]
        return float("nan") if any(v is None for v in sizes) else float(min(sizes))

    data = {
        "speed_kmh": (("speed",), sweep.speeds / KMH),
        "period": (("speed",), sweep.column("period")),
        "converged": (("speed",), np.array([p.converged for p in pts], np.int8)),
        "stable": (("speed",), np.array([-1 if p.stable is None else int(p.stable)
                                         for p in pts], np.int8)),
        "largest_multiplier": (("speed",), sweep.column("largest_multiplier")),
        "critical_multiplier_real": (("speed",), np.array([p.critical_multiplier[0]
                                                           for p in pts])),
        "critical_multiplier_imag": (("speed",), np.array([p.critical_multiplier[1]
                                                           for p in pts])),
        "max_real_part": (("speed",), sweep.column("max_real_part")),
        "current_reverses": (("speed",), np.array([p.current_reverses for p in pts], np.int8)),
        "midspan_max": (("speed",), sweep.column("midspan_max")),
        "static_deflection": (("speed",), sweep.column("static_deflection")),
        "daf": (("speed",), sweep.column("daf")),
        "body_acc_peak": (("speed",), sweep.column("body_acc_peak")),
        "wz": (("speed",), sweep.column("wz")),
        "h": (("speed",), sweep.column("h")),
        "h_down": (("speed",), np.array([index_side(p, +1) for p in pts])),
        "h_up": (("speed",), np.array([index_side(p, -1) for p in pts])),
        "every_size_returned": (("speed",), np.array([p.every_size_returned for p in pts],
                                                     np.int8)),
        "index_fraction": (("speed",), np.array([
            np.nan if p.index is None or p.index.fraction is None else p.index.fraction
            for p in pts])),
        "index_direction": (("speed",), np.array([
            0 if p.index is None or p.index.direction is None else p.index.direction
            for p in pts], np.int8)),
        "w0": (("speed",), sweep.column("w0")),
        "chi": (("speed",), sweep.column("chi")),
        "h_entry": (("speed",), sweep.column("h_entry")),
        "h_entry_down": (("speed",), np.array([crit(p, "down") for p in pts])),
        "h_entry_up": (("speed",), np.array([crit(p, "up") for p in pts])),
        "entry_at_ceiling": (("speed",), np.array([p.entry_at_ceiling for p in pts],
                                                  np.int8)),
        "chi_entry": (("speed",), sweep.column("chi_entry")),
        "integration_error": (("speed",), sweep.column("integration_error")),
    }
    if sweep.options.critical_delay:
        data["tau_c"] = (("speed",), sweep.column("tau_c"))
        data["tau_c_frozen"] = (("speed",), sweep.column("tau_c_frozen"))
    if n_pts:
        for name in ("gap_dev_max", "gap_dev_min", "current_max", "current_min"):
            data[name] = per_point(name)
    coords = {"speed": ("speed", sweep.speeds)}
    if n_pts:
        coords["point"] = ("point", np.arange(1, n_pts + 1))
    ds = xr.Dataset(data, coords=coords)
    for name in ds.data_vars:
        ds[name].attrs["units"] = SWEEP_UNITS.get(str(name), "1")
        ds[name].attrs["long_name"] = SWEEP_NAMES[str(name)]
    for name in ds.coords:
        ds[name].attrs["units"] = SWEEP_UNITS[str(name)]
        ds[name].attrs["long_name"] = SWEEP_NAMES[str(name)]
    ds.attrs.update({
        "title": "maglev-match speed sweep",
        "model": sweep.model,
        "resonances": json.dumps([dataclasses.asdict(r) | {"label": r.label}
                                  for r in sweep.resonances]),
        "stability_changes": json.dumps([dataclasses.asdict(c)
                                         for c in sweep.stability_changes]),
        "warnings": json.dumps(list(sweep.warnings)),
        "standstill": json.dumps(sweep.standstill),
        "chi_standstill": (float("nan") if not sweep.standstill
                           else float(sweep.standstill["chi"])),
        "options": json.dumps(sweep.options.key()),
        "tau": float(sweep.params.tau),
        "points": json.dumps([p.to_json() for p in pts], default=float),
    })
    return annotate(ds, sweep.params)
