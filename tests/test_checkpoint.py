"""Map checkpoints: the folder lock, tile fingerprints, corrupt and foreign tiles."""

import json
import os
import subprocess
import sys
import textwrap
import time
import warnings

import numpy as np
import pytest

from maglev_match.analyses.maps import MAP_VARIABLES, Axis, MapSpec, run_map
from maglev_match.cli import main
from maglev_match.core.checkpoint import (
    CheckpointLocked,
    CheckpointWarning,
    TileStatus,
    check_tile,
    fingerprint,
    lock_folder,
    prepare_folder,
    save_tile,
    tile_path,
    usable_tiles,
)
from maglev_match.core.params import load_params

BASE = load_params("turnout-soft", sets=["omega1=124", "sigma=4e-4"])


def _spec(y_stop=5e-4, nx=3, ny=2, rows_per_tile=1):
    # the paper's index only: these tests are about the checkpoint, not the simulation
    return MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 115.0, 135.0, nx),
                   y=Axis("sigma", 3e-4, y_stop, ny), rows_per_tile=rows_per_tile, ntst=20,
                   simulate=False)


def _fake_tile(spec, rows, value):
    shape = (rows[1] - rows[0], spec.x.count)
    return {k: np.full(shape, value, dtype=float) for k in MAP_VARIABLES}


def test_fingerprint_separates_specs():
    a, b = _spec(), _spec(y_stop=6e-4)
    assert fingerprint(a.key()) == fingerprint(_spec().key())
    assert fingerprint(a.key()) != fingerprint(b.key())
    assert len(fingerprint(a.key())) == 64


def test_tile_of_another_grid_is_rejected(tmp_path):
    """Same tile names and shapes, different grid: the fingerprint tells them apart (the
    case of a resume after spec.json was deleted)."""
    a, b = _spec(), _spec(y_stop=6e-4)
    for t in a.tiles:
        save_tile(tmp_path, t, _fake_tile(a, t, 1.0), a.key())
    assert all(check_tile(tmp_path, t, a.key(), MAP_VARIABLES, 3).ok for t in a.tiles)
    (tmp_path / "spec.json").unlink(missing_ok=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        todo, rejected = usable_tiles(tmp_path, b.tiles, b.key(), MAP_VARIABLES, 3)
    assert todo == b.tiles
    assert {r.status for r in rejected} == {TileStatus.FOREIGN}
    msgs = [str(w.message) for w in caught if w.category is CheckpointWarning]
    assert len(msgs) == len(b.tiles)
    assert all("different map" in m for m in msgs)
    assert str(tile_path(tmp_path, b.tiles[0])) in msgs[0]
    # rejected tiles are moved aside, not reused later
    assert not tile_path(tmp_path, b.tiles[0]).exists()


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04 truncated", b"\x00" * 100,
                                     b"not a zip file at all"])
def test_corrupt_tile_is_named_and_scheduled_again(tmp_path, content):
    spec = _spec()
    t0, t1 = spec.tiles
    save_tile(tmp_path, t0, _fake_tile(spec, t0, 2.0), spec.key())
    tile_path(tmp_path, t1).write_bytes(content)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        todo, rejected = usable_tiles(tmp_path, spec.tiles, spec.key(), MAP_VARIABLES, 3)
    assert todo == [t1]
    assert rejected[0].status is TileStatus.UNREADABLE
    assert tile_path(tmp_path, t1).name in str(caught[0].message)


