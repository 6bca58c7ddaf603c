"""The matching index at speed chi(v) (maglev_match.analyses.speed.index): the standstill
headline index recovered at 1 km/h, the disturbance it applies, the bracket confirmed by
single runs, a margin (not the search's ceiling) on the turnout beams, a direction where
every jump up to the gap range returns reported as such, and the wiring into the speed
point and its JSON."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_match import load_preset
from maglev_match.analyses.speed.grid import KMH
from maglev_match.analyses.speed.index import (
    SpeedIndex,
    check_positions,
    index_at_speed,
    position_time,
)
from maglev_match.analyses.speed.options import SpeedOptions
from maglev_match.analyses.speed.passage import passage_problem, passage_states
from maglev_match.analyses.speed.point import SpeedPoint, periodic_response, speed_point
from maglev_match.core.params import ParameterError
from maglev_match.maglev import moving as mv

SOFT = load_preset("turnout-soft")
UNIT1 = SOFT.replace(n_modes=1)  # model A's beam: one mode per span
NO_CRIT = SpeedOptions(critical=False)


def _mean_mode1(p) -> float:
    """The mean of sin(pi x / L) under the unit's footprint l centred on the span."""
    L, length = p.L, p.l
    return 2.0 * L * math.sin(math.pi * length / (2.0 * L)) / (math.pi * length)


@pytest.mark.slow
def test_index_at_1_kmh_is_the_standstill_headline_index():
    """As v -> 0 with one mode per span, the jump of the mean deflection under the vehicle
    at mid-span is model A's disturbance x5(0) = +-d (every other state at the equilibrium):
    chi(v) at 1 km/h equals the standstill headline index (here decided by the simulated
    critical disturbance, beam down) within the search tolerance, both directions agree
    with the standstill search, and mid-span decides against the quarter point (the
    three-quarter point mirrors it as v -> 0)."""
    from maglev_match.analyses.matching import matching_index

    st = matching_index(UNIT1, model="unit")
    assert st.reading_basis == "simulation"
    v = 1.0 * KMH
    opts = SpeedOptions()
    ix = index_at_speed(UNIT1, "unit", v, periodic_response(UNIT1, "unit", v, NO_CRIT), opts,
                        positions=(0.25, 0.5))
    tol = opts.critical_tol + 1e-5  # at speed + standstill bracket widths (m)
    assert ix.w0 == pytest.approx(st.w0, rel=1e-12)
    assert ix.h == pytest.approx(st.h_headline, abs=tol)
    assert ix.chi == pytest.approx(st.chi, abs=tol / st.w0)
    mid = next(q for q in ix.positions if q.fraction == 0.5)
    # both are the same grazing contact, solved: far inside the search tolerance
    assert mid.down.status == "solved" and st.mechanism_down == "grazing"
    assert mid.down.size == pytest.approx(st.h_simulation_down, abs=1e-7)
    assert mid.down.size == pytest.approx(st.h_simulation_down, abs=tol)
    assert mid.up.size == pytest.approx(st.h_simulation_up, abs=tol)
    assert mid.down.limit == "lower" and mid.up.limit == "upper"
    assert ix.fraction == 0.5 and ix.direction == +1
    # the gap ranges are the standstill ones (the gap sits at c0 at 1 km/h up to ~1e-7 m)
    assert mid.down.gap_range == pytest.approx(UNIT1.c0 - UNIT1.gap_min, abs=1e-6)
    assert mid.up.gap_range == pytest.approx(UNIT1.gap_max - UNIT1.c0, abs=1e-6)


def test_disturbance_is_a_jump_of_the_mean_deflection_in_the_first_mode():
    """At mid-span the displaced span's first mode has the closed-form mean under the
    footprint, 2 L sin(pi l / 2L) / (pi l); the centre sits at the asked fraction of the
    span; bad positions are refused naming the field."""
    v = 60 * KMH
    sol = periodic_response(UNIT1, "unit", v, NO_CRIT)
    ix = index_at_speed(UNIT1, "unit", v, sol, SpeedOptions(critical_sizes=4,
                                                              critical_rounds=1),
                        positions=(0.5,))
    assert ix.positions[0].shape == pytest.approx(_mean_mode1(UNIT1), rel=1e-12)
    for f in (0.1, 0.25, 0.5, 0.75, 0.9):
        t, slot = position_time(UNIT1, "unit", v, f)
        assert 0 <= t <= UNIT1.L / v
        centre = UNIT1.L + v * t - 0.5 * UNIT1.l  # from slot A's left support
        assert centre - (UNIT1.L if slot == "B" else 0.0) == pytest.approx(f * UNIT1.L)
    for bad in ((), (1.0,), (-0.1,), (float("nan"),)):
        with pytest.raises(ParameterError, match="positions"):
            check_positions(bad)


