"""The vehicle at speed over identical spans (maglev_match.analyses.speed.sweep, models/moving.py,
dynamics/passage.py): the moving-force closed form, the periodic response against a long
simulation and its multipliers against finite differences, the low-speed limit, and the
standstill models recovered at v = 0."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_match import load_preset
from maglev_match.analyses.speed.spans import simulate_over_spans
from maglev_match.analyses.speed.sweep import (
    KMH,
    SpeedOptions,
    SpeedPoint,
    observe_all,
    passage_problem,
    passage_readouts,
    passage_states,
    periodic_response,
    quasi_static_state,
    speed_point,
    standstill_point,
)
from maglev_match.dynamics.integrate.passage import (
    PassageOptions,
    finite_difference_jacobian,
    passage_multipliers,
    reduced_factors,
    run_passage,
)
from maglev_match.maglev import moving as mv
from maglev_match.maglev.models import build_system

SOFT = load_preset("turnout-soft")
# the unit with one mode per span (model A's beam): the properties tested do not depend on
# the number of modes, and one model keeps the compiled kernels of this module few
UNIT1 = SOFT.replace(n_modes=1)


# ---------------------------------------------------------------------------------------
# moving force: Fryba's closed form
# ---------------------------------------------------------------------------------------
def fryba_midspan(t, v, params, P):
    """Mid-span deflection of an undamped simply supported beam, one mode, under a constant
    force P crossing it at speed v (Fryba 1999, sec. 1.3; Yang, Yau & Wu 2004, eq. 2.11):
    q'' + w^2 q = (2 P / (mbar L)) sin(Omega t), Omega = pi v / L, from rest:
    q = (2 P / (mbar L w^2)) / (1 - a^2) (sin(Omega t) - a sin(w t)), a = Omega / w, and at
    resonance (a = 1) q = (P / (mbar L w^2)) (sin(w t) - w t cos(w t))."""
    w = float(params.omega1)
    L, mbar = params.L, params.mbar
    Om = math.pi * v / L
    a = Om / w
    st = 2.0 * P / (mbar * L * w**2)
    if abs(a - 1.0) < 1e-12:
        return 0.5 * st * (np.sin(w * t) - w * t * np.cos(w * t))
    return st / (1.0 - a**2) * (np.sin(Om * t) - a * np.sin(w * t))


FORCE_BEAM = SOFT.replace(n_modes=1, xi1=0.0, omega1=10.0)  # a soft beam: a = 1 at 57 m/s


@pytest.mark.parametrize("a", [0.3, 0.7, 1.0, 1.6])
def test_moving_force_matches_closed_form(a):
    """One mode, no damping: the mid-span history of the span under a crossing force and the
    DAF agree with the closed form to 1e-6 relative, at the resonant speed (a = 1) too."""
    p = FORCE_BEAM
    w = float(p.omega1)
    v = a * w * p.L / math.pi
    P = float(p.k) * (p.m + p.M) * p.g
    run = simulate_over_spans(p, "force", v, 1, limited=False, overlay=False)
    assert run.outcome == "ok"
    T = p.L / v
    first = run.t < T
    hist = run.midspan[first, 0]
    exact = fryba_midspan(run.t[first], v, p, P)
    scale = np.max(np.abs(exact))
    assert np.max(np.abs(hist - exact)) < 1e-6 * scale
    # DAF: the largest mid-span deflection over the passage against the static one
    pt = speed_point(p, "force", v)
    st = 2.0 * P / (p.mbar * p.L * w**2)
    assert pt.static_deflection == pytest.approx(st, rel=1e-12)
    tt = np.linspace(0.0, T, 200_001)
    fine = fryba_midspan(tt, v, p, P)
    k = int(np.argmax(fine))
    lo, hi = tt[max(k - 1, 0)], tt[min(k + 1, tt.size - 1)]
    for _ in range(4):  # the closed form's maximum, zoomed in
        tt = np.linspace(lo, hi, 2001)
        fine = fryba_midspan(tt, v, p, P)
        k = int(np.argmax(fine))
        lo, hi = tt[max(k - 1, 0)], tt[min(k + 1, tt.size - 1)]
    daf_exact = float(fine[k]) / st
    assert pt.daf == pytest.approx(daf_exact, rel=1e-6)
    # a moving force has no state-dependent part: the span map discards everything
    assert pt.largest_multiplier == 0.0


# ---------------------------------------------------------------------------------------
# periodic response of the unit: long simulation, finite differences
# ---------------------------------------------------------------------------------------
V_TEST = 90 * KMH


def test_periodic_response_matches_long_simulation():
    """At a stable speed, a long simulation passage after passage from rigid ground (the
    vehicle at its equilibrium on the abutment, every span at rest) settles on the periodic
    response: the read-outs of its last span passage agree with the periodic response's to
    1e-6 relative."""
    opts = SpeedOptions(critical=False)
    pt = speed_point(UNIT1, "unit", V_TEST, opts)
    assert pt.converged and pt.stable
    spans = int(math.ceil(math.log(1e-9) / math.log(pt.largest_multiplier))) + 2
    first = passage_problem(UNIT1, "unit", V_TEST, approach_rigid=True)
    mid = passage_problem(UNIT1, "unit", V_TEST)
    run = run_passage(first, mv.rigid_equilibrium(UNIT1, "unit"))
    gap0 = None
    for k in range(spans - 1):
        if k == 0:
            ro0, _ = passage_readouts(mid, run_passage(mid, run.x_next), UNIT1,
                                      mv.MovingModel.UNIT, opts)
            gap0 = ro0.gap_dev_max[0]
        run = run_passage(mid, run.x_next)
    assert run.outcome == "ok"
    ro, _ = passage_readouts(mid, run, UNIT1, mv.MovingModel.UNIT, opts)
    assert ro.gap_dev_max[0] == pytest.approx(pt.gap_dev_max[0], rel=1e-6)
    assert ro.gap_dev_min[0] == pytest.approx(pt.gap_dev_min[0], rel=1e-6)
    assert ro.current_min[0] == pytest.approx(pt.current_min[0], rel=1e-6)
    assert ro.midspan_max == pytest.approx(pt.midspan_max, rel=1e-6)
    assert ro.body_acc_peak == pytest.approx(pt.body_acc_peak, rel=1e-6)
    assert ro.wz == pytest.approx(pt.wz, rel=1e-6)
    # and the run started away from it (the test can fail)
    assert abs(gap0 - pt.gap_dev_max[0]) > 1e-3 * abs(pt.gap_dev_max[0])


def test_multipliers_match_finite_differences_of_the_span_map():
    """The multipliers from the variational transfer matrices equal the eigenvalues of the
    span map's Jacobian by central differences of the integrated map, to 1e-5."""
    sol = periodic_response(UNIT1, "unit", V_TEST, SpeedOptions(critical=False))
    tight = PassageOptions(rtol=1e-12, atol=1e-12, tangent_rtol=1e-11, tangent_atol=1e-11)
    problem = sol.problem
    x0 = sol.x0
    run = run_passage(problem, x0, tight)
    fac = reduced_factors(problem, run.starts, tight)
    mu = passage_multipliers(fac, problem.n)
    J_fd = finite_difference_jacobian(problem, x0, h=1e-4, options=tight)
    ev = np.linalg.eigvals(J_fd)
    ev = ev[np.argsort(-np.abs(ev), kind="stable")]
    nonzero = mu.values[np.isfinite(mu.log_abs)]
    k = min(nonzero.size, 6)
    assert np.max(np.abs(np.sort_complex(ev[:k]) - np.sort_complex(nonzero[:k]))) < 1e-5
    assert abs(abs(ev[0]) - mu.largest) < 1e-5
    # the reduced Jacobians themselves agree
    assert np.max(np.abs(J_fd - fac.jacobian)) < 1e-5 * max(1.0, np.max(np.abs(J_fd)))
    # the span that leaves the model contributes exact zeros
    assert np.sum(~np.isfinite(mu.log_abs)) >= 2 * UNIT1.n_modes


