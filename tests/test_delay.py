"""Delay-differential systems (dynamics/delay/): the discretisation, characteristic roots,
Hopf points in a delay, l1, cycles and simulation, against closed forms and independent
methods."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from scipy.special import lambertw
from systems import hutchinson, linear_dde, mackey_glass

from maglev_match.dynamics.cycles import cycle_branch
from maglev_match.dynamics.delay import (
    NODES_MAX,
    DelayNodesError,
    DiscretisedSystem,
    characteristic_roots,
    chebyshev_nodes,
    critical_delay,
    delay_crossings,
    delay_hopf_points,
    discretise,
    discretised_matrix,
    simulate_delay,
)
from maglev_match.dynamics.floquet import dominant_multipliers, periodic_eigenvalues
from maglev_match.dynamics.hopf import refine_hopf_point
from maglev_match.dynamics.normal_forms import first_lyapunov_coefficient


# ---------------------------------------------------------------------------------------
# the discretisation
# ---------------------------------------------------------------------------------------
def test_chebyshev_differentiation_is_exact_on_polynomials():
    s, D = chebyshev_nodes(10)
    assert s[0] == 0.0 and s[-1] == -1.0
    for k in range(11):  # degree <= N: exact
        assert np.allclose(D @ s**k, k * s ** max(k - 1, 0) * (k > 0), atol=1e-11)


def test_discretised_jacobian_is_the_matrix_built_from_the_linearisation():
    """The autodiff Jacobian of the discretised right-hand side equals the block matrix of
    the linearised delay equation (the two are built independently)."""
    dde = hutchinson(tau=1.3)
    S = discretise(dde, 11)
    X = S.lift(np.array([1.0]))
    J = S.jacobian(X)
    # x' = r x (1 - y / K): at x = K, df/dx = 0, df/dy = -r, y = x
    M = discretised_matrix(np.array([[0.0]]), [np.array([[-1.0]])], [np.array([[1.0]])],
                           [1.3], 11)
    assert S.dim == 12 and isinstance(S, DiscretisedSystem)
    assert np.allclose(J, M, rtol=1e-13, atol=1e-12)


# ---------------------------------------------------------------------------------------
# x' = -a x(t - tau): closed forms
# ---------------------------------------------------------------------------------------
def test_linear_dde_loses_stability_at_pi_over_2a_with_frequency_a():
    a = 2.0
    dde = linear_dde(a=a, tau=0.3)
    (c,) = delay_crossings(dde, "tau")
    assert abs(c.tau - math.pi / (2 * a)) < 1e-10
    assert abs(c.omega - a) < 1e-10 and c.crossing_speed > 0
    cd = critical_delay(dde)
    assert cd.stable_without_delay and abs(cd.value - math.pi / (2 * a)) < 1e-10
    # the discretised system's own Hopf defining system agrees (a second method)
    S = discretise(dde, 30, tau_max=1.0)
    hp = refine_hopf_point(S, "tau", 0.8, S.lift(np.zeros(1)), 1.9)
    assert hp.converged and abs(hp.value - math.pi / (2 * a)) < 1e-10
    assert abs(hp.frequency - a) < 1e-10


def test_linear_dde_roots_are_the_lambert_w_values():
    a, tau = 1.0, 1.0
    cr = characteristic_roots(linear_dde(a=a, tau=tau), count=12, nodes=40)
    exact = np.array([lambertw(-a * tau, k) / tau for k in range(-8, 9)])
    exact = exact[np.lexsort((-exact.imag, -exact.real))]
    assert cr.trusted >= 8
    for lam in cr.roots[:cr.trusted]:
        assert np.min(np.abs(exact - lam)) <= 1e-10 * max(1.0, abs(lam))
    # every exact root right of the last trusted one is among the trusted
    edge = cr.roots[cr.trusted - 1].real
    right = exact[exact.real > edge + 1e-9]
    assert all(np.min(np.abs(cr.roots[:cr.trusted] - z)) < 1e-9 for z in right)


def test_too_long_delay_is_refused_with_the_rule():
    dde = linear_dde(a=50.0, tau=2.0)  # rate 50 rad/s: 12 + 1.5 * 50 * 2 = 162 > NODES_MAX
    with pytest.raises(DelayNodesError, match=r"at most .* s") as exc:
        discretise(dde)
    assert exc.value.field == "tau" and str(NODES_MAX) in str(exc.value)
    with pytest.raises(DelayNodesError, match=">= 0"):
        discretise(linear_dde(tau=-0.1))


# ---------------------------------------------------------------------------------------
# the delayed logistic equation
# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def hutchinson_branch():
    dde = hutchinson(r=1.0, K=1.0, tau=1.0)
    S = discretise(dde, tau_max=2.0)
    scan = delay_hopf_points(S, "tau", 0.0, 2.0)
    hp = scan.points[0]
    br = cycle_branch(S, hp, "tau", stop_at=1.8, ntst=40, ncol=4, max_steps=80)
    return dde, S, hp, br


def test_hutchinson_hopf_at_r_tau_pi_over_2_is_supercritical(hutchinson_branch):
    dde, S, hp, br = hutchinson_branch
    assert abs(hp.value - math.pi / 2) < 1e-10 and abs(hp.frequency - 1.0) < 1e-10
    assert hp.l1 < 0 and hp.kind == "supercritical"
    # l1 of the discretised system (its own normal form, eigenvectors normalised on the
    # state) equals the characteristic-matrix formula
    l1_disc = first_lyapunov_coefficient(S, hp.x, hp.p, hp.frequency)
    assert abs(l1_disc - hp.l1) <= 1e-8 * abs(hp.l1)
    # the cycles are born stable, on the side of larger delays
    assert all(c.stable and c.value > hp.value for c in br.points[:6])


def test_hutchinson_cycle_period_is_4_tau_at_onset(hutchinson_branch):
    _, _, hp, br = hutchinson_branch
    pts = [c for c in br.points if 0 < c.value - hp.value < 0.01]
    assert len(pts) >= 3
    d = np.array([c.value - hp.value for c in pts])
    T = np.array([c.period for c in pts])
    # T(tau) is smooth through the Hopf point (both grow like the amplitude squared): its
    # quadratic fit at tau* is the onset period, 2 pi / omega = 4 tau*
    at_onset = np.polyfit(d, T, 2)[-1]
    assert abs(at_onset - 4 * hp.value) < 1e-6
    assert abs(pts[0].period - 4 * hp.value) < 1e-3  # and the first cycle is close to it


def test_hutchinson_cycle_amplitude_matches_a_long_simulation(hutchinson_branch):
    dde, S, hp, br = hutchinson_branch
    last = br.points[-1]
    assert abs(last.value - 1.8) < 1e-12 and last.stable
    x_max, x_min = last.extrema["x"]
    # method of steps, independent of the discretisation and of the collocation
    p = dde.params_with(tau=1.8)
    sim = simulate_delay(dde, np.array([1.2]), 400.0, p=p, rtol=1e-11, atol=1e-13, n_save=2)
    assert sim.outcome == "running"
    T = last.period
    t0 = 400.0 - 2 * T
    ts = np.linspace(t0, 400.0, 801)
    xs = sim(ts)[:, 0]
    k_hi, k_lo = int(np.argmax(xs)), int(np.argmin(xs))

    def extremum(k, sign):
        res = minimize_scalar(lambda t: -sign * sim(t)[0], bracket=(ts[k - 1], ts[k],
                                                                    ts[k + 1]),
                              tol=1e-12)
        return sign * -res.fun

    sim_max, sim_min = extremum(k_hi, 1.0), extremum(k_lo, -1.0)
    assert abs((sim_max - sim_min) - (x_max - x_min)) < 1e-6
    assert abs(sim_max - x_max) < 1e-6 and abs(sim_min - x_min) < 1e-6


def test_dominant_multipliers_equal_the_periodic_qz(hutchinson_branch):
    """The Floquet method of the discretised system against the periodic QZ on the same
    transfer matrices (a stiff product: the past decays like exp(-N^2 t / tau))."""
    from maglev_match.dynamics.cycles import CollocationBVP, blocks_at
    from maglev_match.dynamics.floquet import transfer_matrices

    _, S, _, br = hutchinson_branch
    c = br.points[-1]
    prob = CollocationBVP(system=S, ipar=S.param_index("tau"), p0=np.array(c.orbit.p),
                    mesh=np.array(c.orbit.mesh), m=c.orbit.ncol,
                    scale=np.asarray(S.state_scale), T_scale=c.period, lam_scale=1.0)
    J, Tb, h = blocks_at(prob, prob.pack(c.orbit.states, c.period, c.value), prob.mesh)
    P = transfer_matrices(np.asarray(J), Tb, h, c.orbit.ncol)
    mu, p, ok = dominant_multipliers(P, 4)
    pe = periodic_eigenvalues(P)
    ref = np.exp(pe.log_abs + 1j * pe.phase)
    ref = ref[np.argsort(-np.abs(ref))]
    assert ok and np.all(np.abs(mu[p:]) == 0) and np.all(np.abs(ref[p:]) < 1e-12)
    for z in mu[np.abs(mu) > 1e-8]:  # every multiplier that matters, conjugates in any order
        assert np.min(np.abs(ref - z)) <= 1e-12 + 1e-9 * abs(z)
    assert abs(c.trivial_multiplier - 1) < 1e-8


# ---------------------------------------------------------------------------------------
# a period doubling of cycles: Mackey-Glass
# ---------------------------------------------------------------------------------------
# Reference: the same branch with N = 45 Chebyshev nodes and NTST = 60 gives the period
# doubling at tau = 1.3596504222 (N = 20 / 30 with NTST = 40: 1.3596504227 / 1.3596504221):
# a higher-resolution computation of this code; the simulation below (method of steps,
# independent of the discretisation and the collocation) brackets it: period-1 attractor
# at 0.1 below, period-2 attractor at 0.03 above.
MG_PD_REFERENCE = 1.3596504222


@pytest.mark.slow
def test_mackey_glass_period_doubling_is_located():
    dde = mackey_glass()
    S = discretise(dde, 20, tau_max=1.6)
    hp = delay_hopf_points(S, "tau", 0.0, 1.6).points[0]
    assert hp.l1 < 0
    br = cycle_branch(S, hp, "tau", ntst=40, ncol=4, max_steps=60, param_bounds=(0.0, 1.6))
    pds = [s for s in br.special_points if s.type == "PD"]
    assert len(pds) == 1 and pds[0].located == "solved"
    assert abs(pds[0].value - MG_PD_REFERENCE) < 1e-6

    def alternation(tau):
        """|difference of consecutive maxima| of a simulated solution (maxima located on
        its dense output): it dies out on a period-1 attractor, stays on a period-2 one."""
        sim = simulate_delay(dde, np.array([1.1]), 300.0, p=dde.params_with(tau=tau),
                             rtol=1e-9, atol=1e-11, n_save=6001)
        t, x = sim.t, sim.x[:, 0]
        ks = np.nonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:]))[0] + 1
        peaks = [-minimize_scalar(lambda s: -sim(s)[0], bracket=(t[k - 1], t[k], t[k + 1]),
                                  tol=1e-12).fun for k in ks]
        return np.abs(np.diff(peaks))

    below, above = alternation(MG_PD_REFERENCE - 0.1), alternation(MG_PD_REFERENCE + 0.03)
    assert below[-1] < 1e-5 and below[-1] < 1e-3 * below[10]  # period 1 below
    assert above[-1] > 0.04 and abs(above[-1] - above[-3]) < 2e-3  # period 2 above


def test_a_delay_branch_stops_at_the_discretisations_bound_and_says_so():
    """The cycles of the delayed logistic equation continued in tau without a stop value:
    the branch ends at the longest delay the discretisation resolves, and says that the
    delay equations go on beyond it (it said 'the model is not defined beyond it')."""
    dde = hutchinson(r=1.0, K=1.0, tau=1.0)
    S = discretise(dde, tau_max=1.7)
    hi = S.param_ranges["tau"][1]
    hp = delay_hopf_points(S, "tau", 0.0, 1.7).points[0]
    br = cycle_branch(S, hp, "tau", ntst=30, ncol=4, max_steps=200)
    assert br.stopped_reason.startswith("reached the end")
    assert abs(br.points[-1].value - hi) < 0.05 * hi
    said = " ".join(br.warnings)
    assert "longest delay" in said and "discretisation" in said
    assert "not defined" not in said


def test_one_row_delay_candidates_equal_the_qz_eigenvalues():
    """The batched closed form z = 1 / (a^T M^{-1} e_r) for a delay matrix with one nonzero
    row (model A's outer loop) gives the finite eigenvalues of the pencil (M, A_k) that the
    QZ algorithm gives, frequency by frequency; with another delay in M and with a full
    A_k (the QZ path) as well."""
    import scipy.linalg

    from maglev_match.dynamics.delay import crossings

    rng = np.random.default_rng(7)
    n = 6
    A0 = rng.normal(size=(n, n))
    Ak = np.zeros((n, n))
    Ak[3] = rng.normal(size=n)
    Aj = rng.normal(size=(n, n))
    omegas = np.geomspace(1e-3, 50.0, 40)
    for As, taus, k in (([Ak], [0.0], 0), ([Aj, Ak], [0.3, 0.0], 1),
                        ([Ak, Aj], [0.0, 0.2], 1)):
        got = crossings._candidates_on_grid(A0, As, taus, k, omegas)
        assert len(got) == omegas.size
        for w, z in zip(omegas, got, strict=True):
            M = crossings._rest_matrix(A0, As, taus, k, w)
            ref = scipy.linalg.eigvals(M, As[k].astype(complex))
            ref = ref[np.isfinite(ref) & (np.abs(ref) < 1e12)]
            assert z.size == ref.size, (w, z, ref)
            assert np.allclose(np.sort_complex(z), np.sort_complex(ref), rtol=1e-9, atol=0)
            if As[k] is Ak:
                assert z.size == 1  # one finite eigenvalue: the closed form's
