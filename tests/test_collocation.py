"""The collocation linear algebra: the condensed solver (interior nodes eliminated per
interval) against a sparse LU of the whole bordered system, and the two corrector paths
giving the same branches and multipliers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from systems import CYCLE_OMEGA, HOPF_NF, Q_CRIT, lorenz

from maglev_match.dynamics.collocation import (
    CollocationProblem,
    CondensedLU,
    LinearSolver,
    collocation_newton,
    factorize,
    sparse_matrix,
)
from maglev_match.dynamics.cycles import cycle_branch, hopf_start


def _branch(solver: str, stop: float = 0.4):
    p = HOPF_NF.params_with(mu=0.0, l1=-1.0)
    start = hopf_start(HOPF_NF, np.zeros(5), p, "mu", CYCLE_OMEGA, Q_CRIT, -1.0)
    return cycle_branch(HOPF_NF, start, "mu", stop_at=stop, ntst=16, ncol=4, max_steps=200,
                        linear_solver=solver)


def _problem_near(c, system, ipar: int, m: int, seed: int = 0):
    """A collocation problem at a converged cycle c, and a point Y perturbed off it (so the
    residual is not small and the Newton step is a real one)."""
    o = c.orbit
    prob = CollocationProblem(system=system, ipar=ipar, p0=o.p, mesh=o.mesh, m=m,
                              scale=np.asarray(system.state_scale, float),
                              T_scale=o.period, lam_scale=0.1)
    rng = np.random.default_rng(seed)
    Y = prob.pack(o.states, o.period, c.value)
    Y = Y * (1.0 + 1e-3 * rng.standard_normal(Y.size))
    row = prob.W() * rng.standard_normal(Y.size)
    phase = prob.phase_row(o.states)
    return prob, Y, prob.parts(Y, phase, o.states, row, float(row @ Y) + 0.01)


@pytest.mark.parametrize("blocks", ["inverse", "lu"])
@pytest.mark.parametrize("m", [2, 4, 7])
def test_condensed_solve_equals_the_sparse_lu_of_the_whole_system(m, blocks, monkeypatch):
    """Newton step, tangent (right-hand side only in the last row) and an arbitrary
    right-hand side: the condensed solver and SuperLU on the whole matrix agree to 1e-12
    relative, and the condensed solution satisfies the full system to rounding; with the
    interval blocks inverted (small blocks) or LU-factorised (large blocks, forced here)."""
    from maglev_match.dynamics.collocation import linalg

    monkeypatch.setattr(linalg, "LU_BLOCKS_FROM", 10**9 if blocks == "inverse" else 1)
    br = _branch("sparse_lu")
    c = br.points[len(br.points) // 2]
    # re-discretise with NCOL m on the same mesh (the profile is only a starting guess)
    prob, Y, pa = _problem_near(c, HOPF_NF, 0, m) if m == 4 else (None, None, None)
    if prob is None:
        o = c.orbit
        prob = CollocationProblem(system=HOPF_NF, ipar=0, p0=o.p, mesh=o.mesh, m=m,
                                  scale=np.asarray(HOPF_NF.state_scale, float),
                                  T_scale=o.period, lam_scale=0.1)
        from maglev_match.dynamics.collocation import node_times

        s = node_times(o.mesh, m)
        U = o.evaluate(s % 1.0 * (1 - 1e-15))
        rng = np.random.default_rng(1)
        Y = prob.pack(U, o.period, c.value) * (1.0 + 1e-3 * rng.standard_normal(prob.size))
        row = prob.W() * rng.standard_normal(prob.size)
        pa = prob.parts(Y, prob.phase_row(U), U, row, float(row @ Y))
    A = sparse_matrix(prob, pa)
    lu = factorize(A)
    b0 = -pa.resid
    cl = CondensedLU(prob, pa, b0)
    e_last = np.zeros(prob.size)
    e_last[-1] = 1.0
    other = np.random.default_rng(7).standard_normal(prob.size)
    for b in (b0, e_last, other):
        x_ref = lu.solve(b)
        x = cl.solve(b)
        assert np.max(np.abs(x - x_ref)) <= 1e-12 * np.max(np.abs(x_ref))
        assert np.max(np.abs(A @ x - b)) <= 1e-12 * np.max(np.abs(b))


def test_condensed_solve_on_the_lorenz_cycle_near_its_homoclinic_end():
    """A long, strongly unstable Lorenz cycle (multiplier ~ 1e3 or more): the condensed
    step still equals the full sparse LU's to 1e-12 relative."""
    from systems import LORENZ_RHO_H

    sys_ = lorenz()
    br = cycle_branch(sys_, _lorenz_start(sys_), "rho", stop_at=LORENZ_RHO_H - 8.0,
                      ntst=40, ncol=4, max_steps=300)
    c = br.points[-1]
    prob, Y, pa = _problem_near(c, sys_, sys_.param_index("rho"), 4, seed=3)
    lu = factorize(sparse_matrix(prob, pa))
    x_ref = lu.solve(-pa.resid)
    x = CondensedLU(prob, pa, -pa.resid).solve(-pa.resid)
    assert np.max(np.abs(x - x_ref)) <= 1e-12 * np.max(np.abs(x_ref))


