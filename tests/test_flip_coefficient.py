"""The period doubling's normal-form coefficient on PD curves of cycles, the generalised
period doubling (GPD) and the 1:2 resonance (R2) on them, against a system whose Poincare
map is known in closed form.

:func:`flip_system`: a planar cycle x = (cos 2 pi t, sin 2 pi t) (radius 1, period 1) and
a transverse pair y driven in the frame that turns by half the cycle's angle theta (the
"Moebius" frame of tests/systems.py's pd_system): with Pi = (I + [[x1, x2], [x2, -x1]]) / 2
the projection on the direction e(theta / 2) = (cos theta/2, sin theta/2) on the cycle,

    y' = (omega / 2) J y + lam Pi y + kap (I - Pi) y + a (y . Pi y) Pi y + eps J Pi y,

lam = nu - a^2. In the turning coordinates eta = R(-theta / 2) y this is autonomous:
eta1' = lam eta1 + a eta1^3, eta2' = kap eta2 + eps eta1, and over one period the frame
turns by pi, so the Poincare map at theta = 0 is y -> -phi_1(y), phi_t the eta flow. Its
multipliers: -e^{lam}, -e^{kap} (and e^{-2} of the radius, and the trivial 1). The period
doubling is lam = 0: the curve nu = a^2. There (eps = 0) eta1 -> -(eta1 + a eta1^3 +
O(eta1^5)): the flip coefficient is c = -a (q = e1, unit), so the flip is supercritical
for a < 0, subcritical for a > 0, and generalised (GPD) at a = 0, nu = 0. With eps != 0
a second multiplier -e^{kap} reaches -1 at kap = 0 (a Jordan block with the first: R2).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

from maglev_match.dynamics.collocation import node_times
from maglev_match.dynamics.cycle_curves import cycle_curve
from maglev_match.dynamics.cycle_curves.flip import flip_coefficient
from maglev_match.dynamics.cycles.orbits import PeriodicOrbit
from maglev_match.dynamics.system import System

OMEGA = 2.0 * math.pi


def _rhs(x, p):
    nu, a, kap, eps = p[0], p[1], p[2], p[3]
    x1, x2, y = x[0], x[1], x[2:4]
    r2 = x1 * x1 + x2 * x2
    Pi = 0.5 * (jnp.eye(2) + jnp.array([[x1, x2], [x2, -x1]]))
    Py = Pi @ y
    J = jnp.array([[0.0, -1.0], [1.0, 0.0]])
    dy = 0.5 * OMEGA * (J @ y) + (nu - a * a) * Py + kap * (y - Py) \
        + a * jnp.dot(y, Py) * Py + eps * (J @ Py)
    return jnp.concatenate([jnp.stack([x1 * (1 - r2) - OMEGA * x2,
                                       OMEGA * x1 + x2 * (1 - r2)]), dy])


def flip_system() -> System:
    return System(rhs=_rhs, p=np.array([0.0, 0.3, -1.0, 0.0]),
                  param_names=("nu", "a", "kap", "eps"), state_names=("x1", "x2", "y1", "y2"),
                  name="flip normal form")


def cycle(**values: float) -> PeriodicOrbit:
    """The cycle (exact: it does not depend on the parameters) on a mesh of 20 x 4."""
    S = flip_system()
    mesh = np.linspace(0.0, 1.0, 21)
    s = node_times(mesh, 4)
    U = np.column_stack([np.cos(OMEGA * s), np.sin(OMEGA * s), 0 * s, 0 * s])
    return PeriodicOrbit(mesh=mesh, ncol=4, states=U, period=1.0, p=S.params_with(**values))


@pytest.mark.parametrize("a", [0.3, -0.2, 0.05])
def test_flip_coefficient_is_the_closed_form(a):
    fc = flip_coefficient(flip_system(), cycle(nu=a * a, a=a))
    assert fc.ok, fc.message
    assert fc.multiplier == pytest.approx(-1.0, abs=1e-7)
    assert fc.c == pytest.approx(-a, rel=1e-6)
    assert fc.error < 1e-3 * abs(a)


def test_coefficient_along_the_pd_curve_and_the_gpd_point():
    """Started off the curve (nu = a^2 + 0.01 at a = 0.3), corrected onto it and followed
    down through a = 0: the curve nu = a^2, the coefficient -a at every point, and one
    GPD, solved, at (0, 0)."""
    S = flip_system()
    cv = cycle_curve(S, cycle(nu=0.1, a=0.3), "PD", ("nu", "a"), ranges={"a": (-0.3, 0.3)},
                     direction=-1, ds_max=0.5, max_steps=200)
    assert cv.ok, cv.warnings
    nu, a = cv.p1, cv.p2
    assert a[0] == pytest.approx(0.3) and a[-1] == pytest.approx(-0.3, abs=1e-12)
    assert np.max(np.abs(nu - a ** 2)) < 1e-8
    c = np.array([pt.flip for pt in cv.points])
    np.testing.assert_allclose(c, -a, atol=1e-6)
    assert [s.type for s in cv.special_points] == ["GPD"]
    sp = cv.special_points[0]
    assert sp.label == "GPD1" and sp.located == "solved"
    assert sp.values[0] == pytest.approx(0.0, abs=1e-8)
    assert sp.values[1] == pytest.approx(0.0, abs=1e-7)
    ds = cv.to_xarray()
    np.testing.assert_array_equal(ds["flip_coefficient"].values, c)


def test_r2_on_the_pd_curve():
    """With the coupling eps = 1 the second multiplier -e^kap meets -1 at kap = 0 on the
    PD curve nu = a^2 (here a vertical line in (nu, kap)): R2, bracketed there (the PD
    system is singular at R2: its test function is the product of the two multipliers'
    distances from -1); the curve continues through it. The coefficient stays negative
    (no GPD)."""
    S = flip_system()
    cv = cycle_curve(S, cycle(nu=0.09, a=0.3, kap=-0.5, eps=1.0), "PD", ("nu", "kap"),
                     ranges={"kap": (-0.5, 0.5)}, ds_max=0.5, max_steps=200,
                     scales=(0.05, 0.05))
    assert cv.ok, cv.warnings
    assert np.max(np.abs(cv.p1 - 0.09)) < 1e-7  # the least accurate near R2 (Jordan)
    assert [s.type for s in cv.special_points] == ["R2"]
    sp = cv.special_points[0]
    assert sp.located.startswith("bracketed") and sp.values[1] == pytest.approx(0.0, abs=1e-3)
    # the multipliers on the curve: -1 and -e^kap (and e^-2 of the radius)
    for pt in cv.points:
        np.testing.assert_allclose(np.sort(pt.multipliers.real),
                                   np.sort([-1.0, -math.exp(pt.values[1]), math.exp(-2.0)]),
                                   atol=1e-6)
    assert all(pt.flip < 0 for pt in cv.points if abs(pt.values[1]) > 1e-3)
