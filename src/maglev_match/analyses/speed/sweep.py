"""The vehicle at speed over a guideway of identical spans: the periodic response, its
stability from the span map, and what a track-beam designer reads off it at every speed.

Models (:mod:`maglev_match.maglev.moving`): ``unit`` (model A's levitation unit, the
vehicle's k units spread over its length l), ``vehicle`` (model B's six levitation points),
``force`` (a constant point force, the textbook moving-load case).

Periodic response. With identical spans the steady motion repeats every span: one
*passage* lasts T = L / v, from the moment the front of the vehicle reaches a support
(the span ahead enters the model, at rest) to the moment it reaches the next one, and ends
with the hand-over of the span slots (:mod:`maglev_match.maglev.moving`). Between support
crossings of the loads the vector field is smooth; the passage is integrated segment by
segment and the periodic response is the fixed point of the passage map, found by Newton's
method on that map with the variational transfer matrices and the span hand-over as a
linear jump (:mod:`maglev_match.dynamics.integrate.passage`), not by simulating many spans. Its
multipliers (the eigenvalues of the span map's Jacobian; the dropped span gives exact zeros)
decide stability. As v -> 0 the multipliers follow the standstill eigenvalues: ln|mu| T^-1
tends to the mean over the passage of the rightmost real part of the frozen model (the
vehicle standing at each position), see ``docs/speed.md``.

Read-outs per speed (:class:`SpeedPoint`), over one passage of the periodic response:

* the largest and smallest gap deviation c_j - c0 per levitation point, the largest and
  smallest current and whether it would reverse (the response is of the smooth model);
* the largest mid-span deflection of a span while the vehicle is on it (the span entering in
  slot B over the passage, then the same span in slot A until the rear leaves it) and the
  dynamic amplification factor DAF = that deflection over the largest static mid-span
  deflection under the vehicle's weights with the same modes
  (:func:`~maglev_match.maglev.moving.static_midspan_deflection`);
* the car body's peak vertical acceleration and Sperling's ride index Wz of its spectrum
  (:mod:`maglev_match.analyses.speed.ride`; the lines of a periodic signal are exact);
* the multipliers and the verdict;
* the critical disturbance at speed: the largest initial deflection d of the span the
  vehicle is entering (its first mode, mid-span deflection d, at rest) from which runs with
  the physical limits on (current clamp, gap range) return to the periodic response without
  contact, in both directions (beam down: the gap closes; beam up: it opens), found by
  bracketing on batched runs like the standstill simulation; h(v) is the smaller, and
  chi(v) = h(v) / w0 with w0 the standstill index's static deflection of the same model.

Extrema are located on samples at least ``samples_per_period`` per period of the fastest
beam mode and refined by integrating again between the neighbours of the best samples.

Sweeps over speed run point by point, on Dask like maps, with checkpoint tiles
(:mod:`maglev_match.core.checkpoint`); resonance speeds are listed (:func:`resonance_speeds`) and
speeds where a multiplier leaves the unit circle are located by solving
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
from functools import cache
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.analyses.speed.grid import KMH, SPEED_MAX, speeds_kmh
from maglev_match.analyses.speed.ride import sperling_of_periodic
from maglev_match.core.aot import cached_kernel
from maglev_match.core.checkpoint import tile_checkpoint
from maglev_match.core.jobs import Job, run_job
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.integrate.passage import (
    SAVE_SLOTS,
    PassageOptions,
    PassageProblem,
    PeriodicPassage,
    Segment,
    run_passages_batch,
    solve_periodic_passage,
)
from maglev_match.dynamics.integrate.simulate import EventsWithArgs, SimulationOptions, simulate
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
]

CHUNK = SAVE_SLOTS  # saved times per integrator call: one compiled kernel for every run


class CriticalStatus(StrEnum):
    """How a critical-disturbance search ended (as the standstill search)."""

    BRACKETED = "bracketed"
    ALL_COLLIDE = "all_collide"
    ALL_RETURN = "all_return"
    OPEN = "open"
    NOT_COMPUTED = "not_computed"


@dataclass(frozen=True)
class SpeedOptions:
    """Numerical settings at speed (checked on construction; errors name the option).

    rtol, atol : tolerances of the periodic solve's runs (atol per state scale).
    tangent_rtol : tolerance of the variational solves. 1e-6 moves the multipliers by less
        than 2e-8 against 1e-10 on the turnout beams (unit and vehicle, 5 and 60 km/h,
        measured 2026-12-02) at about half the cost of 1e-8.
    newton_tol : scaled residual of the periodic response.
    samples_per_period : read-out samples per period of the fastest beam mode (>= 8).
    min_samples : read-out samples per passage at least.
    critical : compute the critical disturbance at speed.
    critical_sizes : disturbance sizes per direction and round; critical_rounds : rounds;
    critical_tol : bracket width reached (m); critical_rtol : tolerance of those runs.
    return_tol : a disturbed run has returned when the state at a span hand-over is within
        this (scaled: 1 mm, 1 cm/s, 1 A) of the periodic response.
    spans : spans a disturbed run may take to return (the guideway's length in spans).
    """

    rtol: float = 1e-10
    atol: float = 1e-10
    tangent_rtol: float = 1e-6
    newton_tol: float = 1e-9
    samples_per_period: int = 16
    min_samples: int = 512
    critical: bool = True
    critical_sizes: int = 8
    critical_rounds: int = 3
    critical_tol: float = 2e-5
    critical_rtol: float = 1e-8
    return_tol: float = 0.05
    spans: int = 40

    def __post_init__(self) -> None:
        for name in ("rtol", "atol", "tangent_rtol", "newton_tol", "critical_rtol",
                     "return_tol"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0 < v <= 0.1:
                raise ParameterError(name, v, "must be a number in (0, 0.1]")
        if not (isinstance(self.critical_tol, int | float) and 0 < self.critical_tol <= 1e-2):
            raise ParameterError("critical_tol", self.critical_tol, "must lie in (0, 0.01] m")
        for name, lo, hi in (("samples_per_period", 8, 1000), ("min_samples", 64, 10**6),
                             ("critical_sizes", 2, 64), ("critical_rounds", 1, 12),
                             ("spans", 1, 10_000)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
                raise ParameterError(name if name != "spans" else "--spans", v,
                                     f"must be a whole number in [{lo}, {hi}]")

    def passage(self) -> PassageOptions:
        return PassageOptions(rtol=self.rtol, atol=self.atol, tangent_rtol=self.tangent_rtol,
                              tangent_atol=self.tangent_rtol, newton_tol=self.newton_tol)

    def key(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


# ---------------------------------------------------------------------------------------
# set-up and validation
# ---------------------------------------------------------------------------------------
def check_speed_setup(params: Params, model: str, speeds: Sequence[float] = (),
                      spans: int | None = None) -> MovingModel:
    """Validate a computation at speed before any work: the model name, the parameters the
    models at speed need, the speeds (m/s; finite, >= 0 and at most 900 km/h) and the number
    of spans. Raises :class:`~maglev_match.core.params.ParameterError` naming the field, the value
    and the rule."""
    try:
        kind = MovingModel(model)
    except ValueError:
        raise ParameterError("--model", model, "must be 'unit', 'vehicle' or 'force' at "
                             "speed") from None
    if kind is not MovingModel.VEHICLE and "sigma" in params.explicit:
        raise ParameterError(
            "sigma", params.sigma, "is set directly, but at speed the unit's coupling to the "
            "spans follows from the guideway and the vehicle (L, mbar, l, k): set those "
            "instead")
    lay = mv.layout_of(params, kind)
    if not lay.extent < params.L:
        what = "l" if kind is MovingModel.UNIT else "s0"
        value = params.l if kind is MovingModel.UNIT else params.s0
        raise ParameterError(what, value, f"the vehicle's layout ({lay.extent:g} m from the "
                             f"first to the last load) must be shorter than a span "
                             f"(L = {params.L:g} m): at most two spans may carry it")
    if spans is not None:
        if isinstance(spans, bool) or not isinstance(spans, int) or spans < 1:
            raise ParameterError("--spans", spans, "must be a whole number >= 1")
        if spans * params.L < lay.extent:
            raise ParameterError("--spans", spans, f"the guideway ({spans} x {params.L:g} m) "
                                 f"is shorter than the vehicle's layout ({lay.extent:g} m)")
    for v in speeds:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ParameterError("speed", v, "must be a finite number")
        if v < 0:
            raise ParameterError("speed", v, "must be >= 0 (the direction of travel does not "
                                 "matter on identical spans)")
        if v > SPEED_MAX:
            raise ParameterError("speed", v, f"must be at most {SPEED_MAX:g} m/s "
                                 f"({SPEED_MAX / KMH:g} km/h)")
    return kind



def w0_of(params: Params, kind: MovingModel) -> float:
    """The static deflection w0 (m) of the standstill index of the same model: model A's
    sigma (m + M) g / omega1^2 for the unit and the force, model B's static mid-span
    deflection under the vehicle for the vehicle."""
    if MovingModel(kind) is MovingModel.VEHICLE:
        from maglev_match.maglev.models import VehicleModel

        return float(VehicleModel(params).w0)
    return float(params.w0)


def _flags(params: Params, kind: MovingModel, x_front: float) -> tuple[np.ndarray, np.ndarray]:
    lay = mv.layout_of(params, kind)
    xf = x_front + lay.front
    return (xf > params.L).astype(float), (xf - lay.length > params.L).astype(float)


def passage_problem(params: Params, model: str, v: float, *, limited: bool = False,
                    approach_rigid: bool = False, exit_rigid: bool = False) -> PassageProblem:
    """One span passage at speed v (m/s > 0) as a
    :class:`~maglev_match.dynamics.integrate.passage.PassageProblem`: segments between the support
    crossings of the loads' edges, each with its slot flags; the jump hands slot B over to
    A and brings a fresh span at rest into B. ``approach_rigid``: slot A is rigid ground
    (the abutment before the first span); ``exit_rigid``: slot B is (after the last)."""
    kind = MovingModel(model)
    if not v > 0:
        raise ParameterError("speed", v, "a passage needs a speed > 0")
    L = float(params.L)
    T = L / v
    lay = mv.layout_of(params, kind)
    cr = lay.edge_crossings(v)
    br = np.unique(np.concatenate([[0.0, T], cr[(cr > 1e-12 * T) & (cr < T * (1 - 1e-12))]]))
    segs = []
    for a, b in zip(br[:-1], br[1:], strict=True):
        tm = 0.5 * (a + b)
        fb, rb = _flags(params, kind, L + v * tm)
        loaded_a = bool(np.any(L + v * tm + lay.front - lay.length < L))
        act = (0.0 if (approach_rigid or not loaded_a) else 1.0, 0.0 if exit_rigid else 1.0)
        p = mv.moving_param_vector(params, kind, v=v, x_front=L, active=act, front_on_B=fb,
                                   rear_on_B=rb)
        segs.append(Segment(float(b - a), p))
    system = mv.moving_system(params, kind, segs[0].p, limited=limited, period=T)
    sl = mv.slot_slices(kind, params.n_modes)
    n = system.dim - 1
    R = np.eye(n)
    for blk in ("qA", "qA_dot", "qB", "qB_dot"):
        R[sl[blk], :] = 0.0
    m = params.n_modes
    R[sl["qA"], sl["qB"]] = np.eye(m)
    R[sl["qA_dot"], sl["qB_dot"]] = np.eye(m)
    return PassageProblem(system, tuple(segs), R)


def quasi_static_state(params: Params, model: str, x_front: float, *, tol: float = 1e-12,
                       max_iter: int = 30) -> np.ndarray:
    """The equilibrium of the model with the vehicle standing still, the front of its layout
    at ``x_front`` (m from slot A's left support; L is the support between A and B), both
    spans elastic: Newton's method with the exact (autodiff) Jacobian from the equilibrium
    on a rigid guideway. Raises FloatingPointError when Newton does not converge."""
    kind = MovingModel(model)
    fb, rb = _flags(params, kind, x_front)
    p = mv.moving_param_vector(params, kind, v=0.0, x_front=x_front, active=(1.0, 1.0),
                               front_on_B=fb, rear_on_B=rb)
    system = mv.moving_system(params, kind, p)
    n = system.dim - 1
    x = mv.rigid_equilibrium(params, kind)
    sc = system.state_scale[:n]
    for _ in range(max_iter):
        f, J = system.f_and_jacobian(x, p)
        r = f[:n] / sc
        if np.max(np.abs(r)) < tol * max(1.0, float(np.max(np.abs(J[:n, :n] @ sc) / sc))):
            return x
        d = np.linalg.solve(J[:n, :n], -f[:n])
        x[:n] += d
        if np.max(np.abs(d) / sc) < tol:
            return x
    raise FloatingPointError(f"the quasi-static equilibrium at x_front = {x_front:g} m did not "
                             "converge")


# ---------------------------------------------------------------------------------------
# read-outs of one passage
# ---------------------------------------------------------------------------------------
@cache
def _observe_chunk(fns: tuple[Callable, ...]):
    def one(x, p):
        return jnp.concatenate([jnp.ravel(f(x, p)) for f in fns])

    return cached_kernel(jax.vmap(one, in_axes=(0, None)), *fns, name="speed.observe")


@cache
def _observable_sizes(fns: tuple[Callable, ...], dim: int, n_p: int) -> tuple[int, ...]:
    return tuple(int(np.prod(jax.eval_shape(f, jnp.zeros(dim), jnp.zeros(n_p)).shape))
                 for f in fns)


def observe_all(system, X: np.ndarray, p: np.ndarray) -> dict[str, np.ndarray]:
    """Every named observable of ``system`` at the states X (k, dim), as arrays (k, m): one
    compiled kernel for all of them, CHUNK states at a time (the last chunk padded), so the
    same kernel serves every number of states."""
    names = tuple(system.observables)
    fns = tuple(system.observables[n] for n in names)
    X = np.asarray(X, float)
    k = X.shape[0]
    sizes = _observable_sizes(fns, system.dim, np.asarray(p).size)
    ker = _observe_chunk(fns)
    vals = []
    for a in range(0, max(k, 1), CHUNK):
        blk = X[a:a + CHUNK]
        pad = CHUNK - blk.shape[0]
        if pad:
            blk = np.concatenate([blk, np.repeat(blk[-1:], pad, axis=0)])
        vals.append(np.asarray(ker(jnp.asarray(blk), jnp.asarray(p)))[:CHUNK - pad])
    flat = np.concatenate(vals)[:k]
    out, at = {}, 0
    for n, m in zip(names, sizes, strict=True):
        out[n] = flat[:, at:at + m]
        at += m
    return out


def _fast_frequency(params: Params) -> float:
    """The fastest beam mode (Hz) the read-outs must resolve."""
    return params.n_modes**2 * float(params.omega1) / (2.0 * math.pi)


def sample_times(params: Params, T: float, opts: SpeedOptions) -> np.ndarray:
    n = max(opts.min_samples, int(math.ceil(T * opts.samples_per_period
                                            * _fast_frequency(params))))
    return np.linspace(0.0, T, n + 1)


def integrate_saving(system, x_start: np.ndarray, t_rel: np.ndarray, p: np.ndarray,
                      sim: SimulationOptions) -> np.ndarray:
    """States at the relative times ``t_rel`` (increasing, >= 0) of the run from x_start,
    CHUNK saved times per integrator call (one compiled kernel)."""
    out = np.empty((t_rel.size, system.dim))
    x = np.array(x_start, float)
    t_now = 0.0
    k = 0
    while k < t_rel.size:
        chunk = t_rel[k:k + CHUNK]
        s = chunk - t_now
        if s[-1] <= 0.0:  # only the start itself
            out[k:k + chunk.size] = x
            k += chunk.size
            continue
        save = np.concatenate([s, np.full(CHUNK - s.size, s[-1])])
        save = np.maximum(save, 0.0)
        res = simulate(system, x, float(s[-1]), p=p, x_ref=x, options=sim, n_save=CHUNK,
                       t_save=save)
        if res.outcome == "failed":
            raise FloatingPointError("a read-out run failed: " + "; ".join(res.warnings))
        X = np.array(res.x[: s.size], float)
        X[:, -1] = x[-1] + s  # the time state, exactly
        out[k:k + chunk.size] = X
        x = X[-1].copy()
        t_now = float(chunk[-1])
        k += chunk.size
    return out


def passage_states(problem: PassageProblem, starts: np.ndarray, times: np.ndarray,
                   options: SpeedOptions | None = None) -> np.ndarray:
    """The states at the passage times ``times`` (s, in [0, L / v]) of the passage whose
    segment start states are ``starts`` (e.g. ``periodic_response(...).run.starts``)."""
    opts = options or SpeedOptions()
    sim = SimulationOptions(rtol=opts.rtol, atol=opts.atol, max_steps=1_000_000)
    t = np.asarray(times, float)
    order = np.argsort(t, kind="stable")
    bounds = np.concatenate([problem.starts, [problem.period]])
    seg = np.clip(np.searchsorted(bounds, t[order], side="right") - 1, 0,
                  len(problem.segments) - 1)
    X = np.empty((t.size, problem.system.dim))
    for k, sg in enumerate(problem.segments):
        idx = np.nonzero(seg == k)[0]
        if idx.size:
            X[order[idx]] = integrate_saving(problem.system, starts[k],
                                              t[order[idx]] - bounds[k], sg.p, sim)
    return X


@dataclass(frozen=True)
class PassageSamples:
    t: np.ndarray  # (N+1,) passage times
    X: np.ndarray  # (N+1, dim)
    seg: np.ndarray  # segment of each sample
    problem: PassageProblem
    starts: np.ndarray  # segment start states


def sample_passage(problem: PassageProblem, x0_run, params: Params, opts: SpeedOptions,
                    sim: SimulationOptions) -> PassageSamples:
    T = problem.period
    t = sample_times(params, T, opts)
    bounds = np.concatenate([problem.starts, [T]])
    seg = np.clip(np.searchsorted(bounds, t, side="right") - 1, 0, len(problem.segments) - 1)
    X = np.empty((t.size, problem.system.dim))
    for k, sg in enumerate(problem.segments):
        idx = np.nonzero(seg == k)[0]
        if idx.size == 0:
            continue
        X[idx] = integrate_saving(problem.system, x0_run.starts[k], t[idx] - bounds[k],
                                   sg.p, sim)
    return PassageSamples(t, X, seg, problem, x0_run.starts)


def observe_samples(samples: PassageSamples, name: str) -> np.ndarray:
    """Values of a named observable at the samples (k, m), each with its segment's
    parameters."""
    sys_ = samples.problem.system
    vals = None
    for k, sg in enumerate(samples.problem.segments):
        m = samples.seg == k
        if not np.any(m):
            continue
        v = observe_all(sys_, samples.X[m], sg.p)[name]
        if vals is None:
            vals = np.empty((samples.t.size, v.shape[1]))
        vals[m] = v
    return vals  # type: ignore[return-value]


def _refine_extreme(samples: PassageSamples, name: str, comp: int, sign: float, values: np.ndarray,
                    sim: SimulationOptions, candidates: int = 3) -> tuple[float, float]:
    """The largest sign * g_comp over the passage: the best local maxima of the samples,
    each refined by integrating again between its neighbours with CHUNK saved times and a
    parabola through the best three of those. Returns (value, time)."""
    v = sign * values[:, comp]
    n = v.size
    # local maxima of the samples (the ends count), best first
    left = np.concatenate([[-np.inf], v[:-1]])
    right = np.concatenate([v[1:], [-np.inf]])
    peaks = np.nonzero((v >= left) & (v >= right))[0]
    order = peaks[np.argsort(-v[peaks], kind="stable")][:candidates]
    best_v, best_t = float(v[order[0]]), float(samples.t[order[0]])
    bounds = np.concatenate([samples.problem.starts, [samples.problem.period]])
    sys_ = samples.problem.system
    for i in order:
        k = int(samples.seg[i])
        a = max(samples.t[max(i - 1, 0)], bounds[k])
        b = min(samples.t[min(i + 1, n - 1)], bounds[k + 1])
        if not b > a:
            continue
        if i > 0 and samples.seg[i - 1] == k and samples.t[i - 1] >= bounds[k]:
            x_start, t_start = samples.X[i - 1], samples.t[i - 1]
        else:
            x_start, t_start = samples.starts[k], bounds[k]
        ts = np.linspace(a, b, CHUNK)
        Xz = integrate_saving(sys_, x_start, ts - t_start, samples.problem.segments[k].p, sim)
        gz = sign * observe_all(sys_, Xz, samples.problem.segments[k].p)[name][:, comp]
        j = int(np.argmax(gz))
        val, tt = float(gz[j]), float(ts[j])
        if 0 < j < CHUNK - 1:  # parabola through the best three
            y0, y1, y2 = gz[j - 1], gz[j], gz[j + 1]
            den = y0 - 2 * y1 + y2
            if den < 0:
                s = 0.5 * (y0 - y2) / den
                val = float(y1 - 0.25 * (y0 - y2) * s)
                tt = float(ts[j] + s * (ts[1] - ts[0]))
        if val > best_v:
            best_v, best_t = val, tt
    return sign * best_v, best_t


@dataclass(frozen=True)
class PassageReadouts:
    """Read-outs of one passage of a periodic response (SI units; per levitation point
    where an array)."""

    __repr__ = compact_repr

    gap_dev_max: np.ndarray
    gap_dev_min: np.ndarray
    current_max: np.ndarray
    current_min: np.ndarray
    midspan_max: float
    body_acc_peak: float
    wz: float
    samples: int


def passage_readouts(problem: PassageProblem, run, params: Params, kind: MovingModel,
                     opts: SpeedOptions) -> tuple[PassageReadouts, PassageSamples]:
    """The read-outs of the passage whose segment start states are ``run.starts``."""
    sim = SimulationOptions(rtol=opts.rtol, atol=opts.atol, max_steps=1_000_000)
    samples = sample_passage(problem, run, params, opts, sim)
    n_pts = mv.layout_of(params, kind).n_loads if kind is not MovingModel.FORCE else 0
    mid = observe_samples(samples, "midspan")
    comp = int(np.argmax(np.max(mid, axis=0)))
    midspan_max, _ = _refine_extreme(samples, "midspan", comp, 1.0, mid, sim)
    if kind is MovingModel.FORCE:
        empty = np.zeros(0)
        return PassageReadouts(empty, empty, empty, empty, float(midspan_max), float("nan"),
                               float("nan"), samples.t.size), samples
    gap = observe_samples(samples, "gap_deviation")
    cur = observe_samples(samples, "current")
    acc = observe_samples(samples, "body_acceleration")
    gmax = np.array([_refine_extreme(samples, "gap_deviation", j, 1.0, gap, sim)[0]
                     for j in range(n_pts)])
    gmin = np.array([_refine_extreme(samples, "gap_deviation", j, -1.0, gap, sim)[0]
                     for j in range(n_pts)])
    imax = np.array([_refine_extreme(samples, "current", j, 1.0, cur, sim)[0]
                     for j in range(n_pts)])
    imin = np.array([_refine_extreme(samples, "current", j, -1.0, cur, sim)[0]
                     for j in range(n_pts)])
    a = acc[:, 0]
    sign = 1.0 if np.max(a) >= -np.min(a) else -1.0
    peak = abs(_refine_extreme(samples, "body_acceleration", 0, sign, acc, sim)[0])
    wz, _, _ = sperling_of_periodic(a[:-1], problem.period)
    return PassageReadouts(gmax, gmin, imax, imin, float(midspan_max), float(peak), float(wz),
                           samples.t.size), samples


# ---------------------------------------------------------------------------------------
# the critical disturbance at speed
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SpeedCritical:
    """The critical initial deflection of the span being entered, in one direction.

    direction : +1 beam down (mid-span deflection d > 0: the gaps close), -1 beam up.
    status : 'bracketed', 'all_collide', 'all_return', 'open' or 'not_computed'.
    critical : the bracket's midpoint (m) or None; largest_return, smallest_collision (m).
    gap_range : the largest size searched (m): the deflection that would put a gap on its
        limit if the vehicle did not respond (c0 - gap_min down, gap_max - c0 up).
    runs : simulated runs; unresolved : runs neither back within ``spans`` spans nor
    collided; spans : the spans allowed; collision_time : time (s from the disturbed span's
    entry) of the collision at ``smallest_collision``; message : why not computed."""

    direction: int
    status: str
    critical: float | None
    largest_return: float | None
    smallest_collision: float | None
    gap_range: float
    tol: float
    runs: int
    unresolved: int
    spans: int
    rounds: int
    collision_time: float | None
    message: str = ""

    def supported(self) -> float | None:
        """The size this search supports (m), by the standstill index's rule: the bracket's
        midpoint, the whole range when every size returned, 0 when every size collided, for
        an open search the largest size seen to return (None if none)."""
        if self.status == CriticalStatus.ALL_RETURN:
            return float(self.gap_range)
        if self.status == CriticalStatus.ALL_COLLIDE:
            return 0.0
        if self.status == CriticalStatus.BRACKETED:
            return float(self.critical)  # type: ignore[arg-type]
        return None if self.largest_return is None else float(self.largest_return)


def critical_disturbance_at_speed(params: Params, kind: MovingModel, v: float,
                                  x_periodic: np.ndarray, opts: SpeedOptions
                                  ) -> tuple[SpeedCritical, SpeedCritical]:
    """Both directions of the critical disturbance at speed (module docstring). Each round
    runs ``critical_sizes`` sizes per direction in one vmapped batch, span after span, until
    every run has returned (state at a hand-over within ``return_tol`` of the periodic
    response), collided or used ``spans`` spans; the bracket shrinks by
    ``critical_sizes + 1`` per round."""
    problem = passage_problem(params, kind, v, limited=True)
    sys_l = problem.system
    events = EventsWithArgs(mv.gap_events(kind, params.n_modes),
                            (float(params.gap_min), float(params.gap_max)))
    sim = SimulationOptions(rtol=opts.critical_rtol, atol=opts.critical_rtol,
                            max_steps=1_000_000, unroll_stages=False)
    sl = mv.slot_slices(kind, params.n_modes)
    iq = sl["qB"].start  # first mode of the span being entered
    n = problem.n
    scale = problem.scale
    ranges = {+1: params.c0 - params.gap_min, -1: params.gap_max - params.c0}
    seen: dict[int, dict[float, tuple[str, float]]] = {+1: {}, -1: {}}
    unresolved = {+1: 0, -1: 0}
    runs = {+1: 0, -1: 0}
    nb = opts.critical_sizes

    def run_round(sizes: dict[int, np.ndarray]) -> None:
        dirs = [d for d in (+1, -1) if sizes[d].size]
        batch = np.concatenate([np.full(sizes[d].size, d) for d in dirs])
        size = np.concatenate([sizes[d] for d in dirs])
        X = np.tile(x_periodic, (batch.size, 1))
        X[:, iq] += batch * size
        state = np.zeros(batch.size, int)  # 0 running, 1 returned, 2 collided
        t_hit = np.full(batch.size, np.nan)
        for span in range(opts.spans):
            out = run_passages_batch(problem, X, x_periodic, system=sys_l, events=events,
                                     simulation=sim)
            new_hit = out.collided & (state == 0)
            state[new_hit] = 2
            t_hit[new_hit] = span * problem.period + out.event_time[new_hit]
            state[out.failed & (state == 0)] = 3
            dist = np.max(np.abs(out.x_next[:, :n] - x_periodic[None, :n]) / scale[None, :],
                          axis=1)
            state[(state == 0) & (dist < opts.return_tol)] = 1
            X = out.x_next
            X[state != 0] = x_periodic
            if np.all(state != 0):
                break
        for k, d in enumerate(batch):
            d = int(d)
            runs[d] += 1
            if state[k] == 1:
                seen[d][float(size[k])] = ("return", float("nan"))
            elif state[k] == 2:
                seen[d][float(size[k])] = ("collision", float(t_hit[k]))
            else:
                unresolved[d] += 1

    def bracket(d: int) -> tuple[float | None, float | None]:
        coll = [s for s, (o, _) in seen[d].items() if o == "collision"]
        hi = min(coll) if coll else None
        ret = [s for s, (o, _) in seen[d].items() if o == "return" and (hi is None or s < hi)]
        return (max(ret) if ret else None), hi

    first = {d: ranges[d] * np.arange(1, nb + 1) / (nb + 1) for d in (+1, -1)}
    run_round(first)
    rounds = 1
    while rounds < opts.critical_rounds:
        nxt = {}
        for d in (+1, -1):
            lo, hi = bracket(d)
            a = 0.0 if lo is None else lo
            b = ranges[d] if hi is None else hi
            if hi is None or b - a <= opts.critical_tol:
                nxt[d] = np.zeros(0)
            else:
                nxt[d] = a + (b - a) * np.arange(1, nb + 1) / (nb + 1)
        if not any(s.size for s in nxt.values()):
            break
        run_round(nxt)
        rounds += 1
    out = []
    for d in (+1, -1):
        lo, hi = bracket(d)
        tol = opts.critical_tol * 1.0000001
        if hi is None:
            status = CriticalStatus.ALL_RETURN if lo is not None else CriticalStatus.OPEN
        elif lo is None:
            status = CriticalStatus.ALL_COLLIDE if hi <= tol else CriticalStatus.OPEN
        else:
            status = CriticalStatus.BRACKETED if hi - lo <= tol else CriticalStatus.OPEN
        out.append(SpeedCritical(
            direction=d, status=status.value,
            critical=None if (lo is None or hi is None) else 0.5 * (lo + hi),
            largest_return=lo, smallest_collision=hi, gap_range=float(ranges[d]),
            tol=opts.critical_tol, runs=runs[d], unresolved=unresolved[d], spans=opts.spans,
            rounds=rounds, collision_time=None if hi is None else seen[d][hi][1]))
    return out[0], out[1]


# ---------------------------------------------------------------------------------------
# one speed
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SpeedPoint:
    """Everything computed at one speed (SI units; arrays per levitation point).

    speed (m/s), period L / v (s; inf at v = 0). converged : the periodic response was found
    (the residual below the tolerance). stable : every multiplier inside the unit circle
    (at v = 0: every eigenvalue of the vehicle standing at mid-span in the left half-plane).
    largest_multiplier : max |mu| (NaN at v = 0); critical_multiplier (re, im);
    multipliers : the largest ones (re, im pairs); max_real_part : at v = 0 only (1/s).
    gap_dev_max / gap_dev_min (m), current_max / current_min (A), current_reverses.
    midspan_max : largest mid-span deflection of a span under the vehicle (m, downward);
    static_deflection : its static reference (m); daf : their ratio.
    body_acc_peak (m/s^2), wz (Sperling, vertical).
    down, up : the critical disturbance at speed per direction; h (m), w0 (m), chi.
    integration_error, residual, passages, jacobians : diagnostics of the periodic solve.
    warnings : what the numbers cannot be trusted for, in words."""

    __repr__ = compact_repr

    speed: float
    period: float
    converged: bool
    stable: bool | None
    largest_multiplier: float
    critical_multiplier: tuple[float, float]
    multipliers: tuple[tuple[float, float], ...]
    multiplier_method: str
    max_real_part: float
    gap_dev_max: tuple[float, ...]
    gap_dev_min: tuple[float, ...]
    current_max: tuple[float, ...]
    current_min: tuple[float, ...]
    current_reverses: bool
    midspan_max: float
    static_deflection: float
    daf: float
    body_acc_peak: float
    wz: float
    down: SpeedCritical | None
    up: SpeedCritical | None
    h: float
    w0: float
    chi: float
    integration_error: float
    residual: float
    passages: int
    jacobians: int
    samples: int
    warnings: tuple[str, ...] = field(default=())

    @property
    def speed_kmh(self) -> float:
        return self.speed / KMH

    @property
    def gap_dev_abs_max(self) -> float:
        """The largest |c_j - c0| over all points (m)."""
        vals = [abs(v) for v in (*self.gap_dev_max, *self.gap_dev_min)]
        return max(vals) if vals else float("nan")

    @property
    def h_at_ceiling(self) -> bool:
        """h(v) is the search's ceiling, not a measured margin: in the direction that sets
        it every initial deflection up to the gap range returned, so chi(v) is a lower
        bound (no deflection within the gap range was seen to cause contact)."""
        if not np.isfinite(self.h):
            return False
        setting = [c for c in (self.down, self.up)
                   if c is not None and c.supported() is not None and c.supported() == self.h]
        return bool(setting) and all(c.status == CriticalStatus.ALL_RETURN for c in setting)

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["h_at_ceiling"] = self.h_at_ceiling
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> SpeedPoint:
        d = dict(d)
        d.pop("h_at_ceiling", None)  # a property, recomputed
        for k in ("down", "up"):
            if d.get(k) is not None:
                d[k] = SpeedCritical(**d[k])
        for k in ("gap_dev_max", "gap_dev_min", "current_max", "current_min", "warnings"):
            d[k] = tuple(d[k])
        d["critical_multiplier"] = tuple(d["critical_multiplier"])
        d["multipliers"] = tuple(tuple(m) for m in d["multipliers"])
        return cls(**d)


def _nan_point(v: float, params: Params, kind: MovingModel, message: str,
               n_pts: int) -> SpeedPoint:
    nan = float("nan")
    st, _ = mv.static_midspan_deflection(params, kind)
    return SpeedPoint(v, params.L / v if v > 0 else math.inf, False, None, nan, (nan, nan), (),
                      "", nan, (nan,) * n_pts, (nan,) * n_pts, (nan,) * n_pts, (nan,) * n_pts,
                      False, nan, st, nan, nan, nan, None, None, nan, w0_of(params, kind), nan,
                      nan, nan, 0, 0, 0, (message,))


def adiabatic_rate(params: Params, model: str, v: float, positions: int = 40) -> float:
    """The low-speed estimate of ln max|mu| / T (1/s): the mean over one passage of the
    largest real part of the eigenvalues of the vehicle standing at each position (both
    spans elastic), at ``positions`` equally spaced positions of the front (the adiabatic
    limit of a slowly varying linear system; exact as v -> 0 when that eigenvalue stays
    simple)."""
    kind = MovingModel(model)
    T = params.L / v
    reals = []
    for t in (np.arange(positions) + 0.5) * T / positions:
        xf = params.L + v * t
        x = quasi_static_state(params, kind, xf)
        fb, rb = _flags(params, kind, xf)
        p = mv.moving_param_vector(params, kind, v=0.0, x_front=xf, front_on_B=fb,
                                   rear_on_B=rb)
        J = mv.moving_system(params, kind, p).f_and_jacobian(x, p)[1]
        reals.append(float(np.max(np.linalg.eigvals(J[:-1, :-1]).real)))
    return float(np.mean(reals))


def _failed_point(v: float, params: Params, kind: MovingModel, message: str,
                  n_pts: int) -> SpeedPoint:
    """A speed without a periodic response. When the vehicle standing along the span grows
    so fast that the low-speed estimate of the largest multiplier, exp(T x the mean
    growth rate), exceeds 10, the verdict is 'unstable' on that estimate (h = chi = 0) and
    the warning says so; otherwise the verdict stays open."""
    pt = _nan_point(v, params, kind, message, n_pts)
    if v <= 0 or kind is MovingModel.FORCE:
        return pt
    try:
        est = adiabatic_rate(params, kind, v) * params.L / v
    except (FloatingPointError, np.linalg.LinAlgError):
        return pt
    if est > math.log(10.0):
        note = (f"the vehicle standing along the span grows at {est * v / params.L:.3g} 1/s "
                f"on average: the periodic response is strongly unstable (low-speed "
                f"estimate of the largest multiplier exp({est:.3g})) and could not be "
                "computed")
        return dataclasses.replace(pt, stable=False, largest_multiplier=float(math.exp(
            min(est, 700.0))), h=0.0, chi=0.0, warnings=(message, note))
    return pt


def periodic_response(params: Params, model: str, v: float,
                      options: SpeedOptions | None = None) -> PeriodicPassage:
    """The periodic response at speed v (m/s > 0): the fixed point of the span map from the
    quasi-static state at the hand-over, with its multipliers
    (:func:`~maglev_match.dynamics.integrate.passage.solve_periodic_passage`)."""
    opts = options or SpeedOptions()
    kind = MovingModel(model)
    problem = passage_problem(params, kind, v)
    guess = quasi_static_state(params, kind, float(params.L))
    sl = mv.slot_slices(kind, params.n_modes)
    guess[sl["qB"]] = 0.0  # the span ahead is at rest at the hand-over
    guess[sl["qB_dot"]] = 0.0
    return solve_periodic_passage(problem, guess, opts.passage())


def _multiplier_pairs(values: np.ndarray, k: int = 8) -> tuple[tuple[float, float], ...]:
    vals = np.asarray(values, complex)[:k]
    return tuple((float(z.real), float(z.imag)) for z in vals)


def speed_point(params: Params, model: str, v: float,
                options: SpeedOptions | None = None) -> SpeedPoint:
    """All read-outs at one speed v (m/s; v = 0 gives the standstill values,
    :func:`standstill_point`). Failures are reported in the point (``converged`` False and a
    warning), never raised."""
    opts = options or SpeedOptions()
    kind = MovingModel(model)
    n_pts = mv.layout_of(params, kind).n_loads if kind is not MovingModel.FORCE else 0
    if v == 0:
        return standstill_point(params, kind)
    try:
        sol = periodic_response(params, kind, v, opts)
    except FloatingPointError as exc:
        return _failed_point(v, params, kind, f"no periodic response: {exc}", n_pts)
    if not sol.converged or sol.multipliers is None:
        return _failed_point(v, params, kind, f"no periodic response: {sol.message}", n_pts)
    warnings: list[str] = []
    mult = sol.multipliers
    stable = mult.largest < 1.0
    try:
        ro, _ = passage_readouts(sol.problem, sol.run, params, kind, opts)
    except FloatingPointError as exc:
        return _nan_point(v, params, kind, f"read-outs failed: {exc}", n_pts)
    st, _ = mv.static_midspan_deflection(params, kind)
    w0 = w0_of(params, kind)
    reverses = bool(np.any(ro.current_min < 0)) if n_pts else False
    if reverses:
        warnings.append(f"the coil current on the periodic response would reverse (min "
                        f"{float(np.min(ro.current_min)):.3g} A): it is a response of the "
                        "smooth model; the clamped system differs there")
    out_of_range = bool(n_pts and (np.any(ro.gap_dev_min + params.c0 < params.gap_min)
                                   or np.any(ro.gap_dev_max + params.c0 > params.gap_max)))
    if out_of_range:
        warnings.append("the periodic response leaves the physical gap range: the vehicle "
                        "would touch the guideway at this speed")
    if sol.integration_error > 1e-3:
        warnings.append(f"the multipliers may be inaccurate: the variational solve and the "
                        f"state run differ by {sol.integration_error:.2g} (scaled)")
    if not stable:
        warnings.append(f"the periodic response is unstable (largest |multiplier| "
                        f"{mult.largest:.4g})")
    down = up = None
    h = chi = float("nan")
    if kind is MovingModel.FORCE:
        pass
    elif not stable:
        h, chi = 0.0, 0.0
    elif out_of_range:
        h, chi = 0.0, 0.0
    elif opts.critical:
        down, up = critical_disturbance_at_speed(params, kind, v, sol.x0, opts)
        sizes = [c.supported() for c in (down, up)]
        for c in (down, up):
            if c.status == CriticalStatus.OPEN:
                side = "beam down" if c.direction > 0 else "beam up"
                warnings.append(f"critical disturbance ({side}) not resolved: {c.unresolved} "
                                f"run(s) neither returned within {c.spans} spans nor "
                                "collided")
        if all(s is not None for s in sizes):
            h = float(min(sizes))  # type: ignore[type-var]
            chi = h / w0 if w0 > 0 else float("nan")
    crit = mult.critical
    return SpeedPoint(
        speed=float(v), period=float(params.L / v), converged=True, stable=bool(stable),
        largest_multiplier=float(mult.largest),
        critical_multiplier=(float(crit.real), float(crit.imag)),
        multipliers=_multiplier_pairs(mult.values), multiplier_method=mult.method,
        max_real_part=float("nan"),
        gap_dev_max=tuple(map(float, ro.gap_dev_max)),
        gap_dev_min=tuple(map(float, ro.gap_dev_min)),
        current_max=tuple(map(float, ro.current_max)),
        current_min=tuple(map(float, ro.current_min)), current_reverses=reverses,
        midspan_max=float(ro.midspan_max), static_deflection=float(st),
        daf=float(ro.midspan_max / st) if st > 0 else float("nan"),
        body_acc_peak=float(ro.body_acc_peak), wz=float(ro.wz), down=down, up=up, h=h,
        w0=float(w0), chi=chi, integration_error=float(sol.integration_error),
        residual=float(sol.residual), passages=int(sol.passages), jacobians=int(sol.jacobians),
        samples=int(ro.samples), warnings=tuple(warnings))


def standstill_point(params: Params, model: str) -> SpeedPoint:
    """The values at v = 0: the vehicle standing at mid-span on slot A (its layout
    centred), both spans elastic. Stability from the eigenvalues of the Jacobian there (no
    passage, no multipliers); DAF = the equilibrium's mid-span deflection over the static
    reference (1 up to the levitation's redistribution of the weights); Wz and the
    acceleration 0; the critical disturbance at speed is undefined (no span is entered)."""
    kind = MovingModel(model)
    lay = mv.layout_of(params, kind)
    n_pts = lay.n_loads if kind is not MovingModel.FORCE else 0
    x_front = 0.5 * (params.L + lay.extent)
    x = quasi_static_state(params, kind, x_front)
    fb, rb = _flags(params, kind, x_front)
    p = mv.moving_param_vector(params, kind, v=0.0, x_front=x_front, front_on_B=fb,
                               rear_on_B=rb)
    system = mv.moving_system(params, kind, p)
    n = system.dim - 1
    J = system.jacobian(x, p)[:n, :n]
    lam = np.linalg.eigvals(J)
    mr = float(np.max(lam.real))
    st, _ = mv.static_midspan_deflection(params, kind)
    mid = float(np.max(system.observe("midspan", x, p)))
    nan = float("nan")
    if n_pts:
        gd = tuple(map(float, np.atleast_1d(system.observe("gap_deviation", x, p))))
        cu = tuple(map(float, np.atleast_1d(system.observe("current", x, p))))
    else:
        gd = cu = ()
    return SpeedPoint(
        speed=0.0, period=math.inf, converged=True, stable=bool(mr < 0),
        largest_multiplier=nan, critical_multiplier=(nan, nan), multipliers=(),
        multiplier_method="eigenvalues (v = 0)", max_real_part=mr, gap_dev_max=gd,
        gap_dev_min=gd, current_max=cu, current_min=cu,
        current_reverses=bool(cu and min(cu) < 0), midspan_max=mid, static_deflection=st,
        daf=mid / st if st > 0 else nan, body_acc_peak=0.0 if n_pts else nan,
        wz=0.0 if n_pts else nan, down=None, up=None, h=nan, w0=w0_of(params, kind), chi=nan,
        integration_error=nan, residual=0.0, passages=0, jacobians=0, samples=0,
        warnings=("v = 0: the vehicle standing at mid-span (no span is entered, so the "
                  "critical disturbance at speed and chi(v) are not defined there; the "
                  "standstill index is `maglev-match index`)",))


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
    folder. Dask's own messages are left where Dask puts them."""
    job = Job(pieces=spec.tiles, compute=compute, args_of=lambda rows: (spec, rows),
              store=lambda folder: tile_checkpoint(folder, spec.key(), variables, nx))
    return run_job(job, checkpoint, resume=resume, scheduler=scheduler, workers=workers,
                   progress=progress, capture_dask=False,
                   scratch_prefix="maglev-match-speed-")


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
            "warnings": list(self.warnings),
        }


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
    ceiling = [p for p in pts if p.h_at_ceiling]
    if ceiling:
        warnings.append(
            f"at {len(ceiling)} of {len(pts)} speeds (" + ", ".join(
                f"{p.speed / KMH:.4g}" for p in ceiling[:6]) + (", ..." if len(ceiling) > 6
                                                                 else "")
            + " km/h) every initial deflection up to the gap range returned: h(v) there is "
            "the search's ceiling (the gap range), so chi(v) is a lower bound, not a "
            "measured margin")
    res = resonance_speeds(params, kind, min(vals), max(vals)) if max(vals) > 0 else ()
    return SpeedSweep(params=params, model=kind.value, points=tuple(pts), resonances=res,
                      stability_changes=tuple(changes), options=opts,
                      warnings=tuple(warnings))


# ---------------------------------------------------------------------------------------
# the dataset
# ---------------------------------------------------------------------------------------
SWEEP_UNITS = {
    "speed": "m/s", "speed_kmh": "km/h", "period": "s", "converged": "1", "stable": "1",
    "largest_multiplier": "1", "critical_multiplier_real": "1",
    "critical_multiplier_imag": "1", "max_real_part": "1/s", "gap_dev_max": "m",
    "gap_dev_min": "m", "current_max": "A", "current_min": "A", "current_reverses": "1",
    "midspan_max": "m", "static_deflection": "m", "daf": "1", "body_acc_peak": "m/s^2",
    "wz": "1", "h": "m", "h_down": "m", "h_up": "m", "h_at_ceiling": "1", "w0": "m",
    "chi": "1",
    "integration_error": "1", "point": "1",
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
    "h": "critical initial deflection of the span being entered (smaller direction)",
    "h_down": "critical initial deflection, beam down (gaps close)",
    "h_up": "critical initial deflection, beam up (gaps open)",
    "h_at_ceiling": "h is the search's ceiling (1: every deflection up to the gap range "
                    "returned; chi is then a lower bound) or a measured margin (0)",
    "w0": "static deflection of the standstill index (same model)",
    "chi": "matching index at speed chi(v) = h(v) / w0",
    "integration_error": "variational solve against state run, scaled",
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
        "h_down": (("speed",), np.array([crit(p, "down") for p in pts])),
        "h_up": (("speed",), np.array([crit(p, "up") for p in pts])),
        "h_at_ceiling": (("speed",), np.array([p.h_at_ceiling for p in pts], np.int8)),
        "w0": (("speed",), sweep.column("w0")),
        "chi": (("speed",), sweep.column("chi")),
        "integration_error": (("speed",), sweep.column("integration_error")),
    }
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
        "options": json.dumps(sweep.options.key()),
        "points": json.dumps([p.to_json() for p in pts], default=float),
    })
    return annotate(ds, sweep.params)
