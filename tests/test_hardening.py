"""Issue 24: the new surfaces (user model files, restart files, counts and percentages,
design ranges, the environment) refuse bad input with one line and exit code 2, never
answer for another system, never exit 0 silently, never hang; and restarts (issue 21) say
what they did and continue the saved branch exactly.

The table of bad inputs lives in ``tests/bad_inputs.py`` (also a script that runs every case
in a fresh process and summarises the outcomes). Here the cases that need a process of their
own (exits, endless loops, the environment) run in one; the others run in-process, where
the process boundary does not change the outcome."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
import bad_inputs  # noqa: E402
from bad_inputs import BRANCH_ARGS, CASES, judge, make_fixtures, run_fresh  # noqa: E402

from maglev_match.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    """The fixture folder: model files, a saved model-A branch (computed once, in-process)
    and its damaged copies. Returns (folder, the branch's JSON output)."""
    folder = tmp_path_factory.mktemp("bad-inputs")
    make_fixtures(folder)
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = main([*BRANCH_ARGS, "--out", str(folder / "branch")])
    assert code == 0
    bad_inputs.damaged_branches(folder / "branch" / "cycles_unit_sigma.nc", folder)
    return folder, json.loads(out.getvalue())


def _run(capsys, argv):
    code = main(argv)
    cap = capsys.readouterr()
    return code, cap.out, cap.err


IN_PROCESS = [c for c in CASES if not c.fresh and not c.slow]
FRESH = [c for c in CASES if c.fresh and not c.slow and c.group != "environment"]
ENVIRONMENT = [c for c in CASES if c.group == "environment" and not c.slow]


@pytest.mark.parametrize("case", IN_PROCESS, ids=[c.name for c in IN_PROCESS])
def test_bad_input_is_refused_in_one_line(capsys, fixtures, case):
    folder, _ = fixtures
    code, out, err = _run(capsys, case.args(folder))
    assert judge(case, code, out, err) == "as expected", (case.args(folder), code, out, err)


def test_bad_inputs_in_fresh_processes(fixtures):
    """Exits at import or in rhs and endless loops (MAGLEV_MATCH_MODEL_TIMEOUT=2), each in a
    process of its own with a timeout (two at a time); the three environment problems
    together in one more process (each case alone: tests/bad_inputs.py): the result, and
    one warning line naming each variable."""
    from concurrent.futures import ThreadPoolExecutor

    from bad_inputs import Case

    folder, _ = fixtures
    env = {k: v for c in ENVIRONMENT for k, v in c.env.items()}
    together = Case("the environment", "environment", ENVIRONMENT[-1].argv, 0, "", env=env,
                    fresh=True)
    with ThreadPoolExecutor(max_workers=2) as pool:
        runs = list(pool.map(lambda c: run_fresh(c, folder, timeout=240), [*FRESH, together]))
    wrong = [(c.name, judge(c, *r), r) for c, r in zip(FRESH, runs[:-1], strict=True)
             if judge(c, *r) != "as expected"]
    assert not wrong, wrong
    code, out, err = runs[-1]
    assert code == 0 and "Traceback" not in err, err
    warnings = [ln for ln in err.splitlines() if ln.startswith("warning:")]
    for c in ENVIRONMENT:
        assert sum(c.text in ln for ln in warnings) == 1, (c.text, warnings)
    # the ASCII terminal still shows the result, the Greek parameter names spelt out
    assert ENVIRONMENT[-1].name == "PYTHONIOENCODING=ascii"
    assert "sigma = 10, rho = 28" in out and "Equilibrium: UNSTABLE" in out and out.isascii()


def test_table_covers_every_class_of_issue_24():
    groups = {c.group for c in CASES}
    assert {"model file", "restart file", "counts", "design", "environment",
            "options"} <= groups
    assert len(CASES) >= 80


# ---------------------------------------------------------------------------------------
# restart (issue 21): no Hopf search, says what it did, continues the saved branch
# ---------------------------------------------------------------------------------------
def test_restart_without_parameter_options_continues_the_saved_branch(capsys, fixtures):
    """The branch was saved with --preset alpha1 --at omega1=100; a restart given none of
    them uses the saved values (the default preset would be another system) and reproduces
    the saved run's next points; it names the point and file, searches no Hopf point, and
    writes a figure and a restartable file of its own."""
    folder, saved = fixtures
    nc = folder / "branch" / "cycles_unit_sigma.nc"
    code, out, err = _run(capsys, ["cycles", "--restart", str(nc), "--label", "P1",
                                   "--max-steps", "2", "--json", "--out",
                                   str(folder / "again")])
    assert code == 0, err
    doc = json.loads(out)
    assert doc["restart"]["label"] == "P1" and doc["restart"]["hopf_search"] is False
    assert doc["restart"]["file"] == str(nc) and doc["hopf_points"] == []
    assert [r["sigma"] for r in doc["branch"]] == pytest.approx(
        [r["sigma"] for r in saved["branch"][2:4]], rel=1e-8)
    assert [r["period"] for r in doc["branch"]] == pytest.approx(
        [r["period"] for r in saved["branch"][2:4]], rel=1e-8)
    assert "searching Hopf points" not in err
    files = [Path(f) for f in doc["files"]]
    assert all(f.exists() for f in files) and any(f.suffix == ".png" for f in files)
    from maglev_match.analyses.restart import load_cycle_restart

    again = next(f for f in files if f.suffix == ".nc")
    assert load_cycle_restart(again, "P0").path == str(again)  # restartable in turn
    # the Python API's restart: the saved model and values from the file, the same points
    import maglev_match as mm

    api = mm.restart_branch(nc, "P1", max_steps=2)
    assert api.branch.values.tolist() == pytest.approx([r["sigma"] for r in doc["branch"]],
                                                       rel=1e-12)
    assert [str(s.type) for s in api.branch.special_points] == \
        [s["type"] for s in doc["special_points"]]
    # the text form says what was done in its first line
    code, out, _ = _run(capsys, ["cycles", "--restart", str(nc), "--label", "P1",
                                 "--max-steps", "1", "--out", str(folder / "again-text")])
    first = out.splitlines()[0]
    assert code == 0 and "restart from P1 of" in first and str(nc) in first
    assert "no Hopf search" in first


@pytest.fixture(scope="module")
def saved_branch(fixtures):
    import xarray as xr

    folder, _ = fixtures
    return xr.load_dataset(folder / "branch" / "cycles_unit_sigma.nc", engine="h5netcdf")


def _mutations():
    """Dropped variables, wrong shapes, NaN, wrong attributes: each a function of the
    dataset returning a damaged copy."""
    variables = ["r_mesh", "r_states", "r_period", "r_value", "r_t_states", "r_t_period",
                 "r_t_value", "r_ds", "r_accepted", "hopf_x", "hopf_q_re", "hopf_q_im",
                 "hopf_p", "value", "period", "profile", "mesh", "stable"]
    attrs = ["param", "hopf_value", "hopf_frequency", "hopf_l1", "ntst", "ncol", "model",
             "maglev_match_file", "n_states"]
    drop = st.sampled_from(variables).map(lambda v: ("drop", v, None))
    nan = st.tuples(st.just("nan"), st.sampled_from(variables), st.integers(0, 10**6))
    shape = st.tuples(st.just("shape"), st.sampled_from(
        [v for v in variables if v not in ("value", "period", "stable")]), st.just(None))
    attr = st.tuples(st.just("attr"), st.sampled_from(attrs),
                     st.sampled_from([None, "abc", -1.0, 0.0, float("nan"), "kD", "sigma",
                                      "omega1", 3, "cycle-branch", "hopf-curve"]))
    return st.lists(st.one_of(drop, nan, shape, attr), min_size=1, max_size=3)


def _apply(ds, mutations):
    d = ds.copy(deep=True)
    for kind, name, arg in mutations:
        if kind == "drop" and name in d.variables:
            d = d.drop_vars(name)
        elif kind == "nan" and name in d.variables and d[name].size:
            flat = np.array(d[name].values, dtype=float).reshape(-1)
            flat[arg % flat.size] = np.nan
            d[name] = (d[name].dims, flat.reshape(d[name].shape))
        elif kind == "shape" and name in d.variables and d[name].ndim >= 1:
            v = d[name].values  # one more entry along its last dimension (a new one)
            dims = (*d[name].dims[:-1], f"{d[name].dims[-1]}_grown")
            d = d.drop_vars(name).assign({name: (dims, np.concatenate([v, v[..., :1]], -1))})
        elif kind == "attr":
            if arg is None:
                d.attrs.pop(name, None)
            else:
                d.attrs[name] = arg
    return d


@settings(max_examples=100, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(mutations=_mutations(), label=st.sampled_from(["P0", "P1", "P3"]))
def test_restart_loader_on_mutated_files_gives_a_clean_error_or_the_same_restart(
        saved_branch, mutations, label):
    """A property test: whatever is dropped, reshaped, NaN'ed or set wrong in a saved branch,
    the loader either refuses with one line naming the file or returns exactly the restart
    of the undamaged file (a mutation of data the restart does not use changes nothing)."""
    from maglev_match.analyses.restart import RestartFileError, load_cycle_restart
    from maglev_match.core.params import load_params
    from maglev_match.maglev.models import build_system

    system = build_system(load_params("alpha1"), "unit")
    good = load_cycle_restart(saved_branch, label, system)
    bad = _apply(saved_branch, mutations)
    try:
        rs = load_cycle_restart(bad, label, system)
    except RestartFileError as exc:
        text = str(exc)
        assert text.startswith("restart file ") and "\n" not in text
        return
    assert rs.param == good.param and rs.label == label
    for f in ("mesh", "states", "period", "value", "t_states", "t_period", "t_value", "ds",
              "accepted"):
        np.testing.assert_array_equal(getattr(rs.state, f), getattr(good.state, f), err_msg=f)
    for f in ("param", "value", "x", "p", "frequency", "q"):
        np.testing.assert_array_equal(getattr(rs.start, f), getattr(good.start, f), err_msg=f)
    np.testing.assert_array_equal(rs.p, good.p)


def test_restart_cycle_branch_equals_the_uninterrupted_branch():
    """The library restart (validated load, same parameters) of a saved normal-form branch
    gives the uninterrupted branch's next points; other parameter values are refused."""
    from systems import HOPF_NF, Q_CRIT

    from maglev_match.analyses.restart import (
        RestartKind,
        RestartMismatch,
        restart_cycle_branch,
        stamp,
    )
    from maglev_match.dynamics.cycles import cycle_branch, hopf_start

    start = hopf_start(HOPF_NF, np.zeros(5), HOPF_NF.params_with(mu=0.0, l1=1.0), "mu",
                       2.0, Q_CRIT, 1.0)
    kw = dict(ntst=16, ncol=4, lam_scale=0.1, adapt_every=3)
    system = type(HOPF_NF)(**{**HOPF_NF.__dict__, "p": HOPF_NF.params_with(l1=1.0)})
    full = cycle_branch(system, start, "mu", max_steps=10, **kw)
    first = cycle_branch(system, start, "mu", max_steps=4, **kw)
    ds = stamp(first.to_xarray(system), RestartKind.CYCLE_BRANCH, system, "nf", "test")
    rest = restart_cycle_branch(ds, "P3", system, max_steps=6, lam_scale=0.1, adapt_every=3)
    assert "restart from P3" in rest.describe()
    assert len(rest.branch.points) == 6
    for a, b in zip(full.points[4:], rest.branch.points, strict=True):
        assert b.value == pytest.approx(a.value, abs=1e-8)  # (as the saved-branch restart
        assert b.period == pytest.approx(a.period, rel=1e-8)  # test of test_cycles.py)
        # closed form of the normal form: radius^2 = -mu / l1
        assert b.max("radius") == pytest.approx(math.sqrt(-b.value / 1.0), rel=1e-6)
    other = type(system)(**{**system.__dict__, "p": system.params_with(omega=2.5)})
    with pytest.raises(RestartMismatch, match="omega = 2.5 given, 2 saved"):
        restart_cycle_branch(ds, "P3", other, max_steps=2)


def test_hopf_curve_restart_extends_the_closed_form_curve(capsys, fixtures):
    """Lorenz: the Hopf curve rho = sigma (sigma + beta + 3) / (sigma - beta - 1) saved for
    sigma in [5, 20], restarted from a point with sigma up to 40, without a Hopf search."""
    folder, _ = fixtures
    lorenz = str(folder / "lorenz.py")
    code, _, err = _run(capsys, ["hopf-curve", "--model", lorenz, "--params", "rho,sigma",
                                 "--range", "rho=5:60", "--range", "sigma=5:20", "--grid",
                                 "0", "--max-step", "0.05", "--out", str(folder / "hc1")])
    assert code == 0, err
    saved = folder / "hc1" / "hopf_curve_lorenz_rho_sigma.nc"
    code, out, err = _run(capsys, ["hopf-curve", "--model", lorenz, "--restart", str(saved),
                                   "--label", "P3", "--range", "sigma=5:40", "--range",
                                   "rho=5:200", "--grid", "0", "--max-step", "0.05",
                                   "--json", "--out", str(folder / "hc2")])
    assert code == 0, err
    doc = json.loads(out)
    assert doc["restart"]["label"] == "P3" and doc["restart"]["hopf_search"] is False
    beta = 8.0 / 3.0
    sig = np.array([p["sigma"] for p in doc["points"]])
    rho = np.array([p["rho"] for p in doc["points"]])
    np.testing.assert_allclose(rho, sig * (sig + beta + 3) / (sig - beta - 1), rtol=1e-8)
    assert sig.max() == pytest.approx(40.0, abs=1e-9)
    code, _, err = _run(capsys, ["hopf-curve", "--model", lorenz, "--restart", str(saved),
                                 "--label", "P3", "--scan-steps", "10"])
    assert code == 2 and "--scan-steps" in err
    code, _, err = _run(capsys, ["hopf-curve", "--model", lorenz, "--restart", str(saved),
                                 "--label", "P3", "--set", "sigma=7"])
    assert code == 2 and "sigma varies along the saved Hopf curve" in err
    code, _, err = _run(capsys, ["hopf-curve", "--model", lorenz, "--restart", str(saved),
                                 "--label", "P3", "--set", "beta=3"])
    assert code == 2 and "beta = 3 given, 2.666666667 saved" in err
    # the API's restart finds the model file from the saved curve
    from maglev_match.analyses.restart import restart

    curve, rs = restart(saved, "P3", bounds={"rho": (5.0, 200.0), "sigma": (5.0, 40.0)},
                        max_step=0.05)
    assert rs.names == ("rho", "sigma")
    v = curve.values()
    np.testing.assert_allclose(v[:, 0], v[:, 1] * (v[:, 1] + beta + 3) / (v[:, 1] - beta - 1),
                               rtol=1e-8)


def test_equilibrium_branch_restart_finds_the_same_special_points(tmp_path):
    """The S-shaped equilibrium curve mu = x^3 - x with Hopf points at x = -1.2 and x = 0.8
    (mu = -0.528, -0.288) and folds at mu = +-2/(3 sqrt 3): the saved branch restarted from
    a point between the second fold and the second Hopf point locates that Hopf point where
    the uninterrupted branch does, and the closed form says."""
    from systems import s_shaped_hopf

    from maglev_match.analyses.restart import (
        RestartFileError,
        load_equilibrium_restart,
        restart_equilibrium_branch,
        save_equilibrium_branch,
    )
    from maglev_match.dynamics.equilibria import equilibrium_branch

    system = s_shaped_hopf()
    full = equilibrium_branch(system, "mu", -2.0, 2.0)
    assert [str(s.type) for s in full.special_points] == ["H", "LP", "LP", "H"]
    path = save_equilibrium_branch(full, system, tmp_path / "eq.nc", model="s")
    x = full.states[:, 0]
    k = int(np.argmax((x > 0.62) & (x < 0.75)))  # past the second fold, before H2
    rs = load_equilibrium_restart(path, f"P{k}", system)
    assert rs.value == full.values[k] and np.array_equal(rs.x, full.states[k])
    rest, _ = restart_equilibrium_branch(path, f"P{k}", system, 2.0)
    assert [str(s.type) for s in rest.special_points] == ["H"]
    assert rest.special_points[0].value == pytest.approx(full.special_points[3].value,
                                                         abs=1e-10)
    assert rest.special_points[0].value == pytest.approx(0.8**3 - 0.8, abs=1e-10)
    for xs, v in zip(rest.states, rest.values, strict=True):  # the points are equilibria
        assert abs(v - (xs[0] ** 3 - xs[0])) < 1e-8 and abs(xs[1]) < 1e-8
    with pytest.raises(RestartFileError, match="no point 'P9999'"):
        load_equilibrium_restart(path, "P9999", system)


def test_design_ranges_refuse_constants_derived_values_and_meaningless_chi():
    """parse_vary refuses g, mu0 and derived quantities; check_vary_ranges accepts the
    README's beam range and refuses a range whose static deflection falls below W0_MIN
    (chi = h / w0 beyond ~1000), naming the point, before any index is computed."""
    from maglev_match.analyses.design import W0_MIN, check_vary_ranges, parse_vary
    from maglev_match.core.params import ParameterError, load_params

    for text, rule in (("g=1:20", "constant of nature"), ("mu0=1e-7:2e-6", "constant"),
                       ("w0=1e-4:1e-3", "derived"), ("i0=10:30", "derived"),
                       ("chi=1:10", "derived")):
        with pytest.raises(ParameterError, match=rule):
            parse_vary(text)
    base = load_params("turnout-soft")
    check_vary_ranges(base, [parse_vary("EI=5e9:4e10")])  # w0 0.4 .. 3.3 mm
    check_vary_ranges(base, [parse_vary("EI=5e9:4e10"), parse_vary("kD=80:250")])
    w0_at = base.replace(sigma=2e-6).w0
    assert w0_at < W0_MIN
    with pytest.raises(ParameterError, match="sigma = 1e-08") as err:
        check_vary_ranges(base, [parse_vary("sigma=1e-8:1e-3")])
    assert "has no physical meaning" in str(err.value)


def test_an_edited_hopf_curve_file_is_refused(capsys, tmp_path):
    """A saved Hopf curve whose model or number of states was edited is refused with the
    attribute named, not continued as model A (issue 31)."""
    import xarray as xr

    code, _, err = _run(capsys, ["hopf-curve", "--preset", "alpha1", "--range",
                                 "sigma=3e-4:5e-4", "--grid", "0", "--out", str(tmp_path),
                                 "--json"])
    assert code == 0, err
    ds = xr.load_dataset(tmp_path / "hopf_curve_unit_omega1_sigma.nc", engine="h5netcdf")
    for attr, value, words in (("model", "vehicle", "was saved for model 'vehicle', not for "
                                "model 'unit'"),
                               ("n_states", 13, "attribute n_states = 13 but 9 state names")):
        edited = ds.copy()
        edited.attrs[attr] = value
        path = tmp_path / f"edited_{attr}.nc"
        edited.to_netcdf(path, engine="h5netcdf")
        code, out, err = _run(capsys, ["hopf-curve", "--restart", str(path), "--label", "P3",
                                       "--grid", "0"])
        assert code == 2 and out == "", err
        assert words in err and err.count("\n") == 1, err
