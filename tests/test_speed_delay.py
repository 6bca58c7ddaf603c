"""The delayed outer loop at speed (maglev/moving_delay.py, dynamics/delay/clocked.py,
analyses/speed/delay.py): the delay-free sweep unchanged, the delayed moving model against
the standstill delay model, the delayed periodic response's multipliers against finite
differences of its span map, and the critical delay at speed against its low-speed limit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_match import load_preset
from maglev_match.analyses.matching import critical_delay_info
from maglev_match.analyses.speed.delay import (
    critical_delay_at_speed,
    frozen_critical_delay,
    frozen_rate,
)
from maglev_match.analyses.speed.options import SpeedOptions, check_speed_setup
from maglev_match.analyses.speed.point import periodic_response, speed_point
from maglev_match.analyses.speed.sweep import KMH, speed_sweep
from maglev_match.core.params import ParameterError
from maglev_match.dynamics.integrate.passage import (
    finite_difference_jacobian,
    passage_multipliers,
    reduced_factors,
    run_passage,
)
from maglev_match.maglev import moving as mv
from maglev_match.maglev import moving_delay as md

SOFT = load_preset("turnout-soft")
UNIT1 = SOFT.replace(n_modes=1)  # one mode per span: the unit at mid-span is model A
QUICK = SpeedOptions(critical=False)


def test_zero_delay_reproduces_the_sweep_bit_for_bit():
    plain = speed_sweep(UNIT1, "unit", [0.0, 60 * KMH], QUICK)
    zero = speed_sweep(UNIT1.replace(tau=0.0), "unit", [0.0, 60 * KMH], QUICK)
    assert [p.to_json() for p in zero.points] == [p.to_json() for p in plain.points]
    # and the delayed model is a different system: a delay moves the multipliers
    delayed = speed_point(UNIT1.replace(tau=1e-3), "unit", 60 * KMH, QUICK)
    assert delayed.tau == 1e-3 and plain.points[1].tau == 0.0
    assert delayed.largest_multiplier != plain.points[1].largest_multiplier


def test_frozen_at_midspan_the_delayed_unit_is_model_a_with_its_delay():
    # the moving unit at v = 0, centred on one span with one mode, is model A: its critical
    # delay (discretised delay system's rightmost root through 0) is model A's, which the
    # standstill code gets from the characteristic equation (a different method)
    ref = critical_delay_info(UNIT1)["value"]
    mid = frozen_critical_delay(UNIT1, "unit", positions=None)
    assert mid.status == "solved"
    assert mid.value == pytest.approx(ref, rel=1e-6)
    assert mid.multiplier[0] == pytest.approx(0.0, abs=1e-6)  # a root on the axis there
    # at speed 0 the sweep's point is that vehicle standing at mid-span
    st = speed_point(UNIT1.replace(tau=0.99 * ref), "unit", 0.0)
    un = speed_point(UNIT1.replace(tau=1.01 * ref), "unit", 0.0)
    assert st.stable and not un.stable


def test_delayed_multipliers_match_finite_differences_of_the_span_map():
    # near the critical delay at this speed, so that the leading multipliers are the
    # controller's, which the delay moves
    P = UNIT1.replace(tau=1.94e-3)
    sol = periodic_response(P, "unit", 60 * KMH)
    assert sol.converged
    problem = sol.problem
    assert problem.system.dim == problem.system.n_state + problem.system.nodes
    J_fd = finite_difference_jacobian(problem, sol.x0, h=1e-6)
    fd = np.sort(np.abs(np.linalg.eigvals(J_fd)))[::-1][:4]
    run = run_passage(problem, sol.x0)
    mult = passage_multipliers(reduced_factors(problem, run.starts), problem.n)
    an = np.sort(np.abs(mult.values))[::-1][:4]
    np.testing.assert_allclose(an[:2], fd[:2], rtol=1e-5)
    assert an[0] > 0.9  # the controller's multiplier, close to the unit circle
    np.testing.assert_allclose(an[2:], fd[2:], atol=1e-5)
    # the history states do not jump at the hand-over: the commands are the vehicle's
    hist = slice(problem.system.n_state - 1, problem.system.dim - 1)
    np.testing.assert_array_equal(problem.jump[hist, hist], np.eye(hist.stop - hist.start))


def test_delay_the_discretisation_cannot_resolve_is_refused_naming_the_rule():
    top = md.max_delay_at_speed(UNIT1, "unit", 60 * KMH)
    with pytest.raises(ParameterError) as exc:
        check_speed_setup(UNIT1.replace(tau=1.5 * top), "unit", [60 * KMH])
    assert exc.value.field == "tau" and "at 60 km/h" in str(exc.value)
    assert "resolves at most" in str(exc.value)
    check_speed_setup(UNIT1.replace(tau=0.9 * top), "unit", [60 * KMH])
    with pytest.raises(ParameterError, match="force model has no controller"):
        check_speed_setup(UNIT1.replace(tau=1e-3), "force", [60 * KMH])


def test_the_vehicle_takes_the_delay():
    P = SOFT.replace(n_modes=1, tau=1e-3)
    p = mv.moving_param_vector(P, "vehicle", v=30 * KMH)
    system = md.moving_delay_system(P, "vehicle", p, tau=1e-3)
    assert system.dim == system.n_state + 6 * system.nodes
    x = mv.rigid_equilibrium(P, "vehicle")
    X = system.lift(x, md.delayed_vector(p, 1e-3))
    # the commands' constant past at the rigid-guideway equilibrium: the delayed and the
    # delay-free vector fields agree there (the past equals the present)
    f_delay = system.f(X, md.delayed_vector(p, 1e-3))
    f_plain = mv.moving_system(P, "vehicle", p).f(x, p)
    np.testing.assert_allclose(system.current(f_delay), f_plain, atol=1e-12)
    assert math.isfinite(frozen_rate(P, "vehicle", 1e-3, positions=4))


def test_critical_delay_at_speed_is_solved_where_the_multiplier_reaches_one():
    # (120 km/h: a passage half as long as at 60 km/h, so every periodic solve of the
    # search costs about half; the documented commands solve 100 and 120 km/h as well)
    cd = critical_delay_at_speed(UNIT1, "unit", 120 * KMH)
    assert cd.status == "solved"
    assert cd.bracket[0] < cd.value < cd.bracket[1]
    assert math.hypot(*cd.multiplier) == pytest.approx(1.0, abs=1e-7)
    below = periodic_response(UNIT1.replace(tau=0.98 * cd.value), "unit", 120 * KMH)
    above = periodic_response(UNIT1.replace(tau=1.02 * cd.value), "unit", 120 * KMH)
    assert below.multipliers.largest < 1.0 < above.multipliers.largest


def _doc_commands() -> list[list[str]]:
    """The commands of the code block under 'The delayed controller at speed' in
    docs/speed.md."""
    import re
    import shlex
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "speed.md").read_text()
    section = text.split("## The delayed controller at speed", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return [shlex.split(line)[1:] for line in block.splitlines() if line.strip()]


def test_the_documented_commands_run_as_written(tmp_path, monkeypatch, capsys):
    import json

    import xarray as xr

    from maglev_match.cli import main

    monkeypatch.chdir(tmp_path)
    cmds = _doc_commands()
    assert [c[0] for c in cmds] == ["speed", "speed", "map"]
    # the delayed sweep: tau in the text, the CSV and the netCDF
    assert main([*cmds[0], "--out", "delayed"]) == 0
    out = capsys.readouterr().out
    assert "outer-loop delay tau = 1 ms" in out
    csv = (tmp_path / "delayed" / "speed_unit.csv").read_text().splitlines()
    assert csv[0].split(",")[-3:] == ["tau (s)", "tau_c (s)", "tau_c_frozen (s)"]
    assert csv[1].split(",")[-3] == "0.001"
    with xr.open_dataset(tmp_path / "delayed" / "speed_unit.nc") as ds:
        assert ds.attrs["tau"] == 0.001
    # the critical delay at speed, in the JSON
    assert main([*cmds[1], "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    (cd,) = js["critical_delay"]
    assert cd["status"] == "solved" and cd["frozen_limit"] > 0
    # between the mid-span standstill value and the low-speed limit, near the latter
    mid = frozen_critical_delay(UNIT1, "unit", positions=None).value
    assert mid < cd["tau_c"] < cd["frozen_limit"]
    assert cd["tau_c"] == pytest.approx(cd["frozen_limit"], rel=0.05)
    assert js["tau"] == 0.0


def test_the_documented_map_over_speed_and_delay_draws_the_solved_curve(tmp_path,
                                                                       monkeypatch, capsys):
    import xarray as xr

    from maglev_match.cli import main

    monkeypatch.chdir(tmp_path)
    cmd = _doc_commands()[2]
    assert main([*cmd, "--out", "m"]) == 0
    # the solves after the tiles say what they do (not "computing tiles" until the end)
    assert "solving the critical delay tau_c(v)" in capsys.readouterr().err
    with xr.open_dataset(tmp_path / "m" / "map_v_tau.nc") as ds:
        tc = ds["tau_c"].values
        mu = ds["largest_multiplier"].values  # (tau, v)
        taus = ds["tau"].values
        assert np.all(np.isfinite(tc))
        for j in range(tc.size):  # the solved tau_c(v) separates the stable grid points
            for i, t in enumerate(taus):
                assert (mu[i, j] < 1.0) == (t < tc[j])


def test_at_low_speed_the_delayed_growth_follows_the_tracked_frozen_roots():
    """The low-speed limit of the critical delay. For a slowly varying system every
    multiplier follows one frozen root: ln|mu| = T x (that root's mean real part over the
    span) + C + o(1), C independent of T, so the growth between two low speeds (20 and
    30 km/h: slower, the controller's root grows by e^15 and more within one passage near
    mid-span at these delays, and a run from the quasi-static start blows up),
    (ln|mu|(T1) - ln|mu|(T2)) / (T1 - T2), is the largest mean real part of a root branch
    followed along the span (discretised delay system frozen at v = 0). It is not the mean
    of the spectral abscissa: on the unit different roots are rightmost at different
    positions, and the delay where that mean crosses 0 is far from the limit. A wrong delay
    at speed (a second delay model, a history that jumps at the hand-over, a clock out of
    place) breaks the agreement."""
    limit = frozen_critical_delay(UNIT1, "unit")
    abscissa = frozen_critical_delay(UNIT1, "unit", tracked=False)
    mid = frozen_critical_delay(UNIT1, "unit", positions=None)
    assert limit.status == abscissa.status == mid.status == "solved"
    assert mid.value < abscissa.value < 0.9 * limit.value
    for tau in (abscissa.value, limit.value):
        logs, periods = [], []
        for kmh in (20.0, 30.0):
            sol = periodic_response(UNIT1.replace(tau=tau), "unit", kmh * KMH, QUICK,
                                    tau_max=limit.value)
            logs.append(sol.multipliers.log_abs[0])
            periods.append(sol.problem.period)
        growth = (logs[0] - logs[1]) / (periods[0] - periods[1])
        assert growth == pytest.approx(frozen_rate(UNIT1, "unit", tau), abs=0.02)
        if tau == abscissa.value:  # there the abscissa's mean is 0, the growth is not
            assert frozen_rate(UNIT1, "unit", tau, tracked=False) == pytest.approx(0, abs=1e-7)
            assert growth < -0.2
