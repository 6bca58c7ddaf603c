"""Tests of the time simulation with limit events (dynamics/integrate/simulate.py and
kernel.py, simulation.py)."""

from __future__ import annotations

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
import scipy.optimize

from maglev_match import load_preset
from maglev_match.analyses.simulation import (
    critical_disturbance,
    describe_event,
    history_dataset,
    initial_state,
    save_history,
    simulate_maglev,
)
from maglev_match.dynamics.integrate.simulate import SimulationOptions, simulate, simulate_batch
from maglev_match.dynamics.system import System
from maglev_match.maglev import vehicle as vehicle_model
from maglev_match.maglev.limits import gap_limit_events
from maglev_match.maglev.models import build_system
from maglev_match.maglev.unit import gap as unit_gap
from maglev_match.maglev.vehicle import gap_function as vehicle_gap_function


# ---------------------------------------------------------------------------------------
# small conservative systems of our own (module level: stable objects, compiled once)
# ---------------------------------------------------------------------------------------
def pendulum_rhs(x, p):
    return jnp.stack([x[1], -p[0] * jnp.sin(x[0])])


def oscillator_rhs(x, p):
    return jnp.stack([x[1], -x[0]])


def oscillator_events(x, p):
    # limits at x1 = -p[0] and x1 = +p[1]
    return jnp.stack([x[0] + p[0], p[1] - x[0]])


PENDULUM = System(rhs=pendulum_rhs, p=np.array([1.0]), param_names=("g_over_l",),
                  state_names=("theta", "omega"), name="pendulum")
OSCILLATOR = System(rhs=oscillator_rhs, p=np.array([1.0, 10.0]),
                    param_names=("lower", "upper"), state_names=("x", "v"), name="oscillator")


def test_pendulum_conserves_energy():
    """A large-amplitude pendulum (conservative): H = v^2/2 - cos(theta) stays constant."""
    x0 = np.array([2.5, 0.0])
    res = simulate(PENDULUM, x0, 40.0, options=SimulationOptions(rtol=1e-10, atol=1e-10),
                   n_save=801)
    H = 0.5 * res.x[:, 1] ** 2 - np.cos(res.x[:, 0])
    assert res.outcome in ("running", "converged") and res.outcome == "running"
    assert np.max(np.abs(H - H[0])) < 1e-7 * abs(H[0])
    # and it really swings (not a trivial solution)
    assert res.x[:, 0].min() < -2.4


def test_unit_beam_subsystem_conserves_energy():
    """Model A with sigma = 0 and xi1 = 0: the beam mode is an undamped oscillator driven by
    nothing, so w'^2/2 + omega1^2 w^2/2 is conserved while the levitation unit moves."""
    P = load_preset("alpha1").replace(sigma=0.0, xi1=0.0)
    x0 = np.zeros(9)
    x0[4] = -1e-3
    x0[0] = 5e-4  # also disturb the magnet so the rest of the model is busy
    sim = simulate_maglev(P, "unit", x0, 3.0, options=SimulationOptions(rtol=1e-11, atol=1e-11))
    assert sim.outcome != "collision"
    x = sim.result.x
    w1 = P.omega1
    E = 0.5 * x[:, 5] ** 2 + 0.5 * w1**2 * x[:, 4] ** 2
    assert np.max(np.abs(E - E[0])) < 1e-7 * E[0]
    assert np.ptp(x[:, 0]) > 1e-4  # the magnet moved


@pytest.mark.parametrize("model", ["unit", "vehicle"])
def test_small_amplitude_matches_matrix_exponential(model):
    """Limits off, tiny disturbance: x(t) - x* = expm(J t) (x0 - x*) up to O(amplitude)."""
    P = load_preset("alpha1")
    sys_ = build_system(P, model, limited=False)
    xe = initial_state(P, model)
    dx = np.zeros(sys_.dim)
    if model == "unit":
        dx[4] = -1e-8
        dx[0] = 3e-9
    else:
        L = vehicle_model.layout(P.n_modes)
        dx[L["q"].start] = 1e-8
        dx[0] = 2e-9  # frame 1 heave: breaks the symmetry too
    sim = simulate_maglev(P, model, xe + dx, 2.0, limited=False,
                          options=SimulationOptions(rtol=1e-10, atol=1e-12))
    ts = sim.result.t[::50]
    J = sys_.jacobian(xe)
    lin = np.array([scipy.linalg.expm(J * t) @ dx for t in ts])
    got = sim.result.x[::50] - xe
    scale = sys_.state_scale
    err = np.max(np.abs(got - lin) / scale)
    size = np.max(np.abs(lin) / scale)
    assert size > 1e-6
    assert err < 1e-4 * size


