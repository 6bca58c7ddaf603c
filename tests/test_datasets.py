"""Every netCDF file the package writes describes itself: units and long_name on every
variable and coordinate, the parameter set and the package version as attributes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import maglev_match as mm
from maglev_match.cli import main as cli_main
from maglev_match.core.datasets import annotate, simulation_dataset, state_units

SRC = Path(__file__).resolve().parents[1] / "src" / "maglev_match"


def _check_self_describing(path: Path, params: mm.Params) -> xr.Dataset:
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        ds = ds.load()
    for name in list(ds.data_vars) + list(ds.coords):
        attrs = ds[name].attrs
        assert attrs.get("units"), f"{path.name}: '{name}' has no units"
        assert attrs.get("long_name"), f"{path.name}: '{name}' has no long_name"
    assert ds.attrs["maglev_match_version"] == mm.__version__
    stored = json.loads(ds.attrs["params"])
    for k, v in params.as_dict().items():
        assert stored[k] == pytest.approx(v, rel=0, abs=0), k
    return ds


def test_the_writers_are_the_ones_checked_here():
    """If a new netCDF writer appears, this test names it so that it gets a check below."""
    writers = sorted(str(p.relative_to(SRC)) for p in SRC.rglob("*.py")
                     if re.search(r"\.to_netcdf\(|atomic_write_netcdf\(", p.read_text())
                     and p.name != "io.py")  # (io.py: the one atomic writer they all call)
    assert writers == ["analyses/restart/equilibria.py", "analyses/simulation.py",
                       "cli/cycle_curve.py", "cli/cycles.py", "cli/hopf.py", "cli/index.py",
                       "cli/iso_curve.py", "cli/speed.py"], writers


def test_saved_iso_curve_is_self_describing(tmp_path):
    """The netCDF of `iso-curve` (the paper's chi alone, the start point only): units and
    long names on every variable, the version and the parameter set it was computed at."""
    assert cli_main(["iso-curve", "chi=9", "--params", "EI,kD", "--range", "EI=1.5e10:3e10",
                     "--range", "kD=120:180", "--no-simulation", "--points", "1", "--out",
                     str(tmp_path / "i"), "--json"]) == 0
    ncs = sorted((tmp_path / "i").glob("*.nc"))
    assert len(ncs) == 1
    ds = _check_self_describing(ncs[0], mm.load_preset("turnout-soft"))
    assert ds.sizes["point"] == 1


def test_saved_cycle_curve_is_self_describing(tmp_path):
    """The netCDF of `cycle-curve` (model A's fold of cycles, a few steps): units and long
    names on every variable, the version and the parameter set it was computed at."""
    params = mm.load_preset("alpha1").replace(xi0=0.7)
    assert cli_main(["cycle-curve", "--preset", "alpha1", "--set", "xi0=0.7", "--params",
                     "omega1,sigma", "--at", "sigma=4e-4", "--range", "sigma=3.9e-4:4.1e-4",
                     "--max-steps", "5", "--ntst", "40", "--out", str(tmp_path / "c"),
                     "--json"]) == 0
    ncs = sorted((tmp_path / "c").glob("*.nc"))
    assert len(ncs) == 1
    ds = _check_self_describing(ncs[0], params.replace(sigma=4e-4))
    assert ds.sizes["point"] >= 3


def test_saved_cycle_branch_and_hopf_curve_are_self_describing(tmp_path):
    params = mm.load_preset("alpha1")
    assert cli_main(["cycles", "--preset", "alpha1", "--param", "omega1", "--at", "sigma=4e-4",
                     "--ntst", "20", "--max-steps", "8", "--out", str(tmp_path / "c"),
                     "--json"]) == 0
    ncs = sorted((tmp_path / "c").glob("*.nc"))
    assert ncs
    for nc in ncs:
        _check_self_describing(nc, params.replace(sigma=4e-4))
    assert cli_main(["hopf-curve", "--preset", "alpha1", "--range", "sigma=3e-4:5e-4",
                     "--grid", "0", "--out", str(tmp_path / "h"), "--json"]) == 0
    ncs = sorted((tmp_path / "h").glob("*.nc"))
    assert ncs
    for nc in ncs:
        _check_self_describing(nc, params)


@pytest.mark.parametrize("model,extra", [("unit", ["--x5", "-7e-3"]),
                                         ("vehicle", ["--initial", "pressed"])])
def test_simulation_netcdf_is_self_describing(tmp_path, model, extra):
    out = tmp_path / f"run_{model}.nc"
    rc = cli_main(["simulate", "--model", model, "--t", "0.2", "--n-save", "51",
                   "--out", str(out), "--json", *extra])
    assert rc == 0
    ds = _check_self_describing(out, mm.load_preset("turnout-soft"))
    assert ds["time"].attrs["units"] == "s"
    assert ds["gap_deviation"].attrs["units"] == "m"
    assert ds["current"].attrs["units"] == "A"
    if model == "unit":
        assert ds["di"].attrs["units"] == "A"
        assert ds.attrs["outcome"] == "collision"
    else:
        assert ds["th0"].attrs["units"] == "rad"
        assert ds["q2_dot"].attrs["units"] == "m/s"


def test_map_netcdf_is_self_describing(tmp_path):
    out = tmp_path / "m.nc"
    rc = cli_main(["map", "--x", "omega1=120:140:2", "--y", "sigma=3e-4:4e-4:2",
                   "--preset", "alpha1", "--workers", "0", "--out", str(out), "--json"])
    assert rc == 0
    ds = _check_self_describing(out, mm.load_preset("alpha1"))
    assert ds["chi"].attrs["long_name"].startswith("headline matching index")
    assert ds["omega1"].attrs["units"] == "rad/s"


def test_speed_sweep_netcdf_is_self_describing(tmp_path):
    sets = ["--set", "n_modes=1", "--set", "xi1=0", "--set", "omega1=10"]
    rc = cli_main(["speed", "--model", "force", "--from", "0", "--to", "100", "--step", "100",
                   *sets, "--workers", "0", "--json", "--out", str(tmp_path / "s")])
    assert rc == 0
    ds = _check_self_describing(tmp_path / "s" / "speed_force.nc",
                                mm.load_preset("turnout-soft").replace(n_modes=1, xi1=0.0,
                                                                        omega1=10.0))
    assert ds["speed"].attrs["units"] == "m/s"


def test_state_units_cover_both_models():
    for model in ("unit", "vehicle"):
        for name in mm.build_system("turnout-soft", model).state_names:
            unit, long_name = state_units(name)
            assert unit and long_name != name, name


def test_annotate_refuses_an_undocumented_variable():
    ds = xr.Dataset({"mystery": ("t", np.zeros(2))}, coords={"t": [0.0, 1.0]})
    with pytest.raises(ValueError, match="mystery"):
        annotate(ds, long_names={"t": "time"})


def test_simulation_dataset_keeps_the_history():
    sim = mm.simulate("turnout-soft", x5=-1e-3, t_end=0.1, n_save=21)
    ds = simulation_dataset(sim)
    assert ds.identical(sim.to_xarray())
    assert repr(sim) == ("MaglevSimulation(model='unit', limited=True, t_end=0.1, "
                         f"outcome={sim.outcome!r}, saved_points=21)")
    np.testing.assert_array_equal(ds["w"].values, sim.result.x[:, 4])
    assert ds["gap_deviation"].values[0, 0] == pytest.approx(1e-3, rel=1e-12)


def test_root_locus_to_xarray_is_the_annotated_dataset():
    params = mm.load_preset("alpha1")
    res = mm.root_locus("omega1", np.linspace(100.0, 140.0, 5), "alpha1")
    ds = res.to_xarray(params)
    np.testing.assert_array_equal(ds["eigenvalue_real"].values, np.real(res.eigenvalues))
    assert ds["omega1"].attrs["units"] == "rad/s"
    assert json.loads(ds.attrs["params"])["kD"] == params.kD