def _lorenz_start(sys_):
    from systems import LORENZ_RHO_H

    from maglev_match.dynamics.hopf import locate_hopf_points

    return locate_hopf_points(sys_, "rho", LORENZ_RHO_H - 2.0, LORENZ_RHO_H + 2.0,
                              n_scan=8).points[0]


def test_both_linear_solvers_give_the_same_branch_and_multipliers():
    """The corrector with the condensed solver (and its earlier convergence test) and with
    the sparse LU end on the same cycles: amplitude, period, parameter to 1e-9 and the
    Floquet multipliers to 1e-8 (the Newton tolerance is 1e-10 on the scaled unknowns)."""
    a, b = _branch("sparse_lu"), _branch("condensed")
    assert a.stopped_reason == b.stopped_reason == "reached stop_at"
    ca, cb = a.points[-1], b.points[-1]
    assert cb.value == pytest.approx(ca.value, abs=1e-12)
    assert cb.period == pytest.approx(ca.period, rel=1e-9)
    assert cb.max("radius") == pytest.approx(ca.max("radius"), rel=1e-9)
    assert cb.max("radius") == pytest.approx(math.sqrt(ca.value), rel=1e-6)  # closed form
    ma, mb = np.sort_complex(np.asarray(ca.multipliers)), np.sort_complex(
        np.asarray(cb.multipliers))
    assert np.max(np.abs(ma - mb)) < 1e-8
    assert len(a.points) == len(b.points)  # the same steps: the step control is unchanged


def test_newton_stops_only_when_converged():
    """From a perturbed cycle the condensed Newton returns a point whose residual is at
    rounding level, although it may stop one iteration before the update falls below tol."""
    br = _branch("condensed")
    c = br.points[-1]
    prob, Y, _ = _problem_near(c, HOPF_NF, 0, 4, seed=5)
    row = np.zeros(prob.size)
    row[-1] = 1.0
    Uref = c.orbit.states
    Yc, ok, its, _, _, _ = collocation_newton(prob, Y, Uref, row, c.value / 0.1, 1e-10, 12)
    assert ok and its >= 2
    pa = prob.parts(Yc, prob.phase_row(Uref), Uref, row, c.value / 0.1)
    assert np.max(np.abs(pa.resid)) < 1e-11


def test_unknown_linear_solver_is_an_error():
    p = HOPF_NF.params_with(mu=0.0, l1=-1.0)
    start = hopf_start(HOPF_NF, np.zeros(5), p, "mu", CYCLE_OMEGA, Q_CRIT, -1.0)
    with pytest.raises(ValueError, match="linear_solver"):
        cycle_branch(HOPF_NF, start, "mu", stop_at=0.1, linear_solver="dense")
    assert set(LinearSolver) == {"condensed", "sparse_lu"}


@pytest.mark.parametrize(("kw", "field"), [({"predictor_tol": -1.0}, "predictor_tol"),
                                           ({"floquet_method": "product"}, "floquet_method")])
def test_bad_step_and_floquet_options_are_errors_naming_the_field(kw, field):
    p = HOPF_NF.params_with(mu=0.0, l1=-1.0)
    start = hopf_start(HOPF_NF, np.zeros(5), p, "mu", CYCLE_OMEGA, Q_CRIT, -1.0)
    with pytest.raises(ValueError, match=field):
        cycle_branch(HOPF_NF, start, "mu", stop_at=0.1, **kw)


