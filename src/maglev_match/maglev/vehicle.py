"""Model B: the full vehicle (three levitation frames and a car body) over an n-mode
simply supported beam.

State layout (16 + 2 n_modes + 18 entries):

* ``z1, th1, z2, th2, z3, th3, z0, th0``: frame k heave/pitch and car-body heave/pitch,
  z down-positive from the static equilibrium (m, rad);
* their rates (m/s, rad/s);
* ``q1..qn``: absolute modal coordinates of the beam (undeflected beam = 0) (m);
* their rates;
* ``i1..i6``: coil current of levitation point j (A);
* ``y1_1..y1_6``: observer gap signal; ``v1..v6``: observer velocity minus magnet velocity.

Levitation point j = 2k-1, 2k sits at a_j = -s, +s on frame k, frame k at b_k = -s0, 0, +s0
from the body centre; the vehicle centre is at mid-span.

With a delay tau > 0 of the outer control loop (parameter ``tau``, s), every point's current
equation reads its outer-loop command u_j = kP y1_j + kD (v_j + u_j') late, as in model A
(:mod:`maglev_match.maglev.unit`): i_j' = (i_j / c_j) c_j' + ke c_j / K (u_j(t - tau) - i_j
+ i0). :func:`vehicle_dde` is this delay system (six delayed signals).
"""

from __future__ import annotations

from functools import cache

import jax.numpy as jnp
import numpy as np

from maglev_match.core.params import PARAMETER_DOCS, Params, param_ranges
from maglev_match.dynamics.delay import DelayDifferentialSystem
from maglev_match.dynamics.system import System
from maglev_match.maglev.limits import clamp_current, hold_current_rate

PARAM_NAMES = (
    "m_s", "j_s", "m_b", "j_b", "k2", "c2", "g", "mu0", "N", "A", "c0",
    "omega0", "xi0", "kP", "kD", "ke", "xi1", "L", "mbar", "omega1", "s", "s0",
)
_IDX = {n: k for k, n in enumerate(PARAM_NAMES)}
BODY_NAMES = ("z1", "th1", "z2", "th2", "z3", "th3", "z0", "th0")
N_POINTS = 6
# frame of each levitation point, and the sign of its offset a_j = sign * s
POINT_FRAME = np.array([0, 0, 1, 1, 2, 2])
POINT_SIGN = np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0])
FRAME_SIGN = np.array([-1.0, 0.0, 1.0])  # b_k = sign * s0


def state_names(n_modes: int) -> tuple[str, ...]:
    q = tuple(f"q{n}" for n in range(1, n_modes + 1))
    return (
        BODY_NAMES
        + tuple(f"{b}_dot" for b in BODY_NAMES)
        + q
        + tuple(f"{b}_dot" for b in q)
        + tuple(f"i{j}" for j in range(1, 7))
        + tuple(f"y1_{j}" for j in range(1, 7))
        + tuple(f"v{j}" for j in range(1, 7))
    )


def layout(n_modes: int) -> dict[str, slice]:
    """Slices of the state vector by block."""
    n = n_modes
    return {
        "body": slice(0, 8),
        "body_dot": slice(8, 16),
        "q": slice(16, 16 + n),
        "q_dot": slice(16 + n, 16 + 2 * n),
        "i": slice(16 + 2 * n, 22 + 2 * n),
        "y1": slice(22 + 2 * n, 28 + 2 * n),
        "v": slice(28 + 2 * n, 34 + 2 * n),
    }


def geometry(p, n_modes: int):
    q = {k: p[v] for k, v in _IDX.items()}
    b = jnp.asarray(FRAME_SIGN) * q["s0"]
    a = jnp.asarray(POINT_SIGN) * q["s"]
    xj = q["L"] / 2 + b[POINT_FRAME] + a  # positions on the beam (m)
    n = jnp.arange(1, n_modes + 1, dtype=jnp.float64)
    phi = jnp.sin(jnp.outer(n, xj) * jnp.pi / q["L"])  # (n_modes, 6)
    omega = n**2 * q["omega1"]
    K = q["mu0"] * q["N"] ** 2 * q["A"]
    load = (q["m_s"] / 2 + q["m_b"] / 6) * q["g"]  # weight per point (N)
    i0 = q["c0"] * jnp.sqrt(load / K)
    q_static = 2.0 / (q["mbar"] * q["L"] * omega**2) * (phi @ (load * jnp.ones(N_POINTS)))
    return q, a, b, xj, phi, omega, K, i0, q_static


def point_kinematics(x, p, n_modes: int):
    """Magnet displacement u_j, its rate, gap c_j and gap rate at every levitation point."""
    q, a, b, xj, phi, omega, K, i0, q_static = geometry(p, n_modes)
    L = layout(n_modes)
    body, body_dot = x[L["body"]], x[L["body_dot"]]
    z, th = body[0:6:2], body[1:6:2]
    zd, thd = body_dot[0:6:2], body_dot[1:6:2]
    u = z[POINT_FRAME] + a * th[POINT_FRAME]
    ud = zd[POINT_FRAME] + a * thd[POINT_FRAME]
    dq = x[L["q"]] - q_static
    c = q["c0"] + u - dq @ phi
    cd = ud - x[L["q_dot"]] @ phi
    return u, ud, c, cd


