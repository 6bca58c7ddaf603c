"""Models at speed: loads moving at a constant speed v over a guideway of identical simply
supported spans (physics only; the periodic response and its read-outs are in
:mod:`maglev_match.analyses.speed.sweep`).

Guideway
--------
Identical simply supported Euler-Bernoulli spans of length L (bending stiffness EI, mass per
length mbar), each described by its first ``n_modes`` modes with the shapes
sin(n pi x / L) (x measured from the span's left support), circular frequencies
omega_n = n^2 omega1 and modal damping ratio xi1, as in model B. A load F moving on a span
drives its modal coordinates q_n (absolute: undeflected span = 0, m; deflection positive
downwards) by the standard modal equation of a simply supported beam under moving loads
(Fryba, *Vibration of solids and structures under moving loads*, 1972/1999, ch. 1;
Yang, Yau & Wu, *Vehicle-bridge interaction dynamics*, 2004, ch. 2)::

    q_n'' + 2 xi1 omega_n q_n' + omega_n^2 q_n = 2 / (mbar L) sum_j F_j G_nj(t)

where G_nj is the mode shape at a point load j, or its mean over the footprint of a load
spread evenly over a length l_j. The deflection a load feels is w_j = sum_n G_nj q_n (the
same shape functions: the coupling is energy-consistent), and its rate
w_j' = sum_n (G_nj q_n' + dG_nj/dt q_n), which carries the term v dG/dx of the load's motion
along the deflected span.

Span slots
----------
The layout of the loads is shorter than a span, so at most two spans carry loads at a time.
The model carries two *span slots*: A, the span the loads are leaving, and B, the span they
are entering. Time ``t`` (a state, so that the vector field is autonomous) runs over one
passage: at t = 0 the front of the layout reaches the left support of span B (so B enters
the model, at rest by default), and at t = L / v it reaches the next support. In between
each load crosses the support between A and B once; a span keeps its motion while any load
is on it, and slot A, once every load has left it, is frozen (its state no longer matters:
at t = L / v it is dropped). The hand-over at t = L / v is the jump A <- B, B <- the next
span (at rest), t <- 0: one period of the steady response over identical spans.

Which slot each load's front and rear edge is on is a *parameter* of the vector field,
constant on each segment between support crossings (see :data:`KINEMATIC_NAMES`): the
vector field is then smooth inside every segment, and the integrator never steps across a
crossing (the kink of the guideway at a support makes the gap rate jump there).

Models
------
``unit``: model A's levitation unit (masses m, M, suspension ks, cs, controller) with the
vehicle's k units spread evenly over the vehicle length l, all moving as the unit does
(model A's assumption). The guideway carries their total force k F2 spread over l; the unit's
gap sees the mean deflection under the vehicle. With the vehicle centred on one span at
v = 0 and n_modes = 1 this is model A exactly: the mean deflection w = G q1 with
G = 2 L sin(pi l / 2L) / (pi l) obeys w'' + 2 xi1 omega1 w' + omega1^2 w = sigma k F2 / k
with sigma = 2 k G^2 / (mbar L) = 8 k L sin^2(pi l / 2L) / (pi^2 l^2 mbar), model A's force
gain (see :func:`unit_standstill_map`).

``vehicle``: model B (three frames, car body, six levitation points at offsets b_k + a_j
from the body centre), every point acting on the span under it. Body coordinates are
measured from the equilibrium on a rigid guideway (the gap c_j = c0 + u_j - w_j).

``force``: a constant point force P (the vehicle's weight k (m + M) g), no levitation
dynamics: the textbook moving-load problem with a closed-form solution.

State (all models): [vehicle states, q_A (n_modes), q_A' (n_modes), q_B, q_B', t].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.params import Params
from maglev_match.dynamics.system import System
from maglev_match.maglev import irregularity as irr
from maglev_match.maglev import unit as unit_model
from maglev_match.maglev import vehicle as vehicle_model
from maglev_match.maglev.limits import clamp_current, gap_margins

__all__ = [
    "MovingModel",
    "LoadLayout",
    "KINEMATIC_NAMES",
    "layout_of",
    "moving_system",
    "moving_delay_rhs",
    "moving_command",
    "moving_param_names",
    "moving_param_vector",
    "rigid_equilibrium",
    "slot_slices",
    "unit_standstill_map",
    "static_midspan_deflection",
    "coupling",
]


class MovingModel(StrEnum):
    """The models at speed."""

    UNIT = "unit"  # model A's unit, the vehicle's k units spread over its length l
    VEHICLE = "vehicle"  # model B: six levitation points
    FORCE = "force"  # a constant point force, no levitation dynamics


UNIT_VEHICLE_STATES = ("z1", "z1_dot", "z2", "z2_dot", "di", "y1", "v")
UNIT_PARAM_NAMES = unit_model.PARAM_NAMES + ("L", "mbar", "l", "k")
VEHICLE_PARAM_NAMES = vehicle_model.PARAM_NAMES
FORCE_PARAM_NAMES = ("P", "xi1", "L", "mbar", "omega1")
#: Kinematic parameters appended to every model's parameter vector: the speed v (m/s), the
#: position of the layout's front at t = 0 measured from slot A's left support (m; L means
#: "at the support between A and B"), whether slot A and slot B move (1) or are frozen (0),
#: then per load whether its front edge is on slot B and whether its rear edge is.
KINEMATIC_NAMES = ("v", "x_front", "active_A", "active_B")


@dataclass(frozen=True)
class LoadLayout:
    """Where the loads sit: ``front`` (n_loads,) the offset of each load's front edge behind
    the layout's front (m, <= 0), ``length`` (n_loads,) its footprint (m; 0 for a point
    load)."""

    front: np.ndarray
    length: np.ndarray

    @property
    def n_loads(self) -> int:
        return int(self.front.size)

    @property
    def extent(self) -> float:
        """Distance from the layout's front to its rearmost edge (m)."""
        return float(np.max(self.length - self.front))

    def edge_crossings(self, v: float) -> np.ndarray:
        """Times (s) at which a front or rear edge reaches the support between A and B,
        when the layout's front reaches it at t = 0."""
        return np.concatenate([-self.front, self.length - self.front]) / v


