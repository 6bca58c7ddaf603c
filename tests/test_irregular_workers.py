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


def test_runs_on_two_workers_equal_the_runs_here_bit_for_bit(params, here, tmp_path,
                                                             monkeypatch):
    """Through the API's sweep on 2 workers: the runs equal those computed here bit for
    bit, and the sweep's two stages (the periodic responses, then the runs over the
    irregular guideway) share one local cluster."""
    from maglev_match import api
    from maglev_match.core import jobs

    started = []
    real = jobs.local_cluster
    monkeypatch.setattr(jobs, "local_cluster", lambda w: started.append(w) or real(w))
    seen = []
    sweep = api.speed_sweep(params, speeds=SPEEDS, critical=False, irregularity=SPEC,
                            irregular_spans=2, workers=2, checkpoint=tmp_path / "sweep",
                            runs_progress=lambda d, t: seen.append((d, t)))
    assert started == [2]  # one cluster for both stages
    on_dask = sweep.irregular
    _same(here, on_dask)
    # one piece per (speed, seed) in the sweep's folder, a progress call before the first
    # and after each
    assert len(list((tmp_path / "sweep" / "irregular").glob("tile_*.npz"))) == 4
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


def _response_compiled_per_speed(params, model, v, kappa):
    """The linear route's H as it was computed before the forcing was compiled once per
    model (issue 33): the speed's parameters and state as constants of a forcing compiled
    for that speed, the Jacobians taken op by op."""
    import jax
    import jax.numpy as jnp

    from maglev_match.maglev import moving as mv
    from maglev_match.maglev.moving import MovingModel

    kind = MovingModel(model)
    nv = mv.n_vehicle_states(kind)
    rhs = mv.moving_rhs(kind, int(params.n_modes), False, 1)
    gap = mv.observables(kind, int(params.n_modes), 1)["gap_deviation"]
    pb = jnp.asarray(mv.moving_param_vector(params, kind, v=float(v), active=(0.0, 0.0)))
    x0 = jnp.asarray(mv.rigid_equilibrium(params, kind))

    def pv(a, kap, phi):  # one wave: its entries a cos(phi), kappa, a sin(phi)
        return jnp.concatenate([pb, jnp.zeros(7),
                                jnp.stack([a * jnp.cos(phi), kap, a * jnp.sin(phi)])])

    A = np.asarray(jax.jacfwd(lambda x: rhs(x, pv(0.0, 1.0, 0.0)))(x0))[:nv, :nv]
    C = np.asarray(jax.jacfwd(lambda x: gap(x, pv(0.0, 1.0, 0.0)))(x0))[:, :nv]

    @jax.jit
    def forcing(kap):
        def d(phi):
            fa = jax.jacfwd(lambda a: rhs(x0, pv(a, kap, phi)))(0.0)[:nv]
            ga = jax.jacfwd(lambda a: gap(x0, pv(a, kap, phi)))(0.0)
            return fa, ga

        f0, g0 = d(0.0)
        f1, g1 = d(-jnp.pi / 2)
        return f0 + 1j * f1, g0 + 1j * g1

    out = np.empty((C.shape[0], len(kappa)), complex)
    for k, kk in enumerate(kappa):
        F, G = forcing(jnp.asarray(kk))
        x_hat = np.linalg.solve(1j * kk * float(v) * np.eye(nv) - A, np.asarray(F))
        out[:, k] = C @ x_hat + np.asarray(G)
    return out


@pytest.mark.parametrize("model", ["unit", "vehicle"])
def test_the_linear_route_compiled_once_is_the_one_compiled_per_speed(params, model):
    """The forcing and the Jacobians of the linear route are compiled once per model, the
    speed's parameters and state their arguments (0.85 s a speed before, 0.03 s after, for
    400 waves): the unit's H is the same to the last bit, the vehicle's within 1e-14 of
    |H| (4e-15 measured: XLA folds the constants of the per-speed program in another
    order)."""
    kappa = np.linspace(0.05, 3.0, 12)
    for kmh in (150,):
        new = irr.profile_gap_response(params, model, kmh * KMH, kappa)
        old = _response_compiled_per_speed(params, model, kmh * KMH, kappa)
        if model == "unit":
            assert np.array_equal(new, old)
        else:
            assert np.max(np.abs(new - old)) <= 1e-14 * np.max(np.abs(old))
