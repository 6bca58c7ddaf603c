"""Design maps: input errors before work, resume equals one go bit for bit, the map agrees
with the point-wise index, and the distributed path on a real Dask scheduler."""

import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from maglev_match.maps import Axis, MapSpec, map_dataset, parse_axis, run_map
from maglev_match.params import ParameterError, load_preset

BASE = load_preset("alpha1")


def small_spec(rows_per_tile=1):
    return MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 110.0, 140.0, 4),
                   y=Axis("sigma", 3e-4, 5e-4, 3), rows_per_tile=rows_per_tile, ntst=30)


@pytest.mark.parametrize(
    "text,fragment",
    [
        ("omega1=190:40:10", "empty or reversed"),
        ("omega1=40:40:10", "empty or reversed"),
        ("omega1=40:190:1", "at least 2"),
        ("omega9=40:190:10", "unknown parameter 'omega9'"),
        ("omega1=40:190", "three numbers"),
        ("omega1=a:190:3", "must be numbers"),
        ("omega1", "NAME=START:STOP:COUNT"),
    ],
)
def test_axis_errors(text, fragment):
    with pytest.raises(ParameterError) as err:
        parse_axis(text, "--x")
    assert fragment in str(err.value) and "--x" in str(err.value)


def test_invalid_grid_point_rejected_before_work():
    spec = MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 40, 190, 5),
                   y=Axis("sigma", -1e-4, 6e-4, 5))
    with pytest.raises(ParameterError, match="'sigma'"):
        spec.validate()


def test_grid_too_large_rejected():
    spec = MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 40, 190, 5000),
                   y=Axis("sigma", 2e-4, 6e-4, 5000))
    with pytest.raises(ParameterError, match="fit in memory"):
        spec.validate()


def test_engineering_axes_derive_omega1_and_sigma():
    base = load_preset("turnout-soft")
    spec = MapSpec(base=base.as_input_dict(), x=Axis("L", 10, 30, 3), y=Axis("EI", 1e10, 4e10, 3))
    p = spec.point(18.0, 1.96e10)
    assert p.omega1 == pytest.approx(base.omega1, rel=1e-12)
    assert p.sigma == pytest.approx(base.sigma, rel=1e-12)


def test_resumed_map_equals_one_go_bit_for_bit(tmp_path):
    spec = small_spec()
    one_go = run_map(spec, tmp_path / "a", workers=0)
    partial_dir = tmp_path / "b"
    run_map_partial = None
    try:
        run_map_partial = run_map(spec, partial_dir, workers=0, max_tiles=1)
    except RuntimeError as exc:  # interrupted: tiles missing
        assert "run again with --resume" in str(exc)
    assert run_map_partial is None
    assert len(list(partial_dir.glob("tile_*.npz"))) == 1
    resumed = run_map(spec, partial_dir, workers=0, resume=True)
    for k in one_go:
        np.testing.assert_array_equal(one_go[k], resumed[k], err_msg=k)
    # the map has both stable and unstable points and an unstable-cycle case in between
    assert one_go["stable"].any() and (~one_go["stable"]).any()
    assert np.all(one_go["chi"][~one_go["stable"]] == 0.0)
    ds = map_dataset(spec, one_go)
    for name in ("chi", "h", "w0", "stable", "max_real_part"):
        assert ds[name].dims == ("sigma", "omega1")
    path = tmp_path / "m.nc"
    ds.to_netcdf(path, engine="h5netcdf")
    assert path.stat().st_size > 0


def test_map_row_agrees_with_pointwise_index(tmp_path):
    """h read off the branch continued along the row matches the point-wise index (which
    continues from the nearest Hopf point to the point itself)."""
    from maglev_match.matching import matching_index

    spec = MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 118.0, 130.0, 5),
                   y=Axis("sigma", 4e-4, 4.5e-4, 2), rows_per_tile=1, ntst=40)
    data = run_map(spec, tmp_path / "c", workers=0)
    j = 2  # omega1 = 124 at sigma = 4e-4
    assert data["case"][0, j] == 1
    point = matching_index(BASE.replace(omega1=124.0, sigma=4e-4), simulate=False)
    assert data["h"][0, j] == pytest.approx(point.h, rel=2e-2)


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_distributed_map_on_real_scheduler_and_two_workers(tmp_path):
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
         "--port", str(port), "--no-dashboard"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        time.sleep(3)
        for _ in range(2):
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", addr, "--nthreads", "1",
                 "--nworkers", "1", "--no-dashboard"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from dask.distributed import Client

        with Client(addr, timeout=60) as c:
            c.wait_for_workers(2, timeout=120)
            assert len(c.scheduler_info()["workers"]) == 2
        spec = small_spec()
        remote = run_map(spec, tmp_path / "d", scheduler=addr)
        local = run_map(spec, tmp_path / "e", workers=0)
        for k in local:
            np.testing.assert_array_equal(local[k], remote[k], err_msg=k)
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