# ---------------------------------------------------------------------------------------
# low speed and standstill
# ---------------------------------------------------------------------------------------
def test_unit_periodic_response_tends_to_quasi_static():
    """As v -> 0 the unit's periodic response tends to the quasi-static one (its
    equilibrium at every position along the span): the largest difference of gap deviation
    and of mid-span deflection over the passage falls in proportion to v."""
    p = UNIT1
    errs = []
    for kmh in (4.0, 8.0):
        v = kmh * KMH
        sol = periodic_response(p, "unit", v, SpeedOptions(critical=False))
        assert sol.converged
        problem = sol.problem
        times = np.linspace(0.0, problem.period, 41)[:-1]
        bounds = np.concatenate([problem.starts, [problem.period]])
        states = passage_states(problem, sol.run.starts, times)
        gd_err = mid_err = 0.0
        for t, xs in zip(times, states, strict=True):
            seg = problem.segments[int(np.searchsorted(bounds, t, side="right") - 1)]
            xf = p.L + v * t
            xq = quasi_static_state(p, "unit", xf)
            pq = mv.moving_param_vector(p, "unit", v=0.0, x_front=xf,
                                        front_on_B=[float(xf > p.L)],
                                        rear_on_B=[float(xf - p.l > p.L)])
            dyn = observe_all(problem.system, xs[None], seg.p)
            qs = observe_all(problem.system, xq[None], pq)
            gd_err = max(gd_err, abs(dyn["gap_deviation"][0, 0] - qs["gap_deviation"][0, 0]))
            mid_err = max(mid_err, float(np.max(np.abs(dyn["midspan"] - qs["midspan"]))))
        errs.append((gd_err, mid_err))
    (g4, m4), (g8, m8) = errs
    w0 = p.w0
    assert m4 < 2e-3 * w0 and g4 < 2e-3 * w0
    # the difference vanishes with v, at first or second order (the beam's damping and the
    # controller's lag are first order, inertia second): halving v divides it by 2 to 4
    assert 0.2 < m4 / m8 < 0.6
    assert 0.2 < g4 / g8 < 0.6


