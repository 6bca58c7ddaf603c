"""Benchmark: an iso-chi curve (`iso-curve`, issue 32) against the indices it is made of.

* the baseline, in the same process: one headline index of model A at turnout-soft from
  scratch, and one warm-started from a neighbouring design (``near=``, what the curve
  does at every evaluation); medians of ``--repeat``;
* the curve headline chi = 5 in (EI, kD), kD from 75 to 300 A s/m (EI from half to twice
  its base value), at most ``--points`` points: CPU and wall time, index evaluations per
  point and the ratio of the curve's CPU to (points x one warm-started index); the issue's
  target is 30 points under 2 min on 2 cores.

Wall and CPU (process) times; the load average is printed, since the machine is shared.

Usage: python bench/bench_iso.py [--points 30] [--repeat 3] [--no-simulation]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

from maglev_match import api

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/_timing.py
from _timing import timed, timed_once  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=30)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-simulation", action="store_true")
    args = ap.parse_args()
    sim = not args.no_simulation
    print(f"machine: {platform.machine()}, python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.2f}")
    first = api.matching_index("turnout-soft", simulate=sim, stage=False)  # compiles
    api.matching_index("turnout-soft", simulate=sim, stage=False, near=first,
                       EI=1.97e10)  # the continuation's kernels load once (not timed)
    w1, c1, _ = timed(lambda: api.matching_index("turnout-soft", simulate=sim, stage=False,
                                                 EI=1.97e10), args.repeat)
    w2, c2, _ = timed(lambda: api.matching_index("turnout-soft", simulate=sim, stage=False,
                                                 near=first, EI=1.97e10), args.repeat)
    print(f"one index from scratch: {w1:.2f} s wall, {c1:.2f} s CPU; warm-started: "
          f"{w2:.2f} s wall, {c2:.2f} s CPU")
    curve, cpu, wall = timed_once(lambda: api.iso_curve(
        "turnout-soft", 5.0, names=("EI", "kD"), ranges={"kD": (75.0, 300.0)},
        points=args.points, simulate=sim, stage=False))
    n = len(curve.points)
    print(f"iso-chi curve chi = 5 in (EI, kD): {n} points, {curve.evaluations} evaluations "
          f"({curve.evaluations / max(n, 1):.1f} per point), {wall:.1f} s wall, {cpu:.1f} s "
          f"CPU; CPU / (points x one warm-started index) = {cpu / max(n * c2, 1e-9):.1f}; "
          f"target 30 points < 120 s: {'met' if n >= 30 and wall < 120 else 'not met'}")
    print(f"ends: {curve.ends}; special points: "
          f"{[(s['kind'], round(s['EI'], -6), round(s['kD'], 3)) for s in curve.special_rows()]}")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
