"""Before/after timings in one run: a job executed in fresh processes, alternately with the
current source tree and a baseline tree (e.g. ``git archive <commit> src | tar -x -C DIR``),
so that both see the same machine load. Used by bench_cycles.py and bench_vehicle.py."""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
CURRENT_SRC = HERE.parent / "src"


def run_job(script: Path, job: str, src: Path, extra: list[str] | None = None,
            timeout: float = 3600) -> dict:
    """Run ``script --job JOB`` with ``src`` first on PYTHONPATH; its last stdout line is a
    JSON object."""
    # one thread in every pool, as the command line runs (set before NumPy loads BLAS)
    env = dict(os.environ, PYTHONPATH=str(src), OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    out = subprocess.run([sys.executable, str(script), "--job", job, *(extra or [])], env=env,
                         capture_output=True, text=True, timeout=timeout, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def interleaved(script: Path, job: str, baseline: Path, rounds: int,
                extra: list[str] | None = None) -> dict[str, list[dict]]:
    """``rounds`` alternating runs of the job: baseline, current, baseline, current, ..."""
    res: dict[str, list[dict]] = {"baseline": [], "current": []}
    for _ in range(rounds):
        res["baseline"].append(run_job(script, job, baseline, extra))
        res["current"].append(run_job(script, job, CURRENT_SRC, extra))
    return res


def summary(res: dict[str, list[dict]], key: str) -> tuple[float, float, float]:
    """Medians of ``key`` over the runs (baseline, current) and their ratio."""
    b = statistics.median(r[key] for r in res["baseline"])
    c = statistics.median(r[key] for r in res["current"])
    return b, c, b / c


def load() -> str:
    return " / ".join(open("/proc/loadavg").read().split()[:3])
