"""The vehicle at speed over an irregular guideway: ride, gap fluctuation and the probability
of contact per speed, from runs with the physical limits on, and the linear route beside them
(behind ``maglev-match speed --irregularity`` and ``simulate --speed --irregularity``).

At every speed the vehicle runs from rigid ground over ``spans`` spans (:func:`~maglev_match.
analyses.speed.spans.simulate_over_spans`) with the profile under every levitation point,
once per seed (random profiles) or once (deterministic ones); the same run on the smooth
guideway gives the part of the gap deviation that the profile causes. Read-outs over the
run after the run-in (the approach and the first ``warmup`` spans), averaged over the seeds
(the largest values: the largest over the seeds):

* gap deviation: rms and largest |c - c0| (all points); ``gap_rms_profile``: the rms of the
  part the profile causes (run minus smooth run);
* current: rms of i - i0 and the largest i; ``reverses``: a run met i < 0 (the clamp at 0
  acted);
* car body: rms acceleration and Sperling's Wz of the record (its spectral lines, the record
  taken as one period: :func:`~maglev_match.analyses.speed.ride.sperling_of_periodic`);
* DAF: the largest mid-span deflection of a span over the static one;
* contact: the runs that hit a gap limit, over the runs, each run ``spans`` L long; the
  probability of contact over that distance with its 95 % Wilson score interval.

The linear route (any model): the rms gap deviation of the random profile from the frequency
response of the model on a rigid guideway (:func:`profile_gap_response`; for the unit also
model A's closed form :func:`rigid_gap_response`): sigma^2 = mean over the points of the sum
over the profile's waves of |H_j(Omega_k)|^2 a_k^2 / 2, the midpoint rule of the integral of
|H|^2 S over the band (a_k^2 / 2 = S(Omega_k) dOmega).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.analyses.speed.options import SpeedOptions, check_speed_setup
from maglev_match.analyses.speed.ride import sperling_of_periodic
from maglev_match.analyses.speed.spans import simulate_over_spans
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.maglev import moving as mv
from maglev_match.maglev import unit as unit_model
from maglev_match.maglev.irregularity import Irregularity, parse_irregularity
from maglev_match.maglev.moving import MovingModel

__all__ = ["IrregularSweep", "IrregularSpec", "irregular_sweep", "compute_irregular_runs",
           "RUN_READOUTS", "check_irregular_setup", "profile_gap_response",
           "rigid_gap_response", "wilson_interval", "linear_gap_rms", "resolved_wavelength",
           "READOUTS"]

#: read-out name -> (unit, long name)
READOUTS = {
    "gap_rms": ("m", "rms gap deviation (after the run-in, mean over the seeds)"),
    "gap_max": ("m", "largest |gap deviation| (largest over the seeds)"),
    "gap_rms_profile": ("m", "rms of the gap deviation the profile causes (run minus the "
                             "smooth run; mean over the seeds)"),
    "gap_rms_profile_se": ("m", "standard error of gap_rms_profile over the seeds"),
    "gap_rms_linear": ("m", "rms gap deviation of the profile from the rigid-guideway "
                            "linearisation (random profile)"),
    "current_rms": ("A", "rms of i - i0 (mean over the seeds)"),
    "current_max": ("A", "largest coil current"),
    "reverses": ("1", "1: a run's current would have reversed (the clamp at 0 acted)"),
    "acc_rms": ("m/s^2", "rms car-body vertical acceleration (mean over the seeds)"),
    "wz": ("1", "Sperling's ride index of the car body (mean over the seeds)"),
    "daf": ("1", "largest mid-span deflection over the static one"),
    "contacts": ("1", "runs that hit a gap limit"),
    "runs": ("1", "runs (seeds)"),
    "p_contact": ("1", "probability of contact over the run's distance (contacts / runs)"),
    "p_contact_low": ("1", "lower end of the 95 % Wilson score interval of p_contact"),
    "p_contact_high": ("1", "upper end of the 95 % Wilson score interval of p_contact"),
}


def wilson_interval(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The Wilson score interval of a binomial proportion k / n (95 % by default)."""
    if n <= 0:
        return 0.0, 1.0
    p = k / n
    d = 1.0 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return max(0.0, c - h), min(1.0, c + h)


