"""How branches of cycles end, and the special points near their ends: a family that
closes at a second Hopf point, a family that ends at a homoclinic orbit, two branch points
next to a fold, model A's contact with the gap limit solved in its regular chart; and the
options object of :func:`cycle_branch`."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
from systems import (
    TWO_HOPF_K,
    bogdanov_takens_system,
    bt_homoclinic_beta1,
    fitzhugh_nagumo,
    pitchfork_bp_values,
    pitchfork_cycles_system,
    two_hopf_system,
)

from maglev_match.dynamics.cycles import (
    CycleOptions,
    CycleStop,
    cycle_branch,
    orbit_extrema,
)
from maglev_match.dynamics.hopf import locate_hopf_points

BIFURCATIONS = ("LPC", "PD", "NS", "BP")


# ------------------------------------------------------- a family between two Hopf points
@pytest.mark.parametrize("start, other", [(0.0, 1.0), (1.0, 0.0)])
def test_family_from_either_hopf_point_ends_at_the_other(start, other):
    system = two_hopf_system()
    scan = locate_hopf_points(system, "mu", -0.5, 1.5, n_scan=20)
    assert [h.value for h in scan.points] == pytest.approx([0.0, 1.0], abs=1e-12)
    hp = min(scan.points, key=lambda h: abs(h.value - start))
    br = cycle_branch(system, hp, "mu", ntst=20, ncol=4)
    assert br.stopped_reason == CycleStop.HOPF == "the family closed at a Hopf point"
    end = br.closed_at
    assert end is not None and end.type == "H" and end.label == "H1"
    assert end.located == "solved" and end.value == pytest.approx(other, abs=1e-10)
    assert end.frequency == pytest.approx(1.0, rel=1e-10)  # eigenvalues +-i there
    assert f"{other:g}" in br.message and "closed at the Hopf point" in br.message
    # no fold (or any other bifurcation) where the amplitude goes to zero
    assert not [s for s in br.special_points if s.type in BIFURCATIONS]
    # every cycle kept is one of the family (closed form), none of zero amplitude
    assert len(br.points) >= 5
    for c in br.points:
        r2 = c.value * (1.0 - c.value)
        assert 0.0 < c.value < 1.0
        assert c.max("radius") == pytest.approx(math.sqrt(r2), rel=1e-6)
        assert c.period == pytest.approx(2 * math.pi / (1 + TWO_HOPF_K * r2), rel=1e-6)


# ------------------------------------------------------------------ a homoclinic orbit in the plane
def test_planar_homoclinic_approach_reports_no_bifurcation():
    system = bogdanov_takens_system()
    hp = locate_hopf_points(system, "beta1", -0.1, 0.1, n_scan=20).points[0]
    assert abs(hp.value) < 1e-12 and hp.l1 < 0
    br = cycle_branch(system, hp, "beta1", ntst=40, ncol=4, lam_scale=0.05,
                      max_period_factor=20.0)
    assert br.stopped_reason == CycleStop.HOMOCLINIC == "homoclinic approach"
    assert br.message.startswith("homoclinic approach")
    assert "last point with reliable multipliers" in br.message
    assert not [s for s in br.special_points if s.type in BIFURCATIONS]
    # the period grows without bound towards the homoclinic parameter, solved by shooting
    # the saddle's manifolds
    ref = bt_homoclinic_beta1()
    last = br.points[-1]
    assert last.period > 20 * 2 * math.pi / hp.frequency
    assert last.value == pytest.approx(ref, abs=1e-7)
    reliable = [c for c in br.points if c.reliable]
    assert reliable and f"{reliable[-1].value:.10g}" in br.message
    assert all(c.stability == "stable" for c in reliable)  # supercritical: stable cycles


# ------------------------------------------------------------------ branch points near a fold
def test_two_branch_points_of_cycles_near_a_fold_are_both_solved():
    system = pitchfork_cycles_system()
    hp = locate_hopf_points(system, "mu", -0.5, 0.5, n_scan=20).points[0]

    def limits(sys_, orbit):  # stop on the outer branch at radius 1.15, past both BPs
        return {"radius 1.15": 1.15 - orbit_extrema(sys_, orbit, ["radius"])["radius"][0]}

    br = cycle_branch(system, hp, "mu", ntst=20, ncol=4, limits=limits, ds_max=0.5)
    bps = [s for s in br.special_points if s.type == "BP"]
    lpc = [s for s in br.special_points if s.type == "LPC"]
    assert [s.label for s in bps] == ["BP1", "BP2"]
    assert all(s.located == "solved" for s in bps + lpc)
    assert [s.value for s in bps] == pytest.approx(pitchfork_bp_values(), abs=1e-8)
    assert len(lpc) == 1 and lpc[0].value == pytest.approx(-1.0, abs=1e-9)
    for s in bps:  # a nontrivial multiplier at +1 there, the transverse one
        assert np.min(np.abs(np.asarray(s.point.multipliers) - 1.0)) < 1e-6


# ------------------------------------------------------------------ model A: the gap contact
@pytest.fixture(scope="module")
def alpha1_contact():
    from maglev_match.core.params import load_preset
    from maglev_match.maglev.limits import cycle_limit_margins
    from maglev_match.maglev.models import build_system

    params = load_preset("alpha1").replace(sigma=4e-4)
    system = build_system(params, "unit")
    hp = next(h for h in locate_hopf_points(system, "omega1", 100.0, 200.0, n_scan=30).points)
    br = cycle_branch(system, hp, "omega1",
                      limits=cycle_limit_margins(params, include_current=False))
    return params, system, br


def test_model_a_gap_contact_is_solved_in_the_regular_chart(alpha1_contact):
    params, system, br = alpha1_contact
    assert br.stopped_reason == CycleStop.CONTACT == "contact with a physical limit"
    contact = br.special_points[-1]
    assert contact.type == "contact" and contact.label == "contact1"
    assert contact.detail == "gap 0" and contact.located == "solved"
    assert br.chart_from is not None and contact.value < br.chart_from < br.hopf.value
    # the gap touches 0 (the magnet reaches the rail) to the branch tolerance
    assert contact.extrema["gap_deviation"][1] + params.c0 == pytest.approx(0.0, abs=1e-13)
    assert br.points[-1].kind == "contact" and br.points[-1].value == contact.value
    # every point is reliable up to the contact, including those near gap 0
    assert all(c.reliable for c in br.points)
    assert br.points[0].stability == "neutral"  # the first cycle, next to its Hopf point
    assert all(c.stability == "unstable" for c in br.points[1:])


def _chart_flow(system, p):
    """The flow of the regular chart's vector field with its variational equation."""
    rhs = system.chart.rhs
    n = system.dim
    pj = jnp.asarray(p)
    aug = jax.jit(lambda y: jnp.concatenate([rhs(y[:n], pj), (jax.jacfwd(rhs)(y[:n], pj)
                                                               @ y[n:].reshape(n, n)).ravel()]))
    sc = np.asarray(system.chart.state_scale)

    def flow(y0, T):
        z0 = np.concatenate([y0, np.eye(n).ravel()])
        sol = scipy.integrate.solve_ivp(lambda t, z: np.asarray(aug(z)), (0.0, T), z0,
                                        method="DOP853", rtol=1e-12,
                                        atol=np.concatenate([sc * 1e-14, np.full(n * n, 1e-14)]))
        assert sol.success
        return sol.y[:n, -1], sol.y[n:, -1].reshape(n, n)

    return flow


