"""Piecewise-smooth flows and periodic orbits (dynamics/hybrid/): a planar oscillator with
saturated feedback against an independent shooting solve and Liouville's formula; the flow
with a current clamp against the simulator's limited vector field and its sensitivities
(saltation matrices included) against central differences."""

from __future__ import annotations

import math

import numpy as np
import pytest
from systems import (
    OSC_P,
    clamped_oscillator,
    clamped_oscillator_limited,
    saturated_oscillator,
    saturated_oscillator_shooting,
)

from maglev_match.dynamics.hybrid import (
    FlowStatus,
    LinearStop,
    hybrid_floquet,
    hybrid_flow,
    hybrid_periodic_orbit,
    saltation_matrix,
    segments_from_flow,
    shoot_hybrid_orbit,
)
from maglev_match.dynamics.integrate.simulate import SimulationOptions, simulate


@pytest.fixture(scope="module")
def saturated():
    zeta, k = 0.1, 1.0
    T_ref, A_ref = saturated_oscillator_shooting(zeta, k)
    hs = saturated_oscillator(zeta=zeta, k=k)
    segs = segments_from_flow(hs, np.array([1.01 * A_ref, 0.0]), np.zeros(2), T_ref, ntst=80)
    return hs, hybrid_periodic_orbit(hs, segs), T_ref, A_ref, zeta, k


def test_saturated_feedback_cycle_matches_independent_shooting(saturated):
    """Collocation per segment (linear band, saturated above, below) against SciPy's DOP853
    shooting on the continuous field: period and amplitude to 1e-7."""
    hs, orbit, T_ref, A_ref, _, _ = saturated
    assert orbit.converged, orbit.message
    modes = [sg.mode for sg in orbit.segments]
    assert sorted(modes) == [(0, 0), (0, 0), (0, 1), (1, 0)]  # band twice, each saturation
    assert orbit.period == pytest.approx(T_ref, rel=1e-7)
    x_max, x_min = orbit.extrema(hs.observables["x"])
    assert x_max == pytest.approx(A_ref, rel=1e-7)
    assert x_min == pytest.approx(-A_ref, rel=1e-7)  # the field is odd: a symmetric orbit
    y_max, y_min = orbit.extrema(hs.observables["y"])
    assert y_max > 1.0 and y_min < -1.0  # it does enter both saturated regions


def test_saturated_feedback_multipliers_follow_liouville(saturated):
    """The field is continuous, so the saltation matrices have determinant 1 and the
    non-trivial multiplier is exp(int div f dt) = exp((k - 2 zeta) T_lin - 2 zeta T_sat)."""
    hs, orbit, _, _, zeta, k = saturated
    t_lin = sum(sg.duration for sg in orbit.segments if sg.mode == (0, 0))
    t_sat = orbit.period - t_lin
    mu = np.sort(np.abs(orbit.multipliers))
    assert mu[1] == pytest.approx(1.0, abs=1e-8)  # the trivial multiplier
    assert mu[0] == pytest.approx(math.exp((k - 2 * zeta) * t_lin - 2 * zeta * t_sat),
                                  rel=1e-7)
    sg = orbit.segments[0]
    S = saltation_matrix(hs, sg.states[-1], np.asarray(sg.mode, float), sg.switch)
    assert np.linalg.det(S) == pytest.approx(1.0, abs=1e-10)
    fq = hybrid_floquet(hs, orbit)
    M = fq.monodromy(1, 3)  # at a mesh point inside the second segment
    np.testing.assert_allclose(np.sort(np.abs(np.linalg.eigvals(M))), mu, rtol=1e-7)