def resolved_wavelength(params: Params, v: float, opts: SpeedOptions | None = None) -> float:
    """The shortest wavelength (m) the runs' sampling resolves at speed v (m/s): 8 samples
    per wavelength at the read-out sampling of a passage."""
    from maglev_match.analyses.speed.passage import sample_times

    o = opts or SpeedOptions()
    T = float(params.L) / v
    dt = T / (sample_times(params, T, o).size - 1)
    return 8.0 * v * dt


def rigid_gap_response(params: Params, omega) -> np.ndarray:
    """The unit's gap deviation per unit profile amplitude, H(i omega) (complex), at the
    circular frequencies ``omega`` (rad/s): model A linearised at its equilibrium with the
    beam rigid (its deflection and rate replaced by the profile's mean under the footprint
    and its rate), times the footprint's mean of a unit wave of that frequency (the wave
    exp(i omega t) at the front, averaged over the length l behind it)."""
    p = unit_model.param_vector(params)
    x0 = jnp.zeros(9)
    J = np.asarray(jax.jacfwd(unit_model.unit_rhs)(x0, jnp.asarray(p)))
    veh = [0, 1, 2, 3, 6, 7, 8]
    A = J[np.ix_(veh, veh)]
    B0, B1 = J[veh, 4], J[veh, 5]
    w = np.atleast_1d(np.asarray(omega, float))
    I = np.eye(len(veh))
    H = np.empty(w.size, complex)
    for k, om in enumerate(w):
        s = 1j * om
        H[k] = np.linalg.solve(s * I - A, B0 + s * B1)[0] - 1.0
    return H


def footprint_factor(params: Params, v: float, kappa) -> np.ndarray:
    """|mean over the unit's footprint (length l) of a wave of wavenumber kappa| (rad/m)."""
    x = np.asarray(kappa, float) * float(params.l) / 2.0
    return np.abs(np.sinc(x / np.pi))


def profile_gap_response(params: Params, model: str, v: float, kappa) -> np.ndarray:
    """The gap deviation of every levitation point per unit amplitude of a profile wave
    cos(kappa x) (kappa in rad/m) at speed v (m/s), complex (points, kappa): the moving model
    linearised at its equilibrium on a rigid guideway (both span slots frozen, every load on
    one), its vehicle states driven by the wave under each point (the unit: its mean under
    the footprint) at the circular frequency kappa v. For the forcing the wave's amplitude
    is differentiated at 0 with phase 0 and -pi/2 (its real and imaginary parts); the
    steady response is (i kappa v I - A)^-1 times that. Any model at speed; for the unit it
    equals :func:`rigid_gap_response` times :func:`footprint_factor` in magnitude (tested)."""
    kind = MovingModel(model)
    nv = mv.n_vehicle_states(kind)
    pb = jnp.asarray(mv.moving_param_vector(params, kind, v=float(v), active=(0.0, 0.0)))
    x0 = jnp.asarray(mv.rigid_equilibrium(params, kind))
    matrices, forcing = _linearisation(kind, int(params.n_modes))
    A, C = (np.asarray(m) for m in matrices(pb, x0))
    kap = np.atleast_1d(np.asarray(kappa, float))
    out = np.empty((C.shape[0], kap.size), complex)
    eye = np.eye(nv)
    for k, kk in enumerate(kap):
        F, G = forcing(pb, x0, jnp.asarray(kk))
        x_hat = np.linalg.solve(1j * kk * float(v) * eye - A, np.asarray(F))
        out[:, k] = C @ x_hat + np.asarray(G)
    return out


