"""The solved critical disturbance followed from design to design
(analyses/continued.py): along a row and on a small 2-D grid, the continued sizes equal the
point-wise solved ones to 1e-9 m wherever the mechanism does not change; a change of what
decides the size is reported and located between two neighbours; reruns are bit-identical;
the index at a neighbouring design (``near``) equals the point-wise index."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_match.analyses.continued import (
    CriticalStart,
    continue_critical,
    continue_criticals,
    follow_critical,
    follow_grid,
)
from maglev_match.analyses.critical import Mechanism, solve_critical
from maglev_match.core.params import load_preset

TOL = 1e-9  # m: continued against point-wise solved sizes


@pytest.fixture(scope="module")
def soft():
    return load_preset("turnout-soft")


def _pointwise(points, direction):
    return [solve_critical(p, direction) for p in points]


def test_a_row_in_ei_is_continued_and_equals_the_pointwise_solves(soft):
    """Beam down along EI (grazing at gap 0 all along): every point after the first is
    continued (one corrector and two check runs, no bracketing), each equal to the full
    search's solved size to 1e-9 m; the check runs bracket the continued size."""
    pts = [soft.replace(EI=soft.EI * f) for f in (0.98, 0.99, 1.0, 1.01)]
    f = follow_critical(pts, 1)
    assert f.how == ("searched", "continued", "continued", "continued")
    assert not f.changes and not f.fallbacks
    for r, s in zip(f.sizes, _pointwise(pts, 1), strict=True):
        assert r.mechanism == s.mechanism == Mechanism.GRAZING
        assert abs(r.size - s.size) < TOL
        lo, hi = r.bracket
        assert lo < r.size < hi
    assert "continued from a neighbouring design" in f.sizes[-1].reason
    # the sizes move with EI (the continuation is not repeating the first point)
    assert abs(f.sizes[-1].size - f.sizes[0].size) > 1e3 * TOL


def test_a_change_of_mechanism_is_reported_and_located(soft):
    """Beam up along omega1 from 110 to 114 rad/s: the run grazing the upper gap limit
    decides up to 113; at 114 a run just below the continued size collides with the lower
    limit (another contact decides): the fall-back search runs there and the change is
    located between 113 and 114. Where both are solved the sizes agree to 1e-9 m; the
    point-wise search cannot solve 113 (no gap extremum in its window), where the continued
    size lies in its bisection bracket."""
    pts = [soft.replace(omega1=om) for om in (110.0, 111.0, 112.0, 113.0, 114.0)]
    f = follow_critical(pts, -1)
    assert f.how == ("searched", "continued", "continued", "continued", "searched")
    assert len(f.changes) == 1
    ch = f.changes[0]
    assert ch.index == 4 and ch.direction == -1
    assert ch.before == "grazing (upper limit, point 1)" and ch.after != ch.before
    assert "lower gap limit" in ch.reason
    assert [k for k, _ in f.fallbacks] == [4] and f.fallbacks[0][1].reason == ch.reason
    for r, s in zip(f.sizes, _pointwise(pts, -1), strict=True):
        if r.solved and s.solved:
            assert r.mechanism == s.mechanism and abs(r.size - s.size) < TOL
        elif r.solved:
            lo, hi = s.bracket
            assert lo <= r.size <= hi
    assert f.sizes[4].mechanism == solve_critical(pts[4], -1).mechanism


def test_a_small_grid_equals_the_pointwise_solves_and_reruns_are_identical(soft):
    """A 2 x 3 grid (kD across, EI up): each row's first point continued from the row
    below, the rest along the row; all equal to the point-wise solves to 1e-9 m; a second
    run gives the same bits."""
    grid = [[soft.replace(EI=soft.EI * fy, kD=soft.kD * fx) for fx in (0.99, 1.0, 1.01)]
            for fy in (0.995, 1.005)]
    rows = follow_grid(grid, 1)
    assert rows[0].how[0] == "searched" and rows[1].how == ("continued",) * 3
    for row, f in zip(grid, rows, strict=True):
        assert not f.changes
        for r, s in zip(f.sizes, _pointwise(row, 1), strict=True):
            assert r.mechanism == s.mechanism == Mechanism.GRAZING
            assert abs(r.size - s.size) < TOL
    again = follow_grid(grid, 1)
    assert [[r.size for r in f.sizes] for f in again] == [[r.size for r in f.sizes]
                                                         for f in rows]
    assert [f.how for f in again] == [f.how for f in rows]


