"""Benchmark: the matching index at one point, and map throughput.

Prints medians and ratios against baselines run in the same process:

* chi by cycle continuation (``matching_index(..., simulate=False)``) against chi by
  simulation bisection (``critical_disturbance``) at the same parameter points;
* map throughput (points/s) of a (omega1, sigma) map of model A with 1 and 2 local workers;
* ``--sensitivity``: the headline index's sensitivities with the chi_simulation derivatives
  (``index_sensitivity``, the ``sensitivity`` command's computation, boundaries off) against
  one headline index (``matching_index`` with the simulation and the solved critical
  disturbance), runs interleaved, CPU time of the process (target: under 2x).

* the headline map (chi = min(chi_paper, chi_simulation), the simulated critical
  disturbances followed from point to point) against the paper-only map
  (``--no-simulation``) on the same grid, same workers, in the same run (issue 20's target:
  at most 3x), and where a headline tile's time goes (the paper's part, the simulations:
  runs, integration steps paid and used, kernel calls).

Usage: python bench/bench_index.py [--quick] [--sensitivity] [--grid N] [--workers 2]
       [--rows-per-tile R] [--skip-index] [--skip-throughput]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

from maglev_match.analyses.maps import Axis, MapSpec, compute_row, run_map
from maglev_match.analyses.matching import matching_index
from maglev_match.analyses.simulation import critical_disturbance
from maglev_match.core.params import load_preset


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
    ap.add_argument("--skip-throughput", action="store_true",
                    help="skip the paper-only throughput runs (only headline vs paper)")
    ap.add_argument("--rows-per-tile", type=int, default=4,
                    help="rows per tile of the headline/paper comparison")
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
                   y=Axis("sigma", 2e-4, 6e-4, n), rows_per_tile=2, simulate=False)
    if not args.skip_throughput:
        # one row in this process, warm (the cost a worker pays per row, single-threaded)
        row = n // 2
        compute_row(spec, row)
        t_row, _ = timed(lambda: compute_row(spec, row), repeat)
        print(f"one row of {n} points, warm, in this process: {t_row:.3f} s")
        for workers in args.workers:
            with tempfile.TemporaryDirectory() as d:
                t, c = time.perf_counter(), _cpu_seconds()
                run_map(spec, Path(d) / "tiles", workers=workers)
                dt, dc = time.perf_counter() - t, _cpu_seconds() - c
            print(f"paper-only map {n}x{n} with {workers} worker(s): {dt:.1f} s, "
                  f"{n * n / dt:.0f} points/s, CPU {dc:.1f} s (this process and its "
                  "children; includes cluster start and per-worker kernel loading)")
    headline_against_paper(base, n, args.workers, args.rows_per_tile)


def headline_against_paper(base, n: int, workers_list, rows_per_tile: int) -> None:
    """The headline map against the paper-only map (same grid, same workers, this run),
    then one headline tile in this process with its time split into the paper's part and
    the simulations."""
    import dataclasses

    import maglev_match.analyses.maps as maps
    import maglev_match.analyses.maps.simulated as simulated  # where the rows look it up

    paper = MapSpec(base=base.as_input_dict(), x=Axis("omega1", 40, 190, n),
                    y=Axis("sigma", 2e-4, 6e-4, n), rows_per_tile=rows_per_tile,
                    simulate=False)
    headline = dataclasses.replace(paper, simulate=True)
    for workers in workers_list:
        wall: dict[str, list[float]] = {"paper": [], "headline": []}
        cpu: dict[str, list[float]] = {"paper": [], "headline": []}
        # paper, headline, paper: the paper-only map before and after, so that a load that
        # changes during the run shows (the machine is shared)
        for name, spec in (("paper", paper), ("headline", headline), ("paper", paper)):
            with tempfile.TemporaryDirectory() as d:
                t, c = time.perf_counter(), _cpu_seconds()
                data = run_map(spec, Path(d) / "tiles", workers=workers)
                dt, dc = time.perf_counter() - t, _cpu_seconds() - c
            wall[name].append(dt)
            cpu[name].append(dc)
            unresolved = int((~data["resolved"].astype(bool)).sum())
            label = "headline" if spec.simulate else "paper-only (--no-simulation)"
            print(f"{label} map {n}x{n}, {rows_per_tile} rows per tile, {workers} worker(s): "
                  f"{dt:.1f} s wall, CPU {dc:.1f} s; {unresolved} unresolved point(s); load "
                  f"{os.getloadavg()[0]:.1f}", flush=True)
        pw, pc = statistics.mean(wall["paper"]), statistics.mean(cpu["paper"])
        print(f"headline / paper-only (mean of the two) with {workers} worker(s): wall "
              f"{wall['headline'][0] / pw:.2f}x, CPU {cpu['headline'][0] / pc:.2f}x "
              "(target <= 3x)")
    # where a headline tile's time goes (one tile from the middle, warm, this process)
    a = (n // 2 // rows_per_tile) * rows_per_tile
    rows = (a, min(a + rows_per_tile, n))
    stats = {"calls": 0, "runs": 0, "lines": 0, "lane_steps": 0, "run_steps": 0, "cpu": 0.0}
    inner = simulated.critical_sizes_batch

    def counted(*args, **kw):
        c = time.process_time()
        res = inner(*args, **kw)
        stats["cpu"] += time.process_time() - c
        stats["calls"] += res.calls
        stats["runs"] += int(res.runs.sum())
        stats["lines"] += len(res.size)
        stats["lane_steps"] += res.lane_steps
        stats["run_steps"] += res.run_steps
        return res

    maps.compute_tile(headline, rows)  # warm
    simulated.critical_sizes_batch = counted
    try:
        c = time.process_time()
        maps.compute_tile(paper, rows)
        c_paper = time.process_time() - c
        c = time.process_time()
        maps.compute_tile(headline, rows)
        c_head = time.process_time() - c
    finally:
        simulated.critical_sizes_batch = inner
    print(f"tile rows {rows[0]}-{rows[1] - 1} in this process (CPU): paper-only {c_paper:.2f} s; "
          f"headline {c_head:.2f} s, of which simulations {stats['cpu']:.2f} s: "
          f"{stats['lines']} critical disturbances (point x direction), {stats['runs']} runs "
          f"({stats['runs'] / max(stats['lines'], 1):.2f} per disturbance), "
          f"{stats['run_steps']} integration steps used, {stats['lane_steps']} paid in "
          f"{stats['calls']} batched kernel calls "
          f"({stats['lane_steps'] / max(stats['run_steps'], 1):.2f}x: padding and runs "
          "waiting for the slowest of their chunk)")


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

    from maglev_match.analyses.sensitivity import index_sensitivity

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
