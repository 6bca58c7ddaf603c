"""The coil-current clamp of models A and B as a piecewise-smooth system.

Physics only. The limited models (:mod:`maglev_match.maglev.limits`) take the force from
max(i, 0) and hold di/dt at 0 while i <= 0 and falling. Along a trajectory that is a
switched system with, for each levitation point j, two modes:

* **free** (switch off): the smooth model, i_j > 0;
* **held** (switch on): the current sits at zero, i_j = 0 exactly, di_j/dt = 0, and the
  point's magnet gives no force (the sliding motion on the surface i_j = 0 in Filippov's
  sense: the free field points into i_j < 0 there, and the held field is the free field
  with that component removed).

A point is held when its current reaches 0 while falling (guard of the free mode: i_j) and
released when the free rate of the current at i_j = 0,

    di_j/dt|free = ke c_j / K (kP y1_j + kD (v_j + u_j') + i0)      (model B; model A alike),

turns positive. Since c_j > 0, that is when the controller's demand
kP y1_j + kD (v_j + u_j') + i0 turns positive, and the guard of the held mode is minus the
demand (A): the same surface, without the factor c_j, so the guard stays regular where a
run touches the gap limit c = 0 while the current is held (a grazing contact the critical
disturbance is solved at). Entering the held mode projects
the current exactly onto 0, so the sensitivities lose that direction (the saltation matrix
of a sliding entry has rank n - 1). These are the conditions the simulator's limited vector
field approximates step by step; here they are surfaces, so the time of every switch is
located and the flow is differentiable between switches (:mod:`maglev_match.dynamics.hybrid`).

The free field is singular at gap 0 (the force grows as (i / c)^2): a run whose gap falls to
1 um while its current flows leaves the flow's domain there (it has gone through the
limit); while the current is held there is no force and the field stays regular through
gap 0, so a grazing contact at gap 0 with the current held extends smoothly past it.
"""

from __future__ import annotations

from functools import cache

import jax.numpy as jnp
import numpy as np

from maglev_match.core.params import Params
from maglev_match.dynamics.hybrid import HybridSystem
from maglev_match.maglev import unit as unit_model
from maglev_match.maglev import vehicle as vehicle_model

__all__ = ["unit_clamped", "unit_delay_clamped", "vehicle_clamped"]

_I = 6  # model A: x7 = i - i0


# ----------------------------------------------------------------------------- model A
def _unit_at_zero_current(x, p):
    """The state with the coil current set to exactly zero (x7 = -i0)."""
    return x.at[_I].set(-unit_model.levitation_current(p))


def unit_clamped_rhs(x, p, s):
    """Model A in mode s = (held,): the smooth field, or with the current held at zero."""
    held = s[0] > 0.5
    f_free = unit_model.unit_rhs(x, p)
    f_held = unit_model.unit_rhs(_unit_at_zero_current(x, p), p).at[_I].set(0.0)
    return jnp.where(held, f_held, f_free)


_KP, _KD = unit_model.PARAM_NAMES.index("kP"), unit_model.PARAM_NAMES.index("kD")


def unit_clamp_guards(x, p, s):
    """Free: the current i (A); held: minus the controller's demand kP x8 + kD (x9 + x2) + i0
    (A), whose sign is that of the free current rate at i = 0."""
    held = s[0] > 0.5
    i0 = unit_model.levitation_current(p)
    demand = p[_KP] * x[7] + p[_KD] * (x[8] + x[1]) + i0
    return jnp.reshape(jnp.where(held, -demand, x[_I] + i0), (1,))


def unit_clamp_project(x, p, s):
    """Entering the held mode puts the current exactly at zero."""
    return jnp.where(s[0] > 0.5, _unit_at_zero_current(x, p), x)


#: below this gap (m) the free model's magnet force (~ (i / c)^2) is treated as singular
SINGULAR_GAP = 1e-6


def unit_domain(x, p, s):
    """Where model A's field is regular: everywhere while the current is held (no force);
    above a gap of 1 um while it flows (the force grows as (i / c)^2 towards gap 0)."""
    gap = x[0] - x[4] + p[unit_model.PARAM_NAMES.index("c0")]
    return jnp.where(s[0] > 0.5, 1.0, (gap - SINGULAR_GAP) / SINGULAR_GAP)


def unit_clamped(params: Params) -> HybridSystem:
    """Model A with the current clamp as a :class:`HybridSystem` (one switch)."""
    return HybridSystem(
        rhs=unit_clamped_rhs, guards=unit_clamp_guards, project=unit_clamp_project,
        n_switches=1, p=unit_model.param_vector(params), param_names=unit_model.PARAM_NAMES,
        state_names=unit_model.STATE_NAMES, state_scale=unit_model.STATE_SCALE,
        observables={"gap_deviation": unit_model.gap_deviation,
                     "current": unit_model.coil_current},
        name="unit (current clamp)", domain=unit_domain,
    )


