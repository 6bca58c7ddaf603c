"""Matching index: the three cases of h on a synthetic Hopf normal form with a known cycle,
the reading (monotone, never more than the simulation supports, the contradiction warned),
and the trend of h and h_simulation approaching a subcritical Hopf point on model A."""

import functools
import math

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_match.analyses.matching import (
    CASES,
    READING_LEVELS,
    index_of_system,
    matching_index,
    reading,
    reading_rank,
    with_simulation,
)
from maglev_match.analyses.simulation import CriticalDisturbance, critical_disturbance_of_system
from maglev_match.core.params import load_params
from maglev_match.dynamics.system import System


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
    from maglev_match.analyses.simulation import initial_state, simulate_maglev

    base = load_params("alpha1")
    hopf = None
    hs, hsims = [], []
    for w in (124.0, 128.0, 130.5):
        p = base.replace(omega1=w)
        res = matching_index(p, simulation_kwargs={"tol": 2e-5})
        assert res.case == "unstable_cycle", res
        hopf = res.hopf_value
        hs.append(res.h)
        hsims.append(res.h_simulation_up)  # x5(0) < 0, the paper's direction
        assert res.simulation["up"]["status"] == "bracketed"
        assert res.h_simulation == min(res.h_simulation_up, res.h_simulation_down)
        assert res.chi == min(res.chi_paper, res.chi_simulation)  # the headline
        if w == 128.0:
            inside = res.simulation["up"]["largest_return"]
            outside = res.simulation["up"]["smallest_collision"]
            ok = simulate_maglev(p, "unit", initial_state(p, "unit", x5=-inside), 40.0)
            bad = simulate_maglev(p, "unit", initial_state(p, "unit", x5=-outside), 40.0)
            assert ok.outcome == "converged"
            assert bad.outcome == "collision"
    assert hopf is not None and 130.5 < hopf < 133
    assert hs[0] > hs[1] > hs[2] > 0
    assert hsims[0] > hsims[1] > hsims[2] > 0
    # close to the Hopf point the cycle is small (amplitude ~ sqrt(distance))
    assert hs[2] < 0.5 * hs[0]


# ---------------------------------------------------------------------------------------
# the reading
# ---------------------------------------------------------------------------------------
@settings(max_examples=300, deadline=None)
@given(st.floats(min_value=0.0, max_value=1e6), st.floats(min_value=0.0, max_value=1e6))
def test_reading_is_monotone_in_the_index(a, b):
    lo, hi = min(a, b), max(a, b)
    assert reading_rank(lo) <= reading_rank(hi)
    # the words depend on the rank only (for a stable equilibrium)
    if reading_rank(lo) == reading_rank(hi):
        assert reading(lo) == reading(hi)


def test_reading_levels_are_ordered():
    """The issue's counterexample: chi 7.64 must not read better than chi 9.56."""
    uppers = [u for u, _ in READING_LEVELS]
    assert uppers == sorted(uppers)
    assert reading_rank(7.64) <= reading_rank(9.56)
    assert reading_rank(0.0) == 0 and reading_rank(math.inf) == len(READING_LEVELS)
    assert reading(float("nan")).startswith("unknown")


def _cd(status, lo, hi, gap_range=0.01, direction=-1):
    crit = None if lo is None or hi is None else 0.5 * (lo + hi)
    return CriticalDisturbance(direction=direction, largest_return=lo, smallest_collision=hi,
                               critical=crit, status=status, gap_range=gap_range, tol=1e-5,
                               runs=16, unresolved=0, unresolved_sizes=(), horizon=20.0,
                               rounds=1, collision_time=None if hi is None else 0.1,
                               nonmonotone=False)


@functools.cache
def _synthetic_index():
    """The paper's index of one synthetic system (computed once: the property tests below
    vary only the readings combined with it)."""
    s = synthetic(-0.04, 1.0)
    return index_of_system(s, s.p, w0=W0, h_max=H_MAX, search=SEARCH)


@settings(max_examples=150, deadline=None)
@given(st.floats(min_value=1e-4, max_value=0.5), st.floats(min_value=1e-4, max_value=0.0099))
def test_reading_uses_the_smaller_index(h_cycle, d_crit):
    """Whatever the two readings, the words follow min(chi, chi_simulation); a
    disagreement beyond the stated factor is a warning."""
    res = _synthetic_index()
    res = res.__class__(**{**{k: getattr(res, k) for k in res.__dataclass_fields__},
                           "chi": h_cycle / W0, "chi_paper": h_cycle / W0, "h": h_cycle})
    out = with_simulation(res, _cd("bracketed", d_crit - 5e-6, d_crit + 5e-6))
    chi_used = min(out.chi_paper, out.chi_simulation)
    assert reading_rank(chi_used) == reading_rank(
        out.chi_paper if out.reading_basis == "paper" else out.chi_simulation)
    assert out.reading == reading(chi_used)
    assert out.chi_paper == h_cycle / W0  # the paper's index is never altered
    assert out.chi == chi_used  # the headline is the index the reading uses
    # the headline's own h over w0 is the headline (h itself stays the paper's)
    assert out.h_headline / W0 == pytest.approx(out.chi, rel=1e-12)
    assert out.h / W0 == pytest.approx(out.chi_paper, rel=1e-12)
    ratio = max(out.chi_paper, out.chi_simulation) / min(out.chi_paper, out.chi_simulation)
    assert any("differ by more than" in w for w in out.warnings) == (ratio > 1.5)


