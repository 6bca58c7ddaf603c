"""Design maps: input errors before work, resume equals one go bit for bit (headline index
included), the map agrees with the point-wise index, unstable points are their own
category, and the distributed path on a real Dask scheduler."""

import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from maglev_match.analyses.maps import Axis, MapSpec, map_dataset, parse_axis, run_map
from maglev_match.core.params import ParameterError, load_preset

BASE = load_preset("alpha1")


def small_spec(rows_per_tile=1, simulate=False):
    return MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 110.0, 140.0, 4),
                   y=Axis("sigma", 3e-4, 5e-4, 3), rows_per_tile=rows_per_tile, ntst=30,
                   simulate=simulate)


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


def test_a_large_grid_is_checked_on_its_edges_and_a_sub_grid_not_point_by_point():
    """A 2000 x 2000 grid: the parameter sets checked before any tile are its four edges
    and a 100 x 100 sub-grid (about 18k, not 4M: that took minutes, silently), and a rule
    broken inside the grid is broken on an edge, where the check finds it."""
    big = MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 40, 190, 2000),
                  y=Axis("sigma", 2e-4, 6e-4, 2000))
    pts = big._points_to_check()
    assert len(pts) == 4 * 2000 + 100 * 100
    on_edges = {(y, x) for y, x in pts if x in (40, 190) or y in (2e-4, 6e-4)}
    assert len(on_edges) == 4 * 2000 - 4
    big.validate()
    bad = MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 40, 190, 2000),
                  y=Axis("sigma", -1e-4, 6e-4, 2000))
    with pytest.raises(ParameterError, match="'sigma'"):
        bad.validate()
    # a small grid: every point, as before
    small = MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 40, 190, 50),
                    y=Axis("sigma", 2e-4, 6e-4, 40))
    assert len(small._points_to_check()) == 2000


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
    spec = small_spec(rows_per_tile=2, simulate=True)  # tiles (0, 2), (2, 3)
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
    stable = one_go["stable"].astype(bool)
    assert stable.any() and (~stable).any()
    # unstable points are their own category: no index there (not chi = 0)
    for name in ("chi", "chi_paper", "chi_simulation", "h", "h_simulation_up",
                 "h_simulation_down"):
        assert np.all(np.isnan(one_go[name][~stable])), name
    # the headline index is the smaller of its two parts at every resolved stable point
    ok = stable & one_go["resolved"].astype(bool)
    assert np.array_equal(ok, stable) and ok.sum() >= 6
    sim = np.minimum(one_go["h_simulation_up"], one_go["h_simulation_down"]) / one_go["w0"]
    np.testing.assert_array_equal(one_go["chi_simulation"][ok], sim[ok])
    np.testing.assert_array_equal(one_go["chi_paper"][ok], (one_go["h"] / one_go["w0"])[ok])
    np.testing.assert_array_equal(
        one_go["chi"][ok], np.minimum(one_go["chi_paper"], one_go["chi_simulation"])[ok])
    by_sim = one_go["chi_simulation"] < one_go["chi_paper"]
    np.testing.assert_array_equal(one_go["chi_basis"][ok], by_sim[ok].astype(np.int8))
    ds = map_dataset(spec, one_go, check=False)
    for name in ("chi", "chi_paper", "chi_simulation", "h_simulation_up", "h", "w0",
                 "stable", "max_real_part"):
        assert ds[name].dims == ("sigma", "omega1")
    assert ds["h_simulation_down"].attrs["units"] == "m" and ds["chi"].attrs["long_name"]
    assert "min(chi_paper, chi_simulation)" in ds.attrs["index_definition"]
    path = tmp_path / "m.nc"
    ds.to_netcdf(path, engine="h5netcdf")
    assert path.stat().st_size > 0


def test_map_row_agrees_with_pointwise_index(tmp_path):
    """h read off the branch continued along the row matches the point-wise index (which
    continues from the nearest Hopf point to the point itself)."""
    from maglev_match.analyses.matching import matching_index

    spec = MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 118.0, 130.0, 5),
                   y=Axis("sigma", 4e-4, 4.5e-4, 2), rows_per_tile=1, ntst=40,
                   simulate=False)
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
    from maglev_match.analyses.maps import compute_row
    from maglev_match.analyses.matching import matching_index

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


