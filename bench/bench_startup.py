"""Benchmark: start-up and whole commands (``maglev-match index``, ``maglev-match cycles
--param omega1 --at sigma=4e-4``, ``maglev-match --help``) in fresh processes, with the
persistent caches warm and empty, with the ahead-of-time kernels (default) against
``MAGLEV_MATCH_AOT=0`` (plain ``jax.jit``: every kernel traced and lowered again in every
process, then looked up in the XLA cache) as the baseline of the same run.

Prints, per case, the median wall time and the median CPU time (user + sys of the child) of
the runs, the ratio baseline / AOT, and the number of cache files written (XLA executables,
exported kernels). Also the import time of the CLI (``python -c "import maglev_match.cli"``).
The machine may be shared: compare CPU times when the load average is high.

    python bench/bench_startup.py [--repeats 5] [--cold-repeats 5]
    python bench/bench_startup.py --floor [--against OTHER/src] [--repeats 5]

``--floor`` times ``maglev-match index --json`` (the user's cache, warm after one unmeasured
run) interleaved with a bare ``python -c "import jax"`` (the floor no command can go below)
and, with ``--against``, the same command run from another source tree (e.g. an export of
the previous commit): the "before" of a change, measured in the same run.

Targets (issue 14): ``index`` and ``cycles`` under 1.5 s with a warm cache, under 4 s with
an empty one.
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
    "index": ["index"],
    "cycles": ["cycles", "--param", "omega1", "--at", "sigma=4e-4"],
}


def run(args: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall and CPU (children's user + sys) seconds of one process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="mm-bench-cwd-") as cwd:  # output files go here
        proc = subprocess.run([sys.executable, *args], env=env, capture_output=True,
                              text=True, cwd=cwd)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({proc.returncode}): {proc.stderr[-500:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def run_any(args: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall and CPU seconds of one process, whatever its exit code."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def medians(samples: list[tuple[float, float]]) -> tuple[float, float]:
    a = np.asarray(samples)
    return float(np.median(a[:, 0])), float(np.median(a[:, 1]))


def count_files(cache: str) -> tuple[int, int]:
    xla = sum(1 for f in Path(cache).iterdir() if f.is_file())
    aot = Path(cache) / "aot"
    return xla, (sum(1 for _ in aot.glob("*.jaxexport")) if aot.is_dir() else 0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5, help="warm-cache runs per case")
    ap.add_argument("--cold-repeats", type=int, default=5, help="empty-cache runs per case")
    ap.add_argument("--only", choices=sorted(COMMANDS), help="one command only")
    ap.add_argument("--quick-only", action="store_true",
                    help="only the answers without computation (--version, --help, ...)")
    ap.add_argument("--floor", action="store_true",
                    help="index against the bare import of jax, interleaved (see above)")
    ap.add_argument("--against", help="with --floor: another source tree to time as well")
    opts = ap.parse_args()
    base_env = dict(os.environ)
    src = Path(__file__).resolve().parents[1] / "src"
    base_env["PYTHONPATH"] = str(src) + os.pathsep + base_env.get("PYTHONPATH", "")
    base_env.pop("MAGLEV_MATCH_AOT", None)
    print(f"# bench_startup  python {sys.version.split()[0]}  cpus {os.cpu_count()}  "
          f"load {os.getloadavg()[0]:.2f}")

    if opts.floor:
        floor(opts, base_env, src)
        return
    imp = [run(["-c", "import maglev_match.cli"], base_env) for _ in range(opts.repeats)]
    w, c = medians(imp)
    print(f"import maglev_match.cli: {w:.3f} s wall, {c:.3f} s CPU")
    # answers that need no computation (issue 21: no JAX; target under 0.3 s warm); the
    # baseline is the plain interpreter start of the same run
    quick = {"python -c pass": ["-c", "pass"],
             "maglev-match --version": ["-m", "maglev_match.cli", "--version"],
             "maglev-match --help": ["-m", "maglev_match.cli", "--help"],
             "maglev-match presets": ["-m", "maglev_match.cli", "presets", "--json"],
             "maglev-match index --set nosuch=1 (usage error)":
                 ["-m", "maglev_match.cli", "index", "--set", "nosuch=1"]}
    for label, argv in quick.items():
        samples = []
        for _ in range(opts.repeats):
            try:
                samples.append(run(argv, base_env))
            except RuntimeError:  # a usage error exits 2 by design: time it all the same
                samples.append(run_any(argv, base_env))
        w, c = medians(samples)
        print(f"{label}: {w:.3f} s wall, {c:.3f} s CPU")

    for name, cmd in COMMANDS.items():
        if opts.quick_only or (opts.only and name != opts.only):
            continue
        argv = ["-m", "maglev_match.cli", *cmd]
        results = {}
        for label, extra in (("plain jit (MAGLEV_MATCH_AOT=0)", {"MAGLEV_MATCH_AOT": "0"}),
                             ("ahead-of-time (default)", {})):
            cache = tempfile.mkdtemp(prefix="mm-cache-")
            env = {**base_env, **extra, "MAGLEV_MATCH_CACHE": cache}
            try:
                cold = []
                for _ in range(opts.cold_repeats):
                    shutil.rmtree(cache, ignore_errors=True)
                    cold.append(run(argv, env))
                files = count_files(cache)
                warm = [run(argv, env) for _ in range(opts.repeats)]
            finally:
                shutil.rmtree(cache, ignore_errors=True)
            results[label] = (medians(warm), medians(cold), files)
            (ww, wc), (cw, cc), (nx, na) = results[label]
            print(f"{name:6s} {label:31s} warm {ww:6.2f} s wall ({wc:5.2f} s CPU), "
                  f"empty {cw:6.2f} s wall ({cc:5.2f} s CPU); {nx} XLA entries, "
                  f"{na} exported kernels", flush=True)
        (bw, bwc), (bc, bcc), _ = results["plain jit (MAGLEV_MATCH_AOT=0)"]
        (aw, awc), (ac, acc), _ = results["ahead-of-time (default)"]
        print(f"{name:6s} ratio plain / AOT: warm {bw / aw:.2f}x wall ({bwc / awc:.2f}x CPU), "
              f"empty {bc / ac:.2f}x wall ({bcc / acc:.2f}x CPU)")
    print(f"# load at the end {os.getloadavg()[0]:.2f}")


def floor(opts: argparse.Namespace, base_env: dict[str, str], src: Path) -> None:
    """``index --json`` (warm) interleaved with ``import jax`` and, optionally, the same
    command from another source tree; medians of ``--repeats`` rounds."""
    cases = {"python -c 'import jax'": (["-c", "import jax"], base_env),
             f"index --json ({src})": (["-m", "maglev_match", "index", "--json"], base_env)}
    if opts.against:
        other = {**base_env, "PYTHONPATH": str(Path(opts.against).resolve()) + os.pathsep
                 + os.environ.get("PYTHONPATH", "")}
        cases[f"index --json ({opts.against})"] = (
            ["-m", "maglev_match", "index", "--json"], other)
    for argv, env in cases.values():  # warm the caches (exported kernels of each tree)
        run(argv, env)
    samples: dict[str, list[tuple[float, float]]] = {k: [] for k in cases}
    for _ in range(opts.repeats):
        for label, (argv, env) in cases.items():
            samples[label].append(run(argv, env))
    base = medians(samples["python -c 'import jax'"])
    for label, s in samples.items():
        w, c = medians(s)
        print(f"{label}: {w:.3f} s wall, {c:.3f} s CPU  ({w / base[0]:.2f}x the jax floor "
              f"wall)")
    print(f"# load at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
