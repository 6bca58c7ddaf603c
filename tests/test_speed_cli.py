"""The command line at speed: `speed`, `simulate --speed V --spans N`, `map --x v=...`; one
answer across text, JSON, files and the API; bad input refused before any work; sweeps
resumed from their checkpoint tiles."""

from __future__ import annotations

import contextlib
import io
import json
import math

import numpy as np
import pytest

from maglev_match import load_preset
from maglev_match.analyses.speed.sweep import KMH, SpeedOptions, speed_point, speed_sweep
from maglev_match.cli import main

# the same models as tests/test_speed.py (their compiled kernels are shared)
FORCE_SETS = ["--set", "n_modes=1", "--set", "xi1=0", "--set", "omega1=10"]
UNIT_SETS = ["--set", "n_modes=1"]


def run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.mark.parametrize("argv, name", [
    (["speed", "--from", "-5"], "--from"),
    (["speed", "--step", "0"], "--step"),
    (["speed", "--from", "20", "--to", "10"], "--to"),
    (["speed", "--to", "1000"], "--to"),
    (["speed", "--to", "nan"], "--to"),
    (["speed", "--model", "train"], "--model"),
    (["speed", "--spans", "0"], "--spans"),
    (["speed", "--set", "sigma=4e-4"], "sigma"),
    (["speed", "--set", "l=18"], "'l'"),
    (["speed", "--set", "l=19"], "'l'"),
    (["speed", "--model", "vehicle", "--set", "s0=8.5"], "s0"),
    (["simulate", "--speed", "-10"], "--speed"),
    (["simulate", "--speed", "0"], "--speed"),
    (["simulate", "--speed", "60", "--spans", "0"], "--spans"),
    (["simulate", "--spans", "3"], "--spans"),
    (["simulate", "--speed", "60", "--model", "bus"], "--model"),
    (["map", "--x", "v=10:5:3", "--y", "EI=1e10:2e10:2"], "--x"),
    (["map", "--x", "v=0:50:1", "--y", "EI=1e10:2e10:2"], "--x"),
    (["map", "--x", "v=0:50:2", "--y", "v=0:50:2"], "--y"),
])
def test_bad_input_is_one_line_exit_2_before_work(argv, name, tmp_path):
    """Negative or zero speeds where meaningless, a vehicle as long as the span or longer,
    spans too few, an unknown model: exit 2 with one line naming the field, no traceback."""
    code, out, err = run([*argv, "--out", str(tmp_path / "o")])
    assert code == 2, (argv, code, err)
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and name in lines[0], (argv, err)
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_speed_command_agrees_with_closed_form_and_api(tmp_path):
    """`speed --model force` from 0: v = 0 gives the static values (DAF 1, nothing moving),
    the JSON, the netCDF file and the API agree, and the DAF at speed is Fryba's."""
    code, out, err = run(["speed", "--model", "force", "--from", "0", "--to", "200",
                          "--step", "100", *FORCE_SETS, "--workers", "0", "--json",
                          "--out", str(tmp_path / "sweep")])
    assert code == 0, err
    res = json.loads(out)
    assert res["speeds"] == pytest.approx([0.0, 100 * KMH, 200 * KMH])
    pts = res["points"]
    assert pts[0]["daf"] == pytest.approx(1.0, rel=1e-12)
    p = load_preset("turnout-soft").replace(n_modes=1, xi1=0.0, omega1=10.0)
    api = speed_point(p, "force", 200 * KMH)
    assert pts[2]["daf"] == pytest.approx(api.daf, rel=1e-12)
    # Fryba, below resonance: the maximum of (sin(Om t) - a sin(w t)) / (1 - a^2)
    a = math.pi * 200 * KMH / (p.L * 10.0)
    t = np.linspace(0.0, p.L / (200 * KMH), 400_001)
    daf = np.max((np.sin(a * 10.0 * t) - a * np.sin(10.0 * t)) / (1 - a**2))
    assert pts[2]["daf"] == pytest.approx(daf, rel=1e-6)
    import xarray as xr

    with xr.open_dataset(tmp_path / "sweep" / "speed_force.nc") as ds:
        assert ds["speed"].attrs["units"] == "m/s"
        assert ds["daf"].values[2] == pytest.approx(pts[2]["daf"], rel=1e-15)
        assert ds.attrs["model"] == "force"
    assert (tmp_path / "sweep" / "speed_force.png").stat().st_size > 0
    assert not (tmp_path / "sweep" / "speed_force.nc.tiles").exists()


def test_speed_text_output_of_the_unit(tmp_path):
    """The table and the summary lines print the numbers the API computes."""
    code, out, err = run(["speed", "--from", "60", "--to", "60", "--step", "5", *UNIT_SETS,
                          "--no-critical", "--workers", "0", "--out", str(tmp_path)])
    assert code == 0, err
    p = load_preset("turnout-soft").replace(n_modes=1)
    pt = speed_point(p, "unit", 60 * KMH, SpeedOptions(critical=False))
    assert f"{pt.largest_multiplier:.4f}" in out and f"{pt.daf:.4f}" in out
    assert f"{pt.wz:.3f}" in out
    assert "stable at every speed from 60 to 60 km/h" in out
    assert "speed_unit.nc" in out