def moving_param_names(kind: MovingModel, n_loads: int) -> tuple[str, ...]:
    base = {MovingModel.UNIT: UNIT_PARAM_NAMES, MovingModel.VEHICLE: VEHICLE_PARAM_NAMES,
            MovingModel.FORCE: FORCE_PARAM_NAMES}[MovingModel(kind)]
    flags = (tuple(f"front_on_B_{j + 1}" for j in range(n_loads))
             + tuple(f"rear_on_B_{j + 1}" for j in range(n_loads)))
    return base + KINEMATIC_NAMES + flags


def layout_of(params: Params, kind: MovingModel) -> LoadLayout:
    """The load layout of a model: the unit's vehicle as one load spread over l; the six
    levitation points of model B; the single point force."""
    kind = MovingModel(kind)
    if kind is MovingModel.UNIT:
        return LoadLayout(np.zeros(1), np.array([float(params.l)]))
    if kind is MovingModel.FORCE:
        return LoadLayout(np.zeros(1), np.zeros(1))
    b = vehicle_model.FRAME_SIGN * float(params.s0)
    a = vehicle_model.POINT_SIGN * float(params.s)
    x = b[vehicle_model.POINT_FRAME] + a  # offsets from the body centre (m)
    return LoadLayout(x - np.max(x), np.zeros(vehicle_model.N_POINTS))


def vehicle_point_offsets(params: Params) -> np.ndarray:
    """Offsets b_k + a_j of model B's levitation points from the body centre (m)."""
    b = vehicle_model.FRAME_SIGN * float(params.s0)
    a = vehicle_model.POINT_SIGN * float(params.s)
    return b[vehicle_model.POINT_FRAME] + a


def _base_vector(params: Params, kind: MovingModel) -> np.ndarray:
    if kind is MovingModel.UNIT:
        return np.concatenate([unit_model.param_vector(params),
                               [params.L, params.mbar, params.l, float(params.k)]])
    if kind is MovingModel.VEHICLE:
        return vehicle_model.param_vector(params)
    P = float(params.k) * (params.m + params.M) * params.g
    return np.array([P, params.xi1, params.L, params.mbar, float(params.omega1)])


def moving_param_vector(params: Params, kind: MovingModel, v: float = 0.0,
                        x_front: float | None = None, active=(1.0, 1.0),
                        front_on_B=None, rear_on_B=None) -> np.ndarray:
    """The parameter vector of a model at speed (names: :func:`moving_param_names`).
    Defaults: the layout's front at the support between A and B, both slots moving, every
    edge on slot A."""
    kind = MovingModel(kind)
    lay = layout_of(params, kind)
    n = lay.n_loads
    fb = np.zeros(n) if front_on_B is None else np.asarray(front_on_B, float)
    rb = np.zeros(n) if rear_on_B is None else np.asarray(rear_on_B, float)
    xf = float(params.L) if x_front is None else float(x_front)
    return np.concatenate([_base_vector(params, kind), [float(v), xf, *map(float, active)],
                           fb, rb])


def n_vehicle_states(kind: MovingModel) -> int:
    return {MovingModel.UNIT: 7, MovingModel.VEHICLE: 34, MovingModel.FORCE: 0}[
        MovingModel(kind)]