def test_unit_at_standstill_is_model_a():
    """At v = 0 with the vehicle centred on a span and one mode per span, the unit at speed
    is model A exactly: the same equilibrium (shifted by the static deflection) and the
    eigenvalues of model A plus those of the unloaded span."""
    p = UNIT1
    lay = mv.layout_of(p, "unit")
    x_front = 0.5 * (p.L + lay.extent)
    x = quasi_static_state(p, "unit", x_front)
    pv = mv.moving_param_vector(p, "unit", v=0.0, x_front=x_front)
    sys_m = mv.moving_system(p, "unit", pv)
    n = sys_m.dim - 1
    lam_m = np.linalg.eigvals(sys_m.jacobian(x, pv)[:n, :n])
    G, T = mv.unit_standstill_map(p)
    # the unit follows the statically deflected beam: z1 = z2 = w0, q1 = w0 / G
    assert x[0] == pytest.approx(p.w0, rel=1e-10)
    assert G * x[7] == pytest.approx(p.w0, rel=1e-10)
    lam_a = np.linalg.eigvals(build_system(p, "unit").jacobian(np.zeros(9)))
    om = float(p.omega1)
    span_b = np.array([complex(-p.xi1 * om, om * math.sqrt(1 - p.xi1**2)),
                       complex(-p.xi1 * om, -om * math.sqrt(1 - p.xi1**2))])
    expected = np.concatenate([lam_a, span_b])
    d = np.abs(np.sort_complex(lam_m) - np.sort_complex(expected))
    assert np.max(d / np.maximum(1.0, np.abs(expected))) < 1e-9


