"""The maglev models with a delayed outer control loop (parameter tau): the delay-free
limit, convergence of the discretisation, the critical delay, simulation and the index."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from maglev_match.analyses.simulation import simulate_maglev
from maglev_match.core.params import ParameterError, load_preset
from maglev_match.dynamics.delay import (
    DiscretisedSystem,
    characteristic_roots,
    critical_delay,
    delay_first_lyapunov_coefficient,
    simulate_delay,
)
from maglev_match.dynamics.equilibria import stability
from maglev_match.dynamics.hopf import locate_hopf_points, refine_hopf_point
from maglev_match.dynamics.normal_forms import first_lyapunov_coefficient
from maglev_match.dynamics.system import System
from maglev_match.maglev.limits import gap_limit_events
from maglev_match.maglev.models import build_system
from maglev_match.maglev.unit import (
    STATE_SCALE,
    param_vector,
    unit_dde,
    unit_rhs,
    unit_rhs_limited,
    unit_system,
)
from maglev_match.maglev.unit import gap as unit_gap


@pytest.fixture(scope="module")
def soft():
    return load_preset("turnout-soft")


@pytest.fixture(scope="module")
def ode_hopf(soft):
    """Model A's Hopf point along omega1 without delay (128.44 rad/s, subcritical)."""
    return locate_hopf_points(unit_system(soft), "omega1", 100.0, 150.0).points[0]


# ---------------------------------------------------------------------------------------
# tau -> 0
# ---------------------------------------------------------------------------------------
def test_zero_delay_is_todays_ode_exactly(soft, ode_hopf):
    s = build_system(soft, "unit")
    assert type(s) is System and s.rhs is unit_rhs and "tau" not in s.param_names
    assert np.array_equal(s.p, param_vector(soft))
    assert build_system(soft, "unit", limited=True).rhs is unit_rhs_limited
    # the delay system's delay-free system is the same ODE (same function, same numbers)
    dde = unit_dde(soft)
    ode = dde.ode_system()
    assert ode.rhs is unit_rhs and np.array_equal(ode.p, s.p)
    # the characteristic-equation code at tau = 0 reproduces the ODE's eigenvalues and l1
    w = stability(s).eigenvalues
    cr = characteristic_roots(dde, count=9)
    assert np.max(np.abs(np.sort_complex(cr.roots) - np.sort_complex(w))) < 1e-10
    pk = np.append(ode_hopf.p, 0.0)
    l1 = delay_first_lyapunov_coefficient(dde, ode_hopf.x, pk, ode_hopf.frequency)
    assert abs(l1 - ode_hopf.l1) <= 1e-10 * abs(ode_hopf.l1)


def test_discretised_model_a_tends_to_the_ode_as_tau_goes_to_zero(soft, ode_hopf):
    """The Hopf point along omega1 of the discretised delay system moves linearly in tau
    (-1.37e4 rad/s per s): the slopes at tau = 1e-6 and 1e-7 agree, and the linear
    extrapolation to tau = 0 is the ODE's Hopf point."""
    shifts = {}
    for tau in (1e-6, 1e-7):
        S = unit_system(soft.replace(tau=tau))
        hp = refine_hopf_point(S, "omega1", ode_hopf.value, S.lift(ode_hopf.x),
                               ode_hopf.frequency)
        assert hp.converged and isinstance(S, DiscretisedSystem)
        shifts[tau] = hp.value - ode_hopf.value
    s1, s2 = shifts[1e-6] / 1e-6, shifts[1e-7] / 1e-7
    assert abs(s1 - s2) <= 1e-3 * abs(s2) and s2 < 0
    limit = ode_hopf.value + (1e-6 * shifts[1e-7] - 1e-7 * shifts[1e-6]) / (1e-6 - 1e-7)
    assert abs(limit - ode_hopf.value) <= 2e-9 * ode_hopf.value