def test_tile_with_wrong_rows_or_shape_is_malformed(tmp_path):
    spec = _spec()
    t0, t1 = spec.tiles
    key = spec.key()
    # right fingerprint, but the file of rows t0 under the name of t1
    save_tile(tmp_path, t0, _fake_tile(spec, t0, 1.0), key)
    os.replace(tile_path(tmp_path, t0), tile_path(tmp_path, t1))
    chk = check_tile(tmp_path, t1, key, MAP_VARIABLES, 3)
    assert chk.status is TileStatus.MALFORMED and "other rows" in chk.reason
    # wrong number of columns
    bad = {k: np.zeros((1, 5)) for k in MAP_VARIABLES}
    save_tile(tmp_path, t0, bad, key)
    chk = check_tile(tmp_path, t0, key, MAP_VARIABLES, 3)
    assert chk.status is TileStatus.MALFORMED and "shape" in chk.reason
    # a variable missing
    part = _fake_tile(spec, t0, 1.0)
    del part["chi"]
    save_tile(tmp_path, t0, part, key)
    chk = check_tile(tmp_path, t0, key, MAP_VARIABLES, 3)
    assert chk.status is TileStatus.MALFORMED and "'chi'" in chk.reason
    # a tile without any fingerprint (older format) is not trusted
    np.savez(tile_path(tmp_path, t0), **_fake_tile(spec, t0, 1.0))
    assert check_tile(tmp_path, t0, key, MAP_VARIABLES, 3).status is TileStatus.FOREIGN


def test_lock_refuses_a_second_holder_and_releases(tmp_path):
    with lock_folder(tmp_path):
        info = json.loads((tmp_path / ".lock").read_text())
        assert info["pid"] == os.getpid()
        with pytest.raises(CheckpointLocked, match=f"pid {os.getpid()}"):
            with lock_folder(tmp_path):
                pass
    with lock_folder(tmp_path):  # released: can be taken again
        pass


def test_stale_lock_of_a_dead_process_is_taken_over(tmp_path):
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    dead = int(proc.stdout)
    (tmp_path / ".lock").write_text(json.dumps({"pid": dead, "host": "x", "time": 0}))
    with lock_folder(tmp_path):
        assert json.loads((tmp_path / ".lock").read_text())["pid"] == os.getpid()


def test_second_map_on_same_out_refused_while_first_runs(tmp_path, capsys):
    """Another process holds the checkpoint lock (as a running map does): `map` on the same
    --out stops at once with exit code 2 and names the holder."""
    out = tmp_path / "m.nc"
    folder = tmp_path / "m.nc.tiles"
    ready = tmp_path / "ready"
    code = textwrap.dedent(f"""
        import pathlib, time
        from maglev_match.core.checkpoint import lock_folder
        with lock_folder(pathlib.Path({str(folder)!r})):
            pathlib.Path({str(ready)!r}).write_text("1")
            time.sleep(120)
    """)
    holder = subprocess.Popen([sys.executable, "-c", code])
    try:
        deadline = time.time() + 120
        while not ready.exists():
            assert holder.poll() is None and time.time() < deadline
            time.sleep(0.05)
        t = time.perf_counter()
        rc = main(["map", "--x", "omega1=115:135:3", "--y", "sigma=3e-4:5e-4:2",
                   "--workers", "0", "--out", str(out)])
        err = capsys.readouterr().err
        assert rc == 2
        assert f"pid {holder.pid}" in err and "in use by another map" in err
        assert "Traceback" not in err
        assert time.perf_counter() - t < 30  # refused before any computation
    finally:
        holder.kill()
        holder.wait()


def test_resume_refuses_other_spec_and_fresh_run_clears_tiles(tmp_path):
    a, b = _spec(), _spec(y_stop=6e-4)
    prepare_folder(tmp_path, a.key(), resume=False)
    save_tile(tmp_path, a.tiles[0], _fake_tile(a, a.tiles[0], 1.0), a.key())
    with pytest.raises(ValueError, match="different map"):
        prepare_folder(tmp_path, b.key(), resume=True)
    prepare_folder(tmp_path, b.key(), resume=False)
    assert list(tmp_path.glob("tile_*.npz")) == []
    assert (tmp_path / "spec.json").read_text() == b.key()