def test_model_a_gap_contact_agrees_with_shooting_and_is_a_true_orbit(alpha1_contact):
    """Independent reference: single shooting in the chart's coordinates for the orbit that
    touches gap 0, unknowns (y0, T, omega1) with y0 the touching state: periodicity,
    c(y0) = 0 and c'(y0) = 0 (Newton, the parameter derivative of the flow by a central
    difference). The collocation contact agrees to 1e-6 in omega1; its saved orbit,
    integrated over one period from a state far from the rail, returns to it to 1e-7."""
    params, system, br = alpha1_contact
    contact = br.special_points[-1]
    orbit = contact.point.orbit  # in the system's own coordinates (x7 = i - i0)
    chart = system.chart
    to_chart = jax.jit(jax.vmap(chart.to_chart, (0, None)))
    Y = np.asarray(to_chart(orbit.states, orbit.p))
    gap = orbit.states[:, 0] - orbit.states[:, 4] + params.c0
    y = Y[int(np.argmin(gap))].copy()
    T, w1 = orbit.period, contact.value
    n = system.dim
    sc = np.asarray(chart.state_scale)
    for _ in range(8):
        p = system.params_with(orbit.p, omega1=w1)
        yT, M = _chart_flow(system, p)(y, T)
        G = np.concatenate([(yT - y) / sc, [(y[0] - y[4] + params.c0) / 1e-3,
                                            (y[1] - y[5]) / 1e-2]])
        if np.max(np.abs(G)) < 1e-11:
            break
        h = 1e-6 * w1
        fl = [_chart_flow(system, system.params_with(orbit.p, omega1=w1 + s * h))(y, T)[0]
              for s in (1, -1)]
        A = np.zeros((n + 2, n + 2))
        A[:n, :n] = (M - np.eye(n)) / sc[:, None]
        A[:n, n] = np.asarray(chart.rhs(jnp.asarray(yT), jnp.asarray(p))) / sc
        A[:n, n + 1] = (fl[0] - fl[1]) / (2 * h) / sc
        A[n, [0, 4]] = np.array([1.0, -1.0]) / 1e-3
        A[n + 1, [1, 5]] = np.array([1.0, -1.0]) / 1e-2
        d = np.linalg.solve(A, -G)
        y, T, w1 = y + d[:n], T + d[n], w1 + d[n + 1]
    assert np.max(np.abs(G)) < 1e-9
    assert contact.value == pytest.approx(w1, rel=1e-6)
    assert contact.period == pytest.approx(T, rel=1e-6)
    assert w1 != contact.value  # an independent solve, not the same number
    # the saved contact orbit is a true orbit of the model: from its state farthest from
    # the rail, one period of the (chart's) flow comes back to it
    x0 = orbit.states[int(np.argmax(gap))]
    y0 = np.asarray(chart.to_chart(jnp.asarray(x0), jnp.asarray(orbit.p)))
    yT, _ = _chart_flow(system, orbit.p)(y0, orbit.period)
    xT = np.asarray(chart.from_chart(jnp.asarray(yT), jnp.asarray(orbit.p)))
    assert np.max(np.abs(xT - x0) / system.state_scale) < 1e-7