def test_the_predictor_uses_the_derivative(soft):
    """From a solved size with dsize/dp, the prediction at the next design is the first
    order Taylor step (closer to the solved size there than the neighbour's size)."""
    a, b = soft, soft.replace(EI=soft.EI * 1.02)
    sa = solve_critical(a, 1, derivative=True)
    start = CriticalStart.of(a, sa)
    res, check, why = continue_critical(b, start)
    assert why is None and check.runs == 2 and check.status == "bracketed"
    predicted = float(res.reason.split("predicted ")[1].split(" mm")[0]) * 1e-3
    assert abs(predicted - res.size) < 0.1 * abs(sa.size - res.size)


def test_both_directions_batched_equal_each_continued_alone(soft):
    """``continue_criticals`` runs the two directions' correctors as one batched Newton and
    their four check runs as one batch: each size equals the one continued alone (the
    batch changes at most the last bits), with the same check outcome."""
    a, b = soft, soft.replace(EI=soft.EI * 1.01)
    starts = [CriticalStart.of(a, solve_critical(a, d)) for d in (-1, 1)]
    both = continue_criticals(b, starts)
    for start, (res, check, why) in zip(starts, both, strict=True):
        alone, check1, why1 = continue_critical(b, start)
        assert why is None and why1 is None
        assert res.direction == start.critical.direction
        assert res.size == pytest.approx(alone.size, rel=1e-12, abs=0)
        assert abs(res.size - start.critical.size) > 1e3 * TOL  # it moved with EI
        assert (check.largest_return, check.smallest_collision) == pytest.approx(
            (check1.largest_return, check1.smallest_collision), rel=1e-12, abs=0)


def test_the_index_at_a_neighbouring_design_equals_the_pointwise_index(soft):
    """``matching_index(..., near=previous)``: the critical sizes continued, the index equal
    to the point-wise one (h_simulation to 1e-9 m); where the neighbour's mechanism does not
    hold (omega1 112 -> 114 beam up) the full search runs and the result says why."""
    from maglev_match.api import matching_index

    first = matching_index(soft)
    nxt = soft.replace(EI=soft.EI * 1.005)
    r = matching_index(nxt, near=first)
    full = matching_index(nxt)
    assert r.simulation["up"]["continuation"] == {"continued": True}
    assert r.simulation["down"]["continuation"] == {"continued": True}
    for k in ("h_simulation_up", "h_simulation_down"):
        assert abs(getattr(r, k) - getattr(full, k)) < TOL
    assert r.chi == pytest.approx(full.chi, rel=1e-9, abs=0)
    assert r.reading_basis == full.reading_basis and r.reading == full.reading
    a = matching_index(soft.replace(omega1=112.0))
    b = matching_index(soft.replace(omega1=114.0), near=a)
    up = b.simulation["up"]["continuation"]
    assert up["continued"] is False and "lower gap limit" in up["reason"]
    assert b.simulation["down"]["continuation"] == {"continued": True}
    assert b.h_simulation_up == matching_index(soft.replace(omega1=114.0)).h_simulation_up