def test_row_without_a_hopf_point_on_its_path_takes_the_pointwise_index():
    """A row along kD = 148..152 on the soft turnout beam is stable along its whole path
    (extension included) and meets no Hopf point, yet an unstable cycle born at a Hopf point
    along omega1 bounds the basin at each of its points. The row must not claim "no cycle
    within limits" (h = 10 mm, as it once did): its points agree with the point-wise
    index."""
    from maglev_match.analyses.maps import CASE_CODES, compute_row
    from maglev_match.analyses.matching import matching_index

    spec = MapSpec(base=load_preset("turnout-soft").as_input_dict(),
                   x=Axis("kD", 148.0, 152.0, 3), y=Axis("sigma", 4.718e-4, 4.8e-4, 2),
                   ntst=30)
    row = compute_row(spec, 0)
    assert row["stable"].all() and row["resolved"].all()
    for j, xv in enumerate(spec.x.values):
        point = matching_index(spec.point(xv, spec.y.values[0]), simulate=False)
        assert point.case == "unstable_cycle" and point.h < 9e-3
        assert row["case"][j] == CASE_CODES["unstable_cycle"]
        assert row["h"][j] == pytest.approx(point.h, rel=1e-9)


def test_unmatched_sign_change_is_unresolved_with_its_reason(monkeypatch):
    """If no Hopf point can be matched to a sign change of max Re (here: the Hopf search
    made to find nothing), the stable points next to it are unresolved with reason code
    REASON_NO_HOPF, never silently given h = gap_max - c0."""
    import maglev_match.dynamics.hopf as hopf
    from maglev_match.analyses.maps import REASON_CODES, REASON_NO_HOPF, compute_row

    def nothing(system, param, start, stop, p=None, n_scan=200, progress=None):
        return hopf.HopfScan(param, start, stop, [], np.linspace(start, stop, 2),
                             np.zeros(2), ())

    import maglev_match.analyses.maps.rows as rows_mod

    monkeypatch.setattr(hopf, "locate_hopf_points", nothing)  # the fine re-scan
    monkeypatch.setattr(rows_mod, "scan_hopf_points", lambda *args: [])  # the row scan
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
    from maglev_match.analyses.maps import spot_check

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


# ---------------------------------------------------------------------------------------
# the headline index: min(chi_paper, chi_simulation), checked against the point-wise index
# ---------------------------------------------------------------------------------------
@pytest.mark.slow
def test_headline_map_equals_pointwise_index_at_every_spot_point():
    """A 10 x 10 map of the headline index: at every spot point the map's headline chi
    equals the point-wise index's min(chi_paper, chi_simulation) within the stated search
    tolerance, and each direction's simulated critical disturbance equals the point-wise
    search's within that tolerance (both bracket the critical size to it)."""
    import json

    from maglev_match.analyses.maps import compute_tile, simulation_settings

    base = load_preset("turnout-soft")
    spec = MapSpec(base=base.as_input_dict(), x=Axis("omega1", 60.0, 80.0, 10),
                   y=Axis("sigma", 3e-4, 4e-4, 10), rows_per_tile=5)
    parts = [compute_tile(spec, t) for t in spec.tiles]
    data = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    assert data["resolved"].all() and data["stable"].all()
    tol = simulation_settings().tol
    ds = map_dataset(spec, data, seed=3, fraction=0.04)
    a = ds.attrs
    cols = json.loads(a["spot_check_columns"])
    recs = [dict(zip(cols, r, strict=True)) for r in json.loads(a["spot_check_records"])]
    assert len(recs) == 4 and a["spot_check_points"] == 4
    for r in recs:
        for key in ("up", "down"):
            assert abs(r[f"h_simulation_{key}_map"] - r[f"h_simulation_{key}_point"]) <= tol
        assert abs(r["chi_map"] - r["chi_point"]) <= r["chi_allowed_diff"]
        # both decided by the simulation here: the allowance is the search tolerance / w0
        i, j = list(ds["sigma"].values).index(r["y"]), list(ds["omega1"].values).index(r["x"])
        assert r["chi_allowed_diff"] == pytest.approx(tol / float(ds["w0"][i, j]), rel=1e-9)
    assert a["spot_check_headline_passed"] == 1 and a["spot_check_passed"] == 1
    assert a["spot_check_simulation_max_diff"] <= tol
    # here the simulation gives the smaller index everywhere (no cycle within the gap range)
    assert np.all(data["chi_basis"] == 1)
    assert np.all(data["chi"] < data["chi_paper"])