def test_collision_time_matches_dense_root_find():
    """The event time equals a root of the gap found independently (diffrax dense output at
    much tighter tolerance + Brent's method) to 1e-9 s; limit and point are reported. (An
    upper-limit collision: the vector field stays smooth past it, unlike at c = 0.)"""
    P = load_preset("alpha1")
    x0 = initial_state(P, "unit", x5=-2e-3)
    x0[5] = -1.5  # beam moving up at 1.5 m/s: the gap opens fast
    sim = simulate_maglev(P, "unit", x0, 1.0)
    assert sim.outcome == "collision"
    assert sim.point == 1 and sim.limit == "upper"
    T = sim.collision_time + 0.002
    sys_ = build_system(P, "unit", limited=True)
    scale = jnp.asarray(sys_.state_scale)
    pj = jnp.asarray(sys_.p)
    term = diffrax.ODETerm(lambda t, z, a: sys_.rhs(z * scale, pj) / scale)
    sol = diffrax.diffeqsolve(
        term, diffrax.Dopri8(), 0.0, T, None, jnp.asarray(x0) / scale,
        stepsize_controller=diffrax.PIDController(rtol=1e-11, atol=1e-11),
        saveat=diffrax.SaveAt(dense=True), max_steps=100_000,
    )
    evaluate = jax.jit(jax.vmap(sol.evaluate))

    def margin(t):
        z = np.asarray(evaluate(jnp.atleast_1d(jnp.asarray(t, float))))[0] * sys_.state_scale
        return P.gap_max - (P.c0 + z[0] - z[4])

    grid = np.linspace(0.0, T, 401)
    z = np.asarray(evaluate(jnp.asarray(grid))) * sys_.state_scale
    vals = P.gap_max - (P.c0 + z[:, 0] - z[:, 4])
    k = int(np.argmax(vals < 0))
    assert k > 0
    t_root = scipy.optimize.brentq(margin, grid[k - 1], grid[k], xtol=1e-14, rtol=1e-15)
    assert abs(sim.collision_time - t_root) < 1e-9
    # the saved history ends at the limit and never goes past it
    ds = history_dataset(sim)
    assert ds.gap.values.max() <= P.gap_max + 1e-12
    assert ds.time.values[-1] == pytest.approx(sim.collision_time)


def test_grazing_inside_one_step_is_a_collision():
    """x = cos t dips to -1 at t = pi; with the lower limit at -(1 - 1e-6) the excursion
    lasts ~2.8e-3 s, far shorter than a step, and must still be found; with the limit at
    -(1 + 1e-6) there is no collision."""
    x0 = np.array([1.0, 0.0])
    opts = SimulationOptions(rtol=1e-10, atol=1e-10)
    depth = 1e-6
    hit = simulate(OSCILLATOR, x0, 5.0, p=np.array([1.0 - depth, 10.0]),
                   event_fn=oscillator_events, options=opts, n_save=0)
    miss = simulate(OSCILLATOR, x0, 5.0, p=np.array([1.0 + depth, 10.0]),
                    event_fn=oscillator_events, options=opts, n_save=0)
    exact = np.arccos(-(1.0 - depth))
    assert hit.outcome == "collision" and hit.event_index == 0
    # located to integration accuracy: x(t_event) is on the limit (|x'| ~ 1.4e-3 there)
    assert abs(np.cos(hit.event_time) + (1.0 - depth)) < 1e-8
    assert abs(hit.event_time - exact) < 1e-5
    assert miss.outcome == "running"
    assert 0 < miss.min_event_value[0] < 2 * depth
    # the dip is much shorter than the average accepted step, so step-end signs miss it
    assert 5.0 / hit.accepted > 10 * 2 * np.sqrt(2 * depth)


def _two_oscillators(x, p):
    # x1 = cos t and x2 = cos(w t): two uncoupled oscillators (w = p[0])
    return jnp.stack([x[1], -x[0], x[3], -p[0] ** 2 * x[2]])


def _two_dips(x, p):
    # entry 0: x1 above -(1 - 1e-6); entry 1: x2 above -(1 - p[1])
    return jnp.stack([x[0] + 1.0 - 1e-6, x[2] + 1.0 - p[1]])


