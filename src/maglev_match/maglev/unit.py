"""Model A: one levitation unit on the first beam mode (9 states).

State x = [z1, z1', z2, z2', w, w', i - i0, y1, y2 - z1'] with z down-positive from the
static equilibrium, w the equivalent beam deflection and y1, y2 the observer outputs.
Gap c = x1 - x5 + c0. The equilibrium is x = 0.

With a delay tau > 0 of the outer control loop (parameter ``tau``, s) the current
equation reads the outer loop's command late,

    x7' = r (x2 - x6) + ke c / K (u(t - tau) - x7),    u = kP x8 + kD (x9 + x2)

(u: the current the gap and velocity feedback ask for, A, from the observer outputs y1 = x8
and y2 = x9 + x2); the inner current loop (- x7) and the induction term r (x2 - x6) act at
once. :func:`unit_dde` is this delay system; with tau = 0 :func:`unit_system` is the ODE
above, unchanged.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from maglev_match.core.params import PARAMETER_DOCS, ParameterError, Params, param_ranges
from maglev_match.dynamics.delay import DelayDifferentialSystem, DelayNodesError, discretise
from maglev_match.dynamics.system import RegularChart, System
from maglev_match.maglev.limits import clamp_current, hold_current_rate

STATE_NAMES = ("z1", "z1_dot", "z2", "z2_dot", "w", "w_dot", "di", "y1", "v")
STATE_SCALE = np.array([1e-3, 1e-2, 1e-3, 1e-2, 1e-3, 1e-2, 1.0, 1e-3, 1e-2])
PARAM_NAMES = (
    "m", "M", "g", "ks", "cs", "mu0", "N", "A", "c0",
    "omega0", "xi0", "kP", "kD", "ke", "xi1", "omega1", "sigma",
)
_IDX = {n: k for k, n in enumerate(PARAM_NAMES)}


def _unpack(p):
    return {n: p[k] for n, k in _IDX.items()}


def levitation_current(p):
    """i0 = c0/N sqrt(2 (m+M) g / (mu0 A)) (A), from the parameter vector."""
    q = _unpack(p)
    return q["c0"] / q["N"] * jnp.sqrt(2.0 * (q["m"] + q["M"]) * q["g"] / (q["mu0"] * q["A"]))


def _rhs(x, p, limited: bool, command=None):
    q = _unpack(p)
    m, M = q["m"], q["M"]
    K = q["mu0"] * q["N"] ** 2 * q["A"]
    c0 = q["c0"]
    i0 = levitation_current(p)
    r0 = i0 / c0
    x1, x2, x3, x4, x5, x6, x7, x8, x9 = x
    c = x1 - x5 + c0
    i = x7 + i0
    r = (clamp_current(i) if limited else i) / c
    # F2 - (m+M) g written without cancellation: K r0^2 / 2 = (m+M) g exactly.
    dF = 0.5 * K * (r - r0) * (r + r0)
    susp = q["cs"] * (x2 - x4) + q["ks"] * (x1 - x3)
    w1, xi1, sig = q["omega1"], q["xi1"], q["sigma"]
    gap_err = x1 - x5 - x8
    # the outer loop's current command u = kP y1 + kD y2 (read late when delayed)
    u = q["kP"] * x8 + q["kD"] * (x9 + x2) if command is None else command
    di = r * (x2 - x6) + q["ke"] * c / K * (u - x7)
    if limited:
        di = hold_current_rate(i, di)
    return jnp.stack([
        x2,
        -dF / m - susp / m,
        x4,
        susp / M,
        x6,
        -(w1**2) * x5 - 2.0 * xi1 * w1 * x6 + sig * dF,
        di,
        x9 + x2 + 2.0 * q["xi0"] * q["omega0"] * gap_err,
        q["omega0"] ** 2 * gap_err,
    ])


def _rhs_regular(y, p):
    """Model A in the coordinates y = (x1..x6, r - r0, x8, x9), r = i / c the current over
    the gap (A/m), r0 = i0 / c0: the same equations, with x7 = i - i0 replaced by r. The
    current equation x7' = r (x2 - x6) + ke c / K (...) is (r c)' = r c' + c r', so
    r' = ke / K (kP x8 + kD (x9 + x2) - x7) with x7 = r c - i0: a polynomial vector field,
    smooth at gap c = 0, where the original one is 0/0 (i and c vanish together on every
    trajectory that reaches c = 0)."""
    q = _unpack(p)
    m, M = q["m"], q["M"]
    K = q["mu0"] * q["N"] ** 2 * q["A"]
    c0 = q["c0"]
    i0 = levitation_current(p)
    r0 = i0 / c0
    x1, x2, x3, x4, x5, x6, y7, x8, x9 = y
    c = x1 - x5 + c0
    r = y7 + r0
    dF = 0.5 * K * (r - r0) * (r + r0)
    susp = q["cs"] * (x2 - x4) + q["ks"] * (x1 - x3)
    w1, xi1, sig = q["omega1"], q["xi1"], q["sigma"]
    gap_err = x1 - x5 - x8
    dr = q["ke"] / K * (q["kP"] * x8 + q["kD"] * (x9 + x2) - (r * c - i0))
    return jnp.stack([
        x2,
        -dF / m - susp / m,
        x4,
        susp / M,
        x6,
        -(w1**2) * x5 - 2.0 * xi1 * w1 * x6 + sig * dF,
        dr,
        x9 + x2 + 2.0 * q["xi0"] * q["omega0"] * gap_err,
        q["omega0"] ** 2 * gap_err,
    ])


def _to_regular(x, p):
    """y = (x1..x6, (x7 + i0) / c - i0 / c0, x8, x9)."""
    c0 = p[_IDX["c0"]]
    i0 = levitation_current(p)
    c = x[0] - x[4] + c0
    return x.at[6].set((x[6] + i0) / c - i0 / c0)


def _from_regular(y, p):
    """x = (y1..y6, (y7 + i0 / c0) c - i0, y8, y9)."""
    c0 = p[_IDX["c0"]]
    i0 = levitation_current(p)
    c = y[0] - y[4] + c0
    return y.at[6].set((y[6] + i0 / c0) * c - i0)


def _relative_gap(x, p):
    """c / c0: the distance of a state from the singular set c = 0 of unit_rhs."""
    c0 = p[_IDX["c0"]]
    return (x[0] - x[4] + c0) / c0


#: Model A's regular chart (see :func:`_rhs_regular`): cycles that come within 5 % of the
#: rated gap of gap 0 are continued in it (a contact with the gap limit 0 is then solved).
REGULAR_CHART = RegularChart(
    rhs=_rhs_regular, to_chart=_to_regular, from_chart=_from_regular,
    distance=_relative_gap,
    state_scale=np.array([1e-3, 1e-2, 1e-3, 1e-2, 1e-3, 1e-2, 125.0, 1e-3, 1e-2]),
    switch_below=0.05)


def unit_rhs(x, p):
    """Model A vector field (smooth: no current clamp)."""
    return _rhs(x, p, limited=False)


def unit_rhs_limited(x, p):
    """Model A with the no-reversal rule for the coil current."""
    return _rhs(x, p, limited=True)


def outer_loop_command(x, p):
    """u = kP y1 + kD y2 = kP x8 + kD (x9 + x2) (A): the current deviation the gap and
    velocity feedback ask for; the quantity the delay acts on (1-element array)."""
    q = _unpack(p)
    return jnp.reshape(q["kP"] * x[7] + q["kD"] * (x[8] + x[1]), (1,))


def unit_delay_rhs(x, ud, p):
    """Model A with the outer loop delayed: ``ud[0]`` = (u(t - tau),) (smooth)."""
    return _rhs(x, p, limited=False, command=ud[0][0])


def unit_delay_rhs_limited(x, ud, p):
    """Model A with the outer loop delayed and the no-reversal rule for the current."""
    return _rhs(x, p, limited=True, command=ud[0][0])


def gap_deviation(x, p):
    """c - c0 = x1 - x5 (m)."""
    return x[0] - x[4]


def gap(x, p):
    """Model A's gap c = c0 + x1 - x5 (m), as a 1-element array (its one levitation
    point)."""
    return jnp.reshape(p[_IDX["c0"]] + x[0] - x[4], (1,))


def coil_current(x, p):
    """Coil current i = x7 + i0 (A)."""
    return x[6] + levitation_current(p)


def beam_deflection(x, p):
    """Equivalent beam deflection w = x5 (m)."""
    return x[4]


def param_vector(params: Params) -> np.ndarray:
    return np.array([float(getattr(params, n)) for n in PARAM_NAMES])


OBSERVABLES = {
    "gap_deviation": gap_deviation,
    "current": coil_current,
    "beam_deflection": beam_deflection,
}
DELAY_PARAM_NAMES = PARAM_NAMES + ("tau",)


def unit_dde(params: Params, limited: bool = False) -> DelayDifferentialSystem:
    """Model A with the delayed outer loop as a delay system (parameters
    :data:`DELAY_PARAM_NAMES`: those of the ODE and ``tau``); its delay-free system is the
    ODE of :func:`unit_system`."""
    return DelayDifferentialSystem(
        rhs=unit_delay_rhs_limited if limited else unit_delay_rhs,
        signals=(outer_loop_command,), delays=("tau",),
        p=np.append(param_vector(params), float(params.tau)),
        param_names=DELAY_PARAM_NAMES, state_names=STATE_NAMES, state_scale=STATE_SCALE,
        observables=OBSERVABLES, name="unit", signal_names=(("u",),),
        ode_rhs=unit_rhs_limited if limited else unit_rhs, ode_param_names=PARAM_NAMES)


def unit_system(params: Params, limited: bool = False, *, tau_max: float | None = None,
                nodes: int | None = None) -> System:
    """Model A as a :class:`System` for the given parameter set.

    With ``params.tau = 0`` and no ``tau_max`` this is the ODE of the module docstring.
    Otherwise it is the discretised delay system (:func:`~maglev_match.dynamics.delay.
    discretise` of :func:`unit_dde`, its first 9 states those of the ODE) with enough
    Chebyshev nodes for the larger of ``params.tau`` and ``tau_max`` (a delay axis up to
    ``tau_max``), or ``nodes``; a delay that needs more than the maximum is a
    ParameterError.
    """
    if params.tau > 0 or tau_max is not None or nodes is not None:
        return discretised(unit_dde(params, limited), tau_max=tau_max, nodes=nodes)
    return System(
        rhs=unit_rhs_limited if limited else unit_rhs,
        p=param_vector(params),
        param_names=PARAM_NAMES,
        state_names=STATE_NAMES,
        state_scale=STATE_SCALE,
        observables=dict(OBSERVABLES),
        name="unit",
        param_ranges=param_ranges(PARAM_NAMES),
        param_units={n: PARAMETER_DOCS[n][0] for n in PARAM_NAMES if n in PARAMETER_DOCS},
        chart=None if limited else REGULAR_CHART,
    )


def discretised(dde: DelayDifferentialSystem, *, tau_max: float | None = None,
                nodes: int | None = None) -> System:
    """:func:`~maglev_match.dynamics.delay.discretise` with a delay the discretisation cannot
    resolve turned into a ParameterError (one line naming the delay, value and rule)."""
    try:
        return discretise(dde, nodes, tau_max=tau_max)
    except DelayNodesError as exc:
        raise ParameterError(exc.field, exc.value, exc.rule) from None
