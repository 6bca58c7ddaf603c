"""Periodic orbits: collocation, continuation from Hopf points, Floquet multipliers, folds
of cycles, limit contacts; model A cross-checked against shooting and long simulation."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
from systems import CYCLE_OMEGA, FOLD_NF, HOPF_NF, LINEAR_PART, Q5, Q_CRIT

from maglev_match.dynamics.cycles import (
    adapt_mesh,
    correct_cycle,
    cycle_branch,
    floquet_multipliers,
    hopf_start,
)

OMEGA = CYCLE_OMEGA
_Q = Q5


def _start(system, l1):
    p = system.params_with(mu=0.0, l1=l1)
    return hopf_start(system, np.zeros(5), p, "mu", OMEGA, Q_CRIT, l1)


@pytest.mark.parametrize("l1", [-1.0, 1.0])
def test_hopf_normal_form_amplitude_period_multipliers(l1):
    stop = -0.5 * l1  # the side where cycles exist: mu / l1 < 0
    br = cycle_branch(HOPF_NF, _start(HOPF_NF, l1), "mu", stop_at=stop, ntst=20, ncol=4,
                      max_steps=200)
    assert br.stopped_reason == "reached stop_at"
    assert br.points[-1].kind == "stop_at"
    assert br.points[-1].value == pytest.approx(stop, abs=1e-12)
    lin = np.linalg.eigvals(LINEAR_PART)
    for c in br.points:
        radius = math.sqrt(-c.value / l1)
        assert c.max("radius") == pytest.approx(radius, rel=1e-6)
        assert c.min("radius") == pytest.approx(radius, rel=1e-6)
        assert c.period == pytest.approx(2 * math.pi / OMEGA, rel=1e-6)
        expected = np.concatenate([[math.exp(-2 * c.value * c.period)],
                                   np.exp(lin * c.period)])
        got = np.array(c.multipliers)
        for mu in expected:  # each expected multiplier is matched by one computed
            assert np.min(np.abs(got - mu)) < 1e-7 * max(1.0, abs(mu))
        assert abs(c.trivial_multiplier - 1.0) < 1e-8
        if abs(c.value) > 1e-3:
            assert c.stable == (l1 < 0)
            assert c.n_unstable == (0 if l1 < 0 else 1)
    assert len(br.points) > 5


def test_fold_of_cycles_located():
    # r' = r (mu + 2 r^2 - r^4): unstable cycles from mu = 0 fold at mu = -1, r = 1
    def limits(system, orbit):  # stop on the outer branch at radius 1.3
        r = np.sqrt(np.sum((orbit.states @ _Q)[:, :2] ** 2, axis=1))
        return {"radius 1.3": 1.3 - float(np.max(r))}

    br = cycle_branch(FOLD_NF, _start(FOLD_NF, 2.0), "mu", ntst=20, ncol=4,
                      max_steps=300, ds_max=0.5, limits=limits)
    lpc = [s for s in br.special_points if s.type == "LPC"]
    assert len(lpc) == 1
    assert lpc[0].value == pytest.approx(-1.0, abs=1e-7)
    assert lpc[0].extrema["radius"][0] == pytest.approx(1.0, abs=1e-4)
    assert lpc[0].located == "solved"
    # before the fold one unstable multiplier, after it none (the outer, stable cycle)
    before = [c for c in br.points if c.max("radius") < 0.9]
    after = [c for c in br.points if c.max("radius") > 1.1]
    assert before and after
    assert all(c.n_unstable == 1 for c in before)
    assert all(c.stable for c in after)
    # the outer cycle reaches radius 1.3 where mu = r^4 - 2 r^2
    assert br.stopped_reason == "contact with a physical limit"
    assert br.points[-1].value == pytest.approx(1.3**4 - 2 * 1.3**2, rel=1e-7)


def test_branch_stops_at_first_limit_contact():
    def limits(system, orbit):
        r = np.sqrt(np.sum((orbit.states @ _Q)[:, :2] ** 2, axis=1))
        return {"radius 0.5": 0.5 - float(np.max(r))}

    br = cycle_branch(HOPF_NF, _start(HOPF_NF, -1.0), "mu", ntst=20, ncol=4,
                      max_steps=200, limits=limits)
    assert br.stopped_reason == "contact with a physical limit"
    lim = [s for s in br.special_points if s.type == "contact"]
    assert len(lim) == 1 and lim[0].detail == "radius 0.5"
    assert lim[0].value == pytest.approx(0.25, rel=1e-7)
    assert br.points[-1].kind == "contact"
    assert all(c.value <= 0.25 + 1e-9 for c in br.points)  # never stepped past it


def test_failed_branch_keeps_its_points():
    br = cycle_branch(HOPF_NF, _start(HOPF_NF, -1.0), "mu", ntst=10, ncol=3, max_steps=4)
    assert br.stopped_reason == "max_steps"
    assert len(br.points) == 4 and all(br.converged)


def test_mesh_adaptation_concentrates_points_at_a_sharp_pulse():
    m, ntst = 4, 40
    mesh = np.linspace(0, 1, ntst + 1)
    t = np.linspace(0, 1, ntst * m + 1)
    U = np.exp(-(((t - 0.5) / 0.03) ** 2))[:, None]
    new = adapt_mesh(mesh, m, U, np.ones(1))
    h = np.diff(new)
    assert new[0] == 0 and new[-1] == 1 and np.all(h > 0)
    centre = h[np.searchsorted(new, 0.5) - 1]
    assert centre < 0.5 * np.max(h)


def test_correct_cycle_and_floquet_recomputation():
    br = cycle_branch(HOPF_NF, _start(HOPF_NF, -1.0), "mu", stop_at=0.3, ntst=16, ncol=5,
                      max_steps=100)
    orbit = br.points[-1].orbit
    res = correct_cycle(HOPF_NF, orbit, "mu", 0.32)
    assert res.converged
    assert res.point.max("radius") == pytest.approx(math.sqrt(0.32), rel=1e-6)
    mult = floquet_multipliers(HOPF_NF, res.point.orbit)
    assert np.min(np.abs(mult - math.exp(-2 * 0.32 * math.pi))) < 1e-7


# --------------------------------------------------------------------------- model A
@pytest.fixture(scope="module")
def model_a():
    from maglev_match.core.params import load_preset
    from maglev_match.maglev.models import build_system

    return build_system(load_preset("alpha1").replace(sigma=4e-4), "unit")


def _hopf_by_eigenvalues(system, param, a, b):
    """Hopf point from a sign change of the largest real part (an independent route to
    the start data, not using dynamics.hopf)."""
    import scipy.optimize

    def mrp(v):
        return np.max(np.linalg.eigvals(system.jacobian(np.zeros(system.dim),
                                                        system.params_with(**{param: v}))).real)

    v = scipy.optimize.brentq(mrp, a, b, xtol=1e-12)
    p = system.params_with(**{param: v})
    w, V = np.linalg.eig(system.jacobian(np.zeros(system.dim), p))
    k = int(np.argmax(np.where(w.imag > 0, -np.abs(w.real), -np.inf)))
    q = V[:, k] / np.linalg.norm(V[:, k])
    return hopf_start(system, np.zeros(system.dim), p, param, float(w[k].imag), q)


@pytest.mark.slow
def test_model_a_unstable_cycle_matches_shooting(model_a):
    from maglev_match.dynamics.shooting import shoot_periodic_orbit, trajectory_extrema

    hs = _hopf_by_eigenvalues(model_a, "omega1", 110.0, 140.0)
    br = cycle_branch(model_a, hs, "omega1", stop_at=127.0, ntst=80, ncol=4, max_steps=200)
    c = br.points[-1]
    assert br.stopped_reason == "reached stop_at" and c.value == pytest.approx(127.0)
    assert c.value < hs.value and not c.stable  # subcritical: unstable cycle below Hopf
    x0 = c.orbit.states[0]
    guess = x0 + 1e-3 * (x0 - np.zeros(9))
    sh = shoot_periodic_orbit(model_a, guess, c.period * (1 + 1e-4), c.orbit.p)
    assert sh.converged, sh.message
    assert sh.period == pytest.approx(c.period, rel=1e-6)
    ext = trajectory_extrema(model_a, sh.x0, sh.period, sh.p, ["gap_deviation"])
    assert ext["gap_deviation"][0] == pytest.approx(c.max("gap_deviation"), rel=1e-6)
    assert ext["gap_deviation"][1] == pytest.approx(c.min("gap_deviation"), rel=1e-6)
    # the number of unstable multipliers agrees
    mult = sh.multipliers[np.argsort(np.abs(sh.multipliers - 1))[1:]]
    assert int(np.sum(np.abs(mult) > 1 + 1e-6)) == c.n_unstable


@pytest.mark.slow
def test_model_a_stable_cycle_matches_long_simulation(model_a):
    hs = _hopf_by_eigenvalues(model_a, "omega1", 250.0, 320.0)
    br = cycle_branch(model_a, hs, "omega1", stop_at=290.0, ntst=60, ncol=4, max_steps=200)
    c = br.points[-1]
    assert br.stopped_reason == "reached stop_at" and c.stable
    # start ON the cycle and integrate 200 periods: the state must come back to the start
    # (period and orbit right) and the last period must have the collocation amplitude
    x0 = c.orbit.states[0]
    f = model_a.derivatives.f
    pj = jnp.asarray(c.orbit.p)
    t_end = 200 * c.period
    sol = scipy.integrate.solve_ivp(
        lambda t, y: np.asarray(f(y, pj)), (0.0, t_end), x0, method="DOP853", rtol=1e-11,
        atol=model_a.state_scale * 1e-13, dense_output=True)
    assert sol.success
    t = np.linspace(t_end - c.period, t_end, 20001)
    gap = model_a.observe("gap_deviation", sol.sol(t).T, c.orbit.p)
    assert np.max(gap) == pytest.approx(c.max("gap_deviation"), rel=1e-6)
    assert np.min(gap) == pytest.approx(c.min("gap_deviation"), rel=1e-6)
    back = (sol.sol(t_end) - x0) / model_a.state_scale
    assert np.max(np.abs(back)) < 1e-5 * np.max(np.abs(x0 / model_a.state_scale))


# --------------------------------------------------------------------------- CLI
def _run(capsys, *args):
    from maglev_match.cli import main

    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.slow
def test_cli_cycles_json_shape(capsys, tmp_path):
    import json

    code, out, _ = _run(capsys, "cycles", "--param", "sigma", "--at", "omega1=100",
                        "--preset", "alpha1", "--from", "5e-4", "--to", "2e-3",
                        "--scan", "15", "--ntst", "30", "--json", "--out", str(tmp_path))
    assert code == 0
    doc = json.loads(out)
    assert set(doc["hopf"]) >= {"sigma", "l1"}
    assert 5e-4 < doc["hopf"]["sigma"] < 2e-3
    assert doc["branch"]
    for row in doc["branch"]:
        assert set(row) >= {"sigma", "period", "gap_dev_max", "gap_dev_min", "current_min",
                            "stable", "stability", "unstable_multipliers"}
        assert row["gap_dev_max"] >= row["gap_dev_min"]
        if row["stability_reliable"]:
            assert row["stable"] == (row["stability"] == "stable")
            assert (row["stability"] == "unstable") == (row["unstable_multipliers"] > 0)
        else:
            assert row["stability"] == "unknown"
    types = {s["type"] for s in doc["special_points"]}
    assert types <= {"LPC", "PD", "NS", "BP", "H", "contact"}
    labels = [s["label"] for s in doc["special_points"]]
    assert len(set(labels)) == len(labels) and all(labels)
    assert all(s["located"] == "solved" or s["located"].startswith(("bracketed", "not "))
               for s in doc["special_points"])
    assert all(isinstance(r["stability_reliable"], bool) for r in doc["branch"])
    if doc["stopped_reason"] == "contact with a physical limit":
        lim = [s for s in doc["special_points"] if s["type"] == "contact"][0]
        last = doc["branch"][-1]
        assert lim["sigma"] == pytest.approx(last["sigma"])
        # at the contact some limit is reached: gap 0, 18 mm or current 0
        assert min(last["gap_dev_min"] + 0.008, 0.010 - last["gap_dev_max"],
                   last["current_min"] / 26.68) == pytest.approx(0.0, abs=1e-6)
    assert (tmp_path / "cycles_unit_sigma.png").exists()
    # SI values, each header with its unit
    assert (tmp_path / "cycles_unit_sigma.csv").read_text().startswith(
        "branch,hopf,sigma (1/kg),period (s),gap_dev_max (m),gap_dev_min (m),current_min (A)")
    # the full branch as netCDF, and a restart from its third point
    import xarray as xr

    nc = tmp_path / "cycles_unit_sigma.nc"
    saved = xr.load_dataset(nc, engine="h5netcdf")
    np.testing.assert_allclose(saved["value"].values, [r["sigma"] for r in doc["branch"]])
    assert saved["period"].attrs["units"] == "s" and saved["value"].attrs["units"] == "1/kg"
    # (a restart searches no Hopf point: --from/--to/--scan are refused there)
    code, out, _ = _run(capsys, "cycles", "--param", "sigma", "--at", "omega1=100",
                        "--preset", "alpha1", "--ntst", "30", "--json", "--restart", str(nc),
                        "--label", "P2", "--max-steps", "2")
    assert code == 0
    again = json.loads(out)
    assert [r["sigma"] for r in again["branch"]] == pytest.approx(
        [r["sigma"] for r in doc["branch"][3:5]], rel=1e-8)
    code, _, err = _run(capsys, "cycles", "--param", "sigma", "--at", "omega1=100",
                        "--preset", "alpha1", "--restart", str(nc), "--label", "Q7")
    assert code == 2 and "--label Q7" in err


def test_cli_cycles_user_errors(capsys):
    code, _, err = _run(capsys, "cycles", "--ncol", "9")
    assert code == 2 and "ncol" in err
    code, _, err = _run(capsys, "cycles", "--at", "sigma")
    assert code == 2 and "NAME=VALUE" in err


# ------------------------------------------------- special points from test functions
def test_period_doubling_located_exactly_with_closed_form_multipliers():
    from systems import PD_NU, pd_multipliers, pd_system

    from maglev_match.dynamics.hopf import locate_hopf_points

    system = pd_system()
    hp = locate_hopf_points(system, "nu", -0.2, 0.3, n_scan=10).points[0]
    assert abs(hp.value) < 1e-12
    br = cycle_branch(system, hp, "nu", stop_at=0.4, ntst=20, ncol=4, max_steps=100,
                      lam_scale=0.05)
    assert br.stopped_reason == "reached stop_at"
    assert [s.type for s in br.special_points] == ["PD"]
    pd = br.special_points[0]
    assert pd.located == "solved" and pd.label == "PD1"
    assert pd.value == pytest.approx(PD_NU, abs=1e-6)
    assert abs(np.min(np.abs(np.asarray(pd.point.multipliers) + 1.0))) < 1e-6
    # the PD lies inside its step, between the points around it
    assert br.points[pd.step].value < pd.value < br.points[pd.step + 1].value
    for c in br.points:
        expected = pd_multipliers(c.value)[1:]  # the trivial one is split off
        got = np.sort_complex(np.asarray(c.multipliers))
        np.testing.assert_allclose(got.real, np.sort(expected), atol=1e-8)
        assert abs(c.trivial_multiplier - 1.0) < 1e-8 and c.reliable
        assert c.n_unstable == (1 if c.value > PD_NU else 0)


def test_planar_system_never_reports_pd_or_ns():
    from systems import planar_system

    from maglev_match.dynamics.hopf import locate_hopf_points

    system = planar_system()
    hp = locate_hopf_points(system, "mu", -0.5, 1.0, n_scan=10).points[0]
    br = cycle_branch(system, hp, "mu", stop_at=3.0, ntst=20, ncol=4, max_steps=100)
    assert br.stopped_reason == "reached stop_at"
    assert not [s for s in br.special_points if s.type in ("PD", "NS", "BP")]
    for c in br.points:  # r = sqrt(mu), period 2 pi / (1 + mu), multiplier exp(-2 mu T)
        assert c.max("radius") == pytest.approx(math.sqrt(c.value), rel=1e-6)
        assert c.period == pytest.approx(2 * math.pi / (1 + c.value), rel=1e-6)
        assert c.multipliers[0] == pytest.approx(math.exp(-2 * c.value * c.period), rel=1e-6)
        assert c.stable and c.reliable


def test_lorenz_branch_to_the_homoclinic_end_has_no_pd_or_ns():
    from systems import LORENZ_RHO_H, lorenz

    from maglev_match.dynamics.hopf import locate_hopf_points

    system = lorenz()
    scan = locate_hopf_points(system, "rho", 20.0, 30.0, n_scan=50)
    assert len(scan.points) == 1
    hp = scan.points[0]
    assert hp.value == pytest.approx(LORENZ_RHO_H, rel=1e-12)
    assert hp.l1 > 0  # subcritical
    br = cycle_branch(system, hp, "rho", ntst=60, ncol=4, max_steps=300,
                      max_period_factor=30, lam_scale=1.0)
    assert br.stopped_reason == "homoclinic approach"
    assert br.points[-1].value == pytest.approx(13.926, abs=2e-3)  # the homoclinic orbit
    assert not [s for s in br.special_points if s.type in ("PD", "NS")]
    # unstable cycles (one multiplier outside) wherever the multipliers are trusted
    short = [c for c in br.points if c.period < 2.0]
    assert short and all(c.reliable and c.n_unstable == 1 for c in short)
    assert all(abs(c.trivial_multiplier - 1) < 1e-4 for c in short)
    # far up the homoclinic approach (period 180 s): no error, no special point from
    # multipliers whose trivial one has drifted (those points are marked unreliable)
    long = cycle_branch(system, hp, "rho", ntst=60, ncol=4, max_steps=120,
                        max_period_factor=1000, lam_scale=1.0)
    assert long.stopped_reason == "max_steps" and long.points[-1].period > 100
    assert not [s for s in long.special_points if s.type in ("PD", "NS", "BP")]
    for c in long.points:
        assert c.reliable == (abs(c.trivial_multiplier - 1) <= 1e-4)


def test_collocation_problem_exposes_residual_jacobian_and_parameter_derivative():
    from maglev_match.dynamics.collocation import CollocationProblem

    br = cycle_branch(HOPF_NF, _start(HOPF_NF, -1.0), "mu", stop_at=0.3, ntst=12, ncol=4,
                      max_steps=100)
    c = br.points[-1]
    orbit = c.orbit
    prob = CollocationProblem(system=HOPF_NF, ipar=0, p0=orbit.p, mesh=orbit.mesh, m=4,
                              scale=np.asarray(HOPF_NF.state_scale), T_scale=orbit.period,
                              lam_scale=0.1)
    Y = prob.pack(orbit.states, orbit.period, c.value)
    row = np.zeros(prob.size)
    row[-1] = 1.0
    phase = prob.phase_row(orbit.states)
    r, A, _ = prob.evaluate(Y, phase, orbit.states, row, c.value / 0.1)
    assert np.max(np.abs(r)) < 1e-9  # a converged point
    assert A.shape == (prob.size, prob.size)
    # dF/dmu is the lambda column of the Jacobian (scaled by the lambda scale) ...
    # (except the last row, the fixed-parameter condition, which has no p in it)
    col = A[:, -1].toarray().ravel() / 0.1
    dmu = prob.param_derivative(Y, "mu")
    np.testing.assert_allclose(dmu[:-1], col[:-1], atol=1e-12)
    assert dmu[-1] == 0.0
    # ... and dF/dl1 agrees with a central difference of the residual in l1
    d = 1e-6
    rs = []
    for sgn in (1, -1):
        prob.p0 = HOPF_NF.params_with(orbit.p, l1=-1.0 + sgn * d)
        rs.append(prob.evaluate(Y, phase, orbit.states, row, c.value / 0.1)[0])
    prob.p0 = orbit.p
    np.testing.assert_allclose(prob.param_derivative(Y, "l1"), (rs[0] - rs[1]) / (2 * d),
                               atol=1e-7)
    # the profile at a time and its (exactly linear) derivative in Y
    for s in (0.0, 0.137, 0.5, 0.999):
        u, D = prob.profile_at(Y, s)
        np.testing.assert_allclose(u, orbit.evaluate([s])[0], atol=1e-14)
        np.testing.assert_allclose(D @ Y, u, atol=1e-14)


def test_saved_branch_restart_reproduces_the_next_points(tmp_path):
    from maglev_match.dynamics.cycles import load_restart

    kw = dict(ntst=20, ncol=4, ds_max=0.5, adapt_every=3, lam_scale=0.5)
    full = cycle_branch(FOLD_NF, _start(FOLD_NF, 2.0), "mu", max_steps=30, **kw)
    assert len(full.points) == 30 and [s.type for s in full.special_points] == ["LPC"]
    first = cycle_branch(FOLD_NF, _start(FOLD_NF, 2.0), "mu", max_steps=7, **kw)
    ds = first.to_xarray(FOLD_NF, param_unit="1", state_units=["1"] * 5)
    for name, var in ds.data_vars.items():
        assert "units" in var.attrs and var.attrs.get("long_name"), name
    path = tmp_path / "branch.nc"
    ds.to_netcdf(path, engine="h5netcdf")
    start, state, param = load_restart(path, "P6")  # the last point of the short run
    assert param == "mu"
    rest = cycle_branch(FOLD_NF, start, "mu", max_steps=23, restart=state, **kw)
    assert len(rest.points) == 23
    for a, b in zip(full.points[7:], rest.points, strict=True):
        assert b.value == pytest.approx(a.value, abs=1e-8)
        assert b.period == pytest.approx(a.period, rel=1e-8)
        np.testing.assert_allclose(b.orbit.states, a.orbit.states, atol=1e-7)
    # the fold is found again by the restarted run, at the same place
    assert [s.type for s in rest.special_points] == ["LPC"]
    assert rest.special_points[0].value == pytest.approx(full.special_points[0].value,
                                                         abs=1e-10)
    with pytest.raises(KeyError, match="not in the saved branch"):
        load_restart(path, "nope")


def test_restart_in_a_second_parameter():
    from maglev_match.dynamics.cycles import load_restart

    br = cycle_branch(HOPF_NF, _start(HOPF_NF, -1.0), "mu", stop_at=0.3, ntst=16, ncol=4,
                      max_steps=100)
    label = f"P{len(br.points) - 2}"  # the last regular step before the stop value
    start, state, saved = load_restart(br.to_xarray(HOPF_NF), label)
    mu = state.value
    # continue that cycle in l1 (mu fixed): radius^2 = -mu / l1 along the new branch
    new = cycle_branch(HOPF_NF, start, "l1", restart=state, restart_param=saved,
                       stop_at=-0.5, ntst=16, ncol=4, max_steps=100, lam_scale=0.1)
    assert new.stopped_reason == "reached stop_at"
    assert new.points[-1].value == pytest.approx(-0.5, abs=1e-12)
    for c in new.points:
        assert c.orbit.p[0] == pytest.approx(mu, abs=0)
        assert c.max("radius") == pytest.approx(math.sqrt(-mu / c.value), rel=1e-6)


def test_step_growth_on_the_predicted_error_takes_fewer_steps_to_the_same_cycle():
    """Hopf normal form with l1 = +1 (unstable cycles for mu < 0) to mu = -0.5: with the
    predicted-error rule the branch needs fewer steps than with the Newton-count rule
    alone, and the cycle at the stop value is the same (radius sqrt(-mu / l1), closed
    form)."""
    old = cycle_branch(HOPF_NF, _start(HOPF_NF, 1.0), "mu", stop_at=-0.5, ntst=20, ncol=4,
                       max_steps=200, predictor_tol=None)
    new = cycle_branch(HOPF_NF, _start(HOPF_NF, 1.0), "mu", stop_at=-0.5, ntst=20, ncol=4,
                       max_steps=200)
    assert old.stopped_reason == new.stopped_reason == "reached stop_at"
    assert new.steps < old.steps
    a, b = old.points[-1], new.points[-1]
    assert b.max("radius") == pytest.approx(a.max("radius"), rel=1e-9)
    assert b.max("radius") == pytest.approx(math.sqrt(0.5), rel=1e-6)
    assert b.period == pytest.approx(a.period, rel=1e-9)


def test_branch_without_special_points_still_has_multipliers_at_every_kept_point():
    """detect_special_points=False computes the multipliers only for the points the branch
    keeps (not at the trial points of the event location); they equal those of the full
    run at the stop value, and every kept point has its n multipliers."""
    full = cycle_branch(HOPF_NF, _start(HOPF_NF, -1.0), "mu", stop_at=0.4, ntst=16, ncol=4)
    lean = cycle_branch(HOPF_NF, _start(HOPF_NF, -1.0), "mu", stop_at=0.4, ntst=16, ncol=4,
                        detect_special_points=False)
    assert all(len(c.multipliers) == 4 and c.reliable for c in lean.points)
    ma = np.sort_complex(np.asarray(full.points[-1].multipliers))
    mb = np.sort_complex(np.asarray(lean.points[-1].multipliers))
    assert np.max(np.abs(ma - mb)) < 1e-9
    assert lean.points[-1].stable and lean.points[-1].n_unstable == 0


def test_limit_contact_only_bracketed_on_request():
    """locate_limit=False (the matching index's route): the branch still ends at the first
    contact (radius 0.5 at mu = 0.25, closed form), inside the step that crosses it, with
    one trial instead of the solved contact, and says it is only bracketed."""
    def limits(system, orbit):
        r = np.sqrt(np.sum((orbit.states @ _Q)[:, :2] ** 2, axis=1))
        return {"radius 0.5": 0.5 - float(np.max(r))}

    kw = dict(ntst=20, ncol=4, max_steps=200, limits=limits, detect_special_points=False)
    solved = cycle_branch(HOPF_NF, _start(HOPF_NF, -1.0), "mu", **kw)
    rough = cycle_branch(HOPF_NF, _start(HOPF_NF, -1.0), "mu", locate_limit=False, **kw)
    assert solved.stopped_reason == rough.stopped_reason == "contact with a physical limit"
    a, b = (next(s for s in br.special_points if s.type == "contact") for br in (solved, rough))
    assert a.located == "solved" and a.value == pytest.approx(0.25, rel=1e-7)
    assert b.located.startswith("bracketed") and "locate_limit=False" in b.located
    before = rough.points[-2].value  # the last accepted point before the contact
    assert before < 0.25 and abs(b.value - 0.25) <= 0.25 - before
    assert rough.points[-1].kind == "contact"
    assert not any("limit contact" in w for w in rough.warnings)  # asked for: no warning