def slot_slices(kind: MovingModel, n_modes: int) -> dict[str, slice]:
    """Slices of the state vector: vehicle, qA, qA_dot, qB, qB_dot, t."""
    nv = n_vehicle_states(kind)
    m = n_modes
    return {"vehicle": slice(0, nv), "qA": slice(nv, nv + m), "qA_dot": slice(nv + m, nv + 2 * m),
            "qB": slice(nv + 2 * m, nv + 3 * m), "qB_dot": slice(nv + 3 * m, nv + 4 * m),
            "slots": slice(nv, nv + 4 * m), "t": slice(nv + 4 * m, nv + 4 * m + 1)}


def state_names(kind: MovingModel, n_modes: int) -> tuple[str, ...]:
    kind = MovingModel(kind)
    if kind is MovingModel.UNIT:
        veh = UNIT_VEHICLE_STATES
    elif kind is MovingModel.VEHICLE:
        veh = vehicle_model.state_names(n_modes)[:16] + tuple(
            f"{b}{j}" for b in ("i", "y1_", "v") for j in range(1, 7))
    else:
        veh = ()
    slots = tuple(f"{s}{n}{d}" for s in ("qA", "qB") for d in ("", "_dot")
                  for n in range(1, n_modes + 1))
    return veh + slots + ("t",)


def state_scale(kind: MovingModel, n_modes: int, period: float = 1.0) -> np.ndarray:
    """Typical size of every state: 1 mm, 1 cm/s, 1 A as the standstill models; the time
    state by the passage time."""
    kind = MovingModel(kind)
    if kind is MovingModel.UNIT:
        veh = [1e-3, 1e-2, 1e-3, 1e-2, 1.0, 1e-3, 1e-2]
    elif kind is MovingModel.VEHICLE:
        veh = [1e-3] * 8 + [1e-2] * 8 + [1.0] * 6 + [1e-3] * 6 + [1e-2] * 6
    else:
        veh = []
    slots = ([1e-3] * n_modes + [1e-2] * n_modes) * 2
    return np.array(veh + slots + [max(float(period), 1e-3)])


# ---------------------------------------------------------------------------------------
# coupling of loads and span modes
# ---------------------------------------------------------------------------------------
def _mean_shape(a, b, n, L, length):
    """(1/length) int_a^b sin(n pi x / L) dx for local coordinates a <= b on a span."""
    k = n * jnp.pi / L
    return (jnp.cos(k * a) - jnp.cos(k * b)) / (k * length)


def coupling(t, p_kin, lay_front, lay_length, L, n_modes: int, point: bool):
    """G (2, n_modes, n_loads): the shape of mode n of slot A (row 0) and slot B (row 1) at
    each load at time t (s), or its mean over the load's footprint. ``p_kin`` holds the
    kinematic parameters (:data:`KINEMATIC_NAMES` and the edge flags)."""
    v, x_front = p_kin[0], p_kin[1]
    n_loads = lay_front.shape[0]
    fb = p_kin[4:4 + n_loads]
    rb = p_kin[4 + n_loads:4 + 2 * n_loads]
    n = jnp.arange(1, n_modes + 1, dtype=jnp.float64)[:, None]
    xf = x_front + v * t + lay_front  # front edges, measured from slot A's left support
    if point:
        on_b = fb[None, :]
        shape_a = jnp.sin(n * jnp.pi * xf[None, :] / L) * (1.0 - on_b)
        shape_b = jnp.sin(n * jnp.pi * (xf[None, :] - L) / L) * on_b
        return jnp.stack([shape_a, shape_b])
    xr = xf - lay_length
    # footprint on A: [xr, min(xf, L)] while the rear edge is on A; on B: [max(xr, L), xf]
    # while the front edge is on B (local coordinates on B: minus L)
    a_a, b_a = xr, jnp.where(fb > 0.5, L, xf)
    a_b, b_b = jnp.where(rb > 0.5, xr - L, 0.0), xf - L
    shape_a = jnp.where(rb[None, :] > 0.5, 0.0,
                        _mean_shape(a_a[None, :], b_a[None, :], n, L, lay_length[None, :]))
    shape_b = jnp.where(fb[None, :] > 0.5,
                        _mean_shape(a_b[None, :], b_b[None, :], n, L, lay_length[None, :]), 0.0)
    return jnp.stack([shape_a, shape_b])


def _slots(x, nv: int, m: int):
    """(q (2, m), q' (2, m), t) of slots A and B from the state."""
    q = jnp.stack([x[nv:nv + m], x[nv + 2 * m:nv + 3 * m]])
    qd = jnp.stack([x[nv + m:nv + 2 * m], x[nv + 3 * m:nv + 4 * m]])
    return q, qd, x[nv + 4 * m]