def body_accelerations(q, b, body, body_dot, f):
    """The accelerations of the three levitation frames (heave, pitch) and the car body
    (heave, pitch), in state order, from the frames' and body's positions and velocities,
    the frames' offsets ``b`` and the net upward forces ``f`` of the six points (pairs per
    frame): the secondary suspension and the magnets. Shared by model B at standstill and
    at speed."""
    z, zd = body[0:6:2], body_dot[0:6:2]
    z0, th0, z0d, th0d = body[6], body[7], body_dot[6], body_dot[7]
    d = z - z0 - b * th0
    dd = zd - z0d - b * th0d
    susp = q["k2"] * d + q["c2"] * dd
    f_pair = f.reshape(3, 2)
    z_acc = (-(f_pair[:, 0] + f_pair[:, 1]) - susp) / q["m_s"]
    th_acc = q["s"] * (f_pair[:, 0] - f_pair[:, 1]) / q["j_s"]
    z0_acc = jnp.sum(susp) / q["m_b"]
    th0_acc = jnp.sum(b * susp) / q["j_b"]
    return jnp.stack([z_acc[0], th_acc[0], z_acc[1], th_acc[1], z_acc[2], th_acc[2],
                      z0_acc, th0_acc])


def loop_rates(q, K, i0, r, c, cd, ud, i, y1, v, limited: bool, command=None):
    """The rates of the six points' currents, observer states y1 and v: the magnets'
    circuits under the outer loops' commands u_j = kP y1_j + kD (v_j + u_j') (``command``:
    read late when delayed), the current's rate held at the clamp when ``limited``. Shared
    by model B at standstill and at speed."""
    gap_err = c - q["c0"] - y1
    u = q["kP"] * y1 + q["kD"] * (v + ud) if command is None else command
    di = r * cd + q["ke"] * c / K * (u - i + i0)
    if limited:
        di = hold_current_rate(i, di)
    dy1 = v + ud + 2.0 * q["xi0"] * q["omega0"] * gap_err
    dv = q["omega0"] ** 2 * gap_err
    return di, dy1, dv


def _rhs(x, p, n_modes: int, limited: bool, command=None):
    q, a, b, xj, phi, omega, K, i0, q_static = geometry(p, n_modes)
    L = layout(n_modes)
    body, body_dot = x[L["body"]], x[L["body_dot"]]
    u, ud, c, cd = point_kinematics(x, p, n_modes)
    i, y1, v = x[L["i"]], x[L["y1"]], x[L["v"]]
    r0 = i0 / q["c0"]
    r = (clamp_current(i) if limited else i) / c
    f = K * (r - r0) * (r + r0)  # net upward force per point, without cancellation (N)

    body_acc = body_accelerations(q, b, body, body_dot, f)

    qn, qd = x[L["q"]], x[L["q_dot"]]
    q_acc = (-2.0 * q["xi1"] * omega * qd - omega**2 * (qn - q_static)
             + 2.0 / (q["mbar"] * q["L"]) * (phi @ f))

    di, dy1, dv = loop_rates(q, K, i0, r, c, cd, ud, i, y1, v, limited, command)
    return jnp.concatenate([body_dot, body_acc, qd, q_acc, di, dy1, dv])


@cache
def vehicle_rhs(n_modes: int = 3, limited: bool = False):
    """Model B vector field for ``n_modes`` beam modes (cached, so compiled code is reused)."""

    def rhs(x, p):
        return _rhs(x, p, n_modes, limited)

    rhs.__name__ = f"vehicle_rhs_{n_modes}{'_limited' if limited else ''}"
    return rhs


@cache
def vehicle_delay_rhs(n_modes: int = 3, limited: bool = False):
    """Model B with the outer loops delayed: ``rhs(x, ud, p)`` with ``ud[0]`` the six
    commands u_j(t - tau) (cached per n_modes and limits)."""

    def rhs(x, ud, p):
        return _rhs(x, p, n_modes, limited, command=ud[0])

    rhs.__name__ = f"vehicle_delay_rhs_{n_modes}{'_limited' if limited else ''}"
    return rhs


@cache
def outer_loop_commands(n_modes: int = 3):
    """u_j = kP y1_j + kD (v_j + u_j') (A) at the six points: the delayed quantities."""
    L = layout(n_modes)

    def commands(x, p):
        ud = point_kinematics(x, p, n_modes)[1]
        return p[_IDX["kP"]] * x[L["y1"]] + p[_IDX["kD"]] * (x[L["v"]] + ud)

    commands.__name__ = f"vehicle_commands_{n_modes}"
    return commands


def param_vector(params: Params) -> np.ndarray:
    return np.array([float(getattr(params, n)) for n in PARAM_NAMES])


@cache
def gap_function(n_modes: int):
    """``gap(x, p)``: the gaps c_j of the six levitation points (m) (one function object per
    number of modes, so compiled code is shared)."""

    def gap(x, p):
        return point_kinematics(x, p, n_modes)[2]

    return gap


