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

import json
import math
from dataclasses import dataclass, field
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

__all__ = ["IrregularSweep", "irregular_sweep", "check_irregular_setup", "profile_gap_response",
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
    n_modes = int(params.n_modes)
    nv = mv.n_vehicle_states(kind)
    rhs = mv.moving_rhs(kind, n_modes, False, 1)
    gap = mv.observables(kind, n_modes, 1)["gap_deviation"]
    pb = jnp.asarray(mv.moving_param_vector(params, kind, v=float(v), active=(0.0, 0.0)))
    x0 = jnp.asarray(mv.rigid_equilibrium(params, kind))

    def pv(a, kap, phi):
        return jnp.concatenate([pb, jnp.zeros(7), jnp.stack([a, kap, phi])])

    A = np.asarray(jax.jacfwd(lambda x: rhs(x, pv(0.0, 1.0, 0.0)))(x0))[:nv, :nv]
    C = np.asarray(jax.jacfwd(lambda x: gap(x, pv(0.0, 1.0, 0.0)))(x0))[:, :nv]

    @jax.jit
    def forcing(kap):
        def d(phi):
            fa = jax.jacfwd(lambda a: rhs(x0, pv(a, kap, phi)))(0.0)[:nv]
            ga = jax.jacfwd(lambda a: gap(x0, pv(a, kap, phi)))(0.0)
            return fa, ga

        f0, g0 = d(0.0)
        f1, g1 = d(-jnp.pi / 2)
        return f0 + 1j * f1, g0 + 1j * g1

    kap = np.atleast_1d(np.asarray(kappa, float))
    out = np.empty((C.shape[0], kap.size), complex)
    eye = np.eye(nv)
    for k, kk in enumerate(kap):
        F, G = forcing(jnp.asarray(kk))
        x_hat = np.linalg.solve(1j * kk * float(v) * eye - A, np.asarray(F))
        out[:, k] = C @ x_hat + np.asarray(G)
    return out


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
    rms values; ``seeds`` the seeds drawn; ``seconds`` the time per speed."""

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


def irregular_sweep(params: Params, model: str, speeds, profile: Irregularity | str, *,
                    spans: int = 20, warmup: int = 1,
                    options: SpeedOptions | None = None,
                    progress=None) -> IrregularSweep:
    """The read-outs over an irregular guideway at every speed (m/s > 0) (module
    docstring): one run per seed of ``spans`` spans with the limits on, and the smooth run;
    ``progress(done, total)`` after every speed."""
    import time

    speeds = np.asarray(list(speeds), float)
    for v in speeds:
        if not v > 0:
            raise ParameterError("--speed", v * 3.6, "an irregular guideway needs speeds > 0 "
                                 "km/h")
    prof = check_irregular_setup(params, model, speeds, profile, spans, warmup, options)
    kind = MovingModel(model)
    static, _ = mv.static_midspan_deflection(params, kind)
    i0 = float(params.i0_vehicle) if kind is MovingModel.VEHICLE else float(
        unit_model.levitation_current(unit_model.param_vector(params)))
    vals = {k: np.full(speeds.size, math.nan) for k in READOUTS}
    secs = np.zeros(speeds.size)
    warnings: list[str] = []
    for n, v in enumerate(speeds):
        t0 = time.perf_counter()
        smooth = simulate_over_spans(params, kind, float(v), spans, limited=True,
                                     options=options, overlay=False)
        if smooth.outcome != "ok":
            warnings.append(f"{v * 3.6:g} km/h: the smooth run ended in a {smooth.outcome}")
        per = []
        for seed in prof.seed_list:
            run = simulate_over_spans(params, kind, float(v), spans, limited=True,
                                      options=options, profile=prof, seed=seed)
            per.append(_run_readouts(run, smooth, params, warmup, static, i0))
            if run.outcome == "collision":
                warnings.append(f"{v * 3.6:g} km/h, seed {seed}: contact with the "
                                f"{run.collision_limit} gap limit at point "
                                f"{run.collision_point}, t = {run.collision_time:.3f} s")
        for k in ("gap_rms", "gap_rms_profile", "current_rms", "acc_rms", "wz"):
            vals[k][n] = float(np.nanmean([r[k] for r in per]))
        for k in ("gap_max", "current_max", "reverses", "daf"):
            vals[k][n] = float(np.nanmax([r[k] for r in per]))
        prs = np.array([r["gap_rms_profile"] for r in per])
        vals["gap_rms_profile_se"][n] = (float(np.std(prs, ddof=1) / math.sqrt(prs.size))
                                         if prs.size > 1 else math.nan)
        k_hit = int(sum(r["contact"] for r in per))
        vals["contacts"][n], vals["runs"][n] = k_hit, len(per)
        vals["p_contact"][n] = k_hit / len(per)
        vals["p_contact_low"][n], vals["p_contact_high"][n] = wilson_interval(k_hit, len(per))
        if prof.kind == "random":
            vals["gap_rms_linear"][n] = linear_gap_rms(params, float(v), prof, kind.value)
        secs[n] = time.perf_counter() - t0
        if progress is not None:
            progress(n + 1, speeds.size)
    return IrregularSweep(params=params, model=kind.value, profile=prof, speeds=speeds,
                          spans=int(spans), warmup=int(warmup),
                          distance=float(spans * params.L), seeds=prof.seed_list,
                          values=vals, seconds=secs, warnings=tuple(warnings))