def test_characteristic_roots_tend_to_the_ode_eigenvalues_at_second_order(soft):
    """lambda(tau) = lambda0 + tau lambda'(0) + O(tau^2) with the closed form
    lambda'(0) = -lambda0 <u, A1 v> / <u, v> (u, v left/right eigenvectors of A0 + A1;
    from d/dtau of det(lambda I - A0 - A1 exp(-lambda tau)) = 0 at tau = 0): the six
    rightmost roots at tau = 1e-8 equal it to 1e-10, and the remainder falls like tau^2."""
    import scipy.linalg

    from maglev_match.dynamics.delay import delay_jacobians

    A0, (A1,) = delay_jacobians(unit_dde(soft), np.zeros(9))
    w, vl, vr = scipy.linalg.eig(A0 + A1, left=True, right=True)
    rest = {}
    for tau in (1e-6, 1e-7, 1e-8):
        cr = characteristic_roots(unit_dde(soft.replace(tau=tau)), count=6)
        assert cr.trusted == 6
        errs = []
        for lam in cr.roots:
            k = int(np.argmin(np.abs(w - lam)))
            u, v = vl[:, k], vr[:, k]
            slope = -w[k] * (np.conj(u) @ A1 @ v) / (np.conj(u) @ v)
            errs.append(abs(lam - w[k] - tau * slope))
        rest[tau] = np.array(errs)
    assert np.all(rest[1e-8] < 1e-10)
    ratio = rest[1e-6][2:] / rest[1e-7][2:]  # (the first pair is at round-off already)
    assert np.all((ratio > 80) & (ratio < 120))


def test_rightmost_roots_converge_in_the_number_of_nodes(soft):
    """At tau = 1 ms the discretised system's six rightmost eigenvalues agree to 1e-10 for
    N = 16 and 32 and with the Newton-corrected characteristic roots (N = 32 and 48)."""
    p = soft.replace(tau=1e-3)
    dde = unit_dde(p)
    ref = characteristic_roots(dde, count=6, nodes=32)
    assert ref.trusted == 6
    for N in (16, 32):
        w = stability(unit_system(p, nodes=N)).eigenvalues[:6]
        assert np.max(np.abs(w - ref.roots) / np.maximum(1.0, np.abs(ref.roots))) < 1e-10


# ---------------------------------------------------------------------------------------
# the critical delay
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("preset", ["turnout-soft", "turnout-stiff"])
def test_critical_delay_is_where_the_discretised_system_loses_stability(preset):
    params = load_preset(preset)
    dde = unit_dde(params)
    cd = critical_delay(dde, tau_max=0.02)
    assert cd.stable_without_delay and 1e-3 < cd.value < 2e-3 and cd.crossing_speed > 0
    below = stability(unit_system(params.replace(tau=cd.value * (1 - 1e-6))))
    above = stability(unit_system(params.replace(tau=cd.value * (1 + 1e-6))))
    assert below.stable and not above.stable
    pair = above.eigenvalues[0]
    assert abs(abs(pair.imag) - cd.frequency) < 1e-3
    # l1: the characteristic-matrix formula and the discretised system's normal form
    S = unit_system(params.replace(tau=cd.value))
    l1 = first_lyapunov_coefficient(S, S.lift(np.zeros(9)), None, cd.frequency)
    assert l1 == pytest.approx(cd.l1, rel=1e-6) and cd.kind == "supercritical"


def test_a_delay_needing_too_many_nodes_is_a_parameter_error(soft):
    with pytest.raises(ParameterError, match=r"'tau' = 0\.5: needs .* at most"):
        unit_system(soft.replace(tau=0.5))
    with pytest.raises(ParameterError, match="tau"):
        soft.replace(tau=-1e-3)


# ---------------------------------------------------------------------------------------
# simulation: method of steps against the discretised ODE
# ---------------------------------------------------------------------------------------
def test_simulation_with_delay_matches_the_method_of_steps(soft):
    """The discretised ODE (default nodes) against the method of steps on model A with the
    limits on, tau = 1 ms, a constant past: the gap agrees to 1e-11 m and collision times to
    1e-10 s; the states to 2e-4 of their scale (the coil current, near t = tau, where the
    constant past's kink is transported through the history)."""
    p = soft.replace(tau=1e-3)
    ev = gap_limit_events(unit_gap, p.gap_min, p.gap_max)
    dde = unit_dde(p, limited=True)
    for x5, end in ((-1e-3, "running"), (-6e-3, "collision")):
        x0 = np.zeros(9)
        x0[4] = x5
        disc = simulate_maglev(p, "unit", x0, 0.3, n_save=301)
        ref = simulate_delay(dde, x0, 0.3, event_fn=ev, n_save=301)
        assert disc.outcome == ref.outcome == end
        ok = np.all(np.isfinite(disc.result.x), axis=1) & np.all(np.isfinite(ref.x), axis=1)
        xd, xr = disc.result.x[ok, :9], ref.x[ok]
        assert np.max(np.abs((xd[:, 0] - xd[:, 4]) - (xr[:, 0] - xr[:, 4]))) < 1e-11
        assert np.max(np.abs(xd - xr) / STATE_SCALE) < 2e-4
        if end == "collision":
            assert abs(disc.collision_time - ref.event_time) < 1e-10


