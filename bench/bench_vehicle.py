"""Benchmark: the full vehicle (model B, 40 states, turnout-soft): one factorisation of its
collocation Jacobian (NTST 40, NCOL 4: 40 interval blocks of 160 x 160), the vehicle index
without simulation in one warm process, and the whole command `maglev-match index --model
vehicle` in a fresh process (warm caches).

    .venv/bin/python bench/bench_vehicle.py [--against DIR] [--rounds N] [--skip-cli]

With ``--against DIR`` (the source tree of an earlier commit: ``git archive <commit> src |
tar -x -C DIR``) every job runs in fresh processes alternating between that tree and this
one, so before and after see the same machine load; CPU time is the number to compare on a
shared machine. Without it, only this tree, with the factorisation's parts timed.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/_interleave.py


def _vehicle_problem():
    import numpy as np

    from maglev_match.core.params import load_preset
    from maglev_match.dynamics import collocation as C
    from maglev_match.dynamics.cycles import cycle_branch
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.maglev.models import build_system

    system = build_system(load_preset("turnout-soft"), "vehicle")
    scan = locate_hopf_points(system, "omega1", 60.0, 160.0, n_scan=30)
    hp = min(scan.points, key=lambda h: abs(h.value - 128.0))
    br = cycle_branch(system, hp, "omega1", ntst=40, max_steps=4,
                      detect_special_points=False)
    c = br.points[-1]
    o = c.orbit
    prob = C.CollocationProblem(system=system, ipar=system.param_index("omega1"), p0=o.p,
                                mesh=o.mesh, m=o.ncol,
                                scale=np.asarray(system.state_scale, float),
                                T_scale=o.period, lam_scale=5.0)
    Y = prob.pack(o.states, o.period, c.value)
    row = np.zeros(prob.size)
    row[-1] = 1.0
    return prob, Y, row, prob.phase_row(o.states), o.states, c.value / 5.0


def _median_ms(f, n=15):
    cs = []
    for _ in range(n):
        c0 = time.process_time()
        f()
        cs.append(time.process_time() - c0)
    return statistics.median(cs) * 1e3


def factor_job() -> dict:
    from threadpoolctl import threadpool_limits

    from maglev_match.dynamics import collocation as C

    prob, Y, row, phase, Uref, target = _vehicle_problem()
    with threadpool_limits(1):
        pa = prob.parts(Y, phase, Uref, row, target)
        lu = C.CondensedLU(prob, pa, -pa.resid)
        r = -pa.resid
        return {"parts_ms": _median_ms(lambda: prob.parts(Y, phase, Uref, row, target)),
                "factor_ms": _median_ms(lambda: C.CondensedLU(prob, pa, -pa.resid)),
                "solve_ms": _median_ms(lambda: lu.solve(r)),
                "states": prob.n, "ntst": prob.mesh.size - 1, "ncol": prob.m}


def index_job() -> dict:
    from maglev_match.analyses.matching import matching_index
    from maglev_match.core.params import load_preset

    p = load_preset("turnout-soft")
    matching_index(p, model="vehicle", simulate=False)  # warm
    c0, w0 = time.process_time(), time.perf_counter()
    res = matching_index(p, model="vehicle", simulate=False)
    return {"cpu": time.process_time() - c0, "wall": time.perf_counter() - w0,
            "chi": res.chi, "case": str(res.case)}


def cli_job() -> dict:
    """The whole command in a child process (after one warm-up run for the caches)."""
    cmd = [sys.executable, "-m", "maglev_match.cli", "index", "--model", "vehicle", "--json"]
    subprocess.run(cmd, capture_output=True, check=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    w0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, check=True, text=True)
    wall = time.perf_counter() - w0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    doc = json.loads(out.stdout)
    return {"cpu": cpu, "wall": wall, "chi": doc["chi"],
            "chi_simulation": doc.get("chi_simulation")}


JOBS = {"factor": factor_job, "index": index_job, "cli": cli_job}


def parts_breakdown() -> None:
    """The factorisation of this tree taken apart (in this process)."""
    import numpy as np
    from threadpoolctl import threadpool_limits

    from maglev_match.dynamics import collocation as C

    prob, Y, row, phase, Uref, target = _vehicle_problem()
    with threadpool_limits(1):
        pa = prob.parts(Y, phase, Uref, row, target)
        n, m = prob.n, prob.m
        K = pa.blk[:, :, n:]
        rhs = np.concatenate([pa.blk[:, :, :n], pa.colT.reshape(K.shape[0], -1, 1),
                              pa.colL.reshape(K.shape[0], -1, 1)], axis=2)
        lu = C.CondensedLU(prob, pa, -pa.resid)
        print(f"vehicle: {prob.n} states, NTST {K.shape[0]}, NCOL {m}, interval blocks "
              f"{K.shape[1]} x {K.shape[2]}; reduced system {lu.lu.shape[0]} unknowns")
        print(f"  parts kernel (residual + blocks): {_median_ms(lambda: prob.parts(Y, phase, Uref, row, target)):.1f} ms CPU")  # noqa: E501
        print(f"  interval LU + solves (dgetrf/dgetrs, {rhs.shape[2]} columns): "
              f"{_median_ms(lambda: C.batched_lu_solve(K, rhs)):.1f} ms CPU")
        print(f"  interval inverses (dgetrf/dgetri, the small-block path): "
              f"{_median_ms(lambda: C.batched_inverse(K)):.1f} ms CPU")
        print(f"  whole factorisation (CondensedLU): "
              f"{_median_ms(lambda: C.CondensedLU(prob, pa, -pa.resid)):.1f} ms CPU")
        r = -pa.resid
        print(f"  one solve with it (a chord iteration's linear algebra): "
              f"{_median_ms(lambda: lu.solve(r)):.2f} ms CPU")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--against", type=Path, default=None)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--skip-cli", action="store_true")
    ap.add_argument("--jobs", default="factor,index,cli",
                    help="which interleaved jobs (factor, index, cli)")
    ap.add_argument("--job", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.job:
        print(json.dumps(JOBS[args.job]()))
        return
    from _interleave import interleaved, load, summary

    print(f"{os.cpu_count()} cores, load {load()}")
    if "factor" in args.jobs:
        parts_breakdown()
    jobs = [j for j in args.jobs.split(",") if not (args.skip_cli and j == "cli")]
    if args.against is None:  # this tree only: each job once in this process, no baseline
        for job in (j for j in jobs if j != "factor"):
            print(f"{job} (this tree, no baseline): {json.dumps(JOBS[job]())}; load {load()}")
        return
    for job in jobs:
        res = interleaved(Path(__file__), job, args.against, args.rounds)
        key = "factor_ms" if job == "factor" else "cpu"
        b, c, ratio = summary(res, key)
        extra = ""
        if job != "factor":
            bw, cw, rw = summary(res, "wall")
            extra = (f"; wall {bw:.1f} -> {cw:.1f} s ({rw:.2f}x); chi "
                     f"{res['baseline'][-1]['chi']!r} -> {res['current'][-1]['chi']!r}")
        print(f"{job}: before {b:.3f}, after {c:.3f} ({'ms' if job == 'factor' else 's'} CPU, "
              f"median of {args.rounds}), {ratio:.2f}x{extra}; load {load()}")


if __name__ == "__main__":
    main()
