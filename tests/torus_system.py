"""A system with a Neimark-Sacker bifurcation of cycles whose normal form is known in
closed form (tests/test_torus_coefficient.py derives it)."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from maglev_match.dynamics.collocation import node_times
from maglev_match.dynamics.cycles.orbits import PeriodicOrbit
from maglev_match.dynamics.system import System

OMEGA = 2.0 * math.pi  # the cycle's angular frequency: period 1
OMEGA_T = 0.6 * math.pi  # the transverse rotation per unit time: theta = 0.6 pi


def _rhs(x, p):
    mu, a, nu, c, b, k = p[0], p[1], p[2], p[3], p[4], p[5]
    x1, x2, y1, y2, s = x[0], x[1], x[2], x[3], x[4]
    r2 = x1 * x1 + x2 * x2
    w2 = y1 * y1 + y2 * y2
    g = mu + s + a * w2
    return jnp.stack([x1 * (1 - r2) - OMEGA * x2, OMEGA * x1 + x2 * (1 - r2),
                      g * y1 - OMEGA_T * y2 + b * (y1 * y1 - y2 * y2),
                      OMEGA_T * y1 + g * y2 + 2.0 * b * y1 * y2 + k * w2,
                      nu - s * s + c * w2])


def torus_system() -> System:
    return System(rhs=_rhs, p=np.array([-0.5, 0.3, 0.25, 0.0, 0.0, 0.0]),
                  param_names=("mu", "a", "nu", "c", "b", "k"),
                  state_names=("x1", "x2", "y1", "y2", "s"), name="torus normal form")


def torus_cycle(s: float = 0.5, **values: float) -> PeriodicOrbit:
    """The cycle (x on the unit circle, y = 0, s the equilibrium sqrt(nu) = ``s``) on a
    mesh of 20 x 4."""
    S = torus_system()
    mesh = np.linspace(0.0, 1.0, 21)
    t = node_times(mesh, 4)
    U = np.column_stack([np.cos(OMEGA * t), np.sin(OMEGA * t), 0 * t, 0 * t, s + 0 * t])
    return PeriodicOrbit(mesh=mesh, ncol=4, states=U, period=1.0,
                         p=S.params_with(**{"nu": s * s, **values}))