@cache
def _linearisation(kind: MovingModel, n_modes: int):
    """(matrices, forcing) of the moving model on a guideway profile of one wave:
    ``matrices(pb, x0)`` the Jacobians of the vehicle's vector field (A) and of the gap
    deviation (C) by the vehicle's states at the state x0 with the base parameter vector
    pb; ``forcing(pb, x0, kappa)`` the derivatives of the vector field and of the gap deviation
    by the wave's amplitude at 0, at phase 0 and -pi/2 (real and imaginary parts), at the
    state x0. Compiled once per model and number of modes
    (the parameters and the state are arguments, not constants: every speed shares it)."""
    nv = mv.n_vehicle_states(kind)
    rhs = mv.moving_rhs(kind, n_modes, False, 1)
    gap = mv.observables(kind, n_modes, 1)["gap_deviation"]

    @jax.jit
    def forcing(pb, x0, kap):
        def pv(a, phi):  # one wave a cos(kap x + phi): its entries a cos(phi), kap, a sin(phi)
            return jnp.concatenate([pb, jnp.zeros(7),
                                    jnp.stack([a * jnp.cos(phi), kap, a * jnp.sin(phi)])])

        def d(phi):
            fa = jax.jacfwd(lambda a: rhs(x0, pv(a, phi)))(0.0)[:nv]
            ga = jax.jacfwd(lambda a: gap(x0, pv(a, phi)))(0.0)
            return fa, ga

        f0, g0 = d(0.0)
        f1, g1 = d(-jnp.pi / 2)
        return f0 + 1j * f1, g0 + 1j * g1

    @jax.jit
    def matrices(pb, x0):
        p0 = jnp.concatenate([pb, jnp.zeros(7), jnp.array([0.0, 1.0, 0.0])])
        A = jax.jacfwd(lambda x: rhs(x, p0))(x0)[:nv, :nv]
        C = jax.jacfwd(lambda x: gap(x, p0))(x0)[:, :nv]
        return A, C

    return matrices, forcing


def linear_gap_rms(params: Params, v: float, profile: Irregularity,
                   model: str = "unit") -> float:
    """The linear route's rms gap deviation of the random profile at speed v (m/s), over all
    levitation points: sigma^2 = mean over the points of sum_k |H_j(Omega_k)|^2 a_k^2 / 2
    with H_j from :func:`profile_gap_response` (seed-free: a_k and Omega_k do not depend on
    the phases)."""
    amp, kap, _ = profile.wave_vectors(profile.seed0)
    H = profile_gap_response(params, model, v, kap)
    return float(math.sqrt(np.mean(np.sum(np.abs(H) ** 2 * amp**2 / 2.0, axis=1))))


@dataclass(frozen=True)
class IrregularSweep(Plottable):
    """Read-outs over an irregular guideway per speed (SI units; :data:`READOUTS`): each a
    (speeds,) array in ``values``. ``distance`` (m) the length of one run's spans (the
    distance of the probability of contact); ``warmup`` spans of run-in left out of the
    rms values; ``seeds`` the seeds drawn; ``seconds`` the time per speed (the wall times
    of its runs, summed, wherever they ran)."""

    __repr__ = compact_repr

    params: Params
    model: str
    profile: Irregularity
    speeds: np.ndarray
    spans: int
    warmup: int
    distance: float
    seeds: tuple[int, ...]
    values: dict[str, np.ndarray]
    seconds: np.ndarray
    warnings: tuple[str, ...] = field(default=())

    def column(self, name: str) -> np.ndarray:
        return np.asarray(self.values[name], float)

    def rows(self) -> list[dict[str, Any]]:
        return [{"speed": float(v), **{k: float(self.values[k][i]) for k in READOUTS}}
                for i, v in enumerate(self.speeds)]

    def table(self) -> tuple[list[str], list[list[float]]]:
        """The CSV table: headers with SI units, one row per speed."""
        header = ["speed (m/s)", *(f"{k} ({u})" for k, (u, _) in READOUTS.items())]
        return header, [[r["speed"], *(r[k] for k in READOUTS)] for r in self.rows()]

    def summary(self) -> dict[str, Any]:
        return {"model": self.model, "irregularity": self.profile.describe(),
                "spans": self.spans, "warmup_spans": self.warmup, "distance": self.distance,
                "seeds": list(self.seeds), "confidence_interval": "Wilson score, 95 %",
                "rows": self.rows(), "seconds_per_speed": [float(s) for s in self.seconds],
                "warnings": list(self.warnings)}

    def to_xarray(self):
        import xarray as xr

        from maglev_match.core.datasets import annotate

        ds = xr.Dataset({k: (("speed",), self.column(k)) for k in READOUTS},
                        coords={"speed": ("speed", np.asarray(self.speeds, float))})
        ds.attrs.update({"title": "maglev-match at speed over an irregular guideway",
                         "model": self.model, "irregularity": self.profile.describe(),
                         "irregularity_spec": self.profile.text, "spans": self.spans,
                         "warmup_spans": self.warmup, "distance": self.distance,
                         "seeds": json.dumps(list(self.seeds)),
                         "confidence_interval": "Wilson score, 95 %",
                         "warnings": json.dumps(list(self.warnings))})
        return annotate(ds, self.params, units={"speed": "m/s", **{
            k: u for k, (u, _) in READOUTS.items()}}, long_names={
            "speed": "vehicle speed", **{k: n for k, (_, n) in READOUTS.items()}})


