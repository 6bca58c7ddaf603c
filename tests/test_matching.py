"""Matching index: the three cases of h on a synthetic Hopf normal form with a known cycle,
and the trend of h and h_simulation approaching a subcritical Hopf point on model A."""

import jax.numpy as jnp
import numpy as np
import pytest

from maglev_match.dynamics.system import System
from maglev_match.matching import CASES, index_of_system, matching_index, reading
from maglev_match.params import load_params


def normal_form_rhs(x, p):
    """r' = r (mu + l r^2), theta' = 1 in (x1, x2), plus a stable linear state x3.
    For mu / l < 0 the cycle is the circle of radius sqrt(-mu / l), period 2 pi."""
    mu, l = p[0], p[1]
    r2 = x[0] ** 2 + x[1] ** 2
    return jnp.stack([mu * x[0] - x[1] + l * x[0] * r2,
                      x[0] + mu * x[1] + l * x[1] * r2,
                      -2.0 * x[2] + 0.0 * x[0]])


def synthetic(mu, l):
    return System(
        rhs=normal_form_rhs, p=np.array([mu, l]), param_names=("mu", "l"),
        state_names=("x1", "x2", "x3"),
        observables={"gap_deviation": lambda x, p: x[0],
                     "current": lambda x, p: 1.0 + x[1]},
        name="Hopf normal form",
    )


W0 = 0.05
H_MAX = 0.5
SEARCH = {"mu": (-0.2, 0.2)}


def index(mu, l, limits=None):
    s = synthetic(mu, l)
    return index_of_system(s, s.p, w0=W0, h_max=H_MAX, search=SEARCH, limits=limits)


def test_unstable_equilibrium_gives_chi_exactly_zero():
    res = index(0.02, 1.0)
    assert res.case == "unstable_equilibrium"
    assert res.h == 0.0 and res.chi == 0.0
    assert res.reading.startswith("poor")


def test_unstable_cycle_gives_its_amplitude():
    mu, l = -0.04, 1.0
    res = index(mu, l)
    assert res.case == "unstable_cycle"
    radius = np.sqrt(-mu / l)
    assert res.h == pytest.approx(radius, rel=1e-6)
    assert res.chi == pytest.approx(radius / W0, rel=1e-6)
    assert res.cycle_period == pytest.approx(2 * np.pi, rel=1e-6)
    assert res.hopf_value == pytest.approx(0.0, abs=1e-10)
    assert res.l1 > 0  # subcritical
    assert res.cycle_unstable_multipliers == 1
    assert not res.current_reverses  # current = 1 + x2 stays > 0 for radius 0.2


def test_supercritical_hopf_leaves_no_surrounding_cycle():
    res = index(-0.04, -1.0)
    assert res.case == "no_cycle_within_limits"
    assert res.h == H_MAX and res.chi == pytest.approx(H_MAX / W0)
    assert res.converged


def test_cycle_beyond_limits_gives_h_max():
    """The unstable cycle at mu = -0.04 has radius 0.2; with the gap limit at 0.1 the branch
    touches it (at mu = -0.01) before reaching the design point."""

    def limits(system, orbit):
        g = system.observe("gap_deviation", orbit.states, orbit.p)
        return {"upper": float(0.1 - g.max()), "lower": float(g.min() + 0.1)}

    res = index(-0.04, 1.0, limits=limits)
    assert res.case == "no_cycle_within_limits"
    assert res.h == H_MAX
    assert "limit" in res.message


def test_cases_are_the_documented_ones():
    assert set(CASES) == {"unstable_equilibrium", "unstable_cycle", "no_cycle_within_limits"}
    assert reading(0.0, "unstable_equilibrium").startswith("poor")
    assert reading(0.5, "unstable_cycle").startswith("poor")
    assert reading(12.0, "no_cycle_within_limits").startswith("best")


@pytest.mark.slow
def test_h_and_h_simulation_shrink_towards_subcritical_hopf():
    """Model A at sigma = 4e-4: along omega1 towards the Hopf point from the stable side both
    h (cycle amplitude) and h_simulation (critical disturbance) decrease, and the bracket of
    the simulation reading is valid (just inside returns, just outside collides)."""
    from maglev_match.simulation import initial_state, simulate_maglev

    base = load_params("alpha1")
    hopf = None
    hs, hsims = [], []
    for w in (124.0, 128.0, 130.5):
        p = base.replace(omega1=w)
        res = matching_index(p, simulation_kwargs={"tol": 2e-5})
        assert res.case == "unstable_cycle", res
        hopf = res.hopf_value
        hs.append(res.h)
        hsims.append(res.h_simulation)
        assert res.simulation["status"] == "bracketed"
        if w == 128.0:
            inside = res.simulation["largest_return"]
            outside = res.simulation["smallest_collision"]
            ok = simulate_maglev(p, "unit", initial_state(p, "unit", x5=-inside), 40.0)
            bad = simulate_maglev(p, "unit", initial_state(p, "unit", x5=-outside), 40.0)
            assert ok.outcome == "converged"
            assert bad.outcome == "collision"
    assert hopf is not None and 130.5 < hopf < 133
    assert hs[0] > hs[1] > hs[2] > 0
    assert hsims[0] > hsims[1] > hsims[2] > 0
    # close to the Hopf point the cycle is small (amplitude ~ sqrt(distance))
    assert hs[2] < 0.5 * hs[0]
