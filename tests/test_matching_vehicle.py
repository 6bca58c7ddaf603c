"""The matching index of the full vehicle (model B, 40 states): chi = 0 exactly at an
unstable equilibrium, and at a stable point near a subcritical Hopf point the 40-state
cycle that decides h agrees with an independent single-shooting solution of the same cycle."""

import numpy as np
import pytest

from maglev_match.analyses.matching import matching_index
from maglev_match.core.params import load_preset
from maglev_match.maglev.models import VehicleModel

SOFT = load_preset("turnout-soft")


def test_vehicle_unstable_equilibrium_gives_chi_exactly_zero():
    # on the turnout-soft beam the vehicle loses stability at omega1 = 128 rad/s and
    # regains it only near 306 rad/s
    res = matching_index(SOFT.replace(omega1=200.0), model="vehicle", simulate=False)
    assert not res.stable
    assert res.case == "unstable_equilibrium"
    assert res.chi == 0.0 and res.h == 0.0 and res.chi_paper == 0.0
    assert res.model == "vehicle"
    assert res.reading.startswith("poor")


def test_vehicle_w0_is_the_static_mid_span_deflection():
    """w0 of the vehicle = sum_n q_n* sin(n pi / 2) with q_n* the static modal
    coordinates under the six point loads (m_s / 2 + m_b / 6) g."""

    p = SOFT
    _, _, w_mid = VehicleModel(p).pressed_geometry
    load = (p.m_s / 2 + p.m_b / 6) * p.g
    xj = p.L / 2 + np.array([-p.s0 - p.s, -p.s0 + p.s, -p.s, p.s, p.s0 - p.s, p.s0 + p.s])
    w = 0.0
    for n in range(1, p.n_modes + 1):
        qn = 2.0 / (p.mbar * p.L * (n * n * p.omega1) ** 2) * load * np.sum(
            np.sin(n * np.pi * xj / p.L))
        w += qn * np.sin(n * np.pi / 2)
    assert w_mid == pytest.approx(w, rel=1e-12)


@pytest.mark.slow
def test_vehicle_cycle_agrees_with_shooting():
    from maglev_match.dynamics.shooting import shoot_periodic_orbit, trajectory_extrema
    from maglev_match.maglev.vehicle import vehicle_system

    p = SOFT.replace(omega1=124.0)
    res = matching_index(p, model="vehicle", simulate=False)
    assert res.stable and res.case == "unstable_cycle", res.message
    assert res.hopf_param == "omega1" and 124.0 < res.hopf_value < 132.0
    cyc = res.cycle
    system = vehicle_system(p)
    orbit = cyc.orbit
    sh = shoot_periodic_orbit(system, orbit.states[0], orbit.period, p=orbit.p)
    assert sh.converged, sh.message
    assert sh.period == pytest.approx(res.cycle_period, rel=1e-6)
    ext = trajectory_extrema(system, sh.x0, sh.period, sh.p, ["gap_deviation"])
    assert ext["gap_deviation"][0] == pytest.approx(res.h, rel=1e-6)
    # h is the largest over the six points, and the cycle is unstable (it bounds the basin)
    assert res.cycle_unstable_multipliers >= 1
    assert np.max(np.abs(sh.multipliers)) > 1.0 + 1e-6


@pytest.mark.slow
def test_vehicle_critical_disturbance_bracket_is_consistent():
    """The pressed-state line: the size just inside the bracket returns, the one just outside
    collides (simulated independently), and d = w0 is the paper's pressed state."""
    from maglev_match.analyses.simulation import critical_disturbance, simulate_maglev
    from maglev_match.maglev.vehicle import pressed_initial_state

    p = SOFT
    x_eq, delta, w_mid = VehicleModel(p).pressed_geometry
    np.testing.assert_allclose(x_eq + delta, pressed_initial_state(p), atol=1e-15)
    cd = critical_disturbance(p, model="vehicle", direction=-1)
    assert cd.status == "bracketed", cd
    assert cd.smallest_collision - cd.largest_return <= cd.tol * 1.0000001
    inside = x_eq + cd.largest_return / w_mid * delta
    outside = x_eq + cd.smallest_collision / w_mid * delta
    assert simulate_maglev(p, "vehicle", inside, 20.0).outcome == "converged"
    assert simulate_maglev(p, "vehicle", outside, 20.0).outcome == "collision"