def _slots_dynamics(q, qd, p_beam, G, Gdot, forces, n_modes, active):
    """Deflection rate at each load, and the slot velocities and accelerations (frozen
    slots: zero).

    p_beam = (xi1, L, mbar, omega1); G, Gdot (2, n_modes, n_loads); forces (n_loads,) (N,
    downward on the guideway)."""
    xi1, L, mbar, omega1 = p_beam
    wd = jnp.einsum("snj,sn->j", G, qd) + jnp.einsum("snj,sn->j", Gdot, q)
    omega = jnp.arange(1, n_modes + 1, dtype=jnp.float64) ** 2 * omega1
    modal = 2.0 / (mbar * L) * jnp.einsum("snj,j->sn", G, forces)
    qdd = -2.0 * xi1 * omega[None, :] * qd - omega[None, :] ** 2 * q + modal
    act = jnp.asarray(active)[:, None]
    return wd, qd * act, qdd * act


def _kin(p, n_base: int, n_loads: int):
    return p[n_base:n_base + 4 + 2 * n_loads]


def _coupling_and_rate(t, p_kin, front, length, L, n_modes, point):
    def g(tt):
        return coupling(tt, p_kin, front, length, L, n_modes, point)

    return jax.jvp(g, (t,), (jnp.ones_like(t),))


_NA = len(unit_model.PARAM_NAMES)
_NB_UNIT = len(UNIT_PARAM_NAMES)
_NB_VEH = len(VEHICLE_PARAM_NAMES)
_NB_FORCE = len(FORCE_PARAM_NAMES)


def _named(p, names: tuple[str, ...]) -> dict:
    return {n: p[k] for k, n in enumerate(names)}


def _vehicle_offsets(s, s0):
    b = jnp.asarray(vehicle_model.FRAME_SIGN) * s0
    a = jnp.asarray(vehicle_model.POINT_SIGN) * s
    off = b[vehicle_model.POINT_FRAME] + a
    return b, a, off - jnp.max(off)


def _unit_rhs(x, p, n_modes: int, limited: bool, waves: int | None = None, command=None):
    """The unit at speed (module docstring): model A's unit equations with the beam
    deflection x5 = w (the mean deflection under the vehicle) and x6 = w'. With ``waves``
    the parameter vector carries a guideway profile (:mod:`maglev_match.maglev.irregularity`)
    whose mean under the footprint adds to w and w' in the gap. ``command``: the outer
    loop's command read late (1-element array; :mod:`maglev_match.maglev.moving_delay`)."""
    q_ = _named(p[:_NA], unit_model.PARAM_NAMES)
    L, mbar, length, k = p[_NA], p[_NA + 1], p[_NA + 2], p[_NA + 3]
    pk = _kin(p, _NB_UNIT, 1)
    q, qd, t = _slots(x, 7, n_modes)
    G, Gdot = _coupling_and_rate(t, pk, jnp.zeros(1), jnp.reshape(length, (1,)), L, n_modes,
                                 False)
    K = q_["mu0"] * q_["N"] ** 2 * q_["A"]
    i0 = unit_model.levitation_current(p[:_NA])
    w = jnp.einsum("snj,sn->j", G, q)[0]
    zr = zrd = 0.0
    if waves is not None:
        zr, zrd = irr.profile_under(t, pk, p[_NB_UNIT + 6:], jnp.zeros(1),
                                    jnp.reshape(length, (1,)), L, waves, False)
        zr, zrd = zr[0], zrd[0]
        w = w + zr
    c = q_["c0"] + x[0] - w
    i = x[4] + i0
    r = (clamp_current(i) if limited else i) / c
    force = k * 0.5 * K * r**2  # the k units' force on the guideway (N)
    wd, dq, ddq = _slots_dynamics(q, qd, (q_["xi1"], L, mbar, q_["omega1"]), G, Gdot,
                                  jnp.reshape(force, (1,)), n_modes, pk[2:4])
    xa = jnp.stack([x[0], x[1], x[2], x[3], w, wd[0] if waves is None else wd[0] + zrd,
                    x[4], x[5], x[6]])
    fa = unit_model._rhs(xa, p[:_NA], limited, None if command is None else command[0])
    veh = jnp.stack([fa[0], fa[1], fa[2], fa[3], fa[6], fa[7], fa[8]])
    return jnp.concatenate([veh, dq[0], ddq[0], dq[1], ddq[1], jnp.ones(1)])