# ------------------------------------------------------------------ the options object
def test_cycle_options_check_themselves_and_the_keywords_map_onto_them():
    with pytest.raises(ValueError, match=r"CycleOptions.ncol = 9: must be an integer >= 2"):
        CycleOptions(ncol=9)
    with pytest.raises(ValueError, match=r"CycleOptions.newton = 'exact'"):
        CycleOptions(newton="exact")
    with pytest.raises(ValueError, match=r"CycleOptions.param_bounds"):
        CycleOptions(param_bounds=(2.0, 1.0))
    with pytest.raises(ValueError, match=r"CycleOptions.ds"):
        CycleOptions(ds=-1.0)
    system = two_hopf_system()
    hp = locate_hopf_points(system, "mu", -0.5, 1.5, n_scan=20).points[0]
    with pytest.raises(TypeError, match="unexpected keyword argument 'ntsst'"):
        cycle_branch(system, hp, "mu", ntsst=20)
    a = cycle_branch(system, hp, "mu", stop_at=0.5, ntst=20, ds_max=0.5, max_steps=40)
    b = cycle_branch(system, hp, "mu", stop_at=0.5,
                     options=CycleOptions(ntst=20, ds_max=0.5, max_steps=40))
    c = cycle_branch(system, hp, "mu", stop_at=0.5, options=CycleOptions(ntst=20, ds_max=9.0),
                     ds_max=0.5, max_steps=40)  # keywords override the object's fields
    for br in (b, c):
        assert br.ntst == 20 and br.ncol == 4
        assert np.array_equal(br.values, a.values)
        assert np.array_equal(br.periods, a.periods)


# ------------------------------------------------------------------ the valid range
def test_a_branch_at_the_end_of_the_valid_range_says_so():
    import dataclasses

    system = dataclasses.replace(two_hopf_system(), param_ranges={"mu": (0.2, 2.0)})
    hp = locate_hopf_points(system, "mu", 0.5, 1.5, n_scan=20).points[0]
    assert hp.value == pytest.approx(1.0, abs=1e-12)
    br = cycle_branch(system, hp, "mu", ntst=20, ncol=4)
    assert br.stopped_reason == CycleStop.RANGE
    assert br.points[-1].value == pytest.approx(0.2, abs=1e-9)
    assert all(c.value >= 0.2 - 1e-9 for c in br.points)
    assert "valid range" in br.message and any("valid range" in w for w in br.warnings)


def test_folds_between_unreliable_multipliers_are_labelled_fitzhugh_nagumo():
    """FitzHugh-Nagumo: the family from one subcritical Hopf point turns back in a just
    beyond it (the unstable cycles become the stable relaxation oscillation through a
    canard explosion, where the multipliers are unreliable) and closes at the other. Both
    folds are labelled LPC (they were not: the fold test was skipped wherever the
    multipliers were unreliable), at values symmetric under a -> -a, where the branch's
    parameter is extremal and its stability changes."""
    S = fitzhugh_nagumo()
    scan = locate_hopf_points(S, "a", -2.0, 2.0, n_scan=200)
    hp = min(scan.points, key=lambda h: h.value)
    assert hp.kind == "subcritical"
    br = cycle_branch(S, hp, "a", ntst=60, ncol=4, max_steps=400)
    assert "closed at a Hopf point" in br.stopped_reason
    lpc = sorted(sp.value for sp in br.special_points if str(sp.type) == "LPC")
    assert len(lpc) == 2 and all(sp.located == "solved" for sp in br.special_points
                                 if str(sp.type) == "LPC")
    assert abs(lpc[0] + lpc[1]) < 1e-7 and abs(lpc[0]) > abs(hp.value)
    vals = np.array([c.value for c in br.points])
    assert vals.min() == pytest.approx(lpc[0], abs=1e-6)
    assert vals.max() == pytest.approx(lpc[1], abs=1e-6)
    stable = [c.stable for c in br.points]
    assert stable[0] is False and any(stable)  # unstable small cycles, then stable ones