def test_solved_size_separates_return_from_collision_in_single_runs():
    """At 60 km/h, mid-span, beam down: a single run (not the batch) from the periodic
    state with the first mode of the span under the vehicle raised by the closed-form
    amount collides just above the solved size and not just below it."""
    from maglev_match.dynamics.integrate.simulate import (
        EventsWithArgs,
        SimulationOptions,
        simulate,
    )

    p = UNIT1
    v = 60 * KMH
    sol = periodic_response(p, "unit", v, NO_CRIT)
    ix = index_at_speed(p, "unit", v, sol, SpeedOptions(), positions=(0.5,))
    c = ix.positions[0].down
    assert c.status == "solved" and c.largest_return < c.size < c.smallest_collision
    t_pos, slot = position_time(p, "unit", v, 0.5)
    assert slot == "B"
    x = passage_states(sol.problem, sol.run.starts, np.array([t_pos]))[0]
    limited = passage_problem(p, "unit", v, limited=True)
    k = int(np.searchsorted(limited.starts, t_pos, side="right") - 1)
    rest = limited.starts[k] + limited.segments[k].duration - t_pos
    assert c.collision_time < rest  # the contact comes before the next support crossing
    events = EventsWithArgs(mv.gap_events("unit", 1), (p.gap_min, p.gap_max))
    iq = mv.slot_slices("unit", 1)["qB"].start
    sim = SimulationOptions(rtol=1e-10, atol=1e-10, max_steps=1_000_000)
    out = {}
    for factor in (1 - 1e-4, 1 + 1e-4):
        x0 = x.copy()
        x0[iq] += factor * c.size / _mean_mode1(p)
        out[factor] = simulate(limited.system, x0, rest, p=limited.segments[k].p,
                               event_fn=events, x_ref=x, options=sim, n_save=2).outcome
    assert out[1 - 1e-4] != "collision" and out[1 + 1e-4] == "collision"


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["turnout-soft", "turnout-stiff"])
def test_index_is_a_margin_not_the_ceiling_on_the_turnout_beams(preset):
    """Three modes per span at 60 km/h: chi(v) is a measured margin (solved or bracketed)
    well inside the gap range, never the search's ceiling, in the deciding direction at
    the deciding position."""
    p = load_preset(preset)
    v = 60 * KMH
    ix = index_at_speed(p, "unit", v, periodic_response(p, "unit", v, NO_CRIT))
    assert not ix.every_size_returned
    q = next(q for q in ix.positions if q.fraction == ix.fraction)
    c = q.deciding
    assert c.status in ("solved", "bracketed")
    assert c.smallest_collision is not None and c.size < 0.8 * c.gap_range
    assert ix.chi == pytest.approx(ix.h / p.w0)
    assert 2.0 < ix.chi < 8.0


def test_every_size_up_to_the_gap_range_returning_is_reported_as_such():
    """A beam damped at 0.7 of critical does not overshoot: with the upper gap limit
    0.5 mm above c0 every beam-up jump up to the whole range returns. The direction says
    'all_return', its largest run lies within half a tolerance of the range, and h is the
    range (it decides: beam down collides at over 1 mm)."""
    p = UNIT1.replace(xi1=0.7, gap_max=UNIT1.c0 + 0.5e-3)
    v = 60 * KMH
    opts = SpeedOptions()
    ix = index_at_speed(p, "unit", v, periodic_response(p, "unit", v, NO_CRIT), opts,
                        positions=(0.5,))
    up = ix.positions[0].up
    assert up.status == "all_return" and up.smallest_collision is None
    assert up.largest_return >= up.gap_range - 0.5 * opts.critical_tol - 1e-15
    assert ix.direction == -1 and ix.every_size_returned
    assert ix.h == up.gap_range == up.size


def test_speed_point_carries_the_index_and_the_entry_readout():
    """speed_point: h and chi are the index at speed, the entry disturbance is the second
    read-out (h_entry, chi_entry), and all of it survives the JSON of the checkpoint
    tiles."""
    v = 120 * KMH
    pt = speed_point(UNIT1, "unit", v, SpeedOptions(critical_sizes=4, critical_rounds=2))
    assert isinstance(pt.index, SpeedIndex)
    assert pt.h == pt.index.h and pt.chi == pt.index.chi
    assert pt.h == min(q.h for q in pt.index.positions)
    assert np.isfinite(pt.h_entry) and pt.chi_entry == pytest.approx(pt.h_entry / pt.w0)
    again = SpeedPoint.from_json(pt.to_json())
    assert again.index == pt.index and again.chi == pt.chi
    assert again.every_size_returned == pt.every_size_returned


@pytest.mark.slow
def test_speed_command_prints_chi_v_next_to_the_standstill_headline(tmp_path):
    """`speed` with chi(v): the text gives the standstill headline, chi(v) with the position
    and direction deciding it and every direction's outcome; the netCDF file (its JSON
    attributes too) carries the same numbers."""
    import contextlib
    import io
    import json

    import xarray as xr

    from maglev_match.cli import main

    def run(argv):
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
        return code, out.getvalue(), err.getvalue()

    args = ["speed", "--from", "120", "--to", "120", "--step", "5", "--set", "n_modes=1",
            "--workers", "0", "--out", str(tmp_path)]
    code, out, err = run(args)
    assert code == 0, err
    with xr.open_dataset(tmp_path / "speed_unit.nc") as ds:
        chi = float(ds["chi"].values[0])
        frac = float(ds["index_fraction"].values[0])
        direction = int(ds["index_direction"].values[0])
        st = float(ds.attrs["chi_standstill"])
        assert int(ds["every_size_returned"].values[0]) == 0
        assert ds["chi"].attrs["units"] == "1" and ds["h_entry"].attrs["units"] == "m"
        pts = json.loads(ds.attrs["points"])
        standstill = ds.attrs["standstill"]
    assert (tmp_path / "speed_unit.png").stat().st_size > 0
    import csv

    with open(tmp_path / "speed_unit.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 1 and float(rows[0]["chi"]) == pytest.approx(chi, rel=1e-12)
    assert float(rows[0]["index_fraction"]) == frac
    assert rows[0]["status_down"] in ("solved", "bracketed")
    assert f"standstill headline index chi = {st:.3f}" in out
    side = "beam down" if direction > 0 else "beam up"
    assert (f"smallest chi(v) {chi:.3f} at 120 km/h" in out
            and f"vehicle's centre at {frac:g} L, {side}" in out)
    assert "centre at 0.5 L, beam up:" in out and ">=" not in out
    assert pts[0]["index"]["h"] == pytest.approx(chi * pts[0]["w0"], rel=1e-12)
    assert json.loads(standstill)["chi"] == pytest.approx(st, rel=1e-12)