def _vehicle_rhs(x, p, n_modes: int, limited: bool, waves: int | None = None, command=None):
    """Model B at speed: six levitation points, each acting on the span under it (with
    ``waves``: and the guideway profile under each point added to its deflection;
    ``command``: the six outer loops' commands read late)."""
    q_ = _named(p[:_NB_VEH], VEHICLE_PARAM_NAMES)
    pk = _kin(p, _NB_VEH, 6)
    b, a, front = _vehicle_offsets(q_["s"], q_["s0"])
    q, qd, t = _slots(x, 34, n_modes)
    G, Gdot = _coupling_and_rate(t, pk, front, jnp.zeros(6), q_["L"], n_modes, True)
    K = q_["mu0"] * q_["N"] ** 2 * q_["A"]
    weight = (q_["m_s"] / 2 + q_["m_b"] / 6) * q_["g"]
    i0 = q_["c0"] * jnp.sqrt(weight / K)
    body, body_dot = x[0:8], x[8:16]
    i, y1, vv = x[16:22], x[22:28], x[28:34]
    z, th = body[0:6:2], body[1:6:2]
    zd, thd = body_dot[0:6:2], body_dot[1:6:2]
    u = z[vehicle_model.POINT_FRAME] + a * th[vehicle_model.POINT_FRAME]
    ud = zd[vehicle_model.POINT_FRAME] + a * thd[vehicle_model.POINT_FRAME]
    w = jnp.einsum("snj,sn->j", G, q)
    if waves is not None:
        zr, zrd = irr.profile_under(t, pk, p[_NB_VEH + 16:], front, jnp.zeros(6), q_["L"],
                                    waves, True)
        w = w + zr
    c = q_["c0"] + u - w
    r0 = i0 / q_["c0"]
    r = (clamp_current(i) if limited else i) / c
    f = K * (r - r0) * (r + r0)  # net upward force per point (N), without cancellation
    wd, dq, ddq = _slots_dynamics(q, qd, (q_["xi1"], q_["L"], q_["mbar"], q_["omega1"]), G,
                                  Gdot, K * r**2, n_modes, pk[2:4])
    cd = ud - wd if waves is None else ud - wd - zrd
    body_acc = vehicle_model.body_accelerations(q_, b, body, body_dot, f)
    di, dy1, dv = vehicle_model.loop_rates(q_, K, i0, r, c, cd, ud, i, y1, vv, limited,
                                           command)
    return jnp.concatenate([body_dot, body_acc, di, dy1, dv, dq[0], ddq[0], dq[1], ddq[1],
                            jnp.ones(1)])


def _force_rhs(x, p, n_modes: int, limited: bool, waves: int | None = None):
    """A constant point force P crossing the spans (no levitation dynamics)."""
    P, xi1, L, mbar, omega1 = p[0], p[1], p[2], p[3], p[4]
    pk = _kin(p, _NB_FORCE, 1)
    q, qd, t = _slots(x, 0, n_modes)
    G, Gdot = _coupling_and_rate(t, pk, jnp.zeros(1), jnp.zeros(1), L, n_modes, True)
    _, dq, ddq = _slots_dynamics(q, qd, (xi1, L, mbar, omega1), G, Gdot,
                                 jnp.reshape(P, (1,)), n_modes, pk[2:4])
    return jnp.concatenate([dq[0], ddq[0], dq[1], ddq[1], jnp.ones(1)])


_RHS = {MovingModel.UNIT: _unit_rhs, MovingModel.VEHICLE: _vehicle_rhs,
        MovingModel.FORCE: _force_rhs}


@cache
def moving_rhs(kind: MovingModel, n_modes: int, limited: bool = False,
               waves: int | None = None):
    """The vector field x' = f(x, p) of a model at speed (cached per model, number of modes
    and limits, so compiled code is shared by every speed and segment, and exported ahead
    of time: the closure holds plain values only). ``waves``: the parameter vector ends
    with a guideway profile of that many spectral waves
    (:func:`maglev_match.maglev.irregularity.profile_names`)."""
    kind = MovingModel(kind)
    field_ = _RHS[kind]
    n_modes = int(n_modes)
    limited = bool(limited)
    if waves is None:
        def rhs(x, p):
            return field_(x, p, n_modes, limited)
    else:
        waves = int(waves)

        def rhs(x, p):
            return field_(x, p, n_modes, limited, waves)

    rhs.__name__ = (f"moving_rhs_{kind.value}_{n_modes}{'_limited' if limited else ''}"
                    + ("" if waves is None else f"_irregular{waves}"))
    return rhs


@cache
def moving_delay_rhs(kind: MovingModel, n_modes: int, limited: bool = False,
                     waves: int | None = None):
    """The vector field of a model at speed with the outer loops' commands read late:
    ``rhs(x, ud, p)`` with ``ud[0]`` the commands u(t - tau) (:func:`moving_command`) and
    ``p`` the parameter vector of :func:`moving_rhs` followed by tau (the delay model of the
    standstill models, :func:`maglev_match.maglev.unit.unit_dde` and
    :func:`maglev_match.maglev.vehicle.vehicle_dde`: only the command is late)."""
    kind = MovingModel(kind)
    if kind is MovingModel.FORCE:
        raise ValueError("the force model has no controller to delay")
    field_ = _RHS[kind]
    n_modes, limited = int(n_modes), bool(limited)
    w = None if waves is None else int(waves)

    def rhs(x, ud, p):
        return field_(x, p[:-1], n_modes, limited, w, ud[0])

    rhs.__name__ = (f"moving_delay_rhs_{kind.value}_{n_modes}{'_limited' if limited else ''}"
                    + ("" if w is None else f"_irregular{w}"))
    return rhs