def test_simulate_over_spans_command(tmp_path):
    """`simulate --speed V --spans N`: N spans crossed, each span's deflection reported,
    the history written with the periodic response beside it."""
    code, out, err = run(["simulate", "--speed", "60", "--spans", "3", *UNIT_SETS,
                          "--no-limits", "--json", "--out", str(tmp_path / "run.nc")])
    assert code == 0, err
    res = json.loads(out)
    assert res["outcome"] == "ok" and res["spans"] == 3
    assert len(res["span_midspan_max"]) == 3
    assert res["speed"] == pytest.approx(60 * KMH)
    import xarray as xr

    with xr.open_dataset(tmp_path / "run.nc") as ds:
        assert ds["midspan"].shape[1] == 3
        assert "periodic_gap_deviation" in ds
        assert ds["time"].attrs["units"] == "s"
        current = ds["current"].values
    # the figure shows what the docs promise: gap, coil current, body, spans
    from maglev_match.analyses.speed.spans import simulate_over_spans
    from maglev_match.plots.speed import span_run_figure

    p = load_preset("turnout-soft").replace(n_modes=1)
    fig = span_run_figure(simulate_over_spans(p, "unit", 60 * KMH, 3, limited=False))
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == ["gap deviation (mm)", "coil current (A)",
                      "car-body acceleration (m/s^2)", "mid-span deflection (mm, down)"]
    assert np.array_equal(fig.axes[1].lines[0].get_ydata(), current[:, 0])


def test_map_with_a_speed_axis(tmp_path):
    """`map --x v=...` (km/h) maps the read-outs at speed; the file holds v in m/s."""
    code, out, err = run(["map", "--x", "v=100:200:2", "--y", "omega1=10:11:2", "--model",
                          "force", "--set", "n_modes=1", "--set", "xi1=0", "--workers", "0",
                          "--json", "--out", str(tmp_path / "m.nc")])
    assert code == 0, err
    import xarray as xr

    with xr.open_dataset(tmp_path / "m.nc") as ds:
        assert ds["v"].attrs["units"] == "m/s"
        assert ds["v"].values == pytest.approx([100 * KMH, 200 * KMH])
        assert ds["daf"].shape == (2, 2)
        assert np.all(ds["stable"].values == 1)


def test_sweep_resumes_from_its_tiles(tmp_path):
    """A sweep with a checkpoint folder resumes: a removed tile is recomputed, the others
    are read, and the result equals the sweep computed in one go."""
    p = load_preset("turnout-soft").replace(n_modes=1, xi1=0.0, omega1=10.0)
    speeds = [20 * KMH, 40 * KMH, 60 * KMH]
    folder = tmp_path / "tiles"
    done = []
    first = speed_sweep(p, "force", speeds, checkpoint=folder, workers=0)
    tiles = sorted(folder.glob("tile_*.npz"))
    assert len(tiles) == 3
    tiles[1].unlink()
    again = speed_sweep(p, "force", speeds, checkpoint=folder, workers=0, resume=True,
                        progress=lambda d, t: done.append(d))
    assert done[0] == 2 and done[-1] == 3
    assert [q.daf for q in again.points] == [q.daf for q in first.points]


def test_api_speed_sweep_plot_and_dataset():
    """`maglev_match.speed_sweep` takes the km/h range of the command line, returns the
    points, the dataset and the figure."""
    import maglev_match as mm

    sw = mm.speed_sweep("turnout-soft", model="force", kmh=(0.0, 100.0, 50.0), n_modes=1,
                        xi1=0.0, omega1=10.0)
    assert [round(p.speed_kmh, 9) for p in sw.points] == [0.0, 50.0, 100.0]
    ds = sw.to_xarray()
    assert ds["daf"].attrs["units"] == "1" and ds["speed"].attrs["units"] == "m/s"
    assert ds["daf"].values[1] == pytest.approx(sw.points[1].daf)
    fig = sw.plot()
    assert len(fig.axes) == 5


def test_a_sweep_on_dask_keeps_dasks_messages_off_the_terminal(monkeypatch, capfd):
    """`speed --workers 2` printed Dask's "Worker process still alive after 4.0 seconds,
    killing" on every run: the sweep's pieces now run inside the capture of Dask's loggers
    (here a stand-in for the cluster computes them and logs that line as the nanny does)."""
    import logging

    import maglev_match.core.jobs as jobs

    def fake_dask(tasks, save, scheduler, workers, progress, count):
        for key, (fn, args) in tasks.items():
            save(key, fn(*args))
            count.done += 1
        logging.getLogger("distributed.nanny").warning(
            "Worker process still alive after 4.0 seconds, killing")

    monkeypatch.setattr(jobs, "run_pieces_on_dask", fake_dask)
    logging.getLogger("distributed").addHandler(logging.StreamHandler())  # as Dask's own
    try:
        code, out, err = run(["speed", "--from", "60", "--to", "60", "--no-critical",
                              *UNIT_SETS, "--workers", "2", "--json"])
    finally:
        for h in list(logging.getLogger("distributed").handlers):
            if type(h) is logging.StreamHandler:
                logging.getLogger("distributed").removeHandler(h)
    assert code == 0, err
    assert "still alive" not in err + capfd.readouterr().err