def test_shooting_on_the_flow_finds_the_same_cycle(saturated):
    """Single shooting with the flow's sensitivities (saltations included) from a point in
    the middle of a segment: the same period, and the monodromy's eigenvalues."""
    hs, orbit, T_ref, _, _, _ = saturated
    sg = orbit.segments[0]
    mid = sg.states[len(sg.states) // 2]
    shot = shoot_hybrid_orbit(hs, mid + np.array([1e-3, 0.0]), np.asarray(sg.mode, float),
                              1.01 * T_ref)
    assert shot.converged, shot.message
    assert shot.period == pytest.approx(orbit.period, rel=1e-9)
    np.testing.assert_allclose(np.sort(np.abs(shot.multipliers)),
                               np.sort(np.abs(orbit.multipliers)), rtol=1e-7)


@pytest.fixture(scope="module")
def clamped_run():
    """The clamped oscillator pushed down by 1.3: its current is held at zero for a while
    during the first overshoot."""
    hs = clamped_oscillator()
    x0 = np.array([-1.3, 0.0, OSC_P[3]])
    return hs, x0


def test_clamped_flow_matches_the_limited_simulator(clamped_run):
    """The same run as switched modes (switch times located) and as the simulator's limited
    vector field (the clamp inside the field): states agree to 1e-8 (scaled)."""
    hs, x0 = clamped_run
    ts = np.linspace(0.0, 2.0, 41)[1:]
    fl = hybrid_flow(hs, x0, 2.0, t_save=ts)
    assert fl.status[0] == FlowStatus.REACHED
    assert fl.n_switches[0] >= 2  # held and released at least once
    sim = simulate(clamped_oscillator_limited(), x0, 2.0, t_save=np.concatenate([[0.0], ts]),
                   options=SimulationOptions(rtol=1e-12, atol=1e-12))
    err = np.abs(fl.saved[0] - sim.x[1:]) / hs.state_scale
    assert np.max(err) < 1e-8


def test_sensitivities_through_the_clamp_match_central_differences(clamped_run):
    """dx(t)/dx0 and dx(t)/dp after an entry into and an exit from the held mode, against
    central differences of the flow: the saltation matrices are in the derivative."""
    hs, x0 = clamped_run
    t_end = 0.6
    Z = np.zeros((3, 2))
    Z[0, 0] = 1.0  # d/dx0
    P = np.zeros((6, 2))
    P[5, 1] = 1.0  # d/dg (the current's velocity feedback)
    fl = hybrid_flow(hs, x0, t_end, tangents=Z, param_tangents=P)
    assert fl.n_switches[0] >= 2
    h = 1e-6
    e = np.array([1.0, 0.0, 0.0])
    fd_x = (hybrid_flow(hs, x0 + h * e, t_end).x[0]
            - hybrid_flow(hs, x0 - h * e, t_end).x[0]) / (2 * h)
    p = hs.p.copy()
    hp = 1e-6 * p[5]
    pp, pm = p.copy(), p.copy()
    pp[5] += hp
    pm[5] -= hp
    fd_p = (hybrid_flow(hs, x0, t_end, p=pp).x[0] - hybrid_flow(hs, x0, t_end, p=pm).x[0]) \
        / (2 * hp)
    np.testing.assert_allclose(fl.phi[0][:, 0], fd_x, rtol=1e-6, atol=1e-6 * np.abs(fd_x).max())
    np.testing.assert_allclose(fl.phi[0][:, 1], fd_p, rtol=1e-6, atol=1e-6 * np.abs(fd_p).max())


def test_held_entry_saltation_drops_the_current_direction(clamped_run):
    """Entering the held mode projects the current onto 0: the saltation matrix has rank
    n - 1 and maps the current direction to zero."""
    hs, x0 = clamped_run
    fl = hybrid_flow(hs, x0, 0.3)
    t_in = fl.switch_times[0][0]
    x = hybrid_flow(hs, x0, t_in).x[0]  # on the switching surface i = 0
    assert abs(x[2]) < 1e-9
    S = saltation_matrix(hs, x, np.zeros(1), 0)
    assert np.linalg.matrix_rank(S, tol=1e-10) == 2
    np.testing.assert_allclose(S @ np.array([0.0, 0.0, 1.0]), 0.0, atol=1e-12)


def test_stop_at_an_extremum_lands_on_a_zero_rate(clamped_run):
    """A LinearStop on the rate of x ends the run at the first maximum of x."""
    hs, x0 = clamped_run
    w = np.array([1.0, 0.0, 0.0])
    first = hybrid_flow(hs, x0, 0.2)
    fl = hybrid_flow(hs, first.x[0], 1.0, t_start=0.2, s0=first.s[0], stop=LinearStop(a=w))
    assert fl.status[0] == FlowStatus.STOPPED
    rate = float(w @ hs.f(fl.x[0], fl.s[0]))
    assert abs(rate) < 1e-10 * np.abs(hs.f(first.x[0], first.s[0])).max()
    assert fl.x[0][0] > 0  # the overshoot above equilibrium