def test_a_chain_of_neighbouring_indices_predicts_by_the_secant(soft):
    """Along a chain of indices (each ``near=`` the one before), a size continued from a
    neighbour remembers that neighbour, and the next index predicts by the secant through
    the two (the continued size has no derivative): its prediction is closer than the
    neighbour's size, its Newton needs no more steps in either direction (one fewer where
    the size moves most), and the sizes equal the ones continued from the neighbour alone
    to 1e-12 relative."""
    from dataclasses import replace

    from maglev_match.api import matching_index

    d0, d1, d2 = (soft.replace(EI=soft.EI * f) for f in (1.0, 1.01, 1.02))
    r1 = matching_index(d1, near=matching_index(d0))
    r2 = matching_index(d2, near=r1)
    # the same step from r1 with its memory of r0 removed: the neighbour's size as start
    plain = replace(r1, critical_up=replace(r1.critical_up, previous=None),
                    critical_down=replace(r1.critical_down, previous=None))
    r2_plain = matching_index(d2, near=plain)
    fewer = 0
    for k in ("critical_up", "critical_down"):
        c, c_plain, c1 = getattr(r2, k), getattr(r2_plain, k), getattr(r1, k)
        assert c.previous is not None and c.previous[1] == c1.size
        assert c.size == pytest.approx(c_plain.size, rel=1e-12, abs=0)
        predicted = float(c.reason.split("predicted ")[1].split(" mm")[0]) * 1e-3
        assert abs(predicted - c.size) < 0.1 * abs(c1.size - c.size)
        assert c.iterations <= c_plain.iterations
        fewer += c.iterations < c_plain.iterations
    assert fewer >= 1


@pytest.mark.slow
def test_a_basin_boundary_is_continued(soft):
    """Beam up near the Hopf point (omega1 117 -> 118): the saddle cycle of the clamped
    system corrected by collocation from the neighbour's, the landing on its stable
    manifold solved again; equal to the point-wise basin-boundary solves to 1e-9 m."""
    pts = [soft.replace(omega1=om) for om in (117.0, 117.5, 118.0)]
    f = follow_critical(pts, -1)
    assert f.how == ("searched", "continued", "continued") and not f.changes
    for r, s in zip(f.sizes, _pointwise(pts, -1), strict=True):
        assert r.mechanism == s.mechanism == Mechanism.BASIN_BOUNDARY
        assert abs(r.size - s.size) < TOL
        assert np.sum(np.abs(r.orbit.multipliers) > 1 + 1e-6) == 1


def test_the_papers_cycle_at_a_neighbouring_design_is_continued_not_searched(soft,
                                                                              monkeypatch):
    """``near``: the paper's bounding cycle corrected by collocation Newton at the new
    parameters from the neighbour's (no Hopf search, no branch from the Hopf point: the
    search is switched off here), equal to the point-wise index's h to 1e-7 relative (the
    point-wise branch ends on another adapted mesh) along three steps of EI; beyond the
    stretch rules (a 10 % step) the full search runs and gives the point-wise index."""
    import maglev_match.analyses.matching as matching
    from maglev_match.analyses.continued import CYCLE_STEP, continue_cycle

    designs = [soft.replace(EI=soft.EI * (1 + 2e-3 * k)) for k in range(4)]
    full = [matching.matching_index(d, simulate=False) for d in designs]
    assert all(f.case == "unstable_cycle" for f in full)
    real = matching.index_of_system

    def no_search(*a, **k):
        raise AssertionError("the neighbouring design searched its cycle again")

    monkeypatch.setattr(matching, "index_of_system", no_search)
    prev = full[0]
    for d, f in zip(designs[1:], full[1:], strict=True):
        r = matching.matching_index(d, simulate=False, near=prev)
        assert r.case == f.case and r.stable == f.stable
        assert r.h == pytest.approx(f.h, rel=1e-7, abs=0)
        assert r.cycle_unstable_multipliers == f.cycle_unstable_multipliers
        assert r.cycle_period == pytest.approx(f.cycle_period, rel=1e-7)
        assert r.current_reverses == f.current_reverses
        prev = r
    # beyond the stretch rules: the full search, the point-wise index itself
    monkeypatch.setattr(matching, "index_of_system", real)
    far = soft.replace(EI=soft.EI * (1 + 4 * CYCLE_STEP))  # omega1 moves ~ 2 CYCLE_STEP
    why = continue_cycle(matching.maglev_model(far).system(),
                         matching.maglev_model(far).system().p, full[0].cycle,
                         full[0].hopf_param, full[0].hopf_value, np.zeros(9))
    assert isinstance(why, str) and "moved by" in why
    r = matching.matching_index(far, simulate=False, near=full[0])
    assert r == matching.matching_index(far, simulate=False)