TWO_OSC = System(rhs=_two_oscillators, p=np.array([1.0005, 1e-6]), param_names=("w", "depth"),
                 state_names=("x1", "v1", "x2", "v2"), name="two oscillators")


@pytest.mark.parametrize("depth2", [1e-6, 1e-7])
def test_two_entries_dipping_inside_one_step_give_the_first_collision(depth2):
    """Both limits are grazed within one step (minima at t = pi / 1.0005 and pi, 1.6e-3 s
    apart, each excursion ~1e-3 s long): every entry at risk is refined, so the collision is
    the earlier dip (entry 1), not whichever entry looked closest at the samples."""
    x0 = np.array([1.0, 0.0, 1.0, 0.0])
    w = TWO_OSC.p[0]
    res = simulate(TWO_OSC, x0, 4.0, p=np.array([w, depth2]), event_fn=_two_dips,
                   options=SimulationOptions(rtol=1e-10, atol=1e-10), n_save=0)
    assert res.outcome == "collision" and res.event_index == 1
    # on the limit to integration accuracy (the rate there is only ~sqrt(2 depth))
    assert abs(np.cos(w * res.event_time) + (1.0 - depth2)) < 1e-8
    assert res.event_time == pytest.approx(np.arccos(-(1.0 - depth2)) / w, abs=1e-5)


def test_current_clamp_keeps_current_nonnegative():
    """A large disturbance drives the smooth model's current far negative; with the limits
    on the current state never drops below zero by more than the integration tolerance."""
    P = load_preset("alpha3")
    x0 = initial_state(P, "unit", x5=-6e-3)
    smooth = simulate_maglev(P, "unit", x0, 1.0, limited=False)
    i_smooth = smooth.result.x[:, 6] + P.i0
    assert np.nanmin(i_smooth) < -1.0
    lim = simulate_maglev(P, "unit", x0, 1.0, limited=True)
    i_lim = lim.result.x[:, 6] + P.i0
    i_lim = i_lim[np.isfinite(i_lim)]
    assert i_lim.min() >= -1e-6
    assert np.any(i_lim < 1e-3)  # the clamp was active


def _mirror_matrix(n_modes: int) -> np.ndarray:
    """Reflection about mid-span: frame 1 <-> 3, pitch angles change sign, point j <-> 7-j,
    mode n -> (-1)^(n+1) mode n."""
    names = vehicle_model.state_names(n_modes)
    idx = {n: k for k, n in enumerate(names)}
    n = len(names)
    M = np.zeros((n, n))

    def put(a, b, s):
        M[idx[a], idx[b]] = s

    frame = {"1": "3", "2": "2", "3": "1", "0": "0"}
    for suffix in ("", "_dot"):
        for k, kk in frame.items():
            put(f"z{k}{suffix}", f"z{kk}{suffix}", 1.0)
            put(f"th{k}{suffix}", f"th{kk}{suffix}", -1.0)
        for m in range(1, n_modes + 1):
            put(f"q{m}{suffix}", f"q{m}{suffix}", (-1.0) ** (m + 1))
    for j in range(1, 7):
        for b in ("i", "y1_", "v"):
            put(f"{b}{j}", f"{b}{7 - j}", 1.0)
    assert np.allclose(M @ M, np.eye(n))
    return M


def test_vehicle_symmetric_disturbance_stays_symmetric():
    """Model B on the symmetric setup: a symmetric start (pressed, q1 = 3 mm) stays
    mirror-symmetric, and an asymmetric start x0 and its mirror image evolve as mirror
    images (one batched call)."""
    P = load_preset("turnout-soft")
    sys_ = build_system(P, "vehicle", limited=True)
    M = _mirror_matrix(P.n_modes)
    sym = initial_state(P, "vehicle", initial="pressed", q1=3e-3)
    assert np.allclose(M @ sym, sym)
    rng = np.random.default_rng(1)
    asym = sym + (rng.standard_normal(sys_.dim) * sys_.state_scale * 0.2)
    batch = np.stack([sym, asym, M @ asym])
    events = gap_limit_events(vehicle_gap_function(P.n_modes), P.gap_min, P.gap_max)
    b = simulate_batch(sys_, batch, 1.0, event_fn=events, n_save=101)
    assert not np.any(b.outcome == "collision")
    x = b.x / sys_.state_scale
    assert np.max(np.abs(x[0] - x[0] @ M.T)) < 1e-6
    assert np.max(np.abs(x[2] - x[1] @ M.T)) < 1e-6
    assert np.max(np.abs(x[1] - x[1] @ M.T)) > 1e-2  # the asymmetric run is asymmetric