def test_open_simulation_is_a_warning_not_silence():
    res = _synthetic_index()
    out = with_simulation(res, _cd("open", 0.002, 0.004))
    assert out.h_simulation == 0.002  # only what was seen to return is claimed
    assert any("inconclusive" in w for w in out.warnings)
    # nothing seen to return (runs undecided within the horizon): no claim at all
    none = with_simulation(res, _cd("open", None, 0.004))
    # the headline then is the paper's number (and says so); the reading claims nothing
    assert none.h_simulation is None and none.reading_basis == "paper"
    assert none.chi == none.chi_paper and "inconclusive" in none.headline
    assert none.reading.startswith("unknown")
    assert any("inconclusive" in w for w in none.warnings)


def coupled_rhs(x, p):
    """The normal form of :func:`normal_form_rhs` with the stable state x3 driving x1:
    x1' += k x3. The plane x3 = 0 is invariant, so the cycle is the same circle, but an
    initial x3 kicks the gap x1 out by about k x3(0) / 2 before it decays."""
    base = normal_form_rhs(x, p)
    return base.at[0].add(p[2] * x[2])


def test_limit_before_design_point_and_escaping_disturbance_claims_no_robustness():
    """The unstable cycle (radius sqrt(0.2) = 0.45) lies beyond the gap limit 0.1: the branch
    touches the limit before the design point, so the paper's rule gives h = 0.1. But an
    initial x3 inside the disturbance range kicks the gap past its limit: the reading must
    not claim robustness, and a warning names the contradiction."""
    limit = 0.1
    w0 = 0.05

    def limits(system, orbit):
        g = system.observe("gap_deviation", orbit.states, orbit.p)
        return {"upper": float(limit - g.max()), "lower": float(g.min() + limit)}

    def events(x, p):
        return jnp.stack([x[0] + limit, limit - x[0]])

    def run(k):
        s = System(rhs=coupled_rhs, p=np.array([-0.2, 1.0, k]), param_names=("mu", "l", "k"),
                   state_names=("x1", "x2", "x3"), state_scale=np.full(3, 0.01),
                   observables={"gap_deviation": lambda x, p: x[0],
                                "current": lambda x, p: 1.0 + x[1]},
                   name="coupled Hopf normal form")
        res = index_of_system(s, s.p, w0=w0, h_max=limit, search={"mu": (-0.5, 0.5)},
                              limits=limits)
        assert res.case == "no_cycle_within_limits" and res.h == limit
        assert any("touches a limit" in w for w in res.warnings)

        def x0_of(sizes):
            x0 = np.zeros((sizes.size, 3))
            x0[:, 2] = sizes
            return x0

        cd = critical_disturbance_of_system(s, x0_of, limit, events=events,
                                            x_ref=np.zeros(3), t_max=60.0, tol=1e-4)
        return with_simulation(res, cd)

    bad = run(10.0)
    assert bad.simulation["up"]["status"] == "bracketed"
    assert 0 < bad.h_simulation < limit
    assert bad.reading_basis == "simulation"
    assert reading_rank(bad.chi_simulation) < reading_rank(bad.chi_paper)
    assert bad.reading == reading(bad.chi_simulation)
    assert "every disturbance" not in bad.reading
    assert any(w.startswith("contradiction") for w in bad.warnings)
    assert bad.chi_paper == limit / w0  # the paper's index itself is kept
    assert bad.chi == bad.chi_simulation  # and the headline is the smaller
    # control: without the coupling every disturbance returns and nothing is contradicted
    good = run(0.0)
    assert good.simulation["up"]["status"] == "all_return"
    assert good.reading_basis == "paper"
    assert not any(w.startswith("contradiction") for w in good.warnings)