def test_no_simulation_map_is_the_papers_index_and_says_so():
    from maglev_match.analyses.maps import compute_tile

    spec = small_spec()
    data = compute_tile(spec, (1, 2))
    stable = data["stable"].astype(bool)
    np.testing.assert_array_equal(data["chi"][stable], data["chi_paper"][stable])
    assert np.all(np.isnan(data["chi_simulation"])) and np.all(np.isnan(data["h_simulation_up"]))
    assert np.all(np.isnan(data["chi"][~stable]))
    ds = map_dataset(spec, {k: np.repeat(v, 3, axis=0) for k, v in data.items()}, check=False)
    assert "paper's definition only" in ds.attrs["index_definition"]
    assert "not run" in ds.attrs["simulation"]
    # old tiles cannot be reused: the fingerprint names the simulation and the variables
    on = small_spec(simulate=True)
    assert spec.key() != on.key()
    assert '"variables"' in on.key() and "chi_simulation" in on.key()


@pytest.mark.parametrize("undecided,code", [(True, 5), (False, 6)])
def test_unresolved_critical_disturbance_is_marked_with_its_reason(monkeypatch, undecided,
                                                                   code):
    """A critical disturbance the search cannot resolve leaves the point unresolved with
    its reason code; the headline is NaN there, never filled in; the paper's part stays."""
    import maglev_match.analyses.maps.simulated as simulated_mod
    from maglev_match.analyses.maps import REASON_CODES, compute_tile
    from maglev_match.dynamics.integrate.threshold import ThresholdBatch, ThresholdStatus

    def nothing(P, directions, guesses=None, spreads=None, *, gap_limits, cost=None):
        n = len(P)
        nan = np.full(n, np.nan)
        return ThresholdBatch(
            status=np.array([ThresholdStatus.OPEN] * n, dtype=object), size=nan,
            largest_return=nan, smallest_collision=nan, collision_time=nan,
            runs=np.full(n, 4), unresolved=np.full(n, 2 if undecided else 0),
            nonmonotone=np.zeros(n, bool), steps=np.zeros(n, int), tol=1e-5, rounds=3)

    monkeypatch.setattr(simulated_mod, "critical_sizes_batch", nothing)
    data = compute_tile(small_spec(simulate=True), (1, 2))
    stable = data["stable"].astype(bool)
    assert stable.any()
    assert not data["resolved"][stable].any()
    assert np.all(data["reason"][stable] == code) and np.all(data["reason"][~stable] == 0)
    assert np.all(np.isnan(data["chi"][stable]))
    assert np.all(np.isfinite(data["chi_paper"][stable]))
    assert "critical disturbance" in REASON_CODES[code]


def test_dask_messages_go_to_the_log_not_the_terminal(tmp_path):
    """Dask's warnings (a port in use) and log records (a worker killed at shutdown) land in
    the map's log file while a map runs, not on the terminal (here: a stand-in for Dask's
    stderr handler and for the terminal's warning hook); with echo (--debug) they reach
    the terminal as well."""
    import io
    import logging
    import warnings

    import distributed

    from maglev_match.core.jobs import dask_log_capture

    node = str(Path(distributed.__file__).parent / "node.py")
    log = tmp_path / "map.log"
    terminal = io.StringIO()
    dask_handler = logging.StreamHandler(terminal)  # as Dask's own handler on stderr
    logging.getLogger("distributed").addHandler(dask_handler)
    shown: list[str] = []

    def chatter():
        warnings.warn_explicit("Port 8787 is already in use.", UserWarning, node, 195)
        warnings.warn_explicit("a warning of this package", UserWarning, __file__, 1)
        logging.getLogger("distributed.nanny").warning(
            "Worker process still alive after 4.0 seconds, killing")

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = lambda m, *a, **k: shown.append(str(m))
            with dask_log_capture(log):
                chatter()
            quiet, shown[:] = list(shown), []
            quiet_text = terminal.getvalue()
            with dask_log_capture(log, echo=True):
                chatter()
            loud = list(shown)
    finally:
        logging.getLogger("distributed").removeHandler(dask_handler)
    assert quiet == ["a warning of this package"]  # other warnings still shown
    assert "still alive" not in quiet_text
    assert any("8787" in w for w in loud) and "still alive" in terminal.getvalue()
    text = log.read_text()
    assert text.count("Port 8787 is already in use") == 2
    assert text.count("Worker process still alive") == 2
    assert "a warning of this package" not in text
    # outside the block the loggers are as before
    assert dask_handler not in logging.getLogger("distributed").handlers
    assert not any(isinstance(h, logging.FileHandler)
                   for h in logging.getLogger("distributed").handlers)