@cache
def moving_command(kind: MovingModel):
    """``u(x, p)``: the outer loops' commands of a model at speed (unit: 1 entry, vehicle:
    6), the standstill models' own functions (:func:`maglev_match.maglev.unit.
    outer_loop_command`, :func:`maglev_match.maglev.vehicle.outer_loop_commands`) applied
    to the vehicle's states (the commands do not read the guideway)."""
    kind = MovingModel(kind)
    if kind is MovingModel.UNIT:
        def command(x, p):
            xa = jnp.stack([x[0], x[1], x[2], x[3], 0.0, 0.0, x[4], x[5], x[6]])
            return unit_model.outer_loop_command(xa, p[:_NA])
    elif kind is MovingModel.VEHICLE:
        standstill = vehicle_model.outer_loop_commands(0)  # the vehicle's 34 states

        def command(x, p):
            return standstill(x[:34], p[:_NB_VEH])
    else:
        raise ValueError("the force model has no controller to delay")
    command.__name__ = f"moving_command_{kind.value}"
    return command


# ---------------------------------------------------------------------------------------
# read-outs
# ---------------------------------------------------------------------------------------
def _midspan(x, p, nv: int, n_modes: int):
    mid = jnp.sin(jnp.arange(1, n_modes + 1, dtype=jnp.float64) * jnp.pi / 2.0)
    q, _, _ = _slots(x, nv, n_modes)
    return q @ mid


def _loads_deflection(x, p, kind: str, n_modes: int, waves: int | None = None):
    """The deflection each load feels (m): the mean under the unit's footprint, or the
    deflection at each of model B's points."""
    if kind == MovingModel.VEHICLE:
        q_ = _named(p[:_NB_VEH], VEHICLE_PARAM_NAMES)
        _, _, front = _vehicle_offsets(q_["s"], q_["s0"])
        G = coupling(x[34 + 4 * n_modes], _kin(p, _NB_VEH, 6), front, jnp.zeros(6), q_["L"],
                     n_modes, True)
        q, _, _ = _slots(x, 34, n_modes)
        if waves is not None:
            zr, _ = irr.profile_under(x[34 + 4 * n_modes], _kin(p, _NB_VEH, 6),
                                      p[_NB_VEH + 16:], front, jnp.zeros(6), q_["L"], waves,
                                      True)
            return jnp.einsum("snj,sn->j", G, q) + zr
    else:
        G = coupling(x[7 + 4 * n_modes], _kin(p, _NB_UNIT, 1), jnp.zeros(1),
                     jnp.reshape(p[_NA + 2], (1,)), p[_NA], n_modes, False)
        q, _, _ = _slots(x, 7, n_modes)
        if waves is not None:
            zr, _ = irr.profile_under(x[7 + 4 * n_modes], _kin(p, _NB_UNIT, 1),
                                      p[_NB_UNIT + 6:], jnp.zeros(1),
                                      jnp.reshape(p[_NA + 2], (1,)), p[_NA], waves, False)
            return jnp.einsum("snj,sn->j", G, q) + zr
    return jnp.einsum("snj,sn->j", G, q)


def _gap_deviation(x, p, kind: str, n_modes: int, waves: int | None = None):
    if kind == MovingModel.VEHICLE:
        s = p[VEHICLE_PARAM_NAMES.index("s")]
        a = jnp.asarray(vehicle_model.POINT_SIGN) * s
        u = x[0:6:2][vehicle_model.POINT_FRAME] + a * x[1:6:2][vehicle_model.POINT_FRAME]
    else:
        u = x[0:1]
    return u - _loads_deflection(x, p, kind, n_modes, waves)


def _current(x, p, kind: str):
    if kind == MovingModel.VEHICLE:
        return x[16:22]
    return jnp.reshape(x[4] + unit_model.levitation_current(p[:_NA]), (1,))


def _body_acceleration(x, p, kind: str, n_modes: int, waves: int | None = None):
    f = _RHS[MovingModel(kind)](x, p, n_modes, False, waves)
    return f[14] if kind == MovingModel.VEHICLE else f[3]


