"""Benchmark: start-up and whole commands (``maglev-match index``, ``maglev-match cycles``)
in fresh processes, with the persistent compilation cache warm and empty, and with the
default thread settings (one thread, process pinned to its core) against
``MAGLEV_MATCH_THREADS=auto`` (the libraries' own thread pools, no pinning) as the baseline.

Prints, per case, the median wall time and the median CPU time (user + sys of the child) of
``--repeats`` runs, and the ratio against the baseline. Also: the import time of the CLI
(``python -c "import maglev_match.cli"``) and the number of cache entries written.

    .venv/bin/python bench/bench_startup.py [--repeats 5] [--cold-repeats 3]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

COMMANDS = {
    "index": ["index", "--json"],
    "cycles": ["cycles", "--param", "omega1", "--at", "sigma=4e-4", "--preset", "alpha1",
               "--json"],
}


def run(args: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall and CPU (children's user + sys) seconds of one process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({proc.returncode}): {proc.stderr[-500:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def medians(samples: list[tuple[float, float]]) -> tuple[float, float]:
    a = np.asarray(samples)
    return float(np.median(a[:, 0])), float(np.median(a[:, 1]))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--cold-repeats", type=int, default=3)
    opts = ap.parse_args()
    base_env = dict(os.environ)
    src = Path(__file__).resolve().parents[1] / "src"
    base_env["PYTHONPATH"] = str(src) + os.pathsep + base_env.get("PYTHONPATH", "")
    print(f"# bench_startup  python {sys.version.split()[0]}  cpus {os.cpu_count()}  "
          f"load {os.getloadavg()[0]:.2f}")

    imp = [run(["-c", "import maglev_match.cli"], base_env) for _ in range(opts.repeats)]
    w, c = medians(imp)
    print(f"import maglev_match.cli: {w:.3f} s wall, {c:.3f} s CPU")

    for name, cmd in COMMANDS.items():
        argv = ["-m", "maglev_match.cli", *cmd]
        results = {}
        for label, extra in (("auto threads (baseline)", {"MAGLEV_MATCH_THREADS": "auto"}),
                             ("one thread, pinned (default)", {})):
            cache = tempfile.mkdtemp(prefix="mm-cache-")
            env = {**base_env, **extra, "MAGLEV_MATCH_CACHE": cache}
            try:
                cold = []
                for _ in range(opts.cold_repeats):
                    shutil.rmtree(cache, ignore_errors=True)
                    cold.append(run(argv, env))
                entries = len(os.listdir(cache))
                warm = [run(argv, env) for _ in range(opts.repeats)]
            finally:
                shutil.rmtree(cache, ignore_errors=True)
            results[label] = (medians(warm), medians(cold), entries)
        base_warm = results["auto threads (baseline)"][0][0]
        for label, ((ww, wc), (cw, cc), entries) in results.items():
            print(f"{name:6s} {label:30s} warm cache {ww:6.2f} s wall ({wc:5.2f} s CPU), "
                  f"empty cache {cw:6.2f} s wall ({cc:5.2f} s CPU), {entries} cache entries; "
                  f"warm ratio vs baseline {base_warm / ww:.2f}x")
    print(f"# load at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