def test_dask_exceptions_python_can_only_report_go_to_the_log(tmp_path, monkeypatch):
    """An exception raised where Python can only report it (sys.unraisablehook: "Exception
    ignored in ...") inside Dask's code goes to the log, not the terminal, while the
    capture runs (seen in the suite: distributed's GC diagnosis asserting in the middle of
    a speed sweep); one of any other code still reaches the previous hook."""
    import gc
    import sys
    from types import SimpleNamespace

    import distributed.gc

    from maglev_match.core.jobs import dask_log_capture

    reported = []
    monkeypatch.setattr(sys, "unraisablehook", lambda args: reported.append(args.object))

    class Other:
        def __del__(self):
            raise AssertionError("of this package")

    dask_callback = distributed.gc.GCDiagnosis()._gc_callback  # a bound method of Dask's
    log = tmp_path / "map.log"
    with dask_log_capture(log):
        sys.unraisablehook(SimpleNamespace(exc_type=AssertionError, exc_value=AssertionError(),
                                           exc_traceback=None, err_msg=None,
                                           object=dask_callback))
        Other()
        gc.collect()
    assert len(reported) == 1 and type(reported[0]).__name__ == "function"
    assert "exception ignored in" in log.read_text() and "GCDiagnosis" in log.read_text()
    # after the block: the previous hook again, Dask's included
    sys.unraisablehook(SimpleNamespace(exc_type=ValueError, exc_value=ValueError(),
                                       exc_traceback=None, err_msg=None, object=dask_callback))
    assert len(reported) == 2


def test_map_command_removes_its_tiles_after_success_unless_kept(tmp_path, capsys):
    from maglev_match.cli import main

    args = ["map", "--x", "omega1=120:140:2", "--y", "sigma=3e-4:4e-4:2", "--workers", "0",
            "--no-simulation"]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "a" / "map_omega1_sigma.nc").is_file()
    assert not (tmp_path / "a" / "map_omega1_sigma.nc.tiles").exists()
    assert "paper's definition only" in out
    assert main([*args, "--out", str(tmp_path / "b"), "--keep-tiles"]) == 0
    out = capsys.readouterr().out
    kept = tmp_path / "b" / "map_omega1_sigma.nc.tiles"
    assert kept.is_dir() and list(kept.glob("tile_*.npz"))
    assert f"checkpoint tiles kept in {kept}" in out


def test_delay_axis_extension_stays_within_the_discretisation_bound():
    """A row along tau is extended beyond the grid only as far as the discretisation
    resolves a delay (else a valid axis near the bound, tau = 0..0.05 s, failed in every row
    when its extension reached 0.075 s); the grid's own bound is refused up front."""
    from maglev_match.analyses.maps import row_extension
    from maglev_match.core.params import ParameterError
    from maglev_match.dynamics.delay import max_delay_for
    from maglev_match.maglev.unit import unit_dde

    base = load_preset("turnout-soft").as_input_dict()
    for stop in (0.004, 0.05):
        spec = MapSpec(base=base, x=Axis("tau", 0.0, stop, 3), y=Axis("kD", 100.0, 150.0, 2))
        bound = max_delay_for(unit_dde(spec.point(stop, 100.0)).rate_bound())
        lo, hi = row_extension(spec, spec.x.values, 100.0)
        assert lo == []  # a negative delay is not a parameter set
        assert all(x <= bound for x, _ in hi)
        assert len(hi) == min(2, int((bound - stop) // (stop / 2)))
    with pytest.raises(ParameterError, match="the delay must be at most"):
        MapSpec(base=base, x=Axis("tau", 0.0, 1.0, 2), y=Axis("kD", 100.0, 150.0, 2)).validate()
