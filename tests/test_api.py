"""The public API at the package top level: every name imports, importing stays light, and
each function gives what the library (and the command line) gives."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

import maglev_match as mm
from maglev_match.api import resolve_params
from maglev_match.cli import main as cli_main
from maglev_match.dynamics.equilibria import stability as lib_stability
from maglev_match.maglev.models import build_system

PUBLIC = ("load_preset", "load_params", "Params", "System", "stability", "hopf_points",
          "hopf_curve", "cycle_branch", "simulate", "matching_index", "design_map",
          "ParameterError", "root_locus", "build_system", "index_sensitivity",
          "design_search", "study_report", "plot", "figure_of", "root_locus_figure",
          "hopf_curve_figure", "cycle_diagram", "simulation_figure", "map_figure",
          "tornado_figure", "design_path_figure", "hopf_scan_figure", "restart_branch",
          "speed_sweep")


def test_import_is_light_and_every_public_name_resolves():
    code = (
        "import sys, maglev_match as mm\n"
        "heavy = [m for m in ('jax', 'dask', 'xarray', 'matplotlib', 'scipy') if m in "
        "sys.modules]\n"
        "print(mm.__version__, heavy)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out[0] == mm.__version__
    assert out[1] == "[]", f"import maglev_match loaded heavy modules: {out[1:]}"
    for name in PUBLIC:
        assert name in mm.__all__, name
        assert getattr(mm, name) is not None
    with pytest.raises(AttributeError, match="no attribute 'nonsense'"):
        mm.nonsense  # noqa: B018


def test_load_model_exported():
    from maglev_match.maglev.user import load_model

    assert mm.load_model is load_model
    assert "load_model" in mm.__all__


def test_params_from_preset_name_and_overrides_equal_replace():
    p = mm.load_preset("alpha1")
    assert resolve_params("alpha1", kD=120.0) == p.replace(kD=120.0)
    assert resolve_params(p) is p
    assert resolve_params(None) == mm.load_preset("turnout-soft")
    # beam data derive omega1 and sigma, as on the command line
    q = resolve_params("turnout-soft", EI=2.26e10)
    assert q.omega1 == pytest.approx(104.51, abs=0.01)
    with pytest.raises(mm.ParameterError, match="kD"):
        mm.stability("alpha1", kD=-1.0)
    with pytest.raises(mm.ParameterError, match="nonsense"):
        mm.stability(nonsense=1.0)
    with pytest.raises(mm.ParameterError, match="model"):
        mm.stability(model="tram")


def test_stability_equals_library_and_model_b_has_40_states():
    p = mm.load_preset("alpha1")
    a = mm.stability(p)
    b = lib_stability(build_system(p, "unit"))
    np.testing.assert_array_equal(a.eigenvalues, b.eigenvalues)
    assert a.stable and a.margin > 0
    vb = mm.stability(p, model="vehicle")
    assert len(vb.eigenvalues) == 40
    assert isinstance(mm.build_system(p), mm.System)


def test_hopf_points_lie_where_the_margin_vanishes():
    scan = mm.hopf_points("alpha1", "omega1", 40.0, 190.0, n_scan=60)
    assert scan.points, "alpha1 has Hopf points along omega1 in 40..190 rad/s"
    for hp in scan.points:
        # independent check: a plain eigenvalue computation at the reported value
        res = mm.stability("alpha1", omega1=hp.value)
        assert abs(res.max_real_part) < 1e-6
        crossing = res.eigenvalues[np.argmin(np.abs(res.eigenvalues.real))]
        assert abs(abs(crossing.imag) - hp.frequency) < 1e-6 * hp.frequency
    with pytest.raises(mm.ParameterError, match="start"):
        mm.hopf_points(None, "omega1", 100.0, 50.0)
    with pytest.raises(mm.ParameterError, match="param"):
        mm.hopf_points(None, "zeta", 1.0, 2.0)


def test_root_locus_dataset_has_the_margin_of_stability():
    from maglev_match.core.datasets import root_locus_dataset

    p = mm.load_preset("alpha1")
    res = mm.root_locus(p, "omega1", [90.0, 100.0])
    assert res.max_real_part[1] == pytest.approx(mm.stability(p).max_real_part, abs=1e-12)
    ds = root_locus_dataset(res, p, mm.build_system(p).state_names)
    assert ds["eigenvalue_real"].dims == ("omega1", "index")
    assert ds["max_real_part"].attrs["units"] == "1/s"
    assert json.loads(ds.attrs["params"])["kD"] == p.kD


def test_hopf_curve_points_are_hopf_points():
    curves = mm.hopf_curve("alpha1", x=("omega1", 60.0, 160.0), y=("sigma", 3e-4, 5e-4),
                           n_scan=40, max_step=5e-2)
    assert curves and all(c.params == ("omega1", "sigma") for c in curves)
    pts = [pt for c in curves for pt in c.points]
    assert len(pts) >= 5
    for pt in pts[:: max(1, len(pts) // 4)]:
        res = mm.stability("alpha1", omega1=pt.values[0], sigma=pt.values[1])
        assert abs(res.max_real_part) < 1e-5


def test_cycle_branch_starts_at_the_hopf_frequency():
    br = mm.cycle_branch("alpha1", "omega1", ntst=20, max_steps=6)
    assert br.param == "omega1" and br.points
    first = br.points[0]
    assert first.period == pytest.approx(2 * np.pi / br.hopf.frequency, rel=2e-2)
    assert abs(first.value - br.hopf.value) < 0.05 * br.hopf.value
    with pytest.raises(mm.ParameterError, match="ncol"):
        mm.cycle_branch(ncol=9)


def test_simulate_collides_for_a_large_disturbance_and_matches_the_library():
    from maglev_match.analyses.simulation import initial_state, simulate_maglev

    p = mm.load_preset("turnout-soft")
    big = mm.simulate(p, x5=-7e-3, t_end=2.0, n_save=201)
    assert big.outcome == "collision" and big.collision_time < 2.0
    small = mm.simulate(p, x5=-1e-4, t_end=2.0, n_save=201)
    assert small.outcome in ("converged", "running")
    direct = simulate_maglev(p, "unit", initial_state(p, "unit", x5=-1e-4), 2.0, n_save=201)
    np.testing.assert_array_equal(small.result.x, direct.result.x)
    with pytest.raises(mm.ParameterError, match="t_end"):
        mm.simulate(p, t_end=0.0)


def test_matching_index_is_h_over_w0_and_equals_library():
    from maglev_match.analyses.matching import matching_index as lib_index

    p = mm.load_preset("alpha1")
    res = mm.matching_index(p, simulate=False)
    assert res.chi == pytest.approx(res.h / res.w0, rel=1e-12)
    assert res.w0 == pytest.approx(p.w0, rel=1e-12)
    assert res.chi == lib_index(p, simulate=False).chi


def test_design_map_in_memory_equals_cli_map_bit_for_bit(tmp_path):
    x, y = "omega1=110:140:3", "sigma=3e-4:5e-4:2"
    ds = mm.design_map("alpha1", x=("omega1", 110, 140, 3), y=("sigma", 3e-4, 5e-4, 2),
                       workers=0, kD=150.0)
    out = tmp_path / "cli" / "map.nc"
    assert cli_main(["map", "--x", x, "--y", y, "--preset", "alpha1", "--set", "kD=150",
                     "--workers", "0", "--out", str(out), "--json"]) == 0
    with xr.open_dataset(out, engine="h5netcdf") as disk:
        disk = disk.load()
    assert set(ds.data_vars) == set(disk.data_vars)
    for name in ds.data_vars:
        np.testing.assert_array_equal(ds[name].values, disk[name].values, err_msg=name)
        assert ds[name].dtype == disk[name].dtype, name
        assert ds[name].attrs == disk[name].attrs, name
    for name in ds.coords:
        np.testing.assert_array_equal(ds[name].values, disk[name].values)
    # every attribute equal but the spot check's wall time (a measurement, not a result)
    timing = {"spot_check_seconds"}
    assert ({k: v for k, v in ds.attrs.items() if k not in timing}
            == {k: v for k, v in disk.attrs.items() if k not in timing})
    assert timing <= set(ds.attrs) and timing <= set(disk.attrs)
    assert ds["chi"].dims == ("sigma", "omega1") and ds["chi"].shape == (2, 3)
    # the headline index is the smaller of its parts where stable; no index where unstable
    st = ds["stable"].values == 1
    assert st.any() and (~st).any()
    assert np.all(np.isnan(ds["chi"].values[~st]))
    np.testing.assert_array_equal(
        ds["chi"].values[st], np.minimum(ds["chi_paper"], ds["chi_simulation"]).values[st])
    # with a checkpoint folder the same map comes back
    again = mm.design_map(x, y, preset="alpha1", workers=0, kD=150.0,
                          checkpoint=tmp_path / "tiles")
    np.testing.assert_array_equal(again["chi"].values, ds["chi"].values)
    with pytest.raises(mm.ParameterError, match="x"):
        mm.design_map("omega1=190:40:3", y)


def test_earlier_signatures_still_work_warn_and_agree():
    """The forms before the one signature style give the same results, with a
    DeprecationWarning naming the new form."""
    p = mm.load_preset("alpha1")
    with pytest.warns(DeprecationWarning, match=r"hopf_points\(params, param"):
        old = mm.hopf_points("omega1", 40.0, 190.0, p, n_scan=40)
    new = mm.hopf_points(p, "omega1", 40.0, 190.0, n_scan=40)
    assert [h.value for h in old.points] == [h.value for h in new.points]
    with pytest.warns(DeprecationWarning, match=r"root_locus\(params"):
        old = mm.root_locus("omega1", [90.0, 100.0], p)
    np.testing.assert_array_equal(old.eigenvalues,
                                  mm.root_locus(p, "omega1", [90.0, 100.0]).eigenvalues)
    with pytest.warns(DeprecationWarning, match=r"cycle_branch\(params, param\)"):
        old = mm.cycle_branch("omega1", "alpha1", ntst=20, max_steps=3)
    assert old.values.tolist() == mm.cycle_branch("alpha1", ntst=20, max_steps=3).values.tolist()
    with pytest.warns(DeprecationWarning, match="names="):
        old = mm.hopf_curve("alpha1", names=("omega1", "sigma"),
                            bounds={"omega1": (60.0, 160.0), "sigma": (3e-4, 5e-4)},
                            n_scan=40, max_step=5e-2)
    new = mm.hopf_curve("alpha1", x=("omega1", 60.0, 160.0), y=("sigma", 3e-4, 5e-4),
                        n_scan=40, max_step=5e-2)
    np.testing.assert_array_equal(old[0].values(), new[0].values())
    # map axes: the strings of the command line and the keyword ranges are the same grid
    # (both forms are accepted: the command line passes its strings as they are)
    from maglev_match.api.maps import map_axis

    assert map_axis("omega1=40:190:4", "x") == "omega1=40:190:4"
    assert map_axis(("omega1", 40, 190, 4), "x") == "omega1=40.0:190.0:4"
    with pytest.raises(mm.ParameterError, match="count"):
        map_axis(("omega1", 40, 190, 2.5), "x")


def test_full_vehicle_index_sensitivities_and_figures_through_the_api(tmp_path,
                                                                      monkeypatch):
    """matching_index(p, model="vehicle") is the library's vehicle index; the
    sensitivities equal the library's; results with a figure draw it with .plot()."""
    import matplotlib.figure

    from maglev_match.analyses.matching import matching_index as lib_index
    from maglev_match.analyses.sensitivity import index_sensitivity as lib_sens

    p = mm.load_preset("turnout-soft")
    calls = []
    import maglev_match.analyses.matching as matching

    def record(params, **kw):  # the vehicle index itself is tested in test_matching_vehicle
        calls.append((params, kw))
        return "index"

    monkeypatch.setattr(matching, "matching_index", record)
    assert mm.matching_index(p, model="vehicle", simulate=False, kD=140.0) == "index"
    assert calls == [(p.replace(kD=140.0), {"model": "vehicle", "simulate": False,
                                            "stage": None})]
    monkeypatch.setattr(matching, "matching_index", lib_index)
    with pytest.raises(mm.ParameterError, match="model"):
        mm.matching_index(p, model="bus")
    sens = mm.index_sensitivity("alpha1", boundaries=False)
    ref = lib_sens(mm.load_preset("alpha1"), boundaries=False, model="unit")
    assert [(r.name, r.dchi) for r in sens.rows] == [(r.name, r.dchi) for r in ref.rows]
    assert isinstance(sens.plot(), matplotlib.figure.Figure)
    files = mm.root_locus(p, "omega1", np.linspace(90, 140, 11)).plot(tmp_path / "rl")
    assert {f.suffix for f in files} == {".png", ".svg"} and all(f.stat().st_size for f in files)
    assert isinstance(mm.hopf_points(p, "omega1", 40, 190, n_scan=30).plot(),
                      matplotlib.figure.Figure)
    with pytest.raises(TypeError, match="no figure"):
        mm.plot(object())


def test_design_search_takes_keyword_ranges_and_requirements():
    with pytest.raises(mm.ParameterError, match="minimize/maximize"):
        mm.design_search("turnout-soft", vary={"EI": (5e9, 4e10)})
    with pytest.raises(mm.ParameterError):
        mm.design_search("turnout-soft", vary={"EI": (-1.0, 4e10)}, minimize="EI")
    # a range whose static deflection falls below W0_MIN (chi meaningless) is refused before
    # any index is computed, as on the command line, and the message names `vary`
    with pytest.raises(mm.ParameterError, match="has no physical meaning") as err:
        mm.design_search("turnout-soft", vary={"sigma": (1e-8, 1e-3)}, maximize="chi")
    assert "'vary sigma'" in str(err.value)
