"""Benchmark: one branch of model A cycles (printed defaults, sigma = 4e-4) from the Hopf
point until the first physical-limit contact, by collocation (NTST 80, NCOL 4), against a
shooting baseline (Newton on the flow map, DOP853 + variational equations) solving the same
cycles from a warm start (a lower bound on shooting's cost), and the whole CLI command.

    .venv/bin/python bench/bench_cycles.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from maglev_match.dynamics.cycles import cycle_branch
from maglev_match.dynamics.hopf import locate_hopf_points
from maglev_match.dynamics.shooting import shoot_periodic_orbit, trajectory_extrema
from maglev_match.limits_check import cycle_limit_margins
from maglev_match.models import build_system
from maglev_match.params import load_preset


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer repeats, shooting on 1/4")
    args = ap.parse_args()
    repeats = 2 if args.quick else 5
    params = load_preset("alpha1").replace(sigma=4e-4)
    system = build_system(params, "unit")
    hopf = locate_hopf_points(system, "omega1", 110.0, 150.0, n_scan=40).points[0]
    limits = cycle_limit_margins(params)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, load average {os.getloadavg()[0]:.1f}")
    print(f"Hopf point omega1 = {hopf.value:.8g} rad/s, l1 = {hopf.l1:.4g}")

    t = time.perf_counter()
    br = cycle_branch(system, hopf, "omega1", ntst=80, ncol=4, limits=limits)
    first = time.perf_counter() - t
    times, cpu = [], []
    for _ in range(repeats):
        t, c0 = time.perf_counter(), time.process_time()
        br = cycle_branch(system, hopf, "omega1", ntst=80, ncol=4, limits=limits)
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c0)
    coll = statistics.median(times)
    print(f"collocation branch: first call (with compile) {first:.2f} s, median "
          f"{coll:.3f} s wall, {statistics.median(cpu):.3f} s CPU (all threads) over "
          f"{repeats}; min {min(times):.3f} s wall; {br.steps} steps "
          f"({br.rejected_steps} rejected), "
          f"{len(br.points)} cycles, stopped: {br.stopped_reason}")
    for s in br.special_points:
        print(f"  {s.type} at omega1 = {s.value:.8g} ({s.detail}, {s.located})")

    # amplitude accuracy against a finer mesh at one parameter value
    fine = cycle_branch(system, hopf, "omega1", stop_at=125.0, ntst=160, ncol=5)
    coarse = cycle_branch(system, hopf, "omega1", stop_at=125.0, ntst=80, ncol=4)
    a_f, a_c = fine.points[-1].max("gap_deviation"), coarse.points[-1].max("gap_deviation")
    print(f"max gap deviation at omega1 = 125: NTST 80/NCOL 4 {a_c:.10e} m, NTST 160/NCOL 5 "
          f"{a_f:.10e} m, relative difference {abs(a_c - a_f) / abs(a_f):.2e}")

    # shooting baseline over the same parameter values
    pts = br.points[1:] if not args.quick else br.points[1::4]
    t, c0 = time.perf_counter(), time.process_time()
    # Each cycle of the branch solved by shooting from the collocation answer perturbed by
    # 1e-6 (relative): a LOWER BOUND on the cost of shooting on this branch. Natural-parameter
    # shooting continuation was tried and fails near the Hopf point, where the branch is
    # nearly vertical in omega1 (amplitude grows while omega1 barely moves).
    worst = 0.0
    n_ok = 0
    for c in pts:
        x0 = c.orbit.states[0] * (1 + 1e-6)
        sh = shoot_periodic_orbit(system, x0, c.period * (1 + 1e-6), c.orbit.p, max_iter=10)
        if not sh.converged:
            continue
        n_ok += 1
        worst = max(worst, abs(sh.period - c.period) / c.period)
    shoot = time.perf_counter() - t
    shoot_cpu = time.process_time() - c0
    c = pts[len(pts) // 2]
    sh = shoot_periodic_orbit(system, c.orbit.states[0], c.period, c.orbit.p)
    ext = trajectory_extrema(system, sh.x0, sh.period, sh.p, ["gap_deviation"])
    amp = abs(ext["gap_deviation"][0] - c.max("gap_deviation")) / c.max("gap_deviation")
    print(f"shooting baseline: {shoot:.2f} s wall, {shoot_cpu:.2f} s CPU for {len(pts)} "
          f"cycles ({n_ok} converged), "
          f"max period difference {worst:.1e}; amplitude difference at omega1 = "
          f"{c.value:.5g}: {amp:.1e}")
    per_cycle_coll = coll / max(len(br.points), 1)
    per_cycle_shoot = shoot / max(len(pts), 1)
    print(f"per cycle: collocation {per_cycle_coll * 1e3:.1f} ms, shooting "
          f"{per_cycle_shoot * 1e3:.1f} ms, ratio {per_cycle_shoot / per_cycle_coll:.1f}x")

    # the whole command line, compilation (and the persistent cache) included
    exe = Path(sys.executable).parent / "maglev-match"
    t = time.perf_counter()
    subprocess.run([str(exe), "cycles", "--param", "omega1", "--at", "sigma=4e-4",
                    "--preset", "alpha1", "--json"], check=True, capture_output=True)
    print(f"CLI `maglev-match cycles --param omega1 --at sigma=4e-4 --preset alpha1 --json`: "
          f"{time.perf_counter() - t:.2f} s wall")
    _ = np


if __name__ == "__main__":
    main()