@cache
def observables(kind: MovingModel, n_modes: int, waves: int | None = None) -> dict:
    """Named read-outs g(x, p) of a model at speed (module-level per model, so compiled code
    is reused; their closures hold plain values only, so they are exported ahead of time):

    * ``gap_deviation`` c_j - c0 at every levitation point (m) (unit: one entry);
    * ``current`` i_j (A);
    * ``midspan`` the mid-span deflection of slot A and slot B, sum_n q_n sin(n pi / 2) (m,
      downward positive);
    * ``body_acceleration`` the car body's vertical acceleration at its centre (m/s^2,
      downward positive: unit z2'', vehicle z0'').

    The force model has ``midspan`` only. ``waves``: with a guideway profile in the
    parameter vector (the gap deviation then includes it)."""
    kind_s = MovingModel(kind).value
    m = int(n_modes)
    nv = n_vehicle_states(MovingModel(kind))

    def midspan(x, p):
        return _midspan(x, p, nv, m)

    out = {"midspan": midspan}
    if kind_s == MovingModel.FORCE:
        return out

    def gap_deviation(x, p):
        return _gap_deviation(x, p, kind_s, m, waves)

    def current(x, p):
        return _current(x, p, kind_s)

    def body_acceleration(x, p):
        return _body_acceleration(x, p, kind_s, m, waves)

    out.update(gap_deviation=gap_deviation, current=current,
               body_acceleration=body_acceleration)
    return out


def _gap_margins(x, p, limits, kind: str, n_modes: int, ic0: int, waves: int | None = None):
    return jnp.reshape(gap_margins(p[ic0] + _gap_deviation(x, p, kind, n_modes, waves),
                                   limits[0],
                                   limits[1]), (-1,))


@cache
def gap_events(kind: MovingModel, n_modes: int, waves: int | None = None):
    """``g(x, p, (gap_min, gap_max))``: gap_j - gap_min and gap_max - gap_j per levitation
    point (entries 2(j-1), 2(j-1)+1); negative is a collision."""
    kind_s = MovingModel(kind).value
    m = int(n_modes)
    ic0 = (unit_model.PARAM_NAMES.index("c0") if kind_s == MovingModel.UNIT
           else VEHICLE_PARAM_NAMES.index("c0"))

    def events(x, p, limits):
        return _gap_margins(x, p, limits, kind_s, m, ic0, waves)

    return events


# ---------------------------------------------------------------------------------------
# systems and reference states
# ---------------------------------------------------------------------------------------
def moving_system(params: Params, kind: MovingModel, p: np.ndarray | None = None,
                  limited: bool = False, period: float = 1.0,
                  waves: int | None = None) -> System:
    """A model at speed as a :class:`~maglev_match.dynamics.system.System` (the parameter
    vector ``p`` defaults to :func:`moving_param_vector` at v = 0). ``waves``: the
    parameter vector ends with a guideway profile of that many spectral waves."""
    kind = MovingModel(kind)
    n_modes = int(params.n_modes)
    lay = layout_of(params, kind)
    pv = moving_param_vector(params, kind) if p is None else np.asarray(p, float)
    extra = () if waves is None else irr.profile_names(int(waves))
    return System(
        rhs=moving_rhs(kind, n_modes, limited, waves),
        p=pv,
        param_names=moving_param_names(kind, lay.n_loads) + extra,
        state_names=state_names(kind, n_modes),
        x_guess=rigid_equilibrium(params, kind),
        state_scale=state_scale(kind, n_modes, period),
        observables=observables(kind, n_modes, waves),
        name=f"{kind.value} at speed ({n_modes} modes per span)"
             + ("" if waves is None else ", on an irregular guideway"),
    )


def rigid_equilibrium(params: Params, kind: MovingModel) -> np.ndarray:
    """The equilibrium on a rigid guideway: every gap at c0, currents at the levitation
    current, spans undeflected, t = 0."""
    kind = MovingModel(kind)
    sl = slot_slices(kind, params.n_modes)
    x = np.zeros(sl["t"].stop)
    if kind is MovingModel.VEHICLE:
        x[16:22] = params.i0_vehicle
    return x