def pressed_line_derivative(params: Params, direction: int, size: float) -> np.ndarray:
    """d x0 / dp of the index's disturbance line at ``size`` (m): the state
    x_eq + (-direction) size / w_mid (pressed - x_eq) moves with the parameters through the
    equilibrium, the pressed state and the mid-span deflection w_mid; exact, by forward-mode
    differentiation (rows: states, columns: :data:`PARAM_NAMES`)."""
    import jax

    n_modes = params.n_modes
    lay = layout(n_modes)
    mid = jnp.sin(jnp.arange(1, n_modes + 1, dtype=jnp.float64) * jnp.pi / 2.0)

    def x0(p):
        *_, i0, q_static = geometry(p, n_modes)
        x_eq = jnp.zeros(34 + 2 * n_modes).at[lay["q"]].set(q_static).at[lay["i"]].set(i0)
        delta = jnp.zeros_like(x_eq).at[lay["q"]].set(-q_static)
        w_mid = q_static @ mid
        return x_eq + (-direction) * size / w_mid * delta

    return np.asarray(jax.jacfwd(x0)(jnp.asarray(param_vector(params))))


def equilibrium_guess(params: Params) -> np.ndarray:
    """Static equilibrium in closed form: beam statically deflected (q = q*), every gap at
    c0, currents at the vehicle's levitation current, all else zero."""
    n_modes = params.n_modes
    p = param_vector(params)
    *_, i0, q_static = geometry(jnp.asarray(p), n_modes)
    x = np.zeros(34 + 2 * n_modes)
    L = layout(n_modes)
    x[L["q"]] = np.asarray(q_static)
    x[L["i"]] = float(i0)
    return x


def pressed_initial_state(params: Params) -> np.ndarray:
    """'Vehicle pressed onto the free beam': all vehicle and controller states at
    equilibrium, beam undeflected (q = 0, q' = 0)."""
    x = equilibrium_guess(params)
    x[layout(params.n_modes)["q"]] = 0.0
    return x


@cache
def _observables(n_modes: int) -> dict:
    """Named read-outs (module-level per n_modes, so compiled code is reused): gap deviation
    c_j - c0 (m) and current i_j (A) at the six points, modal coordinates q_n (m)."""
    L = layout(n_modes)

    def gap_deviation(x, p):
        return point_kinematics(x, p, n_modes)[2] - p[_IDX["c0"]]

    def current(x, p):
        return x[L["i"]]

    def beam_deflection(x, p):
        return x[L["q"]]

    return {"gap_deviation": gap_deviation, "current": current,
            "beam_deflection": beam_deflection}


DELAY_PARAM_NAMES = PARAM_NAMES + ("tau",)


def _state_scale(n: int) -> np.ndarray:
    L = layout(n)
    scale = np.ones(34 + 2 * n)
    scale[L["body"]] = 1e-3
    scale[L["body_dot"]] = 1e-2
    scale[L["q"]] = 1e-3
    scale[L["q_dot"]] = 1e-2
    scale[L["i"]] = 1.0
    scale[L["y1"]] = 1e-3
    scale[L["v"]] = 1e-2
    return scale


def vehicle_dde(params: Params, limited: bool = False) -> DelayDifferentialSystem:
    """Model B with the delayed outer loops as a delay system (parameters
    :data:`DELAY_PARAM_NAMES`); its delay-free system is the ODE of :func:`vehicle_system`."""
    n = params.n_modes
    return DelayDifferentialSystem(
        rhs=vehicle_delay_rhs(n, limited), signals=(outer_loop_commands(n),), delays=("tau",),
        p=np.append(param_vector(params), float(params.tau)), param_names=DELAY_PARAM_NAMES,
        state_names=state_names(n), x_guess=equilibrium_guess(params),
        state_scale=_state_scale(n), observables=_observables(n),
        name=f"vehicle ({n} modes)", signal_names=(tuple(f"u{j}" for j in range(1, 7)),),
        ode_rhs=vehicle_rhs(n, limited), ode_param_names=PARAM_NAMES)


def vehicle_system(params: Params, limited: bool = False, *, tau_max: float | None = None,
                   nodes: int | None = None) -> System:
    """Model B as a :class:`System` for the given parameter set: the ODE when
    ``params.tau = 0`` and no ``tau_max``, else the discretised delay system (as
    :func:`maglev_match.maglev.unit.unit_system`)."""
    if params.tau > 0 or tau_max is not None or nodes is not None:
        from maglev_match.maglev.unit import discretised

        return discretised(vehicle_dde(params, limited), tau_max=tau_max, nodes=nodes)
    n = params.n_modes
    scale = _state_scale(n)
    return System(
        rhs=vehicle_rhs(n, limited),
        p=param_vector(params),
        param_names=PARAM_NAMES,
        state_names=state_names(n),
        x_guess=equilibrium_guess(params),
        state_scale=scale,
        observables=_observables(n),
        name=f"vehicle ({n} modes)",
        param_ranges=param_ranges(PARAM_NAMES),
        param_units={n: PARAMETER_DOCS[n][0] for n in PARAM_NAMES if n in PARAMETER_DOCS},
    )
