"""Exact sensitivities of the index: closed forms on the embedded Hopf normal form, central
finite differences of the full index on model A."""

from __future__ import annotations

import math

import numpy as np
import pytest
from systems import nf_amplitude as amplitude
from systems import normal_form_system

from maglev_match.analyses.matching import index_of_system, matching_index
from maglev_match.analyses.sensitivity import (
    DerivativeStatus,
    derived_map,
    engineering_names,
    index_sensitivity,
    linearised_spread,
    system_sensitivity,
)
from maglev_match.core.params import load_preset
from maglev_match.dynamics.cycles import orbit_extrema
from maglev_match.dynamics.equilibria import stability
from maglev_match.maglev.unit import unit_system

W0 = 0.1


def _nf_index(system, limits=None, h_max=10.0):
    return index_of_system(system, system.p, w0=W0, h_max=h_max,
                           search={"a": (0.5, 3.0)}, limits=limits)


@pytest.mark.parametrize("values", [{}, {"a": 1.8, "l1": 0.8, "omega": 3.0}])
def test_normal_form_sensitivities_are_exact(values):
    s = normal_form_system(**values)
    mu, a, om, l1, b = s.p
    idx = _nf_index(s)
    assert idx.case == "unstable_cycle"
    h = amplitude(mu, a, l1)
    sens = system_sensitivity(s, idx)
    assert sens.h_status == DerivativeStatus.EXACT
    assert sens.h == pytest.approx(h, abs=1e-9)
    expected = np.array([-1 / (2 * l1 * h), 1 / (2 * l1 * h), 0.0, -h / (2 * l1), 0.0])
    np.testing.assert_allclose(sens.dh_dp, expected, rtol=0, atol=1e-8)
    # max Re lambda = mu - a (the third eigenvalue is -1)
    assert sens.max_real_part == pytest.approx(mu - a, abs=1e-12)
    np.testing.assert_allclose(sens.dmax_re_dp, [1, -1, 0, 0, 0], atol=1e-10)
    # Hopf point along a: a_H = mu
    assert sens.hopf_value == pytest.approx(mu, abs=1e-12)
    np.testing.assert_allclose(sens.dhopf_dp, [1, 0, 0, 0, 0], atol=1e-10)
    assert sens.solve_residual < 1e-10
    assert not sens.warnings


def test_case_rules_give_zero_or_rule_status():
    s = normal_form_system(a=0.8)  # a < mu: unstable equilibrium, chi = 0
    idx = _nf_index(s)
    assert idx.case == "unstable_equilibrium"
    sens = system_sensitivity(s, idx)
    assert sens.h_status == DerivativeStatus.ZERO
    assert not sens.dh_dp.any()
    np.testing.assert_allclose(sens.dmax_re_dp, [1, -1, 0, 0, 0], atol=1e-10)

    def limits(system, orbit):  # the cycle (radius 0.5) leaves the range at radius 0.3
        return {"gap": 0.3 - orbit_extrema(system, orbit, ["gap_deviation"])["gap_deviation"][0]}

    s = normal_form_system()
    idx = _nf_index(s, limits=limits, h_max=0.3)
    assert idx.case == "no_cycle_within_limits"
    sens = system_sensitivity(s, idx)
    assert sens.h_status == DerivativeStatus.RULE
    assert sens.h == 0.3 and not sens.dh_dp.any()


def test_derived_map_matches_params_and_beam_formulas():
    p = load_preset("turnout-soft")
    names = engineering_names(p)
    assert {"L", "EI", "mbar", "l", "k"} <= set(names) and "omega1" not in names
    q = np.array([float(getattr(p, n)) for n in names])
    pm, w0, hmax = derived_map(p)(q)
    sysp = unit_system(p).p
    np.testing.assert_allclose(np.asarray(pm), sysp, rtol=1e-14)
    assert float(w0) == pytest.approx(p.w0, rel=1e-14)
    assert float(hmax) == pytest.approx(p.gap_max - p.c0, rel=1e-14)
    import jax

    jac = np.asarray(jax.jacfwd(lambda qq: derived_map(p)(qq)[0])(q))
    i_w, i_ei = unit_system(p).param_index("omega1"), names.index("EI")
    # omega1 ~ sqrt(EI): d omega1 / d EI = omega1 / (2 EI)
    assert jac[i_w, i_ei] == pytest.approx(p.omega1 / (2 * p.EI), rel=1e-13)
    explicit = p.replace(omega1=p.omega1, sigma=p.sigma)
    assert "omega1" in engineering_names(explicit) and "EI" not in engineering_names(explicit)