@pytest.mark.parametrize("blocks", ["inverse", "lu"])
def test_transfer_matrices_from_the_condensation_equal_the_interval_solves(blocks,
                                                                           monkeypatch):
    """The Floquet transfer matrices taken from the Newton step's condensation (no second
    solve) equal the batched interval solves of the variational collocation to 1e-12
    relative, and give the same multipliers (closed form for the normal form: 1 (double,
    the trivial one and the radial direction's exp(-2 mu T)... checked against the
    interval-solve route to 1e-10)."""
    from maglev_match.dynamics.collocation import linalg
    from maglev_match.dynamics.floquet import (
        floquet_multipliers_from_blocks,
        transfer_matrices,
    )

    monkeypatch.setattr(linalg, "LU_BLOCKS_FROM", 10**9 if blocks == "inverse" else 1)
    br = _branch("condensed")
    c = br.points[-1]
    o = c.orbit
    prob = CollocationProblem(system=HOPF_NF, ipar=0, p0=o.p, mesh=o.mesh, m=4,
                              scale=np.asarray(HOPF_NF.state_scale, float) * np.array(
                                  [1.0, 3.0, 0.5, 2.0, 7.0]),  # unequal scales on purpose
                              T_scale=o.period, lam_scale=0.1)
    Y = prob.pack(o.states, o.period, c.value)
    row = np.zeros(prob.size)
    row[-1] = 1.0
    pa = prob.parts(Y, prob.phase_row(o.states), o.states, row, c.value / 0.1)
    J, T, h = pa.blocks
    P = CondensedLU(prob, pa).transfer_matrices(prob.scale)
    P_ref = transfer_matrices(J, T, h, 4)
    assert np.max(np.abs(P - P_ref)) <= 1e-12 * np.max(np.abs(P_ref))
    mu = np.sort_complex(floquet_multipliers_from_blocks(J, T, h, 4, transfer=P))
    mu_ref = np.sort_complex(floquet_multipliers_from_blocks(J, T, h, 4))
    assert np.max(np.abs(mu - mu_ref)) < 1e-10
    # the trivial multiplier is there, and the radial one is exp(-2 mu T) (l1 = -1)
    assert np.min(np.abs(mu - 1.0)) < 1e-8
    assert np.min(np.abs(mu - math.exp(-2.0 * c.value * c.period))) < 1e-6


def test_chord_newton_reaches_the_newton_solution_with_one_kept_factorisation():
    """From a perturbed cycle, the chord iteration started with the factorisation at the
    unperturbed cycle converges to the solution Newton's method finds (to the tolerance),
    factorising only once more (at the solution, for the tangent and the multipliers);
    the factorisation it returns is the one at its solution."""
    from maglev_match.dynamics.collocation import NewtonStats, chord_newton

    br = _branch("condensed")
    c = br.points[-1]
    prob, Y, _ = _problem_near(c, HOPF_NF, 0, 4, seed=11)
    row = np.zeros(prob.size)
    row[-1] = 1.0
    Uref = c.orbit.states
    target = c.value / 0.1
    Y_exact = prob.pack(c.orbit.states, c.orbit.period, c.value)
    pa0 = prob.parts(Y_exact, prob.phase_row(Uref), Uref, row, target)
    lu0 = CondensedLU(prob, pa0)
    stats = NewtonStats()
    cr = chord_newton(prob, Y, Uref, row, target, 1e-10, 30, lu0=lu0, stats=stats)
    Yn, ok, _, _, _, _ = collocation_newton(prob, Y, Uref, row, target, 1e-10, 12)
    assert cr.converged and ok
    assert np.max(np.abs(cr.Y - Yn)) < 1e-10
    pa = prob.parts(cr.Y, prob.phase_row(Uref), Uref, row, target)
    assert np.max(np.abs(pa.resid)) < 1e-11
    assert cr.factorizations == 1 and stats.factorizations == 1  # only the one at the end
    assert cr.iterations >= 2 and stats.iterations == cr.iterations
    b = np.random.default_rng(2).standard_normal(prob.size)
    x_ref = CondensedLU(prob, pa).solve(b)
    assert np.max(np.abs(cr.lu.solve(b) - x_ref)) <= 1e-12 * np.max(np.abs(x_ref))


