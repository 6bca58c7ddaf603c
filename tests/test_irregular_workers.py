"""The runs over an irregular guideway as a tiled job (issue 33): on Dask workers they give
the in-process numbers bit for bit, a checkpoint keeps one piece per run, an interrupted
sweep resumes to the uninterrupted one bit for bit. (The command line's progress line per
run: tests/test_irregular_config.py.)"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_match.analyses.speed import irregular as irr
from maglev_match.analyses.speed.irregular import irregular_sweep
from maglev_match.api.inputs import resolve_params
from maglev_match.core.errors import MapStopped
from maglev_match.core.params import ParameterError

KMH = 1 / 3.6
SPEEDS = [60 * KMH, 110 * KMH]
SPEC = "random:class=high,seeds=2,waves=16,lmin=4"


@pytest.fixture(scope="module")
def params():
    return resolve_params("turnout-soft", n_modes=1)


@pytest.fixture(scope="module")
def here(params):
    """2 speeds x 2 seeds, runs of 2 spans, computed in this process without a folder."""
    return irregular_sweep(params, "unit", SPEEDS, SPEC, spans=2, warmup=1, workers=0)


def _same(a, b):
    assert a.values.keys() == b.values.keys()
    for k in a.values:
        assert np.array_equal(a.values[k], b.values[k], equal_nan=True), k
    assert a.warnings == b.warnings
    assert a.seeds == b.seeds and np.array_equal(a.speeds, b.speeds)


def test_runs_on_two_workers_equal_the_runs_here_bit_for_bit(params, here, tmp_path):
    folder = tmp_path / "irregular"
    seen = []
    on_dask = irregular_sweep(params, "unit", SPEEDS, SPEC, spans=2, warmup=1, workers=2,
                              checkpoint=folder, progress=lambda d, t: seen.append((d, t)))
    _same(here, on_dask)
    # one piece per (speed, seed), a progress call before the first and after each
    assert len(list(folder.glob("tile_*.npz"))) == 4
    assert seen[0] == (0, 4) and seen[-1] == (4, 4) and len(seen) == 5
    # the read-outs are real: two seeds of a random profile differ, the linear route is there
    assert np.all(here.column("runs") == 2) and np.all(here.column("gap_rms_profile_se") > 0)
    assert np.all(np.isfinite(here.column("gap_rms_linear")))


def test_an_interrupted_sweep_resumes_to_the_uninterrupted_one(params, here, tmp_path,
                                                               monkeypatch):
    folder = tmp_path / "irregular"
    real = irr.compute_irregular_runs
    calls = []

    def stop_at_the_third(spec, rows):
        calls.append(rows)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(spec, rows)

    monkeypatch.setattr(irr, "compute_irregular_runs", stop_at_the_third)
    with pytest.raises(MapStopped, match=r"2 of 4 runs over the irregular guideway are saved"
                                         r".*--resume"):
        irregular_sweep(params, "unit", SPEEDS, SPEC, spans=2, warmup=1, workers=0,
                        checkpoint=folder)
    assert len(list(folder.glob("tile_*.npz"))) == 2
    calls.clear()
    monkeypatch.setattr(irr, "compute_irregular_runs",
                        lambda spec, rows: calls.append(rows) or real(spec, rows))
    resumed = irregular_sweep(params, "unit", SPEEDS, SPEC, spans=2, warmup=1, workers=0,
                              checkpoint=folder, resume=True)
    assert calls == [(2, 3), (3, 4)]  # only the runs not saved
    _same(here, resumed)
    # another profile is not resumed from these runs
    with pytest.raises(ParameterError, match="--resume"):
        irregular_sweep(params, "unit", SPEEDS, SPEC.replace("seeds=2", "seeds=3"), spans=2,
                        warmup=1, workers=0, checkpoint=folder, resume=True)
