"""An NS curve of cycles ends where its critical pair meets the real axis: at a 1:2
resonance (R2, theta = pi) it stops with the point solved and the reason, instead of
running on with the conjugate angle.

:func:`r2_system`: the planar cycle x = (cos 2 pi t, sin 2 pi t) (period 1) and a
transverse pair y driven in the frame turning by half the cycle's angle theta (the
"Moebius" frame of tests/systems.py's pd_system), y' = (omega / 2) J y + K(theta) y with
K(theta) = R(theta/2) K R(-theta/2), K = [[a, 1], [-k, a]], a = g - k^2; on the cycle
R(theta/2) [[0, 1], [1, 0]] R(-theta/2) = [[-x2, x1], [x1, x2]]. Over one period the frame
turns by pi: the transverse multipliers are -e^{K} = e^{a} e^{i (pi +- sqrt(k))} (k > 0).
The NS curve is a = 0, g = k^2, with the angle theta = pi - sqrt(k); at k = 0 the pair
meets at -1 in a Jordan block (R2) and for k < 0 it is real (-e^{+-sqrt(-k)}: period
doublings).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

from maglev_match.dynamics.collocation import node_times
from maglev_match.dynamics.cycle_curves import CurveStop, cycle_curve
from maglev_match.dynamics.cycles.orbits import PeriodicOrbit
from maglev_match.dynamics.system import System

OMEGA = 2.0 * math.pi


def _rhs(x, p):
    g, k = p[0], p[1]
    x1, x2, y = x[0], x[1], x[2:4]
    r2 = x1 * x1 + x2 * x2
    J = jnp.array([[0.0, -1.0], [1.0, 0.0]])
    N = jnp.array([[-x2, x1], [x1, x2]])
    K = (g - k * k) * jnp.eye(2) + 0.5 * (-k - 1.0) * J + 0.5 * (1.0 - k) * N
    dy = 0.5 * OMEGA * (J @ y) + K @ y
    return jnp.concatenate([jnp.stack([x1 * (1 - r2) - OMEGA * x2,
                                       OMEGA * x1 + x2 * (1 - r2)]), dy])


def r2_system() -> System:
    return System(rhs=_rhs, p=np.array([0.25, 0.5]), param_names=("g", "k"),
                  state_names=("x1", "x2", "y1", "y2"), name="R2 on an NS curve")


def _cycle(g: float, k: float) -> PeriodicOrbit:
    mesh = np.linspace(0.0, 1.0, 21)
    s = node_times(mesh, 4)
    U = np.column_stack([np.cos(OMEGA * s), np.sin(OMEGA * s), 0 * s, 0 * s])
    return PeriodicOrbit(mesh=mesh, ncol=4, states=U, period=1.0, p=np.array([g, k]))


def test_ns_curve_stops_at_r2():
    cv = cycle_curve(r2_system(), _cycle(0.26, 0.5), "NS", ("g", "k"),
                     ranges={"k": (-0.5, 1.0)}, direction=-1, ds_max=0.5, max_steps=300)
    assert cv.stopped_reason == CurveStop.RESONANCE and cv.ok, cv.warnings
    assert "1:2 resonance" in cv.message and not cv.warnings
    g, k = cv.p1, cv.p2
    theta = np.array([c.angle for c in cv.points])
    assert np.all(k >= -1e-9) and np.all(theta <= math.pi + 1e-12)  # never past R2
    assert np.max(np.abs(g - k ** 2)) < 1e-7
    assert np.max(np.abs(k - (math.pi - theta) ** 2)) < 1e-7  # theta = pi - sqrt(k)
    end = cv.points[-1]
    assert end.kind == "R2" and end.angle == pytest.approx(math.pi, abs=1e-12)
    assert end.values[0] == pytest.approx(0.0, abs=1e-8)
    assert end.values[1] == pytest.approx(0.0, abs=1e-8)
    sps = [s for s in cv.special_points if s.type == "R2"]
    assert len(sps) == 1 and sps[0].located == "solved" and sps[0].label == "R21"
    assert sps[0].values == end.values
    # the critical pair is a double -1 there
    assert np.sum(np.abs(end.multipliers + 1.0) < 1e-4) == 2