@pytest.fixture(scope="module")
def soft():
    p = load_preset("turnout-soft")
    return p, index_sensitivity(p, boundaries=False, simulate=False)


def _fd(params, name, rel=1e-4):
    v = float(getattr(params, name))
    d = rel * v
    cp = matching_index(params.replace(**{name: v + d}), simulate=False).chi
    cm = matching_index(params.replace(**{name: v - d}), simulate=False).chi
    return (cp - cm) / (2 * d)


@pytest.mark.parametrize("name", ["kD", "EI"])
def test_model_a_dchi_matches_finite_differences(soft, name):
    p, sens = soft
    assert sens.status == DerivativeStatus.EXACT
    assert sens.dchi(name) == pytest.approx(_fd(p, name), rel=1e-4)


@pytest.mark.parametrize("name", ["omega1", "sigma"])
def test_model_a_dchi_dbeam_modal_values(soft, name):
    p0, _ = soft
    p = p0.replace(omega1=p0.omega1, sigma=p0.sigma)
    sens = index_sensitivity(p, boundaries=False, simulate=False)
    assert sens.index.chi == pytest.approx(soft[1].index.chi, rel=1e-12)
    assert sens.dchi(name) == pytest.approx(_fd(p, name), rel=1e-4)


def test_model_a_margin_and_elasticity(soft):
    p, sens = soft
    v, d = p.kD, 1e-4 * p.kD
    mp = stability(unit_system(p.replace(kD=v + d))).margin
    mm = stability(unit_system(p.replace(kD=v - d))).margin
    assert sens.dmargin("kD") == pytest.approx((mp - mm) / (2 * d), rel=1e-5)
    r = sens.row("EI")
    assert r.elasticity == pytest.approx(r.value / sens.index.chi * r.dchi, rel=1e-14)
    # chi = h / w0 and w0 ~ 1/EI at fixed h: an elasticity of EI differs from the one of h
    rows = sens.sorted_rows()
    assert abs(rows[0].elasticity) >= abs(rows[-1].elasticity)
    spread = linearised_spread(sens, {"EI": 5.0, "kD": 10.0})
    expect = math.hypot(sens.dchi("EI") * p.EI * 0.05, sens.dchi("kD") * p.kD * 0.10)
    assert spread["sd"] == pytest.approx(expect, rel=1e-14)


def test_stability_boundary_is_a_zero_of_the_margin(soft):
    p, _ = soft
    sens = index_sensitivity(p, sens_index := soft[1].index, boundaries=True)
    assert sens_index is sens.index
    r = sens.row("kP")
    assert r.boundary is not None
    st = stability(unit_system(p.replace(kP=r.boundary)))
    assert abs(st.max_real_part) < 1e-9
    # the branch's gap maximum does not depend on gap_max, so the cycle-limit boundary in
    # gap_max is exact: the case changes there. It lies above c0 + h, because the cycle is
    # larger on the way from the Hopf point than at the design point.
    g = sens.row("gap_max").limit_boundary
    assert g > p.c0 + sens.index.h
    assert matching_index(p.replace(gap_max=g * 1.001), simulate=False).case == "unstable_cycle"
    assert matching_index(p.replace(gap_max=g * 0.999), simulate=False).case == \
        "no_cycle_within_limits"


def test_sampled_spread_matches_first_order_and_resumes(soft, tmp_path, monkeypatch):
    import maglev_match.analyses.sensitivity as S
    import maglev_match.analyses.sensitivity.uncertainty as uncertainty
    from maglev_match.core.params import ParameterError

    p, sens = soft
    scatter = {"EI": 0.1, "kD": 0.1}  # small: chi is linear over the spread
    mc = S.sampled_spread(p, scatter, 4, tmp_path, chunk=2, workers=0,
                          linearised=linearised_spread(sens, scatter))
    assert mc.failed == 0 and mc.invalid == 0 and np.isfinite(mc.chi).all()
    grad = np.array([sens.dchi("EI"), sens.dchi("kD")])
    x0 = np.array([p.EI, p.kD])
    first_order = sens.index.chi + (mc.samples - x0) @ grad
    dev = np.abs(mc.chi - sens.index.chi)
    np.testing.assert_array_less(np.abs(mc.chi - first_order), 0.02 * dev + 1e-9)
    calls = []
    # sampled_spread calls the mc_chunk of its own module
    monkeypatch.setattr(uncertainty, "mc_chunk", lambda *a: calls.append(a) or np.zeros(2))
    again = S.sampled_spread(p, scatter, 4, tmp_path, chunk=2, workers=0, resume=True)
    assert not calls and np.array_equal(again.chi, mc.chi)
    with pytest.raises(ParameterError, match="--resume"):
        S.sampled_spread(p, {"EI": 0.2}, 4, tmp_path, chunk=2, workers=0, resume=True)


