"""Shared test systems with closed-form cycles for the sensitivity and design tests.

The subcritical Hopf normal form in polar form r' = (mu - a) r + l1 r^3, theta' = omega,
with a stable third direction driven by r^2, embedded by a fixed invertible linear map:
for a > mu and l1 > 0 the equilibrium is stable and surrounded by the unstable cycle of
radius h = sqrt((a - mu) / l1) (Kuznetsov 2004, sec. 3.4), read out as the first normal-form
coordinate ("gap_deviation"). The Hopf point along a is a_H = mu.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from maglev_match.dynamics.system import System

_M = np.array([[1.0, 0.3, -0.2], [-0.4, 1.2, 0.1], [0.25, 0.5, 0.9]])
_MINV = np.linalg.inv(_M)
NAMES = ("mu", "a", "omega", "l1", "b")
DESIGN = {"mu": 1.0, "a": 1.5, "omega": 2.0, "l1": 2.0, "b": 0.7}


def _xi(x):
    return jnp.asarray(_MINV) @ x


def rhs(x, p):
    mu, a, om, l1, b = p[0], p[1], p[2], p[3], p[4]
    u, v, w = _xi(x)
    r2 = u * u + v * v
    du = (mu - a) * u - om * v + l1 * u * r2
    dv = om * u + (mu - a) * v + l1 * v * r2
    dw = -w + b * r2
    return jnp.asarray(_M) @ jnp.stack([du, dv, dw])


def gap(x, p):
    return _xi(x)[0]


def current(x, p):
    return _xi(x)[1]


def normal_form_system(**values: float) -> System:
    """The embedded normal form at DESIGN updated by ``values``."""
    d = dict(DESIGN, **values)
    return System(rhs=rhs, p=np.array([d[n] for n in NAMES]), param_names=NAMES,
                  state_names=("x1", "x2", "x3"),
                  observables={"gap_deviation": gap, "current": current}, name="hopf-nf")


def amplitude(mu: float, a: float, l1: float) -> float:
    """Closed-form radius of the unstable cycle."""
    return math.sqrt((a - mu) / l1)