def test_chord_and_full_newton_give_the_same_branch_with_fewer_factorisations():
    """The chord corrector ends on the same cycle as full Newton (closed-form radius
    sqrt(mu), period, multipliers), with fewer factorisations of the bordered Jacobian."""
    p = HOPF_NF.params_with(mu=0.0, l1=-1.0)
    start = hopf_start(HOPF_NF, np.zeros(5), p, "mu", CYCLE_OMEGA, Q_CRIT, -1.0)
    a, b = (cycle_branch(HOPF_NF, start, "mu", stop_at=0.4, ntst=16, ncol=4, max_steps=200,
                         newton=mode) for mode in ("full", "chord"))
    assert a.stopped_reason == b.stopped_reason == "reached stop_at"
    ca, cb = a.points[-1], b.points[-1]
    assert cb.period == pytest.approx(ca.period, rel=1e-9)
    assert cb.max("radius") == pytest.approx(ca.max("radius"), rel=1e-9)
    assert cb.max("radius") == pytest.approx(math.sqrt(0.4), rel=1e-6)
    ma, mb = (np.sort_complex(np.asarray(x.multipliers)) for x in (ca, cb))
    assert np.max(np.abs(ma - mb)) < 1e-8
    assert b.factorizations < a.factorizations
    assert a.newton_iterations == a.factorizations  # full Newton: one per iteration


def test_multipliers_only_at_the_last_point():
    """multipliers_at='last' (without special points) computes the multipliers of the
    end point only, equal to those of the full run; the other points say they have none."""
    p = HOPF_NF.params_with(mu=0.0, l1=-1.0)
    start = hopf_start(HOPF_NF, np.zeros(5), p, "mu", CYCLE_OMEGA, Q_CRIT, -1.0)
    full = cycle_branch(HOPF_NF, start, "mu", stop_at=0.4, ntst=16, ncol=4,
                        detect_special_points=False)
    lean = cycle_branch(HOPF_NF, start, "mu", stop_at=0.4, ntst=16, ncol=4,
                        detect_special_points=False, multipliers_at="last",
                        factor_at_solution=True)  # the same steps as the full run
    ma, mb = (np.sort_complex(np.asarray(x.points[-1].multipliers)) for x in (full, lean))
    assert len(mb) == 4 and np.max(np.abs(ma - mb)) < 1e-12
    assert lean.points[-1].reliable and lean.points[-1].stable
    assert all(len(c.multipliers) == 0 and not c.reliable for c in lean.points[:-1])
    # by default such a branch also skips the chord corrector's factorisation at each
    # solution (the tangent and the next corrector use the one in force): fewer
    # factorisations, the same cycle at the stop value to the discretisation's accuracy
    # (another step sequence, hence another adapted mesh) and its multipliers (evaluated
    # at that point itself)
    auto = cycle_branch(HOPF_NF, start, "mu", stop_at=0.4, ntst=16, ncol=4,
                        detect_special_points=False, multipliers_at="last")
    assert auto.factorizations < lean.factorizations
    mc = np.sort_complex(np.asarray(auto.points[-1].multipliers))
    assert np.max(np.abs(ma - mc)) < 1e-9 and auto.points[-1].reliable
    assert auto.points[-1].max("radius") == pytest.approx(full.points[-1].max("radius"),
                                                          rel=1e-9)
    assert auto.points[-1].max("radius") == pytest.approx(math.sqrt(0.4), rel=1e-6)


@pytest.mark.parametrize(("kw", "field"), [({"newton": "quasi"}, "newton"),
                                           ({"multipliers_at": "first"}, "multipliers_at")])
def test_bad_corrector_options_are_errors_naming_the_field(kw, field):
    p = HOPF_NF.params_with(mu=0.0, l1=-1.0)
    start = hopf_start(HOPF_NF, np.zeros(5), p, "mu", CYCLE_OMEGA, Q_CRIT, -1.0)
    with pytest.raises(ValueError, match=field):
        cycle_branch(HOPF_NF, start, "mu", stop_at=0.1, **kw)
