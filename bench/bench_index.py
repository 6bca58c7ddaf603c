"""Benchmark: the matching index at one point, and map throughput.

Prints medians and ratios against baselines run in the same process:

* chi by cycle continuation (``matching_index(..., simulate=False)``) against chi by
  simulation bisection (``critical_disturbance``) at the same parameter points;
* map throughput (points/s) of a (omega1, sigma) map of model A with 1 and 2 local workers;
* ``--sensitivity``: the headline index's sensitivities with the chi_simulation derivatives
  (``index_sensitivity``, the ``sensitivity`` command's computation, boundaries off) against
  one headline index (``matching_index`` with the simulation and the solved critical
  disturbance), runs interleaved, CPU time of the process (target: under 2x).

Usage: python bench/bench_index.py [--quick] [--sensitivity]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import tempfile
import time
from pathlib import Path

from maglev_match.maps import Axis, MapSpec, compute_row, run_map
from maglev_match.matching import matching_index
from maglev_match.params import load_preset
from maglev_match.simulation import critical_disturbance


def timed(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="small settings (CI)")
    ap.add_argument("--grid", type=int, default=30, help="map size (grid x grid)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2],
                    help="local worker counts to time the map with")
    ap.add_argument("--skip-index", action="store_true", help="only the map part")
    ap.add_argument("--sensitivity", action="store_true",
                    help="only the headline sensitivity timing")
    args = ap.parse_args()
    if args.sensitivity:
        sensitivity_timing(1 if args.quick else 5)
        return
    print(f"machine: {platform.machine()}, {platform.processor() or 'cpu'}, "
          f"python {platform.python_version()}")
    points = ["turnout-soft", "turnout-stiff", "alpha1"]
    repeat = 1 if args.quick else 3
    for name in points if not args.skip_index else []:
        p = load_preset(name)
        t0 = time.perf_counter()
        matching_index(p, simulate=False)
        first = time.perf_counter() - t0
        t_cyc, res = timed(lambda p=p: matching_index(p, simulate=False), repeat)
        critical_disturbance(p)  # compile
        t_sim, cd = timed(lambda p=p: critical_disturbance(p), repeat)
        print(f"{name:14s} chi = {res.chi:.4g} ({res.case}); first call {first:.2f} s; "
              f"median chi by continuation {t_cyc:.3f} s, by simulation bisection "
              f"{t_sim:.3f} s ({cd.runs} runs): ratio {t_sim / t_cyc:.2f}x")
    n = 10 if args.quick else args.grid
    base = load_preset("turnout-soft")
    spec = MapSpec(base=base.as_input_dict(), x=Axis("omega1", 40, 190, n),
                   y=Axis("sigma", 2e-4, 6e-4, n), rows_per_tile=2)
    # one row in this process, warm (the cost a worker pays per row, single-threaded here)
    row = n // 2
    compute_row(spec, row)
    t_row, _ = timed(lambda: compute_row(spec, row), repeat)
    print(f"one row of {n} points, warm, in this process: {t_row:.3f} s")
    for workers in args.workers:
        with tempfile.TemporaryDirectory() as d:
            t, c = time.perf_counter(), _cpu_seconds()
            run_map(spec, Path(d) / "tiles", workers=workers)
            dt, dc = time.perf_counter() - t, _cpu_seconds() - c
        print(f"map {n}x{n} with {workers} worker(s): {dt:.1f} s, {n * n / dt:.0f} points/s, "
              f"CPU {dc:.1f} s (this process and its children; includes cluster start and "
              "per-worker kernel loading)")


def _cpu_seconds() -> float:
    """User + system CPU time of this process and of its exited children (the Dask
    nannies and, through them, the workers: counted once the cluster is closed)."""
    import os

    t = os.times()
    return t.user + t.system + t.children_user + t.children_system



def sensitivity_timing(repeat: int) -> None:
    """``index_sensitivity`` (the headline index and every derivative, chi_simulation's by
    the implicit function theorem on its solved critical size) against one headline index,
    interleaved, at the two turnout beams; CPU seconds of this process (medians)."""
    import os

    from maglev_match.sensitivity import index_sensitivity

    print(f"load average at the start: {os.getloadavg()[0]:.2f}")
    for name in ("turnout-soft", "turnout-stiff"):
        p = load_preset(name)
        index_sensitivity(p, boundaries=False)  # compile and load every kernel
        t_idx, t_sens = [], []
        for _ in range(repeat):
            c = time.process_time()
            idx = matching_index(p)
            t_idx.append(time.process_time() - c)
            c = time.process_time()
            sens = index_sensitivity(p, boundaries=False)
            t_sens.append(time.process_time() - c)
        mi, ms = statistics.median(t_idx), statistics.median(t_sens)
        print(f"{name:14s} headline chi = {idx.chi:.4g} ({idx.reading_basis}; "
              f"{idx.mechanism_up}/{idx.mechanism_down}); one index {mi:.3f} s CPU, "
              f"sensitivity with chi_simulation derivatives {ms:.3f} s CPU "
              f"(status {sens.status}): ratio {ms / mi:.2f}x")
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