def _run_readouts(run, smooth, params: Params, warmup: int, static: float, i0: float) -> dict:
    T = float(params.L) / run.speed
    keep = run.t >= (warmup + 1) * T
    g = run.gap_deviation[keep]
    gs = smooth.gap_deviation[: run.t.size][keep]
    i = run.current[keep]
    acc = run.body_acceleration[keep]
    out = {"gap_rms": float(np.sqrt(np.mean(g**2))) if g.size else math.nan,
           "gap_max": float(np.max(np.abs(run.gap_deviation))) if run.gap_deviation.size
           else math.nan,
           "gap_rms_profile": float(np.sqrt(np.mean((g - gs) ** 2))) if g.size else math.nan,
           "current_rms": float(np.sqrt(np.mean((i - i0) ** 2))) if i.size else math.nan,
           "current_max": float(np.max(run.current)) if run.current.size else math.nan,
           "reverses": float(np.min(run.current) < 0.0) if run.current.size else math.nan,
           "acc_rms": float(np.sqrt(np.mean(acc**2))) if acc.size else math.nan,
           "wz": sperling_of_periodic(acc, acc.size * (run.t[1] - run.t[0]))[0]
           if acc.size > 4 else math.nan,
           "daf": float(np.nanmax(run.per_span_midspan_max) / static),
           "contact": float(run.outcome == "collision")}
    return out


def check_irregular_setup(params: Params, model: str, speeds, profile, spans: int,
                          warmup: int = 1, options: SpeedOptions | None = None
                          ) -> Irregularity:
    """Validate runs over an irregular guideway before any work (ParameterError naming the
    field, the value and the rule); returns the parsed profile. Speeds of 0 are skipped by
    the runs and not checked here."""
    prof = parse_irregularity(profile)
    if prof is None:
        raise ParameterError("--irregularity", profile, "must name a profile")
    if isinstance(spans, bool) or not isinstance(spans, int) or spans < 1:
        raise ParameterError("--irregular-spans", spans, "must be a whole number >= 1")
    kind = check_speed_setup(params, model, list(speeds), spans, delay=False,
                             refuse_delay="the runs over an irregular guideway have no "
                             "delay of the outer loop yet")
    if kind is MovingModel.FORCE:
        raise ParameterError("--model", model, "an irregular guideway needs a levitated "
                             "model ('unit' or 'vehicle')")
    if isinstance(warmup, bool) or not isinstance(warmup, int) or not 0 <= warmup < spans:
        raise ParameterError("--warmup", warmup,
                             f"must be a whole number from 0 to {spans - 1}")
    for v in speeds:
        if v > 0:
            prof.check(spans, resolved_wavelength(params, float(v), options))
    return prof


#: the read-outs of one run, in the order of a piece's ``values`` row (``gap_rms_linear``:
#: the linear route's rms at the run's speed, in the first seed's run of a random profile,
#: else NaN; ``contact``: 1 if the run hit a gap limit; ``seconds``: the run's wall time,
#: with the smooth run's where this process computed it)
RUN_READOUTS = ("gap_rms", "gap_max", "gap_rms_profile", "current_rms", "current_max",
                "reverses", "acc_rms", "wz", "daf", "contact", "gap_rms_linear", "seconds")


@dataclass(frozen=True)
class IrregularSpec:
    """What the runs over an irregular guideway compute: the base parameters, the model,
    the speeds (m/s > 0), the profile, the length of a run and its run-in (spans) and the
    numerical settings (:meth:`SpeedOptions.key`). One piece per run (speed, seed), the
    piece of run ``n`` holding speed ``n // len(seeds)`` with seed ``n % len(seeds)``;
    ``key()`` fingerprints the checkpoint pieces."""

    base: dict[str, Any]
    model: str
    speeds: tuple[float, ...]
    profile: Irregularity
    spans: int
    warmup: int
    options: dict[str, Any]

    def key(self) -> str:
        prof = {f.name: getattr(self.profile, f.name)
                for f in dataclasses.fields(self.profile) if f.compare}
        d = {"kind": "irregular-runs", "base": {k: self.base[k] for k in sorted(self.base)},
             "model": self.model, "speeds": list(self.speeds), "profile": prof,
             "spans": self.spans, "warmup": self.warmup, "options": self.options}
        return json.dumps(d, sort_keys=True, default=float)

    @property
    def seeds(self) -> tuple[int, ...]:
        return self.profile.seed_list

    @property
    def pieces(self) -> list[tuple[int, int]]:
        return [(n, n + 1) for n in range(len(self.speeds) * len(self.seeds))]

    def params(self) -> Params:
        from maglev_match.core.params import make_params

        return make_params(dict(self.base))

    def shapes(self, rows: tuple[int, int]) -> dict[str, tuple[int, ...]]:
        """The variables of the piece of runs rows[0]..rows[1]-1 and their shapes."""
        n = rows[1] - rows[0]
        return {"values": (n, len(RUN_READOUTS)), "notes": (n,)}


