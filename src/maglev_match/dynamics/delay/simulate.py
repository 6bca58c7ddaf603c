"""Simulation of a delay system by the method of steps.

**Simulation** (:func:`simulate_delay`): the method of steps with a dense-output Runge-Kutta
method (Bellen & Zennaro 2003, *Numerical Methods for Delay Differential Equations*,
ch. 3-4): steps no longer than the smallest delay, so the delayed arguments of every stage lie
in steps already taken and are read from their interpolants; the first breakpoints
t = j tau (where the solution's derivatives jump after a constant initial function) end
steps; limit events end the run as a collision. It is the reference for the discretised
system's simulation (:mod:`maglev_match.dynamics.delay.discretisation`), whose error it
measures.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.delay.system import DelayDifferentialSystem

__all__ = ["DelaySimulation", "simulate_delay"]


# ---------------------------------------------------------------------------------------
# simulation: the method of steps
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DelaySimulation:
    """A run of a delay system by the method of steps.

    t, x : saved times (s) and states (n_save, n) (rows after the end of the run are NaN).
    outcome : 'collision' (an event entry went negative), 'running' (the horizon was
        reached) or 'failed' (the integrator stopped: message in ``warnings``).
    event_time, event_index : the collision (s, entry of the event function) or None.
    final_time, final_state : where the run ended. steps : integrator steps taken.
    """

    __repr__ = compact_repr

    t: np.ndarray
    x: np.ndarray
    outcome: str
    event_time: float | None
    event_index: int | None
    final_time: float
    final_state: np.ndarray
    steps: int
    warnings: tuple[str, ...] = ()

    def __call__(self, t: float | np.ndarray) -> np.ndarray:
        """The dense solution at time(s) t in [0, final_time] (the history before 0)."""
        return self._dense(t)  # type: ignore[attr-defined]


@cache
def _mos_kernels(F: Callable, event_fn: Callable | None):
    f = jax.jit(F)
    e = None if event_fn is None else jax.jit(event_fn)
    return f, e


def simulate_delay(dde: DelayDifferentialSystem, x0: np.ndarray, t_end: float, *,
                   p: np.ndarray | None = None, history: Callable | None = None,
                   event_fn: Callable | None = None, rtol: float = 1e-10,
                   atol: float = 1e-12, n_save: int = 1001, t_save: np.ndarray | None = None,
                   breakpoints: int = 4, samples: int = 8, max_steps: int = 2_000_000
                   ) -> DelaySimulation:
    """Integrate the delay system over [0, t_end] (s) by the method of steps (module
    docstring) with SciPy's DOP853 (Hairer, Norsett & Wanner 1993; its 7th-order dense
    output reads the past).

    Parameters
    ----------
    x0 : the state at t = 0 (n entries). history : the state for t < 0, a function
        ``theta -> x`` (default: the constant initial function x(theta) = x0).
    event_fn : ``g(x, p) -> array``; a negative entry ends the run as a collision, located
        on the dense output (each step is also sampled at ``samples`` inner points, so an
        entry that dips below zero within a step is caught).
    rtol, atol : tolerances (atol in units of the states' scale).
    breakpoints : how many of the points t = j tau_k (where the derivatives of the
        solution jump after a non-matching initial function) end integrator steps.
    """
    from scipy.integrate import DOP853
    from scipy.optimize import brentq

    pv = dde.p if p is None else np.asarray(p, float)
    taus = dde.delay_values(pv)
    if np.any(taus <= 0):
        raise ValueError("simulate_delay needs positive delays (the delay-free ODE otherwise)")
    n = dde.dim
    x0 = np.asarray(x0, float).reshape(n)
    F, E = _mos_kernels(dde.argument_function, event_fn)
    pj = jnp.asarray(pv)
    hist = history if history is not None else (lambda theta: x0)
    t_old: list[float] = []
    dense: list[Any] = []

    def state_at(s: float) -> np.ndarray:
        if s <= 0.0 or not t_old:
            return np.asarray(hist(s), float) if s < 0.0 else (x0 if not t_old else
                                                                dense[0](0.0))
        i = bisect.bisect_right(t_old, s) - 1
        return dense[max(i, 0)](s)

    def fun(t, x):
        U = np.concatenate([x] + [state_at(t - tau) for tau in taus])
        return np.asarray(F(U, pj))

    def events_at(x):
        return np.asarray(E(jnp.asarray(x), pj)) if E is not None else None

    ends = sorted({float(j * t) for t in taus for j in range(1, breakpoints + 1)
                   if j * t < t_end} | {float(t_end)})
    h_max = float(np.min(taus))
    scale = dde.state_scale
    x, t = x0.copy(), 0.0
    steps = 0
    outcome, ev_t, ev_i, warns = "running", None, None, []
    if E is not None and np.any(events_at(x0) < 0):
        outcome, ev_t, ev_i = "collision", 0.0, int(np.argmin(events_at(x0)))
    for t_b in ends:
        if outcome != "running":
            break
        solver = DOP853(fun, t, x, t_b, rtol=rtol, atol=atol * scale, max_step=h_max)
        while solver.status == "running":
            if steps >= max_steps:
                outcome = "failed"
                warns.append(f"stopped after max_steps = {max_steps} steps at t = {t:.6g} s")
                break
            msg = solver.step()
            steps += 1
            if solver.status == "failed":
                outcome = "failed"
                warns.append(f"integrator failed at t = {solver.t:.6g} s: {msg}")
                break
            sol = solver.dense_output()
            t_old.append(solver.t_old)
            dense.append(sol)
            if E is not None:
                ts = np.linspace(solver.t_old, solver.t, samples + 2)
                vals = np.array([events_at(sol(s)) for s in ts])
                bad = np.nonzero(np.any(vals < 0, axis=1))[0]
                if bad.size:
                    j = int(bad[0])
                    times = []
                    for i in np.nonzero(vals[j] < 0)[0]:
                        a, b = ts[j - 1], ts[j]
                        times.append((brentq(lambda s, i=i, sol=sol: events_at(sol(s))[i], a, b,
                                             xtol=1e-15, rtol=1e-15), int(i)))
                    ev_t, ev_i = min(times)
                    outcome = "collision"
                    t_old.append(ev_t)  # the run ends here
                    dense.append(sol)
                    break
            t, x = solver.t, solver.y
        if outcome != "running":
            break
        t, x = solver.t, solver.y
    final_t = float(ev_t) if ev_t is not None else float(t)
    final_x = state_at(final_t) if t_old else x0
    ts = np.linspace(0.0, float(t_end), int(n_save)) if t_save is None else np.asarray(
        t_save, float)
    xs = np.full((ts.size, n), np.nan)
    for i, s in enumerate(ts):
        if s <= final_t + 1e-15:
            xs[i] = state_at(float(s)) if s > 0 else x0
    res = DelaySimulation(t=ts, x=xs, outcome=outcome, event_time=None if ev_t is None
                          else float(ev_t), event_index=ev_i, final_time=final_t,
                          final_state=np.asarray(final_x, float), steps=steps,
                          warnings=tuple(warns))
    object.__setattr__(res, "_dense", np.vectorize(state_at, signature="()->(n)"))
    return res
