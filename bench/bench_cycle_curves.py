"""Benchmark: the fold-of-cycles (LPC) curve of model A (preset alpha1, xi0 = 0.7) in
(omega1, sigma) with 100 points against the one-parameter branch of cycles it starts from
(the same mesh: NTST 80, NCOL 4), both warm, in one process; the medians of the CPU times
(``time.process_time``) and their ratio (the issue's target: under 3x).

    .venv/bin/python bench/bench_cycle_curves.py [--repeats 3]

AUTO-07p is not installed here (no ISW=2 timing to quote).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from maglev_match.core.params import load_preset
from maglev_match.dynamics.cycle_curves import cycle_curve, start_from
from maglev_match.dynamics.cycles import cycle_branch
from maglev_match.dynamics.hopf import locate_hopf_points
from maglev_match.maglev.limits import cycle_limit_margins
from maglev_match.maglev.models import build_system


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    params = load_preset("alpha1").replace(sigma=4e-4, xi0=0.7)
    system = build_system(params, "unit")
    hopf = locate_hopf_points(system, "omega1", 90.0, 150.0, n_scan=40).points[0]
    limits = cycle_limit_margins(params, include_current=False)

    def branch():
        return cycle_branch(system, hopf, "omega1", ntst=80, ncol=4, limits=limits)

    def curve(orbit):
        return cycle_curve(system, orbit, "LPC", ("omega1", "sigma"), max_steps=99,
                           ranges={"sigma": (1e-4, 1e-3)})

    br = branch()  # warm-up (compilation)
    orbit = start_from(br, "LPC1")
    curve(orbit)
    tb, tc = [], []
    for _ in range(args.repeats):
        c0 = time.process_time()
        br = branch()
        tb.append(time.process_time() - c0)
        c0 = time.process_time()
        cv = curve(orbit)
        tc.append(time.process_time() - c0)
    b, c = statistics.median(tb), statistics.median(tc)
    print(f"load {os.getloadavg()[0]:.2f}; branch: {len(br.points)} points, {br.steps} "
          f"steps, {b:.2f} s CPU (median of {args.repeats}); LPC curve: {len(cv.points)} "
          f"points ({cv.stopped_reason}), {cv.newton_iterations} Newton iterations, "
          f"{c:.2f} s CPU; ratio curve / branch {c / b:.2f} (per point "
          f"{(c / len(cv.points)) / (b / len(br.points)):.2f})")
    print(f"curve ends: omega1 {cv.p1[0]:.6g} .. {cv.p1[-1]:.6g}, sigma {cv.p2[0]:.4g} .. "
          f"{cv.p2[-1]:.4g}; special points {[s.label for s in cv.special_points]}")


if __name__ == "__main__":
    main()