# ---------------------------------------------------------------------------------------
# the index with a delay
# ---------------------------------------------------------------------------------------
def test_index_beyond_the_critical_delay_is_zero_and_says_why(soft):
    from maglev_match.analyses.matching import matching_index

    res = matching_index(soft.replace(tau=2e-3), simulate=False)
    assert res.chi == 0.0 and not res.stable and res.case == "unstable_equilibrium"
    cd = res.critical_delay
    ref = critical_delay(unit_dde(soft), tau_max=1.0)
    assert cd["value"] == pytest.approx(ref.value, rel=1e-12) and cd["stable_at_tau"] is False
    assert cd["kind"] == "supercritical" and cd["frequency"] == pytest.approx(ref.frequency)


def test_a_delayed_map_row_simulates_the_delay_system(monkeypatch):
    """A map row with a delay gets its critical disturbances from the point-wise search on
    the delay system (the map's batched search integrates model A's ODE, which has no
    delay): every stable point of the row goes there, with its delay, in both directions,
    and the search's outcome becomes the size by the index's rule (bracketed: the critical
    size; every size returned: the gap range; still open: no number, a reason code)."""
    import maglev_match.analyses.maps as maps
    import maglev_match.analyses.maps.simulated as simulated
    import maglev_match.analyses.simulation as simulation

    calls = []
    outcomes = {0.5e-3: ("bracketed", 2.5e-3), 1e-3: ("all_return", None),
                1.5e-3: ("open", None)}

    def fake(p, *, direction, **kw):
        calls.append((p.tau, direction))
        status, crit = outcomes[round(p.tau, 6)]
        return SimpleNamespace(status=status, critical=crit, gap_range=8e-3)

    def no_batch(*a, **k):
        raise AssertionError("a delayed row must not use the ODE's batched search")

    maps.simulation_settings()  # (read from the real search's signature, before the fake)
    monkeypatch.setattr(simulation, "critical_disturbance", fake)
    monkeypatch.setattr(simulated, "critical_sizes_batch", no_batch)
    base = load_preset("turnout-soft")
    spec = maps.MapSpec(base=base.as_input_dict(), x=maps.Axis("tau", 0.5e-3, 2e-3, 4),
                        y=maps.Axis("kD", base.kD, base.kD, 1))
    stable = np.array([True, True, True, False])  # the last point: no search at all
    row, _ = maps.simulate_row(spec, 0, {"stable": stable, "max_real_part": -np.ones(4)}, [])
    assert sorted(calls) == sorted((t, d) for t in (0.5e-3, 1e-3, 1.5e-3) for d in (-1, 1))
    np.testing.assert_array_equal(row["h_down"][:2], [2.5e-3, 8e-3])
    assert np.isnan(row["h_down"][2]) and np.isnan(row["h_down"][3])
    assert row["reason"].tolist() == [0, 0, maps.REASON_SIM_UNDECIDED, 0]


# ---------------------------------------------------------------------------------------
# the critical disturbance's grazing solve on the delay system
def test_delay_clamp_is_the_limited_discretised_field(soft):
    """The clamp of model A with a delay (a hybrid system on the discretised state) is the
    limited discretised field: in the free mode wherever the current flows, in the held mode
    at i = 0 with the delayed demand negative (current held, no force); its held mode is
    left where the delayed command asks for current (guard = -(u(t - tau) + i0))."""
    from maglev_match.maglev.models import maglev_model

    m = maglev_model(soft.replace(tau=1e-3), "unit")
    hs, lim = m.clamped(), m.system(limited=True)
    assert hs.dim == lim.dim == 9 + lim.nodes and hs.p.tolist() == lim.p.tolist()
    rng = np.random.default_rng(3)
    import jax.numpy as jnp

    i0 = float(m.levitation_current)
    for _ in range(5):
        X = lim.x_guess + 0.05 * rng.standard_normal(lim.dim) * lim.state_scale
        X[6] = abs(X[6])  # current above i0: flowing
        np.testing.assert_allclose(np.asarray(hs.rhs(jnp.asarray(X), hs.p, np.zeros(1))),
                                   np.asarray(lim.rhs(X, lim.p)), rtol=1e-13, atol=1e-300)
        Xh = X.copy()
        Xh[6], Xh[-1] = -i0, -2.0 * i0  # i = 0 and the delayed demand u + i0 < 0
        np.testing.assert_allclose(np.asarray(hs.rhs(jnp.asarray(Xh), hs.p, np.ones(1))),
                                   np.asarray(lim.rhs(Xh, lim.p)), rtol=1e-13, atol=1e-300)
        assert float(hs.guards(jnp.asarray(Xh), hs.p, np.ones(1))[0]) == pytest.approx(i0)