def test_low_speed_multiplier_follows_the_standstill_eigenvalues():
    """The adiabatic limit: at low speed ln|mu_max| / T approaches the mean over the passage
    of the rightmost real part of the frozen model (the vehicle standing at each position,
    :func:`maglev_match.analyses.speed.sweep.adiabatic_rate`)."""
    from maglev_match.analyses.speed.sweep import adiabatic_rate

    v = 4.0 * KMH
    sol = periodic_response(UNIT1, "unit", v, SpeedOptions(critical=False))
    rate = sol.multipliers.log_abs[0] / sol.problem.period
    mean = adiabatic_rate(UNIT1, "unit", v, positions=60)
    assert mean < 0
    assert rate == pytest.approx(mean, rel=0.05)


# ---------------------------------------------------------------------------------------
# the critical disturbance at speed
# ---------------------------------------------------------------------------------------
def _fate(problem, system, events, x_periodic, d_mid, spans):
    """One disturbed run, span after span: 'collision', 'return' or 'undecided'."""
    from maglev_match.dynamics.integrate.simulate import SimulationOptions

    sl = mv.slot_slices("unit", UNIT1.n_modes)
    x = np.array(x_periodic, float)
    x[sl["qB"].start] += d_mid
    sim = SimulationOptions(rtol=1e-8, atol=1e-8, max_steps=1_000_000)
    for _ in range(spans):
        run = run_passage(problem, x, system=system, events=events, simulation=sim)
        if run.outcome == "collision":
            return "collision"
        x = run.x_next
        if np.max(np.abs(x[:-1] - x_periodic[:-1]) / problem.scale) < 0.05:
            return "return"
    return "undecided"


def test_critical_disturbance_bracket_holds_in_single_runs():
    """The bracket of the critical initial deflection of the entering span (beam up, a beam
    stiffer than the standstill Hopf point) is confirmed by single runs: the largest size
    reported to return returns, the smallest reported to collide collides."""
    from maglev_match.dynamics.integrate.simulate import EventsWithArgs

    p = UNIT1.replace(EI=3.45e10)
    v = 60 * KMH
    pt = speed_point(p, "unit", v, SpeedOptions(critical_sizes=5, critical_rounds=2))
    up = pt.up
    assert pt.stable and up.status in ("bracketed", "open")
    assert up.smallest_collision is not None and up.largest_return is not None
    assert up.largest_return < up.smallest_collision <= up.gap_range
    assert pt.h_entry == pytest.approx(min(pt.down.supported(), up.supported()))
    assert pt.chi_entry == pytest.approx(pt.h_entry / p.w0)
    sol = periodic_response(p, "unit", v, SpeedOptions(critical=False))
    limited = passage_problem(p, "unit", v, limited=True)
    events = EventsWithArgs(mv.gap_events("unit", p.n_modes), (p.gap_min, p.gap_max))
    assert _fate(limited, limited.system, events, sol.x0, -up.largest_return, 40) == "return"
    assert _fate(limited, limited.system, events, sol.x0, -up.smallest_collision,
                 40) == "collision"


def _critical(direction, status, size, gap_range):
    from maglev_match.analyses.speed.sweep import SpeedCritical

    bracketed = status == "bracketed"
    return SpeedCritical(direction, status, size if bracketed else None,
                         size if status != "all_collide" else None,
                         size * 1.01 if bracketed else None, gap_range, 1e-5, 8, 0, 40, 2,
                         None)


