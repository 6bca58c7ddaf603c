"""The vehicle at speed over a guideway of N spans: one run from rigid ground (the
abutment) over the spans and off them again, with the physical limits, the periodic response
of :mod:`maglev_match.analyses.speed.point` overlaid (behind ``maglev-match simulate --speed V
--spans
N``)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from maglev_match.analyses.speed.options import SpeedOptions, check_speed_setup
from maglev_match.analyses.speed.passage import (
    CHUNK,
    PassageSamples,
    integrate_saving,
    observe_all,
    observe_samples,
    passage_problem,
    sample_passage,
    sample_times,
)
from maglev_match.analyses.speed.point import periodic_response
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.integrate.simulate import EventsWithArgs, SimulationOptions, simulate
from maglev_match.maglev import moving as mv
from maglev_match.maglev.moving import MovingModel

__all__ = ["SpanRun", "simulate_over_spans"]


@dataclass(frozen=True)
class SpanRun(Plottable):
    """A run from rigid ground (the abutment) over ``spans`` spans and off onto rigid
    ground again, at constant speed (m/s): N + 1 passages, passage k starting when the
    front of the vehicle reaches support k - 1.

    t (s); gap_deviation, current (k, points); body_acceleration (k,); midspan (k, spans):
    the mid-span deflection of every span while the vehicle is on it (NaN before the front
    reaches it and after the rear has left it); span_starts :
    start time of every passage (s). outcome : 'ok', 'collision' or 'failed';
    collision_time (s), collision_point (1-based), collision_limit ('lower'/'upper').
    periodic_gap, periodic_acceleration : the periodic response at the same times
    (repeated passage after passage), or None. passage_starts : the segment start states
    of every passage (for refined read-outs of a passage). limited : the physical limits
    were on. per_span_midspan_max (m) : the largest deflection of each span;
    per_passage_gap_max (m) : the largest |gap deviation| in each passage."""

    __repr__ = compact_repr

    params: Params
    model: str
    speed: float
    spans: int
    limited: bool
    t: np.ndarray
    gap_deviation: np.ndarray
    current: np.ndarray
    body_acceleration: np.ndarray
    midspan: np.ndarray
    span_starts: np.ndarray
    outcome: str
    collision_time: float | None
    collision_point: int | None
    collision_limit: str | None
    periodic_gap: np.ndarray | None
    periodic_acceleration: np.ndarray | None
    passage_starts: tuple[np.ndarray, ...]
    per_span_midspan_max: np.ndarray
    per_passage_gap_max: np.ndarray
    warnings: tuple[str, ...] = field(default=())
    #: the guideway irregularity under the run (its description and seed), or None
    irregularity: str | None = None

    def summary(self) -> dict[str, Any]:
        return {
            "model": self.model, "speed": self.speed, "spans": self.spans,
            "limits": self.limited, "outcome": self.outcome,
            "collision_time": self.collision_time, "collision_point": self.collision_point,
            "collision_limit": self.collision_limit,
            "span_midspan_max": [float(v) for v in self.per_span_midspan_max],
            "passage_gap_deviation_max": [float(v) for v in self.per_passage_gap_max],
            "warnings": list(self.warnings),
        } | ({} if self.irregularity is None else {"irregularity": self.irregularity})

    def to_xarray(self):
        """The histories as an :class:`xarray.Dataset` over ``time`` (s), with units."""
        import xarray as xr

        from maglev_match.core.datasets import annotate

        data = {"body_acceleration": (("time",), self.body_acceleration),
                "midspan": (("time", "span"), self.midspan)}
        coords = {"time": ("time", self.t), "span": ("span", np.arange(1, self.spans + 1))}
        if self.gap_deviation.shape[1]:
            data["gap_deviation"] = (("time", "point"), self.gap_deviation)
            data["current"] = (("time", "point"), self.current)
            coords["point"] = ("point", np.arange(1, self.gap_deviation.shape[1] + 1))
            if self.periodic_gap is not None:
                data["periodic_gap_deviation"] = (("time", "point"), self.periodic_gap)
        if self.periodic_acceleration is not None:
            data["periodic_body_acceleration"] = (("time",), self.periodic_acceleration)
        ds = xr.Dataset(data, coords=coords)
        ds.attrs.update({"title": "maglev-match run over spans", "model": self.model,
                         "speed": self.speed, "speed_units": "m/s", "spans": self.spans,
                         "outcome": self.outcome, "limits": int(self.limited),
                         "span_starts": json.dumps([float(v) for v in self.span_starts]),
                         "warnings": json.dumps(list(self.warnings))})
        if self.irregularity is not None:
            ds.attrs["irregularity"] = self.irregularity
        if self.collision_time is not None:
            ds.attrs.update({"collision_time": self.collision_time,
                             "collision_point": self.collision_point,
                             "collision_limit": self.collision_limit})
        return annotate(ds, self.params, units={
            "body_acceleration": "m/s^2", "midspan": "m", "span": "1",
            "periodic_gap_deviation": "m", "periodic_body_acceleration": "m/s^2"},
            long_names={
                "body_acceleration": "car-body vertical acceleration (down positive)",
                "midspan": "mid-span deflection of each span (down positive; NaN while the "
                           "span is not under the vehicle's model)",
                "span": "span number (1-based, in the direction of travel)",
                "periodic_gap_deviation": "gap deviation of the periodic response",
                "periodic_body_acceleration": "car-body acceleration of the periodic "
                                              "response"})

def _integrate_events(system, x_start, t_rel, p, sim, events):
    """As :func:`integrate_saving`, with an event function: returns (states up to the
    event, relative event time or None, event entry or None, state at the event)."""
    out = []
    x = np.array(x_start, float)
    t_now = 0.0
    k = 0
    while k < t_rel.size:
        chunk = t_rel[k:k + CHUNK]
        s = chunk - t_now
        if s[-1] <= 0.0:
            out.append(np.tile(x, (chunk.size, 1)))
            k += chunk.size
            continue
        save = np.maximum(np.concatenate([s, np.full(CHUNK - s.size, s[-1])]), 0.0)
        res = simulate(system, x, float(s[-1]), p=p, x_ref=x, options=sim, n_save=CHUNK,
                       t_save=save, event_fn=events)
        if res.outcome == "failed":
            raise FloatingPointError("a run over the spans failed: " + "; ".join(res.warnings))
        X = np.array(res.x[: s.size], float)
        if res.outcome == "collision":
            ok = np.all(np.isfinite(X), axis=1) & (s <= float(res.event_time))
            Xo = X[ok]
            Xo[:, -1] = x[-1] + s[ok]
            out.append(Xo)
            ev = np.array(res.event_state, float)
            ev[-1] = x[-1] + float(res.event_time)
            return np.concatenate(out), t_now + float(res.event_time), res.event_index, ev
        X[:, -1] = x[-1] + s
        out.append(X)
        x = X[-1].copy()
        t_now = float(chunk[-1])
        k += chunk.size
    return np.concatenate(out), None, None, None


def simulate_over_spans(params: Params, model: str, v: float, spans: int, *,
                        limited: bool = True, options: SpeedOptions | None = None,
                        overlay: bool = True, max_samples: int = 400_000,
                        profile=None, seed: int = 0) -> SpanRun:
    """Run the vehicle from rigid ground over ``spans`` identical spans and off them at speed
    v (m/s > 0), from its equilibrium on rigid ground with every span at rest; the physical
    limits (current clamp, gap range: a collision ends the run) unless ``limited`` is False.
    With ``overlay`` the periodic response is computed and repeated passage after passage
    beside the run. At most ``max_samples`` saved times in all (each passage sampled as the
    read-outs are, fewer if that would exceed it). ``profile``: a guideway irregularity
    (:class:`~maglev_match.maglev.irregularity.Irregularity`, drawn with ``seed`` if
    random) under every levitation point; then no overlay."""
    opts = options or SpeedOptions()
    kind = check_speed_setup(params, model, [v], spans, delay=False,
                             refuse_delay="a run over a finite number of spans has no "
                             "delay of the outer loop yet")
    if not v > 0:
        raise ParameterError("--speed", v, "must be > 0 for a run over spans")
    L = float(params.L)
    T = L / v
    problems = {
        "first": passage_problem(params, kind, v, limited=limited, approach_rigid=True,
                                 profile=profile),
        "mid": passage_problem(params, kind, v, limited=limited, profile=profile),
        "last": passage_problem(params, kind, v, limited=limited, exit_rigid=True,
                                profile=profile),
    }
    waves = None if profile is None else profile.n_waves
    if profile is not None:
        overlay = False
    sys_ = problems["mid"].system
    events = (EventsWithArgs(mv.gap_events(kind, params.n_modes, waves),
                             (float(params.gap_min), float(params.gap_max)))
              if limited and kind is not MovingModel.FORCE else None)
    sim = SimulationOptions(rtol=opts.rtol, atol=opts.atol, max_steps=1_000_000)
    grid = sample_times(params, T, opts)
    if (grid.size - 1) * (spans + 1) > max_samples:
        grid = np.linspace(0.0, T, max(64, max_samples // (spans + 1)) + 1)
    x = mv.rigid_equilibrium(params, kind)
    if profile is not None:  # start on the profile, not on a jump to it
        p1 = problems["first"].segments[0].p
        n0 = p1.size - profile.zero_vector().size
        x = mv.follow_profile(params, kind, x, np.concatenate(
            [p1[:n0], profile.vector(1, spans, L, seed)]), profile.n_waves)
    n_pts = mv.layout_of(params, kind).n_loads if kind is not MovingModel.FORCE else 0
    t_all, gaps, curs, accs, mids = [], [], [], [], []
    starts_all: list[np.ndarray] = []
    outcome, t_hit, p_hit, lim_hit = "ok", None, None, None
    warnings: list[str] = []
    for k in range(1, spans + 2):
        prob = problems["first"] if k == 1 else (problems["last"] if k == spans + 1
                                                 else problems["mid"])
        bounds = np.concatenate([prob.starts, [T]])
        seg_of = np.clip(np.searchsorted(bounds, grid[:-1], side="right") - 1, 0,
                         len(prob.segments) - 1)
        starts = []
        xk = np.array(x, float)
        xk[-1] = 0.0
        mid = np.full((grid.size - 1, spans), np.nan)
        for j, seg in enumerate(prob.segments):
            starts.append(xk.copy())
            idx = np.nonzero(seg_of == j)[0]
            t_rel = np.concatenate([grid[idx] - bounds[j], [seg.duration]])
            if profile is not None:  # this passage's profile entries
                n0 = seg.p.size - profile.zero_vector().size
                seg = type(seg)(seg.duration, np.concatenate(
                    [seg.p[:n0], profile.vector(k, spans, L, seed)]))
            Xs, te, ie, xe = _integrate_events(prob.system, xk, t_rel, seg.p, sim, events)
            kept = Xs[:-1] if te is None else Xs[Xs[:, -1] < bounds[j] + seg.duration - 1e-15]
            if kept.shape[0] > idx.size:
                kept = kept[:idx.size]
            ids = idx[:kept.shape[0]]
            if ids.size:
                t_all.append((k - 1) * T + grid[ids])
                vals = observe_all(sys_, kept, seg.p)
                if n_pts:
                    gaps.append(vals["gap_deviation"])
                    curs.append(vals["current"])
                    accs.append(vals["body_acceleration"].ravel())
                ms = vals["midspan"]
                # the span behind is drawn while the vehicle is on it: once the rear has
                # left it, it is no longer part of the model (its frozen state is not a
                # motion)
                if k >= 2 and seg.p[prob.system.param_index("active_A")] > 0.5:
                    mid[ids, k - 2] = ms[:, 0]
                if k <= spans:
                    mid[ids, k - 1] = ms[:, 1]
            if te is not None:
                outcome = "collision"
                t_hit = (k - 1) * T + bounds[j] + te
                p_hit, lim_hit = int(ie) // 2 + 1, ("lower", "upper")[int(ie) % 2]
                mids.append(mid[:ids.size] if ids.size else mid[:0])
                break
            xk = np.array(Xs[-1], float)
            xk[-1] = bounds[j] + seg.duration
        starts_all.append(np.array(starts))
        if outcome == "collision":
            break
        mids.append(mid)
        x = prob.apply_jump(xk)
    t = np.concatenate(t_all) if t_all else np.zeros(0)
    gap = np.concatenate(gaps) if gaps else np.zeros((t.size, 0))
    cur = np.concatenate(curs) if curs else np.zeros((t.size, 0))
    acc = np.concatenate(accs) if accs else np.full(t.size, np.nan)
    mid_all = np.concatenate(mids)[: t.size] if mids else np.zeros((0, spans))
    per_pass = np.array([np.nanmax(np.abs(gap[(t >= (k - 1) * T) & (t < k * T)]))
                         if gap.size and np.any((t >= (k - 1) * T) & (t < k * T)) else np.nan
                         for k in range(1, spans + 2)])
    per_span = np.array([np.nanmax(mid_all[:, s]) if np.any(np.isfinite(mid_all[:, s]))
                         else np.nan for s in range(spans)])
    pg = pa = None
    if overlay and kind is not MovingModel.FORCE:
        pt = periodic_response(params, kind, v, opts)
        if pt.converged:
            samples = sample_passage(pt.problem, pt.run, params, opts, sim) \
                if grid.size == sample_times(params, T, opts).size else None
            if samples is None:  # the run's coarser grid: sample the periodic response on it
                bounds = np.concatenate([pt.problem.starts, [T]])
                seg = np.clip(np.searchsorted(bounds, grid, side="right") - 1, 0,
                              len(pt.problem.segments) - 1)
                X = np.empty((grid.size, pt.problem.system.dim))
                for j, sg in enumerate(pt.problem.segments):
                    idx = np.nonzero(seg == j)[0]
                    if idx.size:
                        X[idx] = integrate_saving(pt.problem.system, pt.run.starts[j],
                                                   grid[idx] - bounds[j], sg.p, sim)
                samples = PassageSamples(grid, X, seg, pt.problem, pt.run.starts)
            pgap = observe_samples(samples, "gap_deviation")
            pacc = observe_samples(samples, "body_acceleration")
            rel = np.mod(t, T)
            kk = np.clip(np.rint(rel / (grid[1] - grid[0])).astype(int), 0, grid.size - 1)
            pg, pa = pgap[kk], pacc[kk, 0]
        else:
            warnings.append(f"no periodic response to overlay: {pt.message}")
    return SpanRun(params=params, model=kind.value, speed=float(v), spans=int(spans),
                   limited=bool(limited), t=t, gap_deviation=gap, current=cur,
                   body_acceleration=acc, midspan=mid_all,
                   span_starts=np.arange(spans + 1) * T, outcome=outcome,
                   collision_time=t_hit, collision_point=p_hit, collision_limit=lim_hit,
                   periodic_gap=pg, periodic_acceleration=pa,
                   passage_starts=tuple(starts_all), per_span_midspan_max=per_span,
                   per_passage_gap_max=per_pass, warnings=tuple(warnings),
                   irregularity=None if profile is None else (
                       profile.describe() + ("" if profile.kind != "random"
                                             else f"; this run: seed {seed}")))