#: the smooth run this process made last: (spec key, speed index) -> SpanRun; the runs of
#: the seeds of a speed share it (a process that runs them one after the other makes it once;
#: it goes after the speed's last seed, and when the sweep ends here)
_SMOOTH: dict[tuple[str, int], Any] = {}


def _smooth_run(spec: IrregularSpec, key: str, i: int, params: Params, kind: MovingModel,
                opts: SpeedOptions):
    run = _SMOOTH.get((key, i))
    if run is None:
        run = simulate_over_spans(params, kind, float(spec.speeds[i]), spec.spans,
                                  limited=True, options=opts, overlay=False)
        _SMOOTH.clear()
        _SMOOTH[(key, i)] = run
    return run


def compute_irregular_runs(spec: IrregularSpec, rows: tuple[int, int]
                           ) -> dict[str, np.ndarray]:
    """The runs rows[0]..rows[1]-1 of ``spec`` (a checkpoint piece): ``values`` (runs,
    :data:`RUN_READOUTS`) and ``notes``, each run's warnings as a JSON list (the first seed
    of a speed also says when the smooth run did not end 'ok')."""
    import time

    params = spec.params()
    opts = SpeedOptions(**spec.options)
    kind = MovingModel(spec.model)
    prof = spec.profile
    key = spec.key()
    static, _ = mv.static_midspan_deflection(params, kind)
    i0 = float(params.i0_vehicle) if kind is MovingModel.VEHICLE else float(
        unit_model.levitation_current(unit_model.param_vector(params)))
    n_seeds = len(spec.seeds)
    values, notes = [], []
    for n in range(*rows):
        i, j = divmod(n, n_seeds)
        v, seed = float(spec.speeds[i]), spec.seeds[j]
        t0 = time.perf_counter()
        smooth = _smooth_run(spec, key, i, params, kind, opts)
        said: list[str] = []
        if j == 0 and smooth.outcome != "ok":
            said.append(f"{v * 3.6:g} km/h: the smooth run ended in a {smooth.outcome}")
        run = simulate_over_spans(params, kind, v, spec.spans, limited=True, options=opts,
                                  profile=prof, seed=seed)
        r = _run_readouts(run, smooth, params, spec.warmup, static, i0)
        if run.outcome == "collision":
            said.append(f"{v * 3.6:g} km/h, seed {seed}: contact with the "
                        f"{run.collision_limit} gap limit at point {run.collision_point}, "
                        f"t = {run.collision_time:.3f} s")
        r["gap_rms_linear"] = (linear_gap_rms(params, v, prof, kind.value)
                               if j == 0 and prof.kind == "random" else math.nan)
        r["seconds"] = time.perf_counter() - t0
        if j == n_seeds - 1:  # the speed's last seed: its smooth run is not kept (memory)
            _SMOOTH.pop((key, i), None)
        values.append([r[k] for k in RUN_READOUTS])
        notes.append(json.dumps(said))
    return {"values": np.array(values, float), "notes": np.array(notes)}