def test_batch_equals_single_runs():
    """A batched call gives the same outcomes and collision times as single runs."""
    P = load_preset("alpha3")
    sys_ = build_system(P, "unit", limited=True)
    events = gap_limit_events(unit_gap, P.gap_min, P.gap_max)
    sizes = np.array([-2e-3, -8e-3, 3e-3, -9e-3])
    x0 = np.zeros((4, 9))
    x0[:, 4] = sizes
    b = simulate_batch(sys_, x0, 2.0, event_fn=events,
                       options=SimulationOptions(stop_on_converged=True))
    for k in range(4):
        s = simulate_maglev(P, "unit", x0[k], 2.0)
        assert b.outcome[k] == s.outcome
        if s.outcome == "collision":
            assert abs(b.event_time[k] - s.collision_time) < 1e-12
            assert describe_event(int(b.event_index[k])) == (s.point, s.limit)


def test_critical_disturbance_bracket_is_consistent():
    """The bracket's ends behave as claimed when re-run on their own, and the bracket is
    as narrow as asked."""
    P = load_preset("alpha1")
    tol = 2e-4
    c = critical_disturbance(P, tol=tol, t_max=20.0, batch=8)
    assert c.status == "bracketed"
    assert c.smallest_collision - c.largest_return <= tol * 1.0001
    assert 0 < c.largest_return < c.smallest_collision < c.gap_range
    assert c.unresolved == 0 and c.runs >= 16
    sys_ = build_system(P, "unit", limited=True)
    events = gap_limit_events(unit_gap, P.gap_min, P.gap_max)
    x0 = np.zeros((2, 9))
    x0[:, 4] = [-c.largest_return, -c.smallest_collision]
    b = simulate_batch(sys_, x0, 80.0, event_fn=events,
                       options=SimulationOptions(stop_on_converged=True))
    assert list(b.outcome) == ["converged", "collision"]
    assert b.event_time[1] == pytest.approx(c.collision_time, abs=1e-9)


def test_start_outside_limits_is_collision_at_zero():
    P = load_preset("alpha1")
    sim = simulate_maglev(P, "unit", initial_state(P, "unit", x5=-0.011), 1.0)
    assert sim.outcome == "collision" and sim.collision_time == 0.0 and sim.limit == "upper"


def test_history_files(tmp_path):
    """CSV and netCDF histories hold the gap, current and beam deflection."""
    import xarray as xr

    P = load_preset("alpha1")
    sim = simulate_maglev(P, "unit", initial_state(P, "unit", x5=-1.5e-3), 0.5)
    nc = save_history(sim, tmp_path / "h.nc")
    csv = save_history(sim, tmp_path / "h.csv")
    ds = xr.open_dataset(nc, engine="h5netcdf")
    assert ds.sizes["time"] == 2001
    assert np.allclose(ds.gap_deviation.values[:, 0], ds.z1.values - ds.w.values)
    assert ds.beam_deflection.values[0] == pytest.approx(-1.5e-3)
    table = np.genfromtxt(csv, delimiter=",", names=True)
    assert "gap_deviation_1" in table.dtype.names
    assert np.allclose(table["current_1"], ds.current.values[:, 0])
    # model A: the gap rate is x2 - x6
    assert np.allclose(ds.gap_rate.values[:, 0], ds.z1_dot.values - ds.w_dot.values,
                       rtol=0, atol=1e-12)


def test_initial_condition_names():
    P = load_preset("turnout-soft")
    pressed = initial_state(P, "vehicle", initial="pressed")
    eq = initial_state(P, "vehicle")
    L = vehicle_model.layout(P.n_modes)
    assert np.all(pressed[L["q"]] == 0) and eq[L["q"]][0] > 0
    assert np.array_equal(np.delete(pressed, np.r_[L["q"]]), np.delete(eq, np.r_[L["q"]]))
    q = initial_state(P, "vehicle", initial="pressed", q1=3e-3)
    assert q[L["q"].start] == 3e-3
    from maglev_match.core.params import ParameterError

    with pytest.raises(ParameterError):
        initial_state(P, "unit", initial="pressed")
    with pytest.raises(ParameterError):
        initial_state(P, "vehicle", x5=-1e-3)


