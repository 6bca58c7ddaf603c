"""Benchmark: the vehicle at speed over identical spans (maglev_match.analyses.speed.sweep).

1. One periodic solve (Newton on the span map, multipliers at the solution) against the
   baseline of simulating span after span until the state at the hand-over settles to the
   same tolerance (the "long simulation" the periodic solve replaces), in the same process,
   for the unit and the vehicle at 5, 60 and 150 km/h: CPU time, passages integrated,
   variational solves. Both reach a scaled residual below 1e-9.
2. One whole speed point (periodic solve, read-outs, critical disturbance) at 60 km/h.
3. A sweep of 31 speeds (0 to 150 km/h by 5) of the unit and of the vehicle on a local Dask
   cluster of ``--workers`` processes (default 2), the way ``maglev-match speed`` runs it:
   wall time and the CPU time of this process and its children (the workers).

The persistent compilation cache is used as configured (warm after a first run; compile
times are the first call's). Prints the machine load (``os.getloadavg``) before and after.

    .venv/bin/python bench/bench_speed.py [--skip-vehicle] [--skip-sweeps] [--workers N]
"""

from __future__ import annotations

import os
import resource
import sys
import time

import numpy as np

from maglev_match import load_preset
from maglev_match.analyses.speed.sweep import (
    KMH,
    SpeedOptions,
    passage_problem,
    periodic_response,
    quasi_static_state,
    speed_point,
    speed_sweep,
)
from maglev_match.dynamics.integrate.passage import run_passage

TOL = 1e-9  # scaled residual of both methods


def cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def settle_by_simulation(params, model, v, max_passages=20_000):
    """The baseline: x <- P(x) from the same quasi-static start until max |P(x) - x| / scale
    < TOL. Returns (passages, residual)."""
    from maglev_match.maglev import moving as mv

    problem = passage_problem(params, model, v)
    x = quasi_static_state(params, model, params.L)
    sl = mv.slot_slices(model, params.n_modes)
    x[sl["qB"]] = 0.0
    x[sl["qB_dot"]] = 0.0
    opts = SpeedOptions().passage()
    res = np.inf
    for k in range(1, max_passages + 1):
        run = run_passage(problem, x, opts)
        res = float(np.max(np.abs(run.x_next[:-1] - x[:-1]) / problem.scale))
        x = run.x_next
        if res < TOL:
            return k, res
    return max_passages, res


def timed(fn):
    c0, w0 = time.process_time(), time.perf_counter()
    out = fn()
    return out, time.process_time() - c0, time.perf_counter() - w0


def bench_solves(params, model):
    print(f"\n== one periodic solve, model {model} ==")
    print(f"{'km/h':>5} {'solve CPU s':>11} {'passages':>8} {'var. solves':>11} "
          f"{'max|mu|':>8} | {'settle CPU s':>12} {'passages':>8} | {'ratio':>6}")
    # first calls (compile or load the kernels)
    _, c, w = timed(lambda: periodic_response(params, model, 60 * KMH))
    print(f"(first call, compiling or loading kernels: {c:.2f} s CPU, {w:.2f} s wall)")
    settle_by_simulation(params, model, 150 * KMH, max_passages=2)
    for kmh in (5, 60, 150):
        v = kmh * KMH
        sol, c1, _ = timed(lambda v=v: periodic_response(params, model, v))
        (n, _), c2, _ = timed(lambda v=v: settle_by_simulation(params, model, v))
        print(f"{kmh:>5} {c1:>11.3f} {sol.passages:>8} {sol.jacobians:>11} "
              f"{sol.multipliers.largest:>8.4f} | {c2:>12.3f} {n:>8} | {c2 / c1:>6.2f}")


def bench_point(params, model):
    _, c, w = timed(lambda: speed_point(params, model, 60 * KMH))
    print(f"one speed point at 60 km/h (solve, read-outs, critical disturbance), model "
          f"{model}: {c:.2f} s CPU, {w:.2f} s wall")


def bench_sweep(params, model, workers):
    speeds = list(np.arange(0.0, 150.0 + 1e-9, 5.0) * KMH)
    c0, cc0, w0 = time.process_time(), cpu_children(), time.perf_counter()
    sw = speed_sweep(params, model, speeds, workers=workers)
    wall = time.perf_counter() - w0
    cpu = time.process_time() - c0 + cpu_children() - cc0
    daf, vd = sw.largest("daf")
    print(f"sweep of {len(speeds)} speeds, model {model}, {workers} workers: {wall:.1f} s wall, "
          f"{cpu:.1f} s CPU (this process and its workers); stable everywhere: "
          f"{not sw.loses_stability}; largest DAF {daf:.4f} at {vd / KMH:.0f} km/h")


def main() -> None:
    if "-h" in sys.argv or "--help" in sys.argv:
        print(__doc__)
        return
    workers = 2
    if "--workers" in sys.argv:
        workers = int(sys.argv[sys.argv.index("--workers") + 1])
    params = load_preset("turnout-soft")
    print(f"load average at start: {os.getloadavg()}")
    models = ["unit"] + ([] if "--skip-vehicle" in sys.argv else ["vehicle"])
    for model in models:
        bench_solves(params, model)
        bench_point(params, model)
    if "--skip-sweeps" not in sys.argv:
        print("\n== sweeps ==")
        for model in models:
            bench_sweep(params, model, workers)
    print(f"load average at end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
