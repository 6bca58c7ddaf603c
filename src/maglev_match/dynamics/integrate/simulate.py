"""Time integration of an autonomous :class:`System` with terminal limit events.

Model-agnostic: nothing here knows about maglev. A run integrates ``x' = rhs(x, p)`` with
an explicit Runge-Kutta method of diffrax (Dopri8 by default) and an adaptive PID step-size
controller, in a hand-written step loop so that every accepted step can be inspected
through the solver's dense interpolant:

* **Limit events.** An event function ``g(x, p) -> array`` (m entries) describes limits;
  a negative entry means "this limit has been left" and ends the run. Inside every
  accepted step ``[t_a, t_b]`` the interpolant is sampled at ``samples + 1`` equally spaced
  times; every entry whose sampled minimum is not negative but below its variation over
  the step has its minimum refined by zooming in on the two sub-intervals around its
  smallest sample (6 rounds of 8-section), so an entry that dips below zero and comes back
  *within one step* (grazing) is still caught, for every levitation point at once. The
  first crossing is then located by repeated 16-section of ``g(interpolant(t))`` (keeping
  the first negative point each round) to about 1e-15 of the step length.
* **Convergence.** With a reference state ``x_ref`` (an equilibrium), the scaled distance
  ``d(t) = max_i |x_i - x_ref_i| / scale_i`` is checked at the end of every accepted step.
  Being close is not enough: near an unstable equilibrium a small disturbance stays small
  for a long time while it grows (slowly, just past a Hopf point). So the run counts as
  *converged* only when ``d <= converge_tol`` has held without interruption for
  ``hold_time`` seconds **and** the disturbance must decay: the reference state is a
  linearly stable equilibrium, i.e. its residual ``max_i |f_i(x_ref)| / scale_i`` is below
  ``converge_tol / hold_time`` (it would not drift out of the tolerance within the hold
  time) and every eigenvalue of the Jacobian there has a negative real part (Lyapunov's
  first method: a hyperbolic equilibrium with Re(lambda) < 0 attracts every nearby
  solution exponentially, Kuznetsov 2004, Theorem 2.1 and sec. 2.1). A state that stayed
  within ``decay_floor`` of the reference state over the whole hold time (an exactly
  steady run) is converged as well. ``converged_time`` is when the last uninterrupted
  stretch began; ``reference_max_real`` of the result is the largest real part of the
  eigenvalues (1/s). With ``stop_on_converged`` the run stops as soon as it has converged
  (for basin bisection). A run that stays close to an unstable (or non-hyperbolic, or
  non-stationary) reference state ends as ``running`` with a warning saying so.
* **Outcomes.** ``collision`` (an event fired: time, entry index, state), ``converged``,
  ``running`` (neither by the horizon), ``failed`` (non-finite state, ``max_steps``
  exhausted, or the step size driven down to the resolution of t by rejected steps, i.e.
  a singularity of the solution; never silently reported as one of the others).

The solver works in scaled coordinates ``z = x / state_scale`` so one absolute tolerance
``atol`` means "atol times the typical size" of every state; ``rtol`` is relative.

Batches: :func:`simulate_batch` maps the same compiled kernel over many initial states
and/or parameter vectors with ``jax.vmap``. Compiled kernels are cached per
(right-hand side, event function, solver, options), so repeated calls do not recompile.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from functools import lru_cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.aot import cached_kernel
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.system import System

Array = Any
EventFn = Callable[[Array, Array], Array]

__all__ = [
    "OUTCOMES",
    "Outcome",
    "SimulationOptions",
    "SimulationResult",
    "BatchSimulation",
    "EventsWithArgs",
    "simulate",
    "simulate_batch",
]

class Outcome(StrEnum):
    """How a run ended (compares equal to its string value)."""

    RUNNING = "running"  # neither collided nor converged by the horizon (incl. not decaying)
    COLLISION = "collision"  # an event entry went negative
    CONVERGED = "converged"  # close to the reference state and decaying (module docstring)
    FAILED = "failed"  # non-finite state or max_steps exhausted


# outcome codes used inside the kernel
RUNNING, COLLISION, CONVERGED, FAILED = 0, 1, 2, 3
OUTCOMES = (Outcome.RUNNING, Outcome.COLLISION, Outcome.CONVERGED, Outcome.FAILED)

UNROLL_MAX_DIM = 16  # systems up to this many states get the written-out RK stages
SAVE_BLOCK = 8  # saved times written per vectorised interpolant evaluation

# solver name -> diffrax class name (diffrax is imported when a kernel is first built, so
# commands that never simulate do not pay its import, ~0.3 s)
_SOLVERS = {
    "dopri8": "Dopri8",
    "dopri5": "Dopri5",
    "tsit5": "Tsit5",
}


@dataclass(frozen=True)
class SimulationOptions:
    """Integrator settings.

    rtol, atol : relative tolerance and absolute tolerance in units of ``state_scale``.
    solver : 'dopri8' (default), 'dopri5' or 'tsit5'.
    samples : interpolant samples per step for the event search (>= 2).
    converge_tol : scaled distance to ``x_ref`` that counts as "at the reference state".
    hold_time : how long (s) the distance must stay below ``converge_tol``.
    decay_floor : a run whose scaled distance to the reference state stayed below this over
        the whole hold time is converged even if the reference state is not a stable
        equilibrium (an exactly steady run; the integrator's noise level).
    stop_on_converged : end a run as soon as it has converged.
    max_steps : bound on attempted steps per run (reported as 'failed' when hit).
    dt0 : initial step (s); None lets diffrax choose.
    unroll_stages : write the Runge-Kutta stages out in the compiled step (True), use
        diffrax's loop over the stages (False), or decide by size (None: written out for
        up to 16 states, where it is faster). Same method and tableau either way.
    """

    rtol: float = 1e-8
    atol: float = 1e-8
    solver: str = "dopri8"
    samples: int = 8
    converge_tol: float = 0.05
    hold_time: float = 1.0
    decay_floor: float = 1e-6
    stop_on_converged: bool = False
    max_steps: int = 200_000
    dt0: float | None = None
    unroll_stages: bool | None = None


@dataclass(frozen=True)
class SimulationResult:
    """One run.

    t : saved times (s), shape (n_save,); x : saved states, shape (n_save, dim); rows at
        times after the run ended (collision, early stop) are NaN.
    outcome : 'collision' | 'converged' | 'running' | 'failed'.
    event_time : collision time (s) or None; event_index : entry of g that went negative
        or None; event_state : state at the collision or None.
    final_time, final_state : where the run ended (the collision point for a collision).
    converged_time : start (s) of the final uninterrupted stretch within ``converge_tol``
        of the reference state, or None (set only for a converged run).
    reference_max_real : largest real part (1/s) of the eigenvalues of the Jacobian at the
        reference state (negative: a disturbance decays; module docstring).
    reference_residual : max_i |f_i(x_ref)| / scale_i (1/s): how far the reference state is
        from being an equilibrium.
    min_event_value : smallest value of each entry of g seen over the run (sampled inside
        steps), shape (m,).
    steps, accepted, rejected : step counts. warnings : messages.
    """

    __repr__ = compact_repr

    t: np.ndarray
    x: np.ndarray
    outcome: str
    event_time: float | None
    event_index: int | None
    event_state: np.ndarray | None
    final_time: float
    final_state: np.ndarray
    converged_time: float | None
    min_event_value: np.ndarray
    steps: int
    accepted: int
    rejected: int
    warnings: tuple[str, ...] = field(default=())
    reference_max_real: float = float("nan")
    reference_residual: float = float("nan")

    @property
    def collided(self) -> bool:
        return self.outcome == "collision"


@dataclass(frozen=True)
class BatchSimulation:
    """Many runs of one system (arrays have the batch size as leading axis).

    outcome : array of strings; outcome_code : 0 running, 1 collision, 2 converged, 3 failed.
    event_time : NaN where no collision; event_index : -1 where no collision.
    reference_max_real, reference_residual : as in :class:`SimulationResult`, per run.
    t, x : saved times (n_save,) and histories (batch, n_save, dim) (x is None when no
        history was requested).
    """

    __repr__ = compact_repr

    outcome: np.ndarray
    outcome_code: np.ndarray
    event_time: np.ndarray
    event_index: np.ndarray
    final_time: np.ndarray
    final_state: np.ndarray
    converged_time: np.ndarray
    min_event_value: np.ndarray
    steps: np.ndarray
    t: np.ndarray
    x: np.ndarray | None
    accepted: np.ndarray | None = None
    rejected: np.ndarray | None = None
    reference_max_real: np.ndarray | None = None
    reference_residual: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.outcome)

    def run(self, k: int) -> SimulationResult:
        """Run ``k`` as a :class:`SimulationResult`."""
        code = int(self.outcome_code[k])
        hit = code == COLLISION
        return SimulationResult(
            t=self.t,
            x=self.x[k] if self.x is not None else np.empty((0, self.final_state.shape[1])),
            outcome=OUTCOMES[code],
            event_time=float(self.event_time[k]) if hit else None,
            event_index=int(self.event_index[k]) if hit else None,
            event_state=self.final_state[k] if hit else None,
            final_time=float(self.final_time[k]),
            final_state=self.final_state[k],
            converged_time=(None if not np.isfinite(self.converged_time[k])
                            else float(self.converged_time[k])),
            min_event_value=self.min_event_value[k],
            steps=int(self.steps[k]),
            accepted=int(self.accepted[k]) if self.accepted is not None else -1,
            rejected=int(self.rejected[k]) if self.rejected is not None else -1,
            reference_max_real=(float(self.reference_max_real[k])
                                if self.reference_max_real is not None else float("nan")),
            reference_residual=(float(self.reference_residual[k])
                                if self.reference_residual is not None else float("nan")),
        )


def _no_events(x, p):
    return jnp.zeros((0,), dtype=x.dtype)


@dataclass(frozen=True)
class EventsWithArgs:
    """An event function with numeric arguments that are *traced* inputs of the compiled
    integrator, not constants baked into it: ``fn(x, p, args) -> array`` (the same meaning
    as an ``event_fn``), ``args`` a tuple of floats (e.g. the gap limits in m). Runs with
    the same ``fn`` and different ``args`` share one compiled kernel (a new limit value
    does not recompile). Called as ``events(x, p)`` it is an ordinary event function."""

    fn: Callable[[Array, Array, Array], Array]
    args: tuple[float, ...]

    def __call__(self, x, p):
        return self.fn(x, p, jnp.asarray(self.args, dtype=jnp.float64))


@lru_cache(maxsize=64)
def _event_caller(event_fn, with_args: bool):
    """``g(x, p, args)`` for the kernel: the function of an :class:`EventsWithArgs`, or a
    plain ``event_fn(x, p)`` that ignores ``args`` (cached: a stable object per function,
    so compiled kernels are reused)."""
    if with_args:
        return event_fn

    def call(x, p, args):
        return event_fn(x, p)

    return call


# ---------------------------------------------------------------------------------------
# the compiled kernel
# ---------------------------------------------------------------------------------------
def _unrolled_fsal_step(solver, elementwise: bool = False):
    """An explicit, first-same-as-last Runge-Kutta step written out stage by stage from the
    solver's Butcher tableau (for an autonomous vector field), or None if the solver is not
    of that kind. The same arithmetic as diffrax's step (stages ``k_i = h f(y0 + sum_j
    a_ij k_j)``, solution from the last stage, error ``sum_i e_i k_i``; Hairer, Norsett &
    Wanner, *Solving ODEs I*, sec. II.4-II.6), without diffrax's loop over the stages, which
    costs a loop iteration per stage inside every step.

    ``elementwise=False``: the stage sums are the zero-padded tableau rows dotted with a
    stage buffer, as diffrax does (the same numbers to the last bit). ``elementwise=True``:
    the sums run over the nonzero coefficients only, as plain elementwise arithmetic that
    XLA fuses into the next stage's evaluation (no buffer update, no small matrix product
    per stage). Mathematically the same step; the rounding differs in the last bits. The
    elementwise form halves a vmapped batch (256 model-A runs, measured: 0.78 against
    0.39 s CPU) but is ~20 % slower for a single run, so the kernel uses it for batches.

    Returns ``step(f, z0, f0, h) -> (z1, err, dense_info, f1)``: ``f0 = f(z0)`` from the
    previous step, ``dense_info`` as diffrax's (``y0``, ``y1``, ``k`` = stages x h).
    """
    tab = getattr(solver, "tableau", None)
    if tab is None or not (getattr(tab, "fsal", False) and getattr(tab, "ssal", False)):
        return None
    if getattr(solver, "implicit", False) or tab.c1 != 0.0:
        return None
    n_stages = len(tab.a_lower) + 1
    A = np.zeros((n_stages, n_stages))
    for i, row in enumerate(tab.a_lower):
        A[i + 1, : i + 1] = row
    b_err = np.asarray(tab.b_error, float)
    hi = jax.lax.Precision.HIGHEST

    def combo(coef, ks):
        terms = [float(c) * k for c, k in zip(coef, ks, strict=False) if c != 0.0]
        out = terms[0]
        for t in terms[1:]:
            out = out + t
        return out

    def step_elementwise(f, z0, f0, h):
        ks = [f0 * h]
        for i in range(1, n_stages):
            zi = z0 + combo(A[i, :i], ks)
            fi = f(zi)
            ks.append(fi * h)
        err = combo(b_err, ks)
        return zi, err, dict(y0=z0, y1=zi, k=jnp.stack(ks)), fi

    if elementwise:
        return step_elementwise

    def step(f, z0, f0, h):
        # the same operations as diffrax's stage loop (zero-padded tableau rows dotted
        # with the stage buffer), so the numbers are the same to the last bit
        K = jnp.zeros((n_stages,) + z0.shape, z0.dtype).at[0].set(f0 * h)
        for i in range(1, n_stages):
            zi = z0 + jnp.tensordot(jnp.asarray(A[i]), K, axes=1, precision=hi)
            fi = f(zi)
            K = K.at[i].set(fi * h)
        err = jnp.tensordot(jnp.asarray(b_err), K, axes=1, precision=hi)
        # solution = last stage's point (ssal); its f is the next step's f0 (fsal)
        return zi, err, dict(y0=z0, y1=zi, k=K), fi

    return step


def _make_kernel(rhs, event_fn, solver_name: str, samples: int, n_save: int,
                 stop_on_converged: bool, unroll_stages: bool | None = None,
                 batched: bool = False):
    """Build the (unjitted) single-run kernel. All array inputs are traced. ``batched``:
    the kernel will be vmapped (the stages are then written as elementwise sums,
    :func:`_unrolled_fsal_step`)."""
    import diffrax
    import equinox.internal as eqxi

    solver = getattr(diffrax, _SOLVERS[solver_name])()
    unrolled0 = (_unrolled_fsal_step(solver, elementwise=batched)
                 if unroll_stages is not False else None)
    interp_cls = solver.interpolation_cls
    eps = float(np.finfo(float).eps)

    def kernel(x0, p, scale, x_ref, t_end, ts_save, rtol, atol, converge_tol, hold_time,
               max_steps, dt0, decay_floor, event_args):
        term = diffrax.ODETerm(lambda t, z, args: rhs(z * scale, args) / scale)
        controller = diffrax.PIDController(rtol=rtol, atol=atol)
        order = solver.error_order(term)
        z0 = x0 / scale
        zref = x_ref / scale
        t0 = jnp.asarray(0.0)

        def g_of_z(z):
            return event_fn(z * scale, p, event_args)

        m = int(jax.eval_shape(g_of_z, z0).shape[0])
        sstate = solver.init(term, t0, t_end, z0, p)
        # written-out stages: 2.4x faster steps for model A (9 states); for model B (39
        # states) diffrax's stage loop is faster (58 against 77 ms for 5 s, measured)
        unrolled = unrolled0 if (unroll_stages or z0.shape[0] <= UNROLL_MAX_DIM) else None
        if unrolled is not None:  # first-same-as-last: carry f(z) from step to step
            sstate = rhs(z0 * scale, p) / scale
        tnext, cstate = controller.init(term, t0, t_end, z0, None, p, solver.func, order)
        tnext = jnp.where(dt0 > 0, t0 + dt0, tnext)
        tnext = jnp.minimum(tnext, t_end)
        dim = z0.shape[0]
        d0 = jnp.max(jnp.abs(z0 - zref))
        inside0 = d0 <= converge_tol

        # is the reference state an attracting equilibrium? (scaled coordinates: same
        # eigenvalues as the original ones)
        def f_z(z):
            return rhs(z * scale, p) / scale

        ref_residual = jnp.max(jnp.abs(f_z(zref)))
        ref_max_real = jnp.max(jnp.real(jnp.linalg.eigvals(jax.jacfwd(f_z)(zref))))
        attracting = (ref_max_real < 0) & (ref_residual * hold_time <= converge_tol)

        def settled_of(c):
            held = (c["t"] - c["conv_since"]) >= hold_time
            return held & (attracting | (c["peak"] <= decay_floor))

        carry = dict(
            t=t0, tnext=tnext, z=z0, sstate=sstate, cstate=cstate,
            made_jump=jnp.asarray(False),
            status=jnp.asarray(RUNNING), t_event=jnp.asarray(jnp.nan),
            i_event=jnp.asarray(-1), z_event=jnp.full((dim,), jnp.nan),
            conv_since=jnp.where(inside0, t0, jnp.inf),
            peak=d0,  # largest d seen since conv_since (steps' ends and event samples)
            ys=jnp.full((n_save, dim), jnp.nan), save_idx=jnp.asarray(0),
            steps=jnp.asarray(0), accepted=jnp.asarray(0), rejected=jnp.asarray(0),
            flagged=jnp.asarray(False), stuck=jnp.asarray(False),
            gmin=g_of_z(z0) if m else jnp.zeros((0,)),
        )
        # a start outside the limits is a collision at t = 0
        if m:
            g0 = g_of_z(z0)
            bad0 = jnp.any(g0 < 0)
            carry["status"] = jnp.where(bad0, COLLISION, RUNNING)
            carry["t_event"] = jnp.where(bad0, t0, jnp.nan)
            carry["i_event"] = jnp.where(bad0, jnp.argmin(g0), -1)
            carry["z_event"] = jnp.where(bad0, z0, jnp.nan)

        def cond(c):
            go = ((c["status"] == RUNNING) & (c["t"] < t_end) & (c["steps"] < max_steps)
                  & ~c["stuck"])
            if stop_on_converged:
                go = go & ~settled_of(c)
            return go

        def sample_events(interp, ta, tb):
            """g on samples + 1 equally spaced points of the step's interpolant: the
            samples, their g values, the entries with a negative sample, the entries whose
            sampled minimum is below their variation over the step (a dip between samples
            is possible), and the largest scaled distance to the reference seen."""
            s = ta + (tb - ta) * jnp.linspace(0.0, 1.0, samples + 1)
            zs = jax.vmap(interp.evaluate)(s)  # (samples+1, dim)
            G = jax.vmap(g_of_z)(zs)  # (samples+1, m)
            d_seen = jnp.max(jnp.abs(zs - zref))
            any_neg = jnp.any(G < 0, axis=0)
            g_lo = jnp.min(G, axis=0)
            spread = jnp.max(G, axis=0) - g_lo
            near = (g_lo <= spread) & ~any_neg
            return s, G, any_neg, near, d_seen

        def locate_event(interp, ta, tb, active):
            """First time in [ta, tb] at which an entry of g is negative (inf if none),
            the entry, and the smallest value of each entry seen in the step."""
            s, G, any_neg, _, d_seen = sample_events(interp, ta, tb)
            neg = G < 0
            first = jnp.argmax(neg, axis=0)  # first negative sample per entry
            kmin = jnp.argmin(G, axis=0)
            g_lo = jnp.min(G, axis=0)
            spread = jnp.max(G, axis=0) - g_lo

            def gj(j, tt):
                return g_of_z(interp.evaluate(tt))[j]

            # Grazing: an entry can dip below zero between samples only if its sampled
            # minimum is smaller than its variation within the step. Every entry at risk
            # gets its minimum refined by zooming in on the two sub-intervals around its
            # smallest sample. unvmap_any keeps this a real branch under vmap (taken if
            # any run of a batch needs it).
            near = (g_lo <= spread) & ~any_neg & active

            def refine_min():
                # every entry at risk at once (model B: two points may graze in one step):
                # zoom, sampling 8 sub-intervals at once and keeping the two around the
                # smallest value (the bracket shrinks 4x per round, 4^6 ~ 4e3 in all)
                def one(j):
                    k = kmin[j]
                    lo = s[jnp.maximum(k - 1, 0)]
                    hi = s[jnp.minimum(k + 1, samples)]

                    def body(_, carry):
                        lo, hi, best_t, best_g = carry
                        tt = jnp.linspace(lo, hi, 9)
                        vals = jax.vmap(lambda u: gj(j, u))(tt)
                        kk = jnp.argmin(vals)
                        better = vals[kk] < best_g
                        return (tt[jnp.maximum(kk - 1, 0)], tt[jnp.minimum(kk + 1, 8)],
                                jnp.where(better, tt[kk], best_t),
                                jnp.where(better, vals[kk], best_g))

                    _, _, tm, gm = jax.lax.fori_loop(0, 6, body, (lo, hi, s[k], g_lo[j]))
                    return tm, gm

                return jax.vmap(one)(jnp.arange(m))

            t_min, g_min = jax.lax.cond(
                eqxi.unvmap_any(jnp.any(near)), refine_min,
                lambda: (s[kmin], g_lo))
            graze = near & (g_min < 0)
            # candidate brackets [a_j, b_j] with g_j(a_j) >= 0 > g_j(b_j)
            a_j = s[jnp.maximum(first - 1, 0)]
            b_j = jnp.where(any_neg, s[first], jnp.inf)
            a_j = jnp.where(graze, s[jnp.maximum(kmin - 1, 0)], a_j)
            b_j = jnp.where(graze, t_min, b_j)
            hit = any_neg | graze
            # the earliest bracket holds the first crossing (entries that cross inside the
            # same sub-interval are told apart by their order in g only)
            j_hit = jnp.argmin(b_j)

            def bisect():
                # 16-section: evaluate 15 interior points at once and keep the sub-interval
                # of the first negative one (16^13 ~ 5e15 in all); taking the *first*
                # negative point never skips over an earlier dip
                def body(_, ab):
                    lo, hi = ab
                    tt = jnp.linspace(lo, hi, 17)
                    neg = jax.vmap(lambda u: gj(j_hit, u))(tt) < 0
                    neg = neg.at[16].set(True)
                    kk = jnp.maximum(jnp.argmax(neg), 1)
                    return tt[kk - 1], tt[kk]

                lo, hi = jax.lax.fori_loop(0, 13, body, (a_j[j_hit], b_j[j_hit]))
                return hi  # first time found outside the limit

            # under vmap, finished runs keep being stepped (and masked): exclude them
            any_hit = jnp.any(hit) & active
            t_cross = jax.lax.cond(eqxi.unvmap_any(any_hit), bisect, lambda: jnp.inf)
            t_cross = jnp.where(any_hit, t_cross, jnp.inf)
            g_seen = jnp.where(near, jnp.minimum(g_lo, g_min), g_lo)
            return t_cross, j_hit, g_seen, d_seen

        def save_until(c, interp, t_stop, keep):
            """Write the saved times in (t, t_stop] of an accepted step, SAVE_BLOCK at a
            time (one vectorised interpolant evaluation and one scatter; only the rows
            written are touched, never the whole history)."""
            def block(k, ys):
                idx = k + jnp.arange(SAVE_BLOCK)
                tt = ts_save[jnp.minimum(idx, n_save - 1)]
                mask = (idx < n_save) & (tt <= t_stop) & keep
                vals = jax.vmap(interp.evaluate)(tt) * scale
                ys = ys.at[jnp.where(mask, idx, n_save)].set(vals, mode="drop")
                return k + jnp.sum(mask), ys

            def more(sc):
                k, _ = sc
                return keep & (k < n_save) & (ts_save[jnp.minimum(k, n_save - 1)] <= t_stop)

            # the first block always (most steps hold fewer than SAVE_BLOCK saved times)
            k, ys = block(c["save_idx"], c["ys"])
            return jax.lax.while_loop(more, lambda sc: block(*sc), (k, ys))

        def step(c, full):
            """One attempted step; a no-op once the run is over (``cond`` false), so that
            several steps can share one loop iteration.

            ``full=False`` (the inner loop): the event samples are checked, and a step in
            which a limit may have been crossed or grazed is *not* taken but flagged, so
            the loop contains no conditional (an XLA conditional costs ~6 us per step on
            CPU even when not taken). ``full=True`` takes the flagged step again with the
            complete search (grazing refinement, crossing bisection)."""
            active = cond(c)
            t, tn = c["t"], c["tnext"]
            if unrolled is not None:
                z1, zerr, dense, sstate1 = unrolled(
                    lambda z: rhs(z * scale, p) / scale, c["z"], c["sstate"], tn - t)
            else:
                z1, zerr, dense, sstate1, _ = solver.step(
                    term, t, tn, c["z"], p, c["sstate"], c["made_jump"])
            zerr = jnp.where(jnp.isnan(zerr), jnp.inf, zerr)
            keep, tprev2, tnext2, made_jump2, cstate2, _ = controller.adapt_step_size(
                t, tn, c["z"], z1, p, zerr, order, c["cstate"])
            finite = jnp.all(jnp.isfinite(z1))
            interp = interp_cls(t0=t, t1=tn, **dense)
            flag = jnp.asarray(False)
            if m and not full:
                _, G, any_neg, near, d_seen = sample_events(interp, t, tn)
                flag = active & keep & finite & jnp.any(any_neg | near)
                active = active & ~flag
            keep = keep & finite & active
            tnext2 = jnp.where(tnext2 > t_end - 100 * eps * jnp.abs(t_end), t_end, tnext2)
            tnext2 = jnp.where(finite, tnext2, t + 0.25 * (tn - t))
            tprev2 = jnp.where(keep, tprev2, t)
            tnext2 = jnp.where(active, tnext2, tn)
            cstate2 = jax.tree_util.tree_map(lambda a, b: jnp.where(active, a, b),
                                             cstate2, c["cstate"])

            if m and full:
                t_hit, j_hit, gmin_step, d_seen = locate_event(interp, t, tn, keep)
            elif m:  # nothing near a limit in this step (else it was flagged)
                t_hit, j_hit, gmin_step = jnp.asarray(jnp.inf), jnp.asarray(0), jnp.min(G, 0)
            if m:
                collide = keep & jnp.isfinite(t_hit)
                # values past a collision inside the step are not part of the run
                gmin_step = jnp.where(collide, jnp.maximum(gmin_step, 0.0), gmin_step)
                gmin = jnp.where(keep, jnp.minimum(c["gmin"], gmin_step), c["gmin"])
            else:
                t_hit, j_hit, collide, gmin = jnp.inf, -1, jnp.asarray(False), c["gmin"]
                d_seen = jnp.asarray(0.0)

            t_stop = jnp.where(collide, t_hit, tn)
            if n_save:
                save_idx, ys = save_until(c, interp, t_stop, keep)
            else:
                save_idx, ys = c["save_idx"], c["ys"]

            z_new = jnp.where(keep, z1, c["z"])
            z_hit = interp.evaluate(jnp.where(collide, t_hit, tn))
            d = jnp.max(jnp.abs(z_new - zref))
            inside = d <= converge_tol
            conv_since = jnp.where(
                keep, jnp.where(inside, jnp.minimum(c["conv_since"], tn), jnp.inf),
                c["conv_since"])
            was_inside = jnp.isfinite(c["conv_since"])
            peak = jnp.where(keep, jnp.where(
                inside, jnp.where(was_inside, jnp.maximum(c["peak"], jnp.maximum(d, d_seen)), d),
                jnp.inf), c["peak"])
            status = jnp.where(collide, COLLISION, c["status"])
            steps = c["steps"] + active.astype(int)
            return dict(
                t=jnp.where(collide, t_hit, tprev2),
                tnext=tnext2,
                z=jnp.where(collide, z_hit, z_new),
                sstate=jax.tree_util.tree_map(lambda a, b: jnp.where(keep, a, b),
                                              sstate1, c["sstate"]),
                cstate=cstate2,
                made_jump=jnp.where(keep, made_jump2, c["made_jump"]),
                status=status,
                t_event=jnp.where(collide, t_hit, c["t_event"]),
                i_event=jnp.where(collide, j_hit, c["i_event"]),
                z_event=jnp.where(collide, z_hit, c["z_event"]),
                conv_since=conv_since,
                peak=peak,
                ys=ys, save_idx=save_idx, steps=steps,
                accepted=c["accepted"] + keep.astype(int),
                rejected=c["rejected"] + (active & ~keep).astype(int),
                gmin=gmin, flagged=flag,
                # a rejected step that can no longer shrink: the step is at the resolution
                # of t (a singularity, e.g. a finite-time blow-up); the run fails now
                # instead of spending max_steps on it (and, in a batch, every run with it)
                stuck=c["stuck"] | (active & ~keep & (tn - t <= 64 * eps * jnp.abs(tn))),
            )

        c = jax.lax.while_loop(cond, lambda cc: step(cc, True), carry)
        conv_done = settled_of(c)
        finite = jnp.all(jnp.isfinite(c["z"]))
        incomplete = (c["status"] == RUNNING) & (c["t"] < t_end) & ~conv_done
        status = jnp.where(c["status"] == COLLISION, COLLISION,
                           jnp.where(~finite | incomplete, FAILED,
                                     jnp.where(conv_done, CONVERGED, RUNNING)))
        return dict(
            status=status, t_event=c["t_event"], i_event=c["i_event"],
            t_final=c["t"], x_final=c["z"] * scale,
            conv_since=jnp.where(conv_done, c["conv_since"], jnp.inf),
            ys=c["ys"], gmin=c["gmin"], steps=c["steps"], accepted=c["accepted"],
            rejected=c["rejected"], ref_max_real=ref_max_real, ref_residual=ref_residual,
            near=jnp.isfinite(c["conv_since"]) & ((c["t"] - c["conv_since"]) >= hold_time),
            stuck=c["stuck"],
        )

    return kernel


@lru_cache(maxsize=64)
def _compiled_kernel(rhs, event_fn, solver_name: str, samples: int, n_save: int,
                     stop_on_converged: bool, batch_x: bool, batch_p: bool,
                     unroll_stages: bool | None = None):
    def kernel(*args):
        # built when traced, not here: a kernel loaded ahead of time (aot.py) then never
        # imports diffrax (~0.45 s of a warm command's start-up)
        return _make_kernel(rhs, event_fn, solver_name, samples, n_save, stop_on_converged,
                            unroll_stages, batched=batch_x or batch_p)(*args)

    if batch_x or batch_p:
        axes = (0 if batch_x else None, 0 if batch_p else None) + (None,) * 12
        kernel = jax.vmap(kernel, in_axes=axes)
    return cached_kernel(kernel, rhs, event_fn, solver_name, samples, n_save,
                         stop_on_converged, batch_x, batch_p, unroll_stages)


def _save_times(t_end: float, n_save: int, t_save: Array | None) -> np.ndarray:
    if t_save is not None:
        ts = np.asarray(t_save, dtype=float).ravel()
        if ts.size and (np.any(np.diff(ts) < 0) or ts[0] < 0 or ts[-1] > t_end):
            raise ValueError("t_save must be increasing and inside [0, t_end]")
        return ts
    return np.linspace(0.0, t_end, n_save) if n_save > 0 else np.zeros(0)


def _run(system: System, x0, p, t_end, *, event_fn, x_ref, options, n_save, t_save,
         batch_x, batch_p):
    opts = options or SimulationOptions()
    if opts.solver not in _SOLVERS:
        raise ValueError(f"unknown solver '{opts.solver}'; choose from {', '.join(_SOLVERS)}")
    if not t_end > 0:
        raise ValueError(f"t_end must be > 0, got {t_end}")
    if not opts.decay_floor >= 0:
        raise ValueError(f"decay_floor must be >= 0, got {opts.decay_floor}")
    ts = _save_times(float(t_end), n_save, t_save)
    ev = event_fn if event_fn is not None else _no_events
    with_args = isinstance(ev, EventsWithArgs)
    ev_args = np.asarray(ev.args if with_args else (), dtype=float)
    ev_call = _event_caller(ev.fn if with_args else ev, with_args)
    fn = _compiled_kernel(system.rhs, ev_call, opts.solver, int(max(opts.samples, 2)), ts.size,
                          bool(opts.stop_on_converged), batch_x, batch_p, opts.unroll_stages)
    xr = system.x_guess if x_ref is None else np.asarray(x_ref, float)
    out = fn(
        jnp.asarray(x0, jnp.float64), jnp.asarray(p, jnp.float64),
        jnp.asarray(system.state_scale, jnp.float64), jnp.asarray(xr, jnp.float64),
        jnp.asarray(float(t_end)), jnp.asarray(ts), jnp.asarray(opts.rtol),
        jnp.asarray(opts.atol), jnp.asarray(opts.converge_tol), jnp.asarray(opts.hold_time),
        jnp.asarray(opts.max_steps), jnp.asarray(opts.dt0 or 0.0),
        jnp.asarray(opts.decay_floor), jnp.asarray(ev_args),
    )
    return ts, {k: np.asarray(v) for k, v in out.items()}


def _not_decaying_message(max_real: float, residual: float,
                          opts: SimulationOptions) -> str:
    if not residual * opts.hold_time <= opts.converge_tol:
        why = (f"the reference state is not an equilibrium (residual {residual:.3g} scaled "
               "units per second)")
    elif max_real > 0:
        why = (f"the reference state is an unstable equilibrium (largest eigenvalue real "
               f"part {max_real:.4g} 1/s): the disturbance grows")
    else:
        why = (f"the reference state is not an attracting equilibrium (largest eigenvalue "
               f"real part {max_real:.4g} 1/s): the disturbance need not decay")
    return (f"not converged: the state stayed within converge_tol = {opts.converge_tol:g} "
            f"(scaled) of the reference state for over {opts.hold_time:g} s, but {why}")


def simulate(
    system: System,
    x0: Array,
    t_end: float,
    *,
    p: Array | None = None,
    event_fn: EventFn | None = None,
    x_ref: Array | None = None,
    options: SimulationOptions | None = None,
    n_save: int = 1001,
    t_save: Array | None = None,
) -> SimulationResult:
    """Integrate ``system`` from ``x0`` over [0, t_end] (s) with terminal limit events.

    Parameters
    ----------
    system : the ODE (its ``rhs`` must be a stable function object so compiled code is
        reused, e.g. a module-level function).
    x0 : initial state (units of the system's states).
    t_end : horizon (s).
    p : parameter vector (defaults to ``system.p``).
    event_fn : ``g(x, p) -> array``; a negative entry ends the run as a collision. Use a
        stable function object (cached) for the same reason as ``rhs``, or an
        :class:`EventsWithArgs` whose numeric arguments are traced (new values reuse the
        compiled kernel).
    x_ref : reference state for the convergence test (defaults to ``system.x_guess``).
    options : :class:`SimulationOptions`.
    n_save : number of equally spaced saved times in [0, t_end] (ignored if ``t_save``).
    t_save : explicit increasing saved times (s).

    Returns
    -------
    :class:`SimulationResult`.
    """
    pp = system.p if p is None else np.asarray(p, float)
    ts, o = _run(system, x0, pp, t_end, event_fn=event_fn, x_ref=x_ref, options=options,
                 n_save=n_save, t_save=t_save, batch_x=False, batch_p=False)
    code = int(o["status"])
    hit = code == COLLISION
    warnings: list[str] = []
    if code == FAILED:
        if not np.all(np.isfinite(o["x_final"])):
            warnings.append("the state became non-finite")
        elif bool(o["stuck"]):
            warnings.append(f"the step size fell to the resolution of t at "
                            f"t = {float(o['t_final']):.10g} s after {int(o['steps'])} steps "
                            "(a singularity of the solution, e.g. a finite-time blow-up)")
        else:
            warnings.append(f"stopped after max_steps = {int(o['steps'])} steps at "
                            f"t = {float(o['t_final']):.6g} s before the horizon")
    if code == RUNNING and bool(o["near"]):
        warnings.append(_not_decaying_message(float(o["ref_max_real"]),
                                              float(o["ref_residual"]),
                                              options or SimulationOptions()))
    return SimulationResult(
        t=ts,
        x=o["ys"],
        outcome=OUTCOMES[code],
        event_time=float(o["t_event"]) if hit else None,
        event_index=int(o["i_event"]) if hit else None,
        event_state=o["x_final"] if hit else None,
        final_time=float(o["t_final"]),
        final_state=o["x_final"],
        converged_time=float(o["conv_since"]) if np.isfinite(o["conv_since"]) else None,
        min_event_value=o["gmin"],
        steps=int(o["steps"]),
        accepted=int(o["accepted"]),
        rejected=int(o["rejected"]),
        warnings=tuple(warnings),
        reference_max_real=float(o["ref_max_real"]),
        reference_residual=float(o["ref_residual"]),
    )


def simulate_batch(
    system: System,
    x0: Array,
    t_end: float,
    *,
    p: Array | None = None,
    event_fn: EventFn | None = None,
    x_ref: Array | None = None,
    options: SimulationOptions | None = None,
    n_save: int = 0,
    t_save: Array | None = None,
) -> BatchSimulation:
    """Many runs in one vmapped call: ``x0`` of shape (batch, dim) and/or ``p`` of shape
    (batch, n_params) (a 1-D ``x0`` or ``p`` is shared by every run). Same meaning of the
    arguments as :func:`simulate`; by default no histories are kept (``n_save = 0``).

    Returns a :class:`BatchSimulation`.
    """
    x0 = np.asarray(x0, float)
    pp = system.p if p is None else np.asarray(p, float)
    batch_x, batch_p = x0.ndim == 2, pp.ndim == 2
    if not (batch_x or batch_p):
        raise ValueError("simulate_batch needs x0 (batch, dim) and/or p (batch, n_params)")
    if batch_x and batch_p and x0.shape[0] != pp.shape[0]:
        raise ValueError(f"batch sizes differ: x0 {x0.shape[0]}, p {pp.shape[0]}")
    ts, o = _run(system, x0, pp, t_end, event_fn=event_fn, x_ref=x_ref, options=options,
                 n_save=n_save, t_save=t_save, batch_x=batch_x, batch_p=batch_p)
    codes = o["status"].astype(int)
    return BatchSimulation(
        outcome=np.array([OUTCOMES[c] for c in codes]),
        outcome_code=codes,
        event_time=np.where(codes == COLLISION, o["t_event"], np.nan),
        event_index=np.where(codes == COLLISION, o["i_event"], -1),
        final_time=o["t_final"],
        final_state=o["x_final"],
        converged_time=o["conv_since"],
        min_event_value=o["gmin"],
        steps=o["steps"],
        t=ts,
        x=o["ys"] if ts.size else None,
        accepted=o["accepted"],
        rejected=o["rejected"],
        reference_max_real=o["ref_max_real"],
        reference_residual=o["ref_residual"],
    )