@pytest.mark.parametrize("down, up, ceiling", [
    (("all_return", 8e-3), ("all_return", 10e-3), True),  # h = the down gap range
    (("bracketed", 5e-3), ("all_return", 10e-3), False),  # h measured (down)
    (("all_return", 8e-3), ("bracketed", 9e-3), True),  # h set by the saturated direction
    (("all_return", 8e-3), ("bracketed", 3e-3), False),  # h measured (up)
    (("all_collide", 0.0), ("all_return", 10e-3), False),  # h = 0, not a ceiling
])
def test_entry_at_ceiling_marks_a_saturated_search(down, up, ceiling):
    """The entry disturbance's h_entry = min over the directions of the supported size; it
    is the search's ceiling exactly when the direction that sets it returned at every size
    up to its gap range. The flag survives the JSON round trip of the checkpoint tiles."""
    import dataclasses

    pt = standstill_point(UNIT1, "unit")
    d = _critical(+1, down[0], down[1], 8e-3)
    u = _critical(-1, up[0], up[1], 10e-3)
    h = min(d.supported(), u.supported())
    pt = dataclasses.replace(pt, speed=10.0, down=d, up=u, h_entry=h, chi_entry=h / pt.w0)
    assert pt.entry_at_ceiling is ceiling
    js = pt.to_json()
    assert js["entry_at_ceiling"] is ceiling
    again = SpeedPoint.from_json(js)
    assert again.entry_at_ceiling is ceiling and again.h_entry == pt.h_entry


def test_vehicle_at_standstill_is_model_b_up_to_the_suspension_preload():
    """At v = 0 with the vehicle centred on a span, the full vehicle at speed has model B's
    eigenvalues (plus the unloaded span's) to 1e-4 relative: the only difference is the
    static redistribution of the weight through the secondary suspension (frames standing at
    different deflections; a few newtons against 33 kN per point), which model B's zero
    (its equilibrium on the deflected beam) leaves out."""
    from maglev_match.dynamics.equilibria import stability
    from maglev_match.maglev import vehicle as vehicle_model

    p = SOFT
    lay = mv.layout_of(p, "vehicle")
    x_front = 0.5 * (p.L + lay.extent)
    x = quasi_static_state(p, "vehicle", x_front)
    pv = mv.moving_param_vector(p, "vehicle", v=0.0, x_front=x_front)
    sys_m = mv.moving_system(p, "vehicle", pv)
    n = sys_m.dim - 1
    lam_m = np.linalg.eigvals(sys_m.f_and_jacobian(x, pv)[1][:n, :n])
    lam_b = stability(build_system(p, "vehicle")).eigenvalues
    dist = [np.min(np.abs(lam_m - lb)) / max(1.0, abs(lb)) for lb in lam_b]
    assert max(dist) < 1e-4
    # the preload: suspension forces of a few newtons, gaps within a micrometre of c0
    b = vehicle_model.FRAME_SIGN * p.s0
    d = x[0:6:2] - x[6] - b * x[7]
    assert 0 < np.max(np.abs(p.k2 * d)) < 1e-3 * p.point_load_vehicle
    assert np.max(np.abs(sys_m.observe("gap_deviation", x, pv))) < 1e-5


def test_stability_change_is_located_by_solving():
    """A beam stiffer than the standstill Hopf point (omega1 = 139 rad/s: the unit standing at
    mid-span is unstable): the periodic response is unstable at 70 km/h and stable at
    90 km/h, where the vehicle crosses the unstable middle of the span faster. The speed
    between, where a complex pair of multipliers enters the unit circle (NS), is located to
    |mu| = 1 by solving."""
    from maglev_match.analyses.speed.sweep import locate_stability_change

    p = UNIT1.replace(EI=4.0e10)
    opts = SpeedOptions(critical=False)
    lo, hi = 70 * KMH, 90 * KMH
    mu_lo = periodic_response(p, "unit", lo, opts).multipliers.largest
    mu_hi = periodic_response(p, "unit", hi, opts).multipliers.largest
    assert mu_lo > 1.0 > mu_hi
    ch = locate_stability_change(p, "unit", lo, hi, opts, xtol=1e-5)
    assert ch.converged and ch.kind == "NS" and not ch.becomes_unstable
    assert lo < ch.speed < hi
    at = periodic_response(p, "unit", ch.speed, opts).multipliers
    assert abs(at.largest - 1.0) < 1e-4
    assert abs(complex(*ch.multiplier).imag) > 1e-3