# ----------------------------------------------------------------------------- model B
@cache
def _vehicle_functions(n_modes: int):
    rhs_free = vehicle_model.vehicle_rhs(n_modes, False)
    lay = vehicle_model.layout(n_modes)
    idx, iy1, iv = lay["i"], lay["y1"], lay["v"]
    names = vehicle_model.PARAM_NAMES
    kP, kD = names.index("kP"), names.index("kD")

    def at_zero(x, s):
        i = x[idx]
        return x.at[idx].set(jnp.where(s > 0.5, 0.0, i))

    def rhs(x, p, s):
        f = rhs_free(at_zero(x, s), p)
        return f.at[idx].set(jnp.where(s > 0.5, 0.0, f[idx]))

    def guards(x, p, s):
        ud = vehicle_model.point_kinematics(x, p, n_modes)[1]
        i0 = vehicle_model.geometry(p, n_modes)[7]
        demand = p[kP] * x[iy1] + p[kD] * (x[iv] + ud) + i0
        return jnp.where(s > 0.5, -demand, x[idx])

    def project(x, p, s):
        return at_zero(x, s)

    def domain(x, p, s):
        gaps = vehicle_model.point_kinematics(x, p, n_modes)[2]
        return jnp.min(jnp.where(s > 0.5, 1.0, (gaps - SINGULAR_GAP) / SINGULAR_GAP))

    rhs.__qualname__ = f"vehicle_clamped_rhs_{n_modes}"
    guards.__qualname__ = f"vehicle_clamp_guards_{n_modes}"
    project.__qualname__ = f"vehicle_clamp_project_{n_modes}"
    domain.__qualname__ = f"vehicle_clamp_domain_{n_modes}"
    return rhs, guards, project, domain


def vehicle_clamped(params: Params) -> HybridSystem:
    """Model B with the current clamp at each of the six levitation points (six switches)."""
    n = params.n_modes
    system = vehicle_model.vehicle_system(params)
    rhs, guards, project, domain = _vehicle_functions(n)
    return HybridSystem(
        rhs=rhs, guards=guards, project=project, domain=domain,
        n_switches=vehicle_model.N_POINTS,
        p=system.p, param_names=system.param_names, state_names=system.state_names,
        state_scale=np.asarray(system.state_scale), observables=dict(system.observables),
        name=f"vehicle ({n} modes, current clamp)",
    )


# ------------------------------------------------------------------ model A with a delay
@cache
def _unit_delay_functions(smooth_rhs):
    """The clamp on the discretised delay system X = (x, Y) of model A whose smooth field is
    ``smooth_rhs`` (:func:`~maglev_match.dynamics.delay.discretise` of the delayed model, its
    last state the delayed command u(t - tau)): the held mode is the smooth field at the
    current x7 = -i0 with that component removed; the past Y is carried in both modes (the
    command u = kP x8 + kD (x9 + x2) it records does not depend on the current)."""
    n = len(unit_model.STATE_NAMES)

    def rhs(X, p, s):
        held = s[0] > 0.5
        f_free = smooth_rhs(X, p)
        f_held = smooth_rhs(X.at[:n].set(_unit_at_zero_current(X[:n], p)), p).at[_I].set(0.0)
        return jnp.where(held, f_held, f_free)

    def guards(X, p, s):
        # held: minus the demand the current rate at i = 0 follows, now the delayed command
        # u(t - tau) + i0 (the last node of the past); free: the current
        held = s[0] > 0.5
        i0 = unit_model.levitation_current(p)
        return jnp.reshape(jnp.where(held, -(X[-1] + i0), X[_I] + i0), (1,))

    def project(X, p, s):
        return jnp.where(s[0] > 0.5, X.at[:n].set(_unit_at_zero_current(X[:n], p)), X)

    def domain(X, p, s):
        return unit_domain(X[:n], p, s)

    name = getattr(smooth_rhs, "__name__", "rhs")
    rhs.__qualname__ = f"unit_delay_clamped_rhs_{name}"
    guards.__qualname__ = f"unit_delay_clamp_guards_{name}"
    project.__qualname__ = f"unit_delay_clamp_project_{name}"
    domain.__qualname__ = f"unit_delay_clamp_domain_{name}"
    return rhs, guards, project, domain


def unit_delay_clamped(system) -> HybridSystem:
    """Model A with a delayed outer loop and the current clamp as a :class:`HybridSystem`:
    ``system`` is the *smooth* discretised delay system of model A (``unit_system(params)``
    with tau > 0); the state is its (x, past), one switch. The same modes and surfaces as
    :func:`unit_clamped`, with the controller's demand read ``tau`` late."""
    rhs, guards, project, domain = _unit_delay_functions(system.rhs)
    return HybridSystem(
        rhs=rhs, guards=guards, project=project, n_switches=1, p=system.p,
        param_names=system.param_names, state_names=system.state_names,
        state_scale=np.asarray(system.state_scale), observables=dict(system.observables),
        name=f"{system.name} (current clamp)", domain=domain,
    )