def irregular_sweep(params: Params, model: str, speeds, profile: Irregularity | str, *,
                    spans: int = 20, warmup: int = 1,
                    options: SpeedOptions | None = None,
                    progress=None, checkpoint: Path | None = None, resume: bool = False,
                    scheduler: str | None = None, workers: int | None = 0
                    ) -> IrregularSweep:
    """The read-outs over an irregular guideway at every speed (m/s > 0) (module
    docstring): one run per seed of ``spans`` spans with the limits on, and the smooth run.

    The runs (one per speed and seed, :class:`IrregularSpec`) go through the package's job
    runner (:func:`maglev_match.core.jobs.run_job`) as the sweep's speeds do: in this process
    (``workers == 0`` and no ``scheduler``) or on Dask (a local cluster of ``workers``
    processes, None: one per core, or an existing ``scheduler``), each run saved into the
    ``checkpoint`` folder as it finishes (``resume`` reuses them; a resumed sweep equals the
    uninterrupted one bit for bit); ``progress(done, total)`` before the first run and
    after each. The read-outs of a speed are formed here from its runs, in seed order, so
    where the runs were computed does not change a bit of them."""
    from maglev_match.core.checkpoint import Checkpoint
    from maglev_match.core.jobs import Job, run_job

    speeds = np.asarray(list(speeds), float)
    for v in speeds:
        if not v > 0:
            raise ParameterError("--speed", v * 3.6, "an irregular guideway needs speeds > 0 "
                                 "km/h")
    prof = check_irregular_setup(params, model, speeds, profile, spans, warmup, options)
    kind = MovingModel(model)
    spec = IrregularSpec(base=params.as_input_dict(), model=kind.value,
                         speeds=tuple(float(v) for v in speeds), profile=prof,
                         spans=int(spans), warmup=int(warmup),
                         options=(options or SpeedOptions()).key())
    job = Job(pieces=spec.pieces, compute=compute_irregular_runs,
              args_of=lambda rows: (spec, rows),
              store=lambda folder: Checkpoint(Path(folder), spec.key(), spec.shapes,
                                              what="set of runs over an irregular guideway",
                                              noun="run"),
              noun="runs over the irregular guideway", run="speed sweep")
    try:
        pieces = run_job(job, None if checkpoint is None else Path(checkpoint),
                         resume=resume, scheduler=scheduler, workers=workers,
                         progress=progress, scratch_prefix="maglev-match-irregular-")
    finally:
        _SMOOTH.clear()
    values = np.concatenate([np.asarray(pc["values"], float) for pc in pieces])
    notes = [str(t) for pc in pieces for t in np.ravel(pc["notes"])]
    return _gathered(params, spec, values, notes)


def _gathered(params: Params, spec: IrregularSpec, values: np.ndarray, notes: list[str]
              ) -> IrregularSweep:
    """The read-outs per speed from the runs' (:data:`RUN_READOUTS` rows in piece order):
    means over the seeds, the largest values, the contacts and their interval."""
    speeds = np.asarray(spec.speeds, float)
    n_seeds = len(spec.seeds)
    vals = {k: np.full(speeds.size, math.nan) for k in READOUTS}
    secs = np.zeros(speeds.size)
    warnings: list[str] = []
    for n in range(speeds.size):
        per = values[n * n_seeds:(n + 1) * n_seeds]

        def col(k, per=per):
            return np.ascontiguousarray(per[:, RUN_READOUTS.index(k)])

        for said in notes[n * n_seeds:(n + 1) * n_seeds]:
            warnings.extend(json.loads(said))
        for k in ("gap_rms", "gap_rms_profile", "current_rms", "acc_rms", "wz"):
            vals[k][n] = float(np.nanmean(col(k)))
        for k in ("gap_max", "current_max", "reverses", "daf"):
            vals[k][n] = float(np.nanmax(col(k)))
        prs = col("gap_rms_profile")
        vals["gap_rms_profile_se"][n] = (float(np.std(prs, ddof=1) / math.sqrt(prs.size))
                                         if prs.size > 1 else math.nan)
        k_hit = int(sum(float(c) for c in col("contact")))
        vals["contacts"][n], vals["runs"][n] = k_hit, n_seeds
        vals["p_contact"][n] = k_hit / n_seeds
        vals["p_contact_low"][n], vals["p_contact_high"][n] = wilson_interval(k_hit, n_seeds)
        if spec.profile.kind == "random":
            vals["gap_rms_linear"][n] = float(col("gap_rms_linear")[0])
        secs[n] = float(np.sum(col("seconds")))
    return IrregularSweep(params=params, model=spec.model, profile=spec.profile,
                          speeds=speeds, spans=spec.spans, warmup=spec.warmup,
                          distance=float(spec.spans * params.L), seeds=spec.seeds,
                          values=vals, seconds=secs, warnings=tuple(warnings))
