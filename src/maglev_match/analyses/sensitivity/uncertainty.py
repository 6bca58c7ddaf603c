"""The spread of chi under independent scatter of the parameters: to first order from the
exact sensitivities (:func:`linearised_spread`, from an
:class:`~maglev_match.analyses.sensitivity.index.IndexSensitivity`) and by Monte Carlo
(:func:`sampled_spread`, :class:`SampledSpread`): the samples in chunks (:func:`mc_chunks`),
each chunk's index computed by :func:`mc_chunk` on Dask (the design map's workers,
:mod:`maglev_match.analyses.maps`) and saved in a resumable checkpoint folder
(:func:`mc_checkpoint`, :class:`maglev_match.core.checkpoint.Checkpoint`) under the study's
fingerprint (base, scatter, n, seed, chunk size, model).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from maglev_match.analyses.matching import matching_index
from maglev_match.analyses.sensitivity.index import IndexSensitivity
from maglev_match.core.params import Params
from maglev_match.maglev.catalog import DEFAULT_MODEL

__all__ = [
    "linearised_spread",
    "SampledSpread",
    "sampled_spread",
    "mc_chunk",
    "mc_checkpoint",
    "mc_chunks",
]


def linearised_spread(sens: IndexSensitivity, scatter: Mapping[str, float]
                      ) -> dict[str, Any]:
    """Standard deviation of chi to first order for independent parameters with relative
    standard deviations ``scatter`` (name -> percent): sd = sqrt(sum (dchi/dp p pct/100)^2)."""
    parts = {}
    for name, pct in scatter.items():
        r = sens.row(name)
        parts[name] = abs(r.dchi * r.value * pct / 100.0)
    sd = math.sqrt(sum(v * v for v in parts.values()))
    return {"chi": sens.index.chi, "sd": sd, "contributions": parts}


# ---------------------------------------------------------------------------------------
# sampled spread (Monte Carlo on Dask, resumable)
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SampledSpread:
    """chi over N parameter sets drawn around ``base`` (independent normal relative
    scatter per parameter), beside the linearised estimate."""

    n: int
    chi: np.ndarray  # (n,) NaN where the index failed or the sample was not a valid set
    samples: np.ndarray  # (n, len(names))
    names: tuple[str, ...]
    mean: float
    sd: float
    quantiles: dict[str, float]  # "5%", "50%", "95%"
    failed: int  # samples whose index did not converge
    invalid: int  # samples outside the parameter rules (not computed)
    linearised: dict[str, Any] | None = None

    def fraction_below(self, bound: float) -> float:
        ok = np.isfinite(self.chi)
        return float(np.mean(self.chi[ok] < bound)) if ok.any() else float("nan")

    def as_json(self) -> dict[str, Any]:
        return {"n": self.n, "mean": self.mean, "sd": self.sd, "quantiles": self.quantiles,
                "failed": self.failed, "invalid": self.invalid, "names": list(self.names),
                "linearised": self.linearised}


def _chunk_key(base: Params, scatter: Mapping[str, float], n: int, seed: int,
               chunk: int, model: str = "unit") -> str:
    import json

    d = {"base": {k: v for k, v in sorted(base.as_input_dict().items())},
         "scatter": dict(sorted(scatter.items())), "n": n, "seed": seed, "chunk": chunk}
    if model != DEFAULT_MODEL:  # model A's key as before: its existing checkpoints resume
        d["model"] = model
    return json.dumps(d, sort_keys=True, default=float)


def _sample(base: Params, scatter: Mapping[str, float], n: int, seed: int) -> np.ndarray:
    names = tuple(scatter)
    rng = np.random.default_rng(seed)
    v0 = np.array([float(getattr(base, k)) for k in names])
    pct = np.array([scatter[k] for k in names]) / 100.0
    return v0 * (1.0 + pct * rng.standard_normal((n, len(names))))


def mc_chunk(base_values: dict[str, Any], names: tuple[str, ...], rows: np.ndarray,
             model: str = "unit") -> np.ndarray:
    """chi (no simulation) of ``model`` for each row of sampled values; NaN where the index
    failed, -inf where the sample breaks a parameter rule. Runs on a Dask worker."""
    from maglev_match.core.params import ParameterError, make_params

    out = np.empty(len(rows))
    for i, r in enumerate(rows):
        vals = dict(base_values, **{k: float(v) for k, v in zip(names, r, strict=True)})
        try:
            p = make_params(vals)
        except ParameterError:
            out[i] = -np.inf
            continue
        out[i] = matching_index(p, model=model, simulate=False).chi
    return out


def mc_piece(base_values: Mapping[str, float], names: Sequence[str], rows: np.ndarray,
             model: str = "unit") -> dict[str, np.ndarray]:
    """One chunk of a Monte Carlo study as the job runner saves it: {"chi": chi of the
    rows} (:func:`mc_chunk`)."""
    return {"chi": mc_chunk(base_values, names, rows, model)}


def mc_checkpoint(folder: Any, key: str) -> Any:
    """The Monte Carlo study's checkpoint folder (:class:`maglev_match.core.checkpoint.Checkpoint`):
    ``study.json`` and one ``chunk_AAAAAAA_BBBBBBB.npz`` per chunk of samples [A, B), each
    holding ``chi`` of shape (B - A,) with the study's fingerprint; the map's guarantees (a
    lock, atomic writes, damaged or foreign chunks named and recomputed)."""
    from pathlib import Path

    from maglev_match.core.checkpoint import Checkpoint

    return Checkpoint(folder=Path(folder), spec_key=key,
                      shapes_of=lambda rows: {"chi": (rows[1] - rows[0],)}, prefix="chunk",
                      digits=7, spec_name="study.json", what="Monte Carlo study",
                      noun="chunk", stale=("chunk_*.npy",))


def mc_chunks(n: int, chunk: int) -> list[tuple[int, int]]:
    """The sample ranges [a, b) of the chunks of a study of ``n`` samples."""
    return [(a, min(a + chunk, n)) for a in range(0, n, chunk)]


def sampled_spread(base: Params, scatter: Mapping[str, float], n: int, checkpoint: Any, *,
                   seed: int = 0, chunk: int = 16, resume: bool = False,
                   workers: int | None = None, scheduler: str | None = None,
                   progress: Callable[[int, int], None] | None = None,
                   linearised: dict[str, Any] | None = None,
                   model: str = "unit") -> SampledSpread:
    """The distribution of chi over ``n`` samples, chunk by chunk on Dask (the map's worker
    set-up: single-threaded processes, glibc's malloc thresholds), each chunk saved in
    ``checkpoint`` as it finishes; with ``resume`` finished chunks are reused.

    The folder has the map's guarantees (:func:`mc_checkpoint`): it is locked while the study
    runs (a second run on it raises :class:`~maglev_match.core.checkpoint.CheckpointLocked`),
    chunks are written atomically with the fingerprint of the study (base, scatter, n, seed,
    chunk size, model), and on resume a chunk of another study, a truncated or otherwise
    damaged chunk is named in a :class:`~maglev_match.core.checkpoint.CheckpointWarning` and
    recomputed. ``workers == 0`` computes in this process; ``model`` 'unit' or 'vehicle'.
    """
    from pathlib import Path

    from maglev_match.core.jobs import Job, run_job
    from maglev_match.core.options import MonteCarloOptions

    MonteCarloOptions(samples=n, seed=seed, workers=workers, chunk=chunk)  # checks them
    n = int(n)
    names = tuple(scatter)
    X = _sample(base, scatter, n, int(seed))
    key = _chunk_key(base, scatter, n, seed, chunk, model)
    base_values = base.as_input_dict()
    job = Job(pieces=mc_chunks(n, chunk), compute=mc_piece,
              args_of=lambda ab: (base_values, names, X[ab[0]:ab[1]], model),
              store=lambda folder: mc_checkpoint(folder, key), noun="Monte Carlo chunks",
              run="Monte Carlo run")
    folder = Path(checkpoint)
    parts = run_job(job, folder, resume=resume, scheduler=scheduler, workers=workers,
                    progress=progress, log=folder / "dask.log")
    chi = np.concatenate([part["chi"] for part in parts])
    invalid = int(np.sum(chi == -np.inf))
    chi = np.where(chi == -np.inf, np.nan, chi)
    failed = int(np.sum(np.isnan(chi))) - invalid
    ok = chi[np.isfinite(chi)]
    q = {f"{int(100 * x)}%": float(np.quantile(ok, x)) if ok.size else float("nan")
         for x in (0.05, 0.5, 0.95)}
    return SampledSpread(n=n, chi=chi, samples=X, names=names,
                         mean=float(np.mean(ok)) if ok.size else float("nan"),
                         sd=float(np.std(ok, ddof=1)) if ok.size > 1 else float("nan"),
                         quantiles=q, failed=failed, invalid=invalid, linearised=linearised)