# ---------------------------------------------------------------------------------------
# maps check themselves
# ---------------------------------------------------------------------------------------
KD_ROWS = MapSpec(base=load_preset("turnout-soft").as_input_dict(),
                  x=Axis("omega1", 60.0, 140.0, 13),
                  y=Axis("kD", 80.0 + 10 * 170.0 / 12, 80.0 + 11 * 170.0 / 12, 2), ntst=30)


def test_row_with_hopf_point_just_outside_the_grid_matches_pointwise_index():
    """`map --x omega1=60:140:13 --y kD=80:250:13`, row kD = 221.7: the Hopf point lies
    just beyond omega1 = 140; its cycle bounds the basin at omega1 = 133.3. The map once
    missed it (coarse extension) and gave h = 10 mm; the point-wise index gives 5.156 mm."""
    from maglev_match.maps import compute_row
    from maglev_match.matching import matching_index

    row = compute_row(KD_ROWS, 0)
    j = 11
    assert KD_ROWS.x.values[j] == pytest.approx(133.33333333333334)
    point = matching_index(KD_ROWS.point(KD_ROWS.x.values[j], KD_ROWS.y.values[0]),
                           simulate=False)
    assert point.case == "unstable_cycle"
    assert point.h == pytest.approx(5.156e-3, rel=1e-3)
    assert row["resolved"][j]
    assert row["case"][j] == 1
    assert row["h"][j] == pytest.approx(point.h, rel=3e-2)
    # the distance to that Hopf point is measured in omega1 (rad/s), beyond the grid too
    hopf_w = point.hopf_value
    assert row["hopf_distance"][-1] == pytest.approx(abs(hopf_w - 140.0), rel=1e-6)


def test_unmatched_sign_change_is_unresolved_with_its_reason(monkeypatch):
    """If no Hopf point can be matched to a sign change of max Re (here: the Hopf search
    made to find nothing), the stable points next to it are unresolved with reason code
    REASON_NO_HOPF, never silently given h = gap_max - c0."""
    import maglev_match.dynamics.hopf as hopf
    from maglev_match.maps import REASON_CODES, REASON_NO_HOPF, compute_row

    def nothing(system, param, start, stop, p=None, n_scan=200, progress=None):
        return hopf.HopfScan(param, start, stop, [], np.linspace(start, stop, 2),
                             np.zeros(2), ())

    import maglev_match.maps as maps_mod

    monkeypatch.setattr(hopf, "locate_hopf_points", nothing)  # the fine re-scan
    monkeypatch.setattr(maps_mod, "_scan_hopf_points", lambda *args: [])  # the row scan
    spec = small_spec()
    row = compute_row(spec, 1)  # sigma = 4e-4: stable below the Hopf point, unstable above
    stable = row["stable"]
    assert stable.any() and (~stable).any()
    assert not row["resolved"][stable].any()
    assert np.all(row["reason"][stable] == REASON_NO_HOPF)
    assert np.all(np.isnan(row["h"][stable]))
    assert row["resolved"][~stable].all() and np.all(row["h"][~stable] == 0.0)
    assert "without a Hopf" in REASON_CODES[REASON_NO_HOPF]


def test_spot_check_catches_a_wrong_map(tmp_path):
    from maglev_match.maps import spot_check

    spec = small_spec()
    data = run_map(spec, tmp_path / "s", workers=0)
    ok = spot_check(spec, data, fraction=1.0, max_points=5, seed=1)
    recs = __import__("json").loads(ok["spot_check_records"])
    assert any(r[3] > 0 for r in recs)  # at least one stable point checked
    assert ok["spot_check_passed"] == 1 and ok["spot_check_max_rel_diff"] < 3e-2
    wrong = dict(data, h=data["h"] * 1.5)
    bad = spot_check(spec, wrong, fraction=1.0, max_points=5, seed=1)
    assert bad["spot_check_passed"] == 0
    assert bad["spot_check_max_rel_diff"] == pytest.approx(0.5, abs=0.05)
    assert "spot check" in bad["warnings"]
    ds = map_dataset(spec, data)
    assert "reason" in ds and "spot_check_max_rel_diff" in ds.attrs