def test_cli_json_shape(capsys, tmp_path):
    """`simulate --json` prints exactly the issue's object; --out writes the history."""
    import json

    from maglev_match.cli import main

    out = tmp_path / "h.csv"
    rc = main(["simulate", "--model", "unit", "--preset", "alpha3", "--x5", "-8e-3",
               "--t", "1", "--n-save", "2001", "--json", "--out", str(out)])
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == {"outcome", "collision_time", "limit", "point", "final_gap_deviation"}
    assert data["outcome"] == "collision" and data["limit"] == "lower" and data["point"] == 1
    assert data["final_gap_deviation"] == pytest.approx(-8e-3)
    assert out.is_file()
    assert main(["simulate", "--model", "unit", "--initial", "pressed"]) == 2


# ---------------------------------------------------------------------------------------
# the convergence verdict: close to the reference state is not enough, it must decay
# ---------------------------------------------------------------------------------------
def focus_rhs(x, p):
    # x' = a x - w y, y' = w x + a y: a focus with eigenvalues a +- i w (p = [a, w])
    return jnp.stack([p[0] * x[0] - p[1] * x[1], p[1] * x[0] + p[0] * x[1]])


FOCUS = System(rhs=focus_rhs, p=np.array([-0.2, 10.0]), param_names=("a", "w"),
               state_names=("x", "y"), name="focus")


@pytest.mark.parametrize("a, expected", [(-0.2, "converged"), (0.01, "running"),
                                         (0.0, "running")])
def test_converged_only_when_the_disturbance_decays(a, expected):
    """A focus with a tiny disturbance (1e-3 of the scale, 50x inside converge_tol) stays
    close to the origin for the whole run whatever its stability; only the stable one
    (a < 0) may be reported converged. The growing one (a = 0.01) and the centre (a = 0)
    end as 'running' with a warning saying why; the eigenvalues' largest real part is a."""
    x0 = np.array([1e-3, 0.0])
    res = simulate(FOCUS, x0, 10.0, p=np.array([a, 10.0]), x_ref=np.zeros(2),
                   options=SimulationOptions(rtol=1e-10, atol=1e-12), n_save=201)
    r = np.hypot(res.x[:, 0], res.x[:, 1])
    assert np.max(r) < 0.05  # the old "stayed within tolerance" test would pass for all three
    assert np.allclose(r, 1e-3 * np.exp(a * res.t), rtol=1e-8)  # a real focus, r0 e^(a t)
    assert res.outcome == expected
    assert res.reference_max_real == pytest.approx(a, abs=1e-12)
    assert res.reference_residual == 0.0
    if expected == "converged":
        assert res.converged_time == 0.0 and not res.warnings
    else:
        assert res.converged_time is None
        assert len(res.warnings) == 1 and "not converged" in res.warnings[0]
        assert ("unstable" in res.warnings[0]) == (a > 0)


def test_verdict_batch_matches_single_and_stops_when_converged():
    """Batched runs give the same verdicts as single runs; with stop_on_converged a stable
    run stops right after the hold time, an unstable one runs to the horizon; an exactly
    steady state at an unstable equilibrium is converged (it stays there); a reference
    state that is not an equilibrium never is."""
    p = np.array([[-0.2, 10.0], [0.01, 10.0], [0.3, 10.0], [0.3, 10.0], [-0.2, 10.0]])
    x0 = np.array([[1e-3, 0.0], [1e-3, 0.0], [1e-3, 0.0], [0.0, 0.0], [0.0, 0.0]])
    x_ref = np.zeros(2)
    opts = SimulationOptions(rtol=1e-10, atol=1e-12, stop_on_converged=True)
    b = simulate_batch(FOCUS, x0, 6.0, p=p, x_ref=x_ref, options=opts)
    assert list(b.outcome) == ["converged", "running", "running", "converged", "converged"]
    assert np.allclose(b.reference_max_real, p[:, 0], rtol=0, atol=1e-12)
    for k in range(5):
        s = simulate(FOCUS, x0[k], 6.0, p=p[k], x_ref=x_ref, options=opts, n_save=0)
        assert s.outcome == b.outcome[k]
        # (vmapped and single kernels round the step sizes differently: ~1e-9)
        assert s.final_time == pytest.approx(float(b.final_time[k]), rel=1e-6)
    assert 1.0 <= b.final_time[0] < 1.1  # stopped at the end of the hold time
    assert b.final_time[1] == 6.0
    assert np.hypot(*b.final_state[2]) < 0.05  # grew, yet still within the tolerance
    # a reference state off the equilibrium (its drift, 0.2 / s, leaves the tolerance)
    off = simulate(FOCUS, np.array([0.01, 0.0]), 3.0, p=np.array([-0.2, 10.0]),
                   x_ref=np.array([0.0, 0.02]), options=opts, n_save=0)
    assert off.reference_residual == pytest.approx(0.2)
    assert off.outcome == "running"


