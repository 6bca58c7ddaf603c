"""One span passage at speed: the problem, its samples and its read-outs.

With identical spans the steady motion repeats every span: one *passage* lasts T = L / v,
from the moment the front of the vehicle reaches a support (the span ahead enters the
model, at rest) to the moment it reaches the next one, and ends with the hand-over of the
span slots (:mod:`maglev_match.maglev.moving`). Between support crossings of the loads the
vector field is smooth; the passage is integrated segment by segment
(:func:`passage_problem`: the segments with their slot flags, the hand-over as a linear
jump; :mod:`maglev_match.dynamics.integrate.passage`). :func:`quasi_static_state` is the
vehicle standing still at a position, the start of the periodic solve.

Read-outs over one passage (:func:`passage_readouts`): the largest and smallest gap
deviation and current per levitation point, the largest mid-span deflection of a span
under the vehicle, the car body's peak vertical acceleration and Sperling's Wz of its
spectrum (:mod:`maglev_match.analyses.speed.ride`). Extrema are located on samples at least
``samples_per_period`` per period of the fastest beam mode and refined by integrating again
between the neighbours of the best samples."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.analyses.speed.options import SpeedOptions
from maglev_match.analyses.speed.ride import sperling_of_periodic
from maglev_match.core.aot import cached_kernel
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.integrate.passage import SAVE_SLOTS, PassageProblem, Segment
from maglev_match.dynamics.integrate.simulate import SimulationOptions, simulate
from maglev_match.maglev import moving as mv
from maglev_match.maglev import moving_delay as md
from maglev_match.maglev.moving import MovingModel

__all__ = ["CHUNK", "slot_flags", "passage_problem", "lift_state", "quasi_static_state",
           "observe_all", "sample_times", "integrate_saving", "passage_states", "PassageSamples",
           "sample_passage", "observe_samples", "PassageReadouts", "passage_readouts"]

CHUNK = SAVE_SLOTS  # saved times per integrator call: one compiled kernel for every run


def slot_flags(params: Params, kind: MovingModel, x_front: float) -> tuple[np.ndarray, np.ndarray]:
    """Whether the front and the rear of the vehicle's layout are on slot B (1.0) or not
    (0.0) with the front at ``x_front`` (m from slot A's left support)."""
    lay = mv.layout_of(params, kind)
    xf = x_front + lay.front
    return (xf > params.L).astype(float), (xf - lay.length > params.L).astype(float)


def passage_problem(params: Params, model: str, v: float, *, limited: bool = False,
                    approach_rigid: bool = False, exit_rigid: bool = False,
                    profile=None, tau_max: float | None = None) -> PassageProblem:
    """One span passage at speed v (m/s > 0) as a
    :class:`~maglev_match.dynamics.integrate.passage.PassageProblem`: segments between the support
    crossings of the loads' edges, each with its slot flags; the jump hands slot B over to
    A and brings a fresh span at rest into B. ``approach_rigid``: slot A is rigid ground
    (the abutment before the first span); ``exit_rigid``: slot B is (after the last).
    ``profile``: an :class:`~maglev_match.maglev.irregularity.Irregularity`; the segments'
    parameter vectors then end with its (zero) entries, which a run over the spans sets per
    passage (:meth:`~maglev_match.maglev.irregularity.Irregularity.vector`). With a delay
    ``params.tau`` > 0 (or ``tau_max``, the discretisation then sized for delays up to it)
    the system is the discretised delayed model (:mod:`maglev_match.maglev.moving_delay`),
    every segment's vector ends with tau, and the hand-over keeps the commands' history."""
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
        fb, rb = slot_flags(params, kind, L + v * tm)
        loaded_a = bool(np.any(L + v * tm + lay.front - lay.length < L))
        act = (0.0 if (approach_rigid or not loaded_a) else 1.0, 0.0 if exit_rigid else 1.0)
        p = mv.moving_param_vector(params, kind, v=v, x_front=L, active=act, front_on_B=fb,
                                   rear_on_B=rb)
        if profile is not None:
            p = np.concatenate([p, profile.zero_vector()])
        segs.append(Segment(float(b - a), p))
    waves = None if profile is None else profile.n_waves
    if params.tau > 0 or tau_max is not None:
        system = md.moving_delay_system(params, kind, segs[0].p, tau=float(params.tau),
                                        limited=limited, period=T, waves=waves,
                                        tau_max=tau_max)
        segs = [Segment(s.duration, md.delayed_vector(s.p, params.tau)) for s in segs]
    else:
        system = mv.moving_system(params, kind, segs[0].p, limited=limited, period=T,
                                  waves=waves)
    sl = mv.slot_slices(kind, params.n_modes)
    n = system.dim - 1
    R = np.eye(n)
    for blk in ("qA", "qA_dot", "qB", "qB_dot"):
        R[sl[blk], :] = 0.0
    m = params.n_modes
    R[sl["qA"], sl["qB"]] = np.eye(m)
    R[sl["qA_dot"], sl["qB_dot"]] = np.eye(m)
    return PassageProblem(system, tuple(segs), R)


def lift_state(problem: PassageProblem, x: np.ndarray) -> np.ndarray:
    """A moving model's state (clock last) as a state of ``problem``'s system: unchanged
    for a delay-free model; with the delayed model, the constant past of the commands
    (every history node holds the commands of ``x``)."""
    x = np.asarray(x, float)
    if x.shape[-1] == problem.system.dim:
        return x
    return problem.system.lift(x, problem.segments[0].p)


def quasi_static_state(params: Params, model: str, x_front: float, *, tol: float = 1e-12,
                       max_iter: int = 30) -> np.ndarray:
    """The equilibrium of the model with the vehicle standing still, the front of its layout
    at ``x_front`` (m from slot A's left support; L is the support between A and B), both
    spans elastic: Newton's method with the exact (autodiff) Jacobian from the equilibrium
    on a rigid guideway. Raises FloatingPointError when Newton does not converge."""
    kind = MovingModel(model)
    fb, rb = slot_flags(params, kind, x_front)
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