def test_cli_index_kd120_text_and_json_agree(capsys):
    """`index --set kD=120` (the issue's case): the cycle branch touches the limit before
    the design point; the simulation shows collisions inside the gap range. The text names
    the reading's basis and prints every warning of the JSON, and never claims every
    disturbance; the paper's chi is kept as "chi_paper", and the headline "chi" is the
    smaller, chi_simulation."""
    import json

    from maglev_match.cli import main

    assert main(["index", "--set", "kD=120", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["chi_paper"] == pytest.approx(12.051, rel=1e-3)
    assert doc["chi"] == doc["chi_simulation"] < doc["chi_paper"]
    assert doc["case"] == "no_cycle_within_limits"
    assert doc["reading_basis"] == "simulation"
    assert 0 < doc["h_simulation_down"] < doc["h_simulation_up"] < 0.01
    assert doc["h_simulation"] == doc["h_simulation_down"]
    assert "every disturbance" not in doc["reading"]
    assert any("touches a limit" in w for w in doc["warnings"])
    assert any(w.startswith("contradiction") for w in doc["warnings"])
    assert main(["index", "--set", "kD=120"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for w in doc["warnings"]:
        assert " ".join(w.split()) in text
    assert "reading (of the headline chi, from the simulation" in text
    assert text.index(f"chi = {doc['chi']:.4g}") < text.index("chi_paper")


def test_no_simulation_headline_is_the_paper_chi_and_says_so(capsys):
    """`index --no-simulation`: the headline chi is the paper's number, labelled as such in
    the text and in JSON (reading_basis "paper", no mechanisms)."""
    import json

    from maglev_match.cli import main

    assert main(["index", "--no-simulation", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["chi"] == doc["chi_paper"] and doc["chi_simulation"] is None
    assert doc["reading_basis"] == "paper" and doc["mechanism_up"] is None
    assert "the paper's number" in doc["headline"]
    assert main(["index", "--no-simulation"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert f"chi = {doc['chi']:.4g} (headline: the paper's chi" in text
    assert "chi_paper = h / w0" in text and "(the paper's definition)" in text


def test_turnout_soft_headline_is_the_solved_chi_simulation():
    """The shipped default: the headline is chi_simulation, beam down decides, and both
    directions are decided by a grazing contact that was solved (so chi_simulation has a
    derivative)."""
    from maglev_match.core.params import load_preset

    res = matching_index(load_preset("turnout-soft"))
    assert res.reading_basis == "simulation" and res.chi == res.chi_simulation
    assert res.chi_paper == pytest.approx(9.562, rel=1e-3)
    assert res.h_headline == res.h_simulation and res.h_headline / res.w0 == pytest.approx(
        res.chi, rel=1e-12)
    assert res.mechanism_up == res.mechanism_down == "grazing"
    assert res.h_simulation == res.h_simulation_down == res.critical_down.size
    assert res.simulation_derivative
    assert res.simulation["down"]["critical"]["limit"] == "lower"
    # the solved size lies in the bisection's bracket
    lo, hi = res.critical_down.bracket
    assert lo <= res.h_simulation <= hi
    assert "here: simulation" in res.headline


def test_one_headline_in_the_api_the_text_and_the_json(tmp_path, capsys):
    """The headline chi, its basis and its reading are one answer: the API object, the
    text of `index` and the JSON file it writes (issue 31)."""
    import json
    import re

    import maglev_match as mm
    from maglev_match.cli import main

    res = mm.matching_index("turnout-soft")
    assert main(["index", "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    doc = json.loads((tmp_path / "index_unit.json").read_text())
    assert doc["chi"] == res.chi and doc["reading_basis"] == res.reading_basis
    assert doc["reading"] == res.reading and doc["chi_paper"] == res.chi_paper
    m = re.search(r"chi = ([\d.]+) \(headline: .*here: (\w+)\)", text)
    assert m and float(m.group(1)) == pytest.approx(res.chi, abs=5e-4)
    assert m.group(2) == res.reading_basis
    assert f"reading (of the headline chi, from the {res.reading_basis}): {res.reading}" \
        in text
    assert res.h_headline / res.w0 == pytest.approx(res.chi, rel=1e-12)


@pytest.mark.slow
def test_one_headline_in_the_full_and_the_quick_report(tmp_path, capsys):
    """The report states the same headline as the API and `index`: the full report the
    simulated headline (chi, basis, reading), the quick one the paper's chi and says so,
    in its text line, its JSON summary and its HTML (issue 31)."""
    import json

    import maglev_match as mm
    from maglev_match.cli import main

    res = mm.matching_index("turnout-soft")
    quick = mm.matching_index("turnout-soft", simulate=False)
    # the full report through its JSON summary, the quick one through its text (one run each)
    for flag, expect in ((None, res), ("--quick", quick)):
        out = tmp_path / f"r{flag or ''}.html"
        args = ["report", "--no-vehicle", "--out", str(out)] + (["--quick"] if flag else
                                                                 ["--json"])
        assert main(args) == 0
        printed = capsys.readouterr().out
        assert f"chi = {expect.chi:.3f}: {expect.reading}" in out.read_text()
        if flag is None:
            assert json.loads(printed)["headline"] == {
                "chi": expect.chi, "chi_paper": expect.chi_paper, "reading": expect.reading,
                "reading_basis": expect.reading_basis}
        else:
            assert f"chi = {expect.chi:.4g} (the paper's chi: --quick skips the simulation): " \
                f"{expect.reading}" in printed
    assert res.reading_basis == "simulation" and quick.chi == res.chi_paper != res.chi