def test_cli_unstable_equilibrium_is_not_converged(capsys):
    """The issue's case: alpha1 moved just past its Hopf point (omega1 = 159.6 rad/s,
    sigma = 4.92e-5 1/kg) with a 1 um beam disturbance: the oscillation grows slowly and
    stays far inside the convergence tolerance for 30 s; it must not be 'converged'."""
    import json

    from maglev_match.cli import main

    rc = main(["simulate", "--preset", "alpha1", "--set", "omega1=159.6",
               "--set", "sigma=4.92e-5", "--x5", "-1e-6", "--t", "30", "--json"])
    assert rc == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["outcome"] == "running"
    assert "unstable equilibrium" in " ".join(captured.err.split())  # (Rich wraps lines)


def _unit_gap_events_tight(x, p):
    # the gap limits of model A written out with an upper limit of 10.2 mm as constants:
    # an independent event function for the traced-limits test below
    gap = p[_C0] + x[0] - x[4]
    return jnp.stack([gap - 0.0, 10.2e-3 - gap])


_C0 = build_system(load_preset("alpha1"), "unit", limited=True).param_names.index("c0")


def test_gap_limits_are_traced_arguments():
    """Gap limits are arguments of the compiled kernel: a new limit value compiles nothing,
    and the run with it is the run with the limits written into the event function."""
    from maglev_match.dynamics.integrate import kernel

    P = load_preset("alpha1")
    assert P.gap_min == 0.0 and P.gap_max > 10.2e-3  # the control below uses these
    sys_ = build_system(P, "unit", limited=True)
    x0 = initial_state(P, "unit", x5=-1.5e-3)  # the gap starts at 9.5 mm, peaks at 10.6
    opts = SimulationOptions(stop_on_converged=True)
    wide = simulate(sys_, x0, 5.0, event_fn=gap_limit_events(unit_gap, P.gap_min, P.gap_max),
                    options=opts, n_save=11)
    misses = kernel.compiled_kernel.cache_info().misses
    tight = simulate(sys_, x0, 5.0, event_fn=gap_limit_events(unit_gap, 0.0, 10.2e-3),
                     options=opts, n_save=11)
    assert kernel.compiled_kernel.cache_info().misses == misses  # no new kernel
    assert wide.outcome == "converged" and tight.outcome == "collision"
    ref = simulate(sys_, x0, 5.0, event_fn=_unit_gap_events_tight, options=opts, n_save=11)
    assert ref.outcome == "collision" and ref.event_index == tight.event_index == 1
    assert tight.event_time == pytest.approx(ref.event_time, abs=1e-12)
    assert tight.event_state[0] - tight.event_state[4] + P.c0 == pytest.approx(10.2e-3,
                                                                                abs=1e-12)


def blowup_rhs(x, p):
    # x' = x^2 (x = x0 / (1 - x0 t): a singularity at t = 1/x0 for x0 > 0), y' = -y
    return jnp.stack([x[0] ** 2, -x[1]])


BLOWUP = System(rhs=blowup_rhs, p=np.array([0.0]), param_names=("unused",),
                state_names=("x", "y"), name="finite-time blow-up")


def test_singularity_fails_at_once_and_spares_the_batch():
    """A solution that blows up in finite time is 'failed' at the singularity with a
    warning saying so, after a few hundred steps (not max_steps of rejected steps), and a
    batch that contains it is not held up: the regular run beside it is exact."""
    opts = SimulationOptions(rtol=1e-10, atol=1e-12)
    r = simulate(BLOWUP, np.array([1.0, 1.0]), 2.0, x_ref=np.zeros(2), n_save=0,
                 options=opts)
    assert r.outcome == "failed"
    assert r.final_time == pytest.approx(1.0, abs=1e-6)
    assert r.steps < 2000
    assert any("singularity" in w for w in r.warnings)
    b = simulate_batch(BLOWUP, np.array([[1.0, 1.0], [-1.0, 1.0]]), 2.0, x_ref=np.zeros(2),
                       options=opts)
    assert list(b.outcome) == ["failed", "running"]
    assert b.steps.max() < 2000
    assert b.final_time[1] == 2.0
    np.testing.assert_allclose(b.final_state[1], [-1.0 / 3.0, np.exp(-2.0)], rtol=1e-8)