def test_resumed_map_recomputes_corrupt_and_foreign_tiles(tmp_path):
    """A resumed map with one truncated tile and one tile of another grid recomputes both
    (with warnings naming them) and equals the map computed in one go, bit for bit."""
    spec = _spec(nx=3, ny=2, rows_per_tile=1)
    ref = run_map(spec, tmp_path / "ref", workers=0)
    folder = tmp_path / "ck"
    run_map(spec, folder, workers=0)
    t0, t1 = spec.tiles
    other = _spec(y_stop=6e-4)
    save_tile(folder, t0, _fake_tile(other, t0, 7.0), other.key())
    data = tile_path(folder, t1).read_bytes()
    tile_path(folder, t1).write_bytes(data[: len(data) // 2])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        again = run_map(spec, folder, resume=True, workers=0)
    msgs = " ".join(str(w.message) for w in caught if w.category is CheckpointWarning)
    assert tile_path(folder, t0).name in msgs and tile_path(folder, t1).name in msgs
    for k in MAP_VARIABLES:
        np.testing.assert_array_equal(again[k], ref[k])


@pytest.mark.parametrize("changes,option", [({"ntst": 1}, "--ntst"), ({"ntst": 0}, "--ntst"),
                                            ({"ncol": 8}, "--ncol"),
                                            ({"max_steps": -1}, "--max-steps")])
def test_run_map_refuses_unresolving_mesh_before_work(tmp_path, changes, option):
    """NTST 1 once gave a wrong map marked resolved; the library refuses it too, before the
    checkpoint folder is even created."""
    from dataclasses import replace

    from maglev_match.core.params import ParameterError

    spec = replace(_spec(), **changes)
    with pytest.raises(ParameterError) as err:
        run_map(spec, tmp_path / "ck", workers=0)
    assert err.value.field == option
    assert not (tmp_path / "ck").exists()


def test_run_map_refuses_negative_workers(tmp_path):
    from maglev_match.core.params import ParameterError

    with pytest.raises(ParameterError, match="--workers"):
        run_map(_spec(), tmp_path / "ck", workers=-1)


def test_lost_scheduler_stops_with_resume_hint(tmp_path):
    """The scheduler of an existing cluster dies mid-map: one line naming the loss and how to
    resume, exit code 1, no Dask traceback; the tiles finished so far stay valid."""
    import signal
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    dask_bin = os.path.join(os.path.dirname(sys.executable), "dask")
    if not os.path.exists(dask_bin):
        pytest.skip("the dask command of dask.distributed is not installed beside python")
    procs = []
    try:
        sched = subprocess.Popen([dask_bin, "scheduler", "--host", "127.0.0.1", "--port",
                                  str(port), "--no-dashboard"], env=env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        procs.append(sched)
        addr = f"tcp://127.0.0.1:{port}"
        procs.append(subprocess.Popen([dask_bin, "worker", addr, "--nthreads", "1",
                                       "--no-dashboard"], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        out = tmp_path / "m.nc"
        cmd = [sys.executable, "-m", "maglev_match.cli", "map", "--x", "omega1=100:140:6",
               "--y", "sigma=3e-4:5e-4:100", "--rows-per-tile", "1", "--scheduler", addr,
               "--out", str(out)]
        mp = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
        procs.append(mp)
        folder = tmp_path / "m.nc.tiles"
        deadline = time.time() + 300
        while not list(folder.glob("tile_*.npz")):
            assert mp.poll() is None, mp.communicate()[1][-2000:]
            assert time.time() < deadline
            time.sleep(0.2)
        sched.send_signal(signal.SIGKILL)
        _, err = mp.communicate(timeout=120)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    assert mp.returncode == 1, err[-2000:]
    assert "lost the Dask scheduler" in err and "--resume" in err
    assert "Traceback" not in err
    spec_key = (folder / "spec.json").read_text()
    tiles = sorted(folder.glob("tile_*.npz"))
    assert tiles
    for f in tiles:
        a, b = (int(v) for v in f.stem.split("_")[1:])
        assert check_tile(folder, (a, b), spec_key, MAP_VARIABLES, 6).ok


# ---------------------------------------------------------------------------------------
# the Monte Carlo folder: the map's guarantees (issue 24)
# ---------------------------------------------------------------------------------------
def _fake_chunks(monkeypatch, calls):
    """A stand-in for the index of each sample, a pure function of its values, so that the
    checkpoint (not the index) is what these tests exercise; counts the samples computed.
    Patched where sampled_spread looks it up: the module that defines both."""
    import maglev_match.analyses.sensitivity.uncertainty as S

    def chunk(base_values, names, rows, model="unit"):
        calls.append(len(rows))
        return np.asarray(rows, float) @ np.arange(1.0, rows.shape[1] + 1.0) * 1e-9

    monkeypatch.setattr(S, "mc_chunk", chunk)
    return S


def test_monte_carlo_second_run_on_the_folder_is_refused(tmp_path, monkeypatch):
    """While one study holds the folder, a second one is refused at once (it used to delete
    the first one's chunks), both by the library and by the command line before any work."""
    S = _fake_chunks(monkeypatch, [])
    folder = tmp_path / "monte-carlo"
    with lock_folder(folder, "Monte Carlo run"):
        with pytest.raises(CheckpointLocked, match="in use by another Monte Carlo run"):
            S.sampled_spread(BASE, {"EI": 3.0}, 4, folder, chunk=2, workers=0)
        t = time.perf_counter()
        code = main(["index", "--scatter", "EI=3", "--monte-carlo", "4", "--workers", "0",
                     "--no-simulation", "--out", str(tmp_path)])
        assert code == 2 and time.perf_counter() - t < 20  # refused before the index
    mc = S.sampled_spread(BASE, {"EI": 3.0}, 4, folder, chunk=2, workers=0)  # lock let go
    assert mc.n == 4 and np.isfinite(mc.chi).all()


def test_monte_carlo_truncated_chunk_is_named_and_recomputed(tmp_path, monkeypatch):
    """A chunk cut short (a crash mid-write of an older version, a damaged disk) is named
    in a warning on --resume and recomputed; foreign chunks too; the result equals an
    uninterrupted run bit for bit and only the damaged chunks are computed again."""
    calls: list[int] = []
    S = _fake_chunks(monkeypatch, calls)
    scatter = {"EI": 3.0, "kD": 2.0}
    ref = S.sampled_spread(BASE, scatter, 7, tmp_path / "ref", chunk=3, workers=0, seed=5)
    folder = tmp_path / "ck"
    S.sampled_spread(BASE, scatter, 7, folder, chunk=3, workers=0, seed=5)
    chunks = sorted(folder.glob("chunk_*.npz"))
    assert [c.name for c in chunks] == ["chunk_0000000_0000003.npz",
                                        "chunk_0000003_0000006.npz",
                                        "chunk_0000006_0000007.npz"]
    data = chunks[1].read_bytes()
    chunks[1].write_bytes(data[: len(data) // 2])
    # a chunk of another study (another seed) under the name of the last one
    other = tmp_path / "other"
    S.sampled_spread(BASE, scatter, 7, other, chunk=3, workers=0, seed=6)
    os.replace(other / chunks[2].name, chunks[2])
    calls.clear()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        again = S.sampled_spread(BASE, scatter, 7, folder, chunk=3, workers=0, seed=5,
                                 resume=True)
    msgs = [str(w.message) for w in caught if w.category is CheckpointWarning]
    assert any(chunks[1].name in m and "truncated or corrupt" in m for m in msgs), msgs
    assert any(chunks[2].name in m and "different Monte Carlo study" in m for m in msgs), msgs
    assert calls == [3, 1]  # the two damaged chunks, nothing else
    np.testing.assert_array_equal(again.chi, ref.chi)
    np.testing.assert_array_equal(again.samples, ref.samples)
    assert (again.mean, again.sd) == (ref.mean, ref.sd)
    # a fresh (non-resumed) run starts over, an old-format .npy chunk included
    np.save(folder / "chunk_0000000.npy", np.zeros(3))
    calls.clear()
    S.sampled_spread(BASE, scatter, 7, folder, chunk=3, workers=0, seed=5)
    assert calls == [3, 3, 1] and not list(folder.glob("chunk_*.npy"))


def test_monte_carlo_counts_are_checked_by_the_library(tmp_path):
    import maglev_match.analyses.sensitivity as S
    from maglev_match.core.params import ParameterError

    for kw, field in (({"n": 10**20}, "--monte-carlo"), ({"n": 1}, "--monte-carlo"),
                      ({"seed": -1}, "--seed"), ({"workers": -1}, "--workers"),
                      ({"n": 4.5}, "--monte-carlo")):
        args = {"n": 4, "seed": 0, "workers": 0, **kw}
        with pytest.raises(ParameterError) as err:
            S.sampled_spread(BASE, {"EI": 3.0}, args.pop("n"), tmp_path / "x", **args)
        assert err.value.field == field
    assert not (tmp_path / "x").exists()  # refused before the folder is touched


# ---------------------------------------------------------------------------------------
# the job runner itself (maglev_match.core.jobs), on a job that is not a map
# ---------------------------------------------------------------------------------------
def _toy_piece(a, b, calls):
    calls.append((a, b))
    return {"x": np.arange(3 * a, 3 * b, dtype=float).reshape(b - a, 3)}


def _toy_job(calls, compute=_toy_piece):
    from maglev_match.core.checkpoint import tile_checkpoint
    from maglev_match.core.jobs import Job

    return Job(pieces=[(0, 2), (2, 3)], compute=compute, args_of=lambda p: (*p, calls),
               store=lambda folder: tile_checkpoint(folder, '{"toy": 1}', ("x",), 3))


def test_job_runner_in_memory_checkpointed_resumed_and_interrupted(tmp_path):
    """The runner knows nothing about maps: in memory it returns the pieces' results; with a
    folder it saves them, a limited run leaves the rest to a resume that computes only the
    missing pieces (the same results), and a Ctrl-C inside a piece is MapStopped with exit
    code 130 and the resume hint, the stop note counting the pieces saved by then."""
    from maglev_match.core.checkpoint import MapStopped
    from maglev_match.core.interrupts import stop_note
    from maglev_match.core.jobs import run_job

    calls: list = []
    seen: list = []
    memory = run_job(_toy_job(calls), None, workers=0, progress=lambda d, t: seen.append((d, t)))
    assert calls == [(0, 2), (2, 3)] and seen == [(0, 2), (1, 2), (2, 2)]
    calls.clear()
    with pytest.raises(RuntimeError, match="run again with --resume"):
        run_job(_toy_job(calls), tmp_path / "ck", workers=0, limit=1)
    assert calls == [(0, 2)] and len(list((tmp_path / "ck").glob("tile_*.npz"))) == 1
    calls.clear()
    resumed = run_job(_toy_job(calls), tmp_path / "ck", workers=0, resume=True)
    assert calls == [(2, 3)]
    for m, r in zip(memory, resumed, strict=True):
        np.testing.assert_array_equal(m["x"], r["x"])
    notes: list = []

    def interrupted(a, b, calls):
        if (a, b) == (2, 3):
            notes.append(stop_note())
            raise KeyboardInterrupt
        return _toy_piece(a, b, calls)

    with pytest.raises(MapStopped) as err:
        run_job(_toy_job(calls, interrupted), tmp_path / "ck2", workers=0)
    assert err.value.exit_code == 130
    assert "1 of 2 tiles are saved in" in notes[0] and "--resume" in notes[0]
    assert str(err.value) == notes[0]
    assert stop_note() == "interrupted"  # the note is gone with the job
