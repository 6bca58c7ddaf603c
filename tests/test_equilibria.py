"""Branches of equilibria by pseudo-arclength continuation: folds, branch points and Hopf
points located by solving their test functions (known answers from closed forms)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from systems import S_HOPF_X, pitchfork, s_shaped_hopf, saddle_node

from maglev_match.dynamics.continuation import SpecialPointKind, StopReason
from maglev_match.dynamics.equilibria import equilibrium_branch
from maglev_match.dynamics.hopf import locate_hopf_points, refine_hopf_point


def test_saddle_node_fold_located_exactly():
    sys_ = saddle_node()
    br = equilibrium_branch(sys_, "mu", 1.0, -1.0, x0=np.array([1.0, 1.0]), n_points=40)
    lps = [sp for sp in br.special_points if sp.type == SpecialPointKind.LP]
    assert len(lps) == 1 and len(br.special_points) == 1
    lp = lps[0]
    assert lp.located == "solved" and lp.label == "LP1"
    assert abs(lp.value) < 1e-12
    assert np.max(np.abs(lp.x)) < 1e-7  # x = sqrt(mu) is only sqrt-accurate in mu
    # the branch turns: it came down x = +sqrt(mu) and returns on x = -sqrt(mu)
    assert br.stop_reason == StopReason.BOUND
    assert br.values[-1] == pytest.approx(1.0, abs=1e-12)
    assert br.states[-1, 0] == pytest.approx(-1.0, abs=1e-10)
    np.testing.assert_allclose(br.states[:, 0] ** 2, br.values, atol=1e-10)


def test_pitchfork_branch_point_located_exactly():
    br = equilibrium_branch(pitchfork(), "mu", -1.0, 1.0, n_points=15)
    bps = [sp for sp in br.special_points if sp.type == SpecialPointKind.BP]
    assert len(bps) == 1
    assert bps[0].located == "solved"
    assert abs(bps[0].value) < 1e-10
    assert not [sp for sp in br.special_points if sp.type == SpecialPointKind.LP]


def test_s_shaped_curve_both_hopf_points_found():
    """The upper Hopf point lies between the two folds: a natural-parameter scan from the
    lower branch jumps over it; the arclength branch passes both folds and finds it."""
    sys_ = s_shaped_hopf()
    br = equilibrium_branch(sys_, "mu", -1.0, 1.0, n_points=60)
    kinds = [sp.type for sp in br.special_points]
    assert kinds.count(SpecialPointKind.LP) == 2
    lp = sorted(sp.value for sp in br.special_points if sp.type == SpecialPointKind.LP)
    fold = 2 / (3 * math.sqrt(3))
    np.testing.assert_allclose(lp, [-fold, fold], atol=1e-10)
    scan = locate_hopf_points(sys_, "mu", -1.0, 1.0, n_scan=60)
    assert len(scan.points) == 2
    for hp, x in zip(scan.points, S_HOPF_X, strict=True):
        assert hp.converged
        assert hp.value == pytest.approx(x**3 - x, abs=1e-12)
        assert hp.frequency == pytest.approx(math.sqrt(3 * x * x - 1), rel=1e-10)
        assert hp.x[0] == pytest.approx(x, abs=1e-10)
    # the branch is not monotone in mu (it folds back), unlike a grid of values
    assert np.any(np.diff(scan.scan_values) < 0)


def test_neutral_saddle_is_not_a_hopf_point():
    # x' = y, y' = (x^2 - mu^2 ...): a saddle whose eigenvalues +-a sum to zero
    import jax.numpy as jnp

    from maglev_match.dynamics.system import System

    sys_ = System(rhs=lambda x, p: jnp.stack([x[1] + p[0] * x[0], x[0] - x[0] ** 3]),
                  p=np.array([-1.0]), param_names=("mu",), state_names=("x", "y"))
    # J = [[mu, 1], [1, 0]]: eigenvalues sum to mu, product -1 (a saddle throughout)
    scan = locate_hopf_points(sys_, "mu", -1.0, 1.0, n_scan=20)
    assert scan.points == []


def test_refine_rejects_a_hopf_point_outside_its_range():
    from maglev_match.core.params import load_preset
    from maglev_match.maglev.models import build_system

    unit = build_system(load_preset("turnout-soft"), "unit")
    free = dataclasses.replace(unit, param_ranges={})  # the model without its valid ranges
    # from a poor frequency guess Newton lands on a Hopf point at omega1 < 0
    hp = refine_hopf_point(free, "omega1", 110.0, unit.x_guess, 50.0)
    assert hp.value < 0  # a true solution of the defining system, but not physical
    assert hp.converged  # without a range nothing forbids it...
    hp = refine_hopf_point(free, "omega1", 110.0, unit.x_guess, 50.0, bounds=(30.0, 400.0))
    assert not hp.converged  # ...with the search bounds it is rejected with the reason
    assert "outside [30, 400]" in hp.message and "outside" in hp.warnings[-1]
    ranged = dataclasses.replace(unit, param_ranges={"omega1": (0.0, math.inf)})
    hp = refine_hopf_point(ranged, "omega1", 110.0, unit.x_guess, 50.0)
    assert not hp.converged and "outside" in hp.message
    # the shipped model declares omega1 in (0, 1e5]: its Newton path stops where it leaves
    assert unit.param_ranges["omega1"][0] > 0
    hp = refine_hopf_point(unit, "omega1", 110.0, unit.x_guess, 50.0)
    assert not hp.converged
    assert "the Newton path left the valid range" in hp.message
    assert "omega1 = -" in hp.message and "(0, 100000]" in hp.message
    # a good guess converges and is validated: +-i omega an eigenvalue pair there
    good = refine_hopf_point(unit, "omega1", 125.0, unit.x_guess, 145.0, bounds=(30, 400))
    assert good.converged and good.message == ""
    w = np.linalg.eigvals(unit.jacobian(good.x, good.p))
    assert np.min(np.abs(w - 1j * good.frequency)) < 1e-8 * good.frequency


def test_equilibrium_branch_stops_at_the_end_of_the_valid_range():
    """Model A declares omega1 > 0: a branch asked to run from 50 to -50 rad/s stops at the
    end of that range (close to omega1 = 0, where the beam loses its stiffness and the
    equilibrium its uniqueness, so the bound itself cannot be solved) and says so; one
    asked to start at -50 does not start."""
    from maglev_match.core.params import load_preset
    from maglev_match.dynamics.equilibria import equilibrium_branch
    from maglev_match.maglev.models import build_system

    unit = build_system(load_preset("alpha1"), "unit")
    br = equilibrium_branch(unit, "omega1", 50.0, -50.0, n_points=20)
    assert np.all(br.values > 0.0) and br.values[-1] < 1.0
    assert any("valid range of omega1" in w for w in br.warnings)
    bad = equilibrium_branch(unit, "omega1", -50.0, 50.0, n_points=20)
    assert bad.values.size == 0 and "outside its valid range" in bad.message