@pytest.fixture(scope="module")
def delay_down(soft):
    """Model A at tau = 1 ms and the search of its critical disturbance, beam down (30
    runs of the stiff discretised delay system: shared by the two tests below)."""
    from maglev_match.analyses.simulation import critical_disturbance
    from maglev_match.maglev.models import maglev_model

    m = maglev_model(soft.replace(tau=1e-3), "unit")
    return m, critical_disturbance(m, direction=1)


def test_delay_grazing_is_solved_and_agrees_with_the_simulation(soft, delay_down):
    """At tau = 1 ms the critical disturbance (beam pressed down) is *solved* as a grazing
    contact on the delay system, not left at the bisection's midpoint: the size lies in the
    bracket of the search, and the limited discretised system's own runs at 1e-7 below it
    return without a collision while those 1e-7 above collide (the two independent
    computations agree to ~3e-10 m); d size / d tau equals the central difference (measured
    -0.5671720634 both ways, 1e-9 apart)."""
    from maglev_match.analyses.critical import Mechanism, critical_from_bisection
    from maglev_match.dynamics.integrate.simulate import simulate_batch
    from maglev_match.maglev.models import maglev_model

    m, cd = delay_down
    res = critical_from_bisection(m, cd)
    assert res.mechanism == Mechanism.GRAZING and res.solved, res.reason
    lo, hi = res.bracket
    assert lo <= res.size <= hi and hi - lo <= 1e-5
    assert res.limit == "lower" and res.t_star > 0
    sys_ = m.system(limited=True)
    sizes = res.size * (1 + np.array([-1e-7, 1e-7]))
    b = simulate_batch(sys_, sys_.lift(m.disturbance(1).x0_of(sizes)), 20.0,
                       event_fn=m.gap_events(), x_ref=sys_.lift(m.equilibrium()))
    assert b.outcome.tolist() == ["converged", "collision"]
    # its derivative in the delay (implicit function theorem on the grazing conditions, with
    # the sensitivities of the discretised past) is the central difference of solved sizes
    dres = critical_from_bisection(m, cd, derivative=True)
    names = list(m.clamped().param_names)
    assert dres.derivative_available and len(dres.dsize_dp) == len(names)
    h = 1e-7
    sizes = [critical_from_bisection(maglev_model(soft.replace(tau=1e-3 + s * h), "unit"),
                                     cd).size for s in (-1, 1)]
    assert dres.dsize_dp[names.index("tau")] == pytest.approx(
        (sizes[1] - sizes[0]) / (2 * h), rel=1e-6)


def test_delay_grazing_is_continued_to_a_neighbouring_design(soft, delay_down):
    """The solved grazing size at tau = 1 ms continued to kD + 1 % (Newton from the
    neighbour's size, two check runs) equals the size solved from that design's own search
    (1e-12 relative)."""
    from dataclasses import replace

    from maglev_match.analyses.continued import CriticalStart, continue_critical
    from maglev_match.analyses.critical import Mechanism, critical_from_bisection
    from maglev_match.analyses.simulation import critical_disturbance
    from maglev_match.maglev.models import maglev_model

    m0, cd0 = delay_down
    c0 = critical_from_bisection(m0, cd0)
    c0 = replace(c0, at=np.asarray(m0.param_vector()))
    m1 = maglev_model(soft.replace(tau=1e-3, kD=soft.kD * 1.01), "unit")
    size, check, fallback = continue_critical(m1, CriticalStart(c0.at, c0), model="unit")
    assert fallback is None and size.mechanism == Mechanism.GRAZING
    point = critical_from_bisection(m1, critical_disturbance(m1, direction=1))
    assert point.mechanism == Mechanism.GRAZING
    assert size.size == pytest.approx(point.size, rel=1e-12) and size.size != c0.size
    assert check.largest_return < size.size < check.smallest_collision
