"""Benchmark: one branch of model A cycles (printed defaults, sigma = 4e-4) from the Hopf
point until the first physical-limit contact, by collocation (NTST 80, NCOL 4), in one warm
process: the current path (chord Newton on the condensed system, Floquet transfer matrices
from the condensation, block cyclic QR when its bound allows) against last round's path
(``newton="full"``) and the earlier path (``linear_solver="sparse_lu"``,
``floquet_method="periodic_qz"``, Newton-count steps), all run in the same process; the
cost of one Newton iteration and one chord iteration at NTST 80; chi at one point warm
(against the earlier route and the simulated critical disturbance); then a
shooting baseline (Newton on the flow map, DOP853 + variational equations) solving the same
cycles from a warm start (a lower bound on shooting's cost), and the whole CLI command.

    .venv/bin/python bench/bench_cycles.py [--quick] [--skip-shooting] [--against DIR]

``--against DIR`` (a source tree of an earlier commit, e.g. ``git archive <commit> src |
tar -x -C DIR``) first times the same branch in fresh processes alternating between that
tree and this one (``--rounds`` pairs, each process: one warm-up branch and the median of
7), so the before/after ratio is measured under one machine load; CPU time is the number
to compare on a shared machine. AUTO-07p is not installed here: its timing on this job
(0.25 s wall, one thread; an earlier measurement 0.166 s) is quoted from issue 25 and
bench/RESULTS.md.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/_interleave.py

from maglev_match.core.params import load_preset  # noqa: E402
from maglev_match.dynamics.cycles import cycle_branch  # noqa: E402
from maglev_match.dynamics.hopf import locate_hopf_points  # noqa: E402
from maglev_match.dynamics.shooting import shoot_periodic_orbit, trajectory_extrema  # noqa: E402
from maglev_match.maglev.limits import cycle_limit_margins  # noqa: E402
from maglev_match.maglev.models import build_system  # noqa: E402


def branch_job() -> None:
    """The benchmark job in this process: warm-up, then the median of 7 branches (JSON)."""
    params = load_preset("alpha1").replace(sigma=4e-4)
    system = build_system(params, "unit")
    hopf = locate_hopf_points(system, "omega1", 110.0, 150.0, n_scan=40).points[0]
    limits = cycle_limit_margins(params)
    br = cycle_branch(system, hopf, "omega1", ntst=80, ncol=4, limits=limits)
    cs, ws = [], []
    for _ in range(7):
        c0, w0 = time.process_time(), time.perf_counter()
        br = cycle_branch(system, hopf, "omega1", ntst=80, ncol=4, limits=limits)
        cs.append(time.process_time() - c0)
        ws.append(time.perf_counter() - w0)
    import json

    print(json.dumps({"cpu": statistics.median(cs), "cpu_min": min(cs),
                      "wall": statistics.median(ws), "wall_min": min(ws),
                      "steps": br.steps, "iterations": br.newton_iterations,
                      "factorisations": br.factorizations, "end": br.points[-1].value,
                      "end_kind": br.points[-1].kind}))


def against(baseline: Path, rounds: int) -> None:
    from _interleave import interleaved, load, summary

    print(f"interleaved before/after, {rounds} pairs of fresh processes, load {load()}")
    res = interleaved(Path(__file__), "branch", baseline, rounds)
    for tree in ("baseline", "current"):
        for r in res[tree]:
            print(f"  {tree}: {r['cpu']:.3f} s CPU (min {r['cpu_min']:.3f}), {r['wall']:.3f} s "
                  f"wall (min {r['wall_min']:.3f}); {r['steps']} steps, {r['iterations']} "
                  f"iterations, {r['factorisations']} factorisations; ends at {r['end']:.10g} "
                  f"({r['end_kind']})")
    b, c, ratio = summary(res, "cpu")
    bw, cw, rw = summary(res, "wall")
    print(f"branch, median CPU: before {b:.3f} s, after {c:.3f} s, {ratio:.2f}x; wall "
          f"{bw:.3f} -> {cw:.3f} s ({rw:.2f}x); AUTO-07p (quoted, one thread): 0.25 s wall "
          f"({'faster' if cw < 0.25 else 'not faster'} in wall, "
          f"{'faster' if c < 0.25 else 'not faster'} in CPU); load after {load()}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer repeats, shooting on 1/4")
    ap.add_argument("--skip-shooting", action="store_true",
                    help="only the collocation timings (no shooting, no CLI run)")
    ap.add_argument("--against", type=Path, default=None,
                    help="source tree of the baseline for the interleaved before/after")
    ap.add_argument("--rounds", type=int, default=3, help="pairs of processes (--against)")
    ap.add_argument("--only-against", action="store_true",
                    help="only the interleaved before/after")
    ap.add_argument("--job", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.job == "branch":
        branch_job()
        return
    if args.against is not None:
        against(args.against, args.rounds)
        if args.only_against:
            return
    repeats = 2 if args.quick else 5
    params = load_preset("alpha1").replace(sigma=4e-4)
    system = build_system(params, "unit")
    hopf = locate_hopf_points(system, "omega1", 110.0, 150.0, n_scan=40).points[0]
    limits = cycle_limit_margins(params)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, load average {os.getloadavg()[0]:.1f}")
    print(f"Hopf point omega1 = {hopf.value:.8g} rad/s, l1 = {hopf.l1:.4g}")

    print(f"load (uptime): {open('/proc/loadavg').read().split()[:3]}")

    # three paths, run in this process: the code before issue 14 ("earlier": whole-system
    # sparse LU, periodic QZ, Newton-count steps), last round's ("round 2": condensed LU,
    # full Newton, cyclic QR, predicted-error steps), and the current one (chord Newton with
    # the Floquet transfer matrices from the condensation)
    paths = {
        "earlier": {"linear_solver": "sparse_lu", "floquet_method": "periodic_qz",
                    "predictor_tol": None, "newton": "full"},
        "round 2": {"newton": "full"},
        "current": {},
    }

    def run(path: str):
        return cycle_branch(system, hopf, "omega1", ntst=80, ncol=4, limits=limits,
                            **paths[path])

    res: dict[str, float] = {}
    for path in paths:
        t = time.perf_counter()
        br = run(path)
        first = time.perf_counter() - t
        times, cpu = [], []
        for _ in range(repeats):
            t, c0 = time.perf_counter(), time.process_time()
            br = run(path)
            times.append(time.perf_counter() - t)
            cpu.append(time.process_time() - c0)
        res[path] = statistics.median(cpu)
        print(f"{path}: first call {first:.2f} s, median {statistics.median(times):.3f} s wall, "
              f"{res[path]:.3f} s CPU over {repeats} (min {min(cpu):.3f} s CPU); "
              f"{br.steps} steps ({br.rejected_steps} rejected), {len(br.points)} cycles, "
              f"corrector iterations {br.newton_iterations} "
              f"({br.newton_iterations / max(br.steps, 1):.1f} per step), factorisations "
              f"{br.factorizations} ({br.factorizations / max(br.steps, 1):.1f} per step), "
              f"stopped: {br.stopped_reason}")
        for sp in br.special_points:
            print(f"  {sp.type} at omega1 = {sp.value:.12g} ({sp.detail}, {sp.located})")
    coll = res["current"]
    print(f"branch CPU ratio earlier / current: {res['earlier'] / coll:.2f}x, round 2 / "
          f"current: {res['round 2'] / coll:.2f}x (AUTO-07p one thread, quoted: 0.25 s: "
          f"{'faster' if coll < 0.25 else 'not faster'})")

    # one Newton iteration at NTST 80: residual + Jacobian blocks, factorisation, solve;
    # and one chord iteration (residual, solve with the kept factorisation)
    from maglev_match.dynamics.collocation import (
        CollocationProblem,
        factor_jacobian,
    )
    c = br.points[len(br.points) // 2]
    o = c.orbit
    prob = CollocationProblem(system=system, ipar=system.param_index("omega1"), p0=o.p,
                              mesh=o.mesh, m=4, scale=np.asarray(system.state_scale, float),
                              T_scale=o.period, lam_scale=5.0)
    Y = prob.pack(o.states, o.period, c.value)
    row = np.zeros(prob.size)
    row[-1] = 1.0
    phase = prob.phase_row(o.states)

    def timed(f, n=50):
        ts, cs = [], []
        for _ in range(n):
            t, c0 = time.perf_counter(), time.process_time()
            f()
            ts.append(time.perf_counter() - t)
            cs.append(time.process_time() - c0)
        return statistics.median(ts) * 1e3, statistics.median(cs) * 1e3, min(ts) * 1e3

    def newton_iteration(solver):
        pa = prob.parts(Y, phase, o.states, row, c.value / 5.0)
        lu = factor_jacobian(prob, pa, solver, -pa.resid)
        lu.solve(-pa.resid)

    kept = factor_jacobian(prob, prob.parts(Y, phase, o.states, row, c.value / 5.0), "condensed")

    def chord_iteration():
        r = prob.residual(Y, phase, o.states, row, c.value / 5.0)
        kept.solve(-r)

    it = {}
    for name, f in (("Newton, sparse_lu", lambda: newton_iteration("sparse_lu")),
                    ("Newton, condensed", lambda: newton_iteration("condensed")),
                    ("chord (kept factorisation)", chord_iteration)):
        w, cp, mn = timed(f)
        it[name] = cp
        print(f"one {name} iteration, NTST 80: median {w:.2f} ms wall, {cp:.2f} ms CPU, "
              f"min {mn:.2f} ms (target < 1.5 ms)")
    br_now = run("current")
    print(f"branch average, current path: {coll * 1e3 / max(br_now.newton_iterations, 1):.2f} "
          f"ms CPU per corrector iteration, everything included (Floquet, read-outs)")

    # chi at one point, warm (continuation), against the same route with the multipliers at
    # every point and the whole-system LU (the earlier path), and against the simulated
    # critical disturbance at the same point
    from maglev_match.analyses.matching import matching_index
    from maglev_match.analyses.simulation import critical_disturbance
    from maglev_match.dynamics import basin
    p_alpha = load_preset("alpha1")
    current_cb = basin.cycle_branch

    def earlier_cb(*a, **kw):
        kw.update(multipliers_at="all", linear_solver="sparse_lu")
        return current_cb(*a, **kw)

    chi = {}
    for name, cb in (("earlier", earlier_cb), ("current", current_cb)):
        basin.cycle_branch = cb
        try:
            matching_index(p_alpha, simulate=False)
            ts, cs = [], []
            for _ in range(repeats):
                t, c0 = time.perf_counter(), time.process_time()
                mi = matching_index(p_alpha, simulate=False)
                ts.append(time.perf_counter() - t)
                cs.append(time.process_time() - c0)
        finally:
            basin.cycle_branch = current_cb
        chi[name] = statistics.median(cs)
        print(f"chi at alpha1 by continuation, warm, {name} route: median "
              f"{statistics.median(ts):.3f} s wall, {chi[name]:.3f} s CPU "
              f"(chi = {mi.chi!r}; target < 0.1 s)")
    critical_disturbance(p_alpha, direction=-1)
    ts, cs = [], []
    for _ in range(repeats):
        t, c0 = time.perf_counter(), time.process_time()
        critical_disturbance(p_alpha, direction=-1)
        critical_disturbance(p_alpha, direction=1)
        ts.append(time.perf_counter() - t)
        cs.append(time.process_time() - c0)
    sim = statistics.median(cs)
    print(f"simulated critical disturbance at alpha1 (both directions), warm: median "
          f"{statistics.median(ts):.3f} s wall, {sim:.3f} s CPU; continuation chi is "
          f"{sim / chi['current']:.2f}x faster (target >= 3x); chi ratio earlier / current "
          f"{chi['earlier'] / chi['current']:.2f}x")
    if args.skip_shooting:
        return

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
