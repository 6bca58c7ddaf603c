"""The models at speed with the delayed outer loop: the standstill delay model
(:func:`maglev_match.maglev.unit.unit_dde`, :func:`maglev_match.maglev.vehicle.vehicle_dde`:
the outer loops' commands u = kP y1 + kD (v + u') are read late by tau, the inner current
loop and the induction term act at once) applied to the unit and the vehicle running over
the spans (:mod:`maglev_match.maglev.moving`).

The delay system x'(t) = f(x(t), u(t - tau), p) has the moving model's state x (its clock
t last) and the commands u as its delayed signals; it is discretised by the package's
pseudospectral method (:mod:`maglev_match.dynamics.delay.discretisation`: the commands'
past at N Chebyshev nodes of [-tau, 0], N from the fastest rate of the model at that speed)
and the history states are placed before the clock
(:func:`~maglev_match.dynamics.delay.clocked.clock_last`), so the periodic response, its
Floquet multipliers and every run at speed treat the delayed model as any other moving
model. The parameter vector is the moving model's followed by ``tau``. With tau = 0 the
computations at speed use the delay-free moving model itself (unchanged, bit for bit).

The span hand-over does not touch the history: the commands are the vehicle's, and the
vehicle does not jump at a support.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from maglev_match.core.params import ParameterError, Params
from maglev_match.dynamics.delay import (
    NODES_MAX,
    DelayDifferentialSystem,
    DelayNodesError,
    discretise,
    max_delay_for,
)
from maglev_match.dynamics.delay.clocked import ClockedDelaySystem, clock_last
from maglev_match.maglev import moving as mv
from maglev_match.maglev.moving import MovingModel

__all__ = ["DELAY_NAME", "delayed_vector", "rate_at_speed", "max_delay_at_speed",
           "check_delay_at_speed", "moving_delay_system", "gap_events_for"]

#: The delay parameter appended to a moving model's parameter vector.
DELAY_NAME = "tau"


def delayed_vector(p: np.ndarray, tau: float) -> np.ndarray:
    """A moving model's parameter vector followed by the delay tau (s)."""
    return np.append(np.asarray(p, float), float(tau))


def rate_at_speed(params: Params, kind: MovingModel, v: float) -> float:
    """The fastest rate (rad/s) of the moving model at speed v, which sizes the
    discretisation of the delay: the spectral radius of the delay-free Jacobian (the clock
    left out) on a rigid guideway's equilibrium, the vehicle at mid-span."""
    kind = MovingModel(kind)
    lay = mv.layout_of(params, kind)
    xf = 0.5 * (float(params.L) + lay.extent)
    xl = xf + lay.front
    fb = (xl > params.L).astype(float)
    rb = (xl - lay.length > params.L).astype(float)
    p = mv.moving_param_vector(params, kind, v=float(v), x_front=xf, front_on_B=fb,
                               rear_on_B=rb)
    system = mv.moving_system(params, kind, p)
    J = system.jacobian(mv.rigid_equilibrium(params, kind), p)[:-1, :-1]
    return float(np.max(np.abs(np.linalg.eigvals(J))))


def max_delay_at_speed(params: Params, kind: MovingModel, v: float) -> float:
    """The longest delay (s) the largest discretisation resolves at speed v."""
    return max_delay_for(rate_at_speed(params, kind, v), NODES_MAX)


def check_delay_at_speed(params: Params, kind: MovingModel, speeds) -> None:
    """Refuse a delay the discretisation cannot resolve at one of the speeds (m/s):
    ParameterError naming ``tau``, its value and the rule."""
    tau = float(params.tau)
    if tau == 0:
        return
    if not math.isfinite(tau) or tau < 0:
        raise ParameterError("tau", tau, "a delay must be a finite number >= 0 s")
    if MovingModel(kind) is MovingModel.FORCE:
        raise ParameterError("tau", tau, "the force model has no controller to delay: "
                             "use --model unit or vehicle")
    for v in sorted(set(float(s) for s in speeds)) or [0.0]:
        top = max_delay_at_speed(params, kind, v)
        if tau > top:
            raise ParameterError(
                "tau", tau, f"at {v * 3.6:g} km/h the delay's discretisation resolves at "
                f"most {top:.4g} s ({NODES_MAX} Chebyshev intervals for the model's fastest "
                f"rate {rate_at_speed(params, kind, v):.4g} rad/s)")


def moving_delay_system(params: Params, kind: MovingModel, p: np.ndarray, *, tau: float,
                        limited: bool = False, period: float = 1.0, waves: int | None = None,
                        tau_max: float | None = None, nodes: int | None = None
                        ) -> ClockedDelaySystem:
    """The model at speed with the delayed outer loop, discretised (module docstring).
    ``p``: the moving model's parameter vector (without tau, e.g. a passage segment's);
    ``tau`` the delay (s, > 0); ``tau_max``: size the discretisation for delays up to this
    (one system for a whole search in tau); ``nodes``: the Chebyshev intervals, explicitly.
    The system's parameter vector is ``p`` followed by tau."""
    kind = MovingModel(kind)
    base = mv.moving_system(params, kind, p, limited=limited, period=period, waves=waves)
    v = float(np.asarray(p, float)[base.param_names.index("v")])
    dde = DelayDifferentialSystem(
        rhs=mv.moving_delay_rhs(kind, int(params.n_modes), limited, waves),
        signals=(mv.moving_command(kind),), delays=(DELAY_NAME,),
        p=delayed_vector(p, tau), param_names=tuple(base.param_names) + (DELAY_NAME,),
        state_names=base.state_names, x_guess=base.x_guess, state_scale=base.state_scale,
        observables=_without_delay(base.observables), name=base.name,
        signal_names=(("u",) if kind is MovingModel.UNIT
                      else tuple(f"u{j}" for j in range(1, 7)),),
        rate=rate_at_speed(params, kind, v))
    try:
        disc = discretise(dde, nodes, tau_max=tau_max)
    except DelayNodesError as exc:
        raise ParameterError(exc.field, exc.value, exc.rule) from None
    return clock_last(disc, name=f"{base.name}, outer loop delayed (N = {disc.nodes})")


def _without_delay(observables) -> dict:
    return {k: _drop_last(g) for k, g in observables.items()}


@cache
def _drop_last(g):
    """g(x, p[:-1]): an observable of the moving model read with the delayed vector
    (cached per function, so compiled read-outs are shared)."""
    def h(x, p):
        return g(x, p[:-1])

    h.__name__ = getattr(g, "__name__", "observable")
    return h


def gap_events_for(system, kind: MovingModel, n_modes: int):
    """The gap events of :func:`maglev_match.maglev.moving.gap_events` for the states and
    parameters of ``system``: unchanged for a delay-free moving model; for the delayed one
    (:class:`~maglev_match.dynamics.delay.clocked.ClockedDelaySystem`) read on its current
    state (clock last) and its parameter vector without tau."""
    ev = mv.gap_events(kind, n_modes)
    if not isinstance(system, ClockedDelaySystem):
        return ev
    return _delayed_events(ev, int(system.n_state), int(system.dim))


@cache
def _delayed_events(ev, n: int, dim: int):
    import jax.numpy as jnp

    def events(X, p, limits):
        return ev(jnp.concatenate([X[:n - 1], X[dim - 1:]]), p[:-1], limits)

    return events