def test_model_a_hopf_point_derivative_matches_finite_differences(soft):
    p, sens = soft
    k = unit_system(p).param_index("kD")
    d = 1e-4 * p.kD
    hp = matching_index(p.replace(kD=p.kD + d), simulate=False).hopf_value
    hm = matching_index(p.replace(kD=p.kD - d), simulate=False).hopf_value
    assert sens.system.hopf_value == pytest.approx(sens.index.hopf_value, rel=1e-10)
    assert sens.system.dhopf_dp[k] == pytest.approx((hp - hm) / (2 * d), rel=1e-5)


def test_unstable_point_has_zero_derivative_and_a_boundary():
    p = load_preset("turnout-soft").replace(EI=4e10)  # past the Hopf curve
    sens = index_sensitivity(p)
    assert sens.index.case == "unstable_equilibrium"
    assert sens.status == DerivativeStatus.ZERO
    assert all(r.dchi == 0.0 for r in sens.rows)
    r = sens.row("EI")
    assert r.boundary is not None and r.boundary < p.EI
    st = stability(unit_system(p.replace(EI=r.boundary)))
    assert abs(st.max_real_part) < 1e-9
    assert "derivative exactly 0" in r.note


def test_model_a_derivative_of_the_polynomial_maximum_is_exact_to_1e6(soft):
    # the index reads h on a fine grid of the cycle (about 1e-8 relative below the
    # polynomial's maximum, which moves with p); the sensitivities differentiate the
    # maximum itself, so central differences of that maximum agree much more closely
    p, sens = soft
    d = 1e-4 * p.kD
    sp = index_sensitivity(p.replace(kD=p.kD + d), boundaries=False, simulate=False)
    sm = index_sensitivity(p.replace(kD=p.kD - d), boundaries=False, simulate=False)
    fd = (sp.system.h / sp.index.w0 - sm.system.h / sm.index.w0) / (2 * d)
    assert sens.dchi("kD") == pytest.approx(fd, rel=1e-6)


def test_case_rule_boundary_from_the_branch_contact_with_the_gap_limit():
    # the cheapest soft beam of the design problem: the cycle branch from the Hopf point in
    # sigma reaches gap 0 before the design sigma, and cannot be continued past it even
    # without limits; the case boundary in sigma (the branch parameter) is that contact
    base = load_preset("turnout-soft").replace(EI=8.2e9)
    p = base.replace(sigma=base.sigma)  # sigma explicit: it has a row
    sens = index_sensitivity(p, boundaries=True, simulate=False)
    assert sens.status == DerivativeStatus.RULE
    assert "reaches the gap-deviation limit" in sens.limit_boundary_note
    s_c = sens.row("sigma").limit_boundary
    assert p.sigma < s_c < sens.index.hopf_value
    above = matching_index(p.replace(sigma=1.01 * s_c), simulate=False)
    below = matching_index(p.replace(sigma=0.99 * s_c), simulate=False)
    assert above.case == "unstable_cycle" and below.case == "no_cycle_within_limits"


def test_a_delay_is_refused_by_the_analysis_itself_naming_tau():
    """Not only the API: the analysis refuses tau > 0 before any work (its beam-to-model
    maps are of the delay-free models; it used to fail on a matrix size, 17 vs 18), and the
    iso-chi curve, which calls it for its gradient, says why it falls back."""
    from maglev_match.analyses.iso.maglev import MaglevChi
    from maglev_match.analyses.iso.trace import Sample
    from maglev_match.analyses.matching import MatchingIndex
    from maglev_match.analyses.sensitivity import index_sensitivity as analysis
    from maglev_match.core.params import ParameterError, load_preset

    p = load_preset("turnout-soft").replace(tau=1e-3)
    with pytest.raises(ParameterError) as e:
        analysis(p, simulate=False)
    assert e.value.field == "tau" and "delay-free models only" in e.value.rule
    ev = MaglevChi(p, ("EI", "kD"), simulate=False)
    idx = object.__new__(MatchingIndex)  # a converged index; the gradient reads no more
    object.__setattr__(idx, "converged", True)
    grad, why = ev.gradient(p.EI, p.kD, Sample(5.0, 5.0, state=idx))
    assert grad == {} and "with a delay (tau > 0)" in why
