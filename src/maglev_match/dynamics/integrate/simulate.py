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
The kernel itself (the step loop, the event search inside steps, the written-out
Runge-Kutta stages) is built in :mod:`maglev_match.dynamics.integrate.kernel`; this module
holds the options, the results and the entry points.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from functools import lru_cache
from typing import Any

import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.beside import stop_point
from maglev_match.core.jax_setup import kernel_arg
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.integrate.kernel import (
    COLLISION,
    CONVERGED,  # noqa: F401  (an outcome code, imported from this module by its users)
    FAILED,
    RUNNING,
    SOLVERS,
    compiled_kernel,
)
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


# the outcome codes of the kernel (kernel.py) as outcomes
OUTCOMES = (Outcome.RUNNING, Outcome.COLLISION, Outcome.CONVERGED, Outcome.FAILED)


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




def _save_times(t_end: float, n_save: int, t_save: Array | None) -> np.ndarray:
    if t_save is not None:
        ts = np.asarray(t_save, dtype=float).ravel()
        if ts.size and (np.any(np.diff(ts) < 0) or ts[0] < 0 or ts[-1] > t_end):
            raise ValueError("t_save must be increasing and inside [0, t_end]")
        return ts
    return np.linspace(0.0, t_end, n_save) if n_save > 0 else np.zeros(0)


def _run(system: System, x0, p, t_end, *, event_fn, x_ref, options, n_save, t_save,
         batch_x, batch_p):
    stop_point()  # a part run beside another stops here when asked (core/beside.py)
    opts = options or SimulationOptions()
    if opts.solver not in SOLVERS:
        raise ValueError(f"unknown solver '{opts.solver}'; choose from {', '.join(SOLVERS)}")
    if not t_end > 0:
        raise ValueError(f"t_end must be > 0, got {t_end}")
    if not opts.decay_floor >= 0:
        raise ValueError(f"decay_floor must be >= 0, got {opts.decay_floor}")
    ts = _save_times(float(t_end), n_save, t_save)
    ev = event_fn if event_fn is not None else _no_events
    with_args = isinstance(ev, EventsWithArgs)
    ev_args = np.asarray(ev.args if with_args else (), dtype=float)
    ev_call = _event_caller(ev.fn if with_args else ev, with_args)
    fn = compiled_kernel(system.rhs, ev_call, opts.solver, int(max(opts.samples, 2)), ts.size,
                          bool(opts.stop_on_converged), batch_x, batch_p, opts.unroll_stages)
    xr = system.x_guess if x_ref is None else np.asarray(x_ref, float)
    out = fn(
        kernel_arg(x0, jnp.float64), kernel_arg(p, jnp.float64),
        kernel_arg(system.state_scale, jnp.float64), kernel_arg(xr, jnp.float64),
        kernel_arg(float(t_end)), kernel_arg(ts), kernel_arg(opts.rtol),
        kernel_arg(opts.atol), kernel_arg(opts.converge_tol), kernel_arg(opts.hold_time),
        kernel_arg(opts.max_steps), kernel_arg(opts.dt0 or 0.0),
        kernel_arg(opts.decay_floor), kernel_arg(ev_args),
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