def follow_profile(params: Params, kind: MovingModel, x: np.ndarray, p: np.ndarray,
                   waves: int) -> np.ndarray:
    """The state ``x`` (the equilibrium on rigid ground, t = 0) moved onto the guideway
    profile in ``p``: every levitation point raised with the profile under it and moving
    with its rate, so that a run over an irregular guideway starts without the jump of a
    profile that is not zero where it starts. The unit: z1, z2 by the profile's mean under
    the footprint, their rates by its rate, the observer's velocity state v by minus it
    (the steady following of a moving guideway). The vehicle: each frame's heave and pitch
    through its two points, the car body's heave and pitch through the outer frames, the
    observers' v_j by minus the points' rates. Gaps and currents are unchanged."""
    kind = MovingModel(kind)
    g = observables(kind, int(params.n_modes), int(waves))["gap_deviation"]
    x = np.array(x, float)
    e = np.zeros_like(x)
    e[-1] = 1.0
    gv, gdot = jax.jvp(lambda xx: g(xx, jnp.asarray(p)), (jnp.asarray(x),), (jnp.asarray(e),))
    z, zd = -np.asarray(gv), -np.asarray(gdot)  # u = 0 and w = 0 at the start
    if kind is MovingModel.UNIT:
        x[0] += z[0]
        x[2] += z[0]
        x[1] += zd[0]
        x[3] += zd[0]
        x[6] -= zd[0]
        return x
    s, s0 = float(params.s), float(params.s0)
    for off, val in ((0, z), (8, zd)):
        zf = 0.5 * (val[0::2] + val[1::2])
        thf = (val[1::2] - val[0::2]) / (2.0 * s)
        x[off + 0:off + 6:2] += zf
        x[off + 1:off + 6:2] += thf
        x[off + 6] += float(np.mean(zf))
        x[off + 7] += (zf[2] - zf[0]) / (2.0 * s0)
    x[28:34] -= zd
    return x


def static_midspan_deflection(params: Params, kind: MovingModel, samples: int = 2001
                              ) -> tuple[float, float]:
    """The largest static mid-span deflection of one span under the layout's weights (m),
    and the front position where it occurs (m from the span's left support): the static
    reference of the dynamic amplification factor, with the same modes as the dynamic
    model. Weights: the unit's k (m + M) g spread over l, model B's point loads
    (m_s/2 + m_b/6) g, the force P. Mid-span deflection under a static load F_j with shape
    value G_nj: sum_n 2 F_j G_nj sin(n pi / 2) / (mbar L omega_n^2)."""
    kind = MovingModel(kind)
    lay = layout_of(params, kind)
    L = float(params.L)
    if kind is MovingModel.UNIT or kind is MovingModel.FORCE:
        weights = np.array([float(params.k) * (params.m + params.M) * params.g])
    else:
        weights = np.full(6, params.point_load_vehicle)
    n = np.arange(1, params.n_modes + 1)
    omega = n**2 * float(params.omega1)
    amp = 2.0 * np.sin(n * np.pi / 2.0) / (params.mbar * L * omega**2)

    def w_mid(front: np.ndarray) -> np.ndarray:
        xf = front[:, None] + lay.front[None, :]  # (positions, loads) on one span
        xr = xf - lay.length[None, :]
        a, b = np.clip(xr, 0.0, L), np.clip(xf, 0.0, L)
        shape = np.empty((front.size, n.size, lay.n_loads))
        for k, nn in enumerate(n):
            kk = nn * math.pi / L
            if np.all(lay.length == 0):
                inside = (xf >= 0) & (xf <= L)
                shape[:, k, :] = np.where(inside, np.sin(kk * xf), 0.0)
            else:
                shape[:, k, :] = (np.cos(kk * a) - np.cos(kk * b)) / (kk * lay.length[None, :])
        return np.einsum("pnj,j,n->p", shape, weights, amp)

    fronts = np.linspace(0.0, L + lay.extent, samples)
    vals = w_mid(fronts)
    k = int(np.argmax(vals))
    lo, hi = fronts[max(k - 1, 0)], fronts[min(k + 1, fronts.size - 1)]
    for _ in range(3):  # zoom in on the maximum
        fine = np.linspace(lo, hi, 201)
        fv = w_mid(fine)
        kk = int(np.argmax(fv))
        lo, hi = fine[max(kk - 1, 0)], fine[min(kk + 1, fine.size - 1)]
    best = 0.5 * (lo + hi)
    return float(w_mid(np.array([best]))[0]), float(best)


def unit_standstill_map(params: Params) -> tuple[float, np.ndarray]:
    """For the unit at v = 0 centred on slot A with n_modes = 1: (G, T) with G the mean of
    mode 1 under the vehicle, 2 L sin(pi l / 2L) / (pi l), and T (9, 11) the linear map from
    the moving state [z1, z1', z2, z2', di, y1, v, qA, qA', qB, qB'] (t left out) to model A's
    state x_A = [z1, z1', z2, z2', w - w0, w', di, y1, v] taken about the static state,
    w = G qA. With it the two Jacobians are similar: J_A = T J T^+ on the coupled part."""
    L, length = float(params.L), float(params.l)
    G = 2.0 * L * math.sin(math.pi * length / (2.0 * L)) / (math.pi * length)
    T = np.zeros((9, 11))
    for a, b in ((0, 0), (1, 1), (2, 2), (3, 3), (6, 4), (7, 5), (8, 6)):
        T[a, b] = 1.0
    T[4, 7] = G
    T[5, 8] = G
    return G, T
