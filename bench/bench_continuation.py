"""Benchmark: the solved critical disturbance continued from design to design (issue 34).

Prints medians and ratios against baselines run in the same process (warm: every kernel is
called once before timing):

* a row of neighbouring designs (turnout-soft, EI from 0.98 to 1.02 of the preset, beam
  down, grazing all along): ``follow_critical`` (the first point searched, the rest
  continued: predictor, Newton on the grazing condition, two check runs) against the
  point-wise ``solve_critical`` at every point (bracketing by 30 runs, classification,
  solve);
* the headline index at a neighbouring design in one process: ``matching_index(...,
  near=previous)`` against ``matching_index(...)`` at the same designs (EI steps of
  0.1 %), with the paper-only index (``simulate=False``, point-wise and with ``near``: the
  cycle continued) and the critical delay of the controller (part of every index, not
  continued) beside them, wall and CPU time;
* ``--basin``: the same row comparison for a basin boundary (beam up, omega1 117 -> 118.5).

Usage: python bench/bench_continuation.py [--points N] [--repeat R] [--basin]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path

from maglev_match.analyses.continued import follow_critical
from maglev_match.analyses.critical import solve_critical
from maglev_match.api import matching_index
from maglev_match.core.params import load_preset

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/_timing.py
from _timing import cpu, timed  # noqa: E402


def row(points: list, direction: int, repeat: int, label: str) -> None:
    follow_critical(points, direction)  # warm
    [solve_critical(p, direction) for p in points]
    wf, cf, f = timed(lambda: follow_critical(points, direction), repeat)
    wp, cp, sizes = timed(lambda: [solve_critical(p, direction) for p in points], repeat)
    diff = max(abs(a.size - b.size) for a, b in zip(f.sizes, sizes, strict=True)
               if a.solved and b.solved)
    n = len(points)
    print(f"{label}: {n} points, continued {f.continued}, changes {len(f.changes)}")
    print(f"  point-wise solves   {wp:.3f} s wall ({wp / n * 1e3:.0f} ms/point), {cp:.3f} s CPU")
    print(f"  continued row       {wf:.3f} s wall ({wf / n * 1e3:.0f} ms/point), {cf:.3f} s CPU")
    print(f"  ratio (point-wise / continued): {wp / wf:.2f}x wall, {cp / cf:.2f}x CPU; "
          f"largest difference {diff:.2e} m")


def neighbour(steps: int, repeat: int, step: float = 1e-3) -> None:
    P = load_preset("turnout-soft")
    designs = [P.replace(EI=P.EI * (1 + step * k)) for k in range(steps + 1)]
    first = matching_index(designs[0])
    matching_index(designs[1], near=first)  # warm
    matching_index(designs[1], simulate=False)
    near_w, near_c, full_w, full_c, pap_w, pap_c = [], [], [], [], [], []
    pnear_w, pnear_c, cd_w = [], [], []
    first_paper = matching_index(designs[0], simulate=False)
    from maglev_match.analyses.matching import critical_delay_info
    for _ in range(repeat):
        prev = first
        prev_paper = first_paper
        for d in designs[1:]:
            t, c = time.perf_counter(), cpu()
            r = matching_index(d, near=prev)
            near_w.append(time.perf_counter() - t)
            near_c.append(cpu() - c)
            assert r.simulation["up"]["continuation"]["continued"]
            assert r.simulation["down"]["continuation"]["continued"]
            prev = r
            t, c = time.perf_counter(), cpu()
            matching_index(d)
            full_w.append(time.perf_counter() - t)
            full_c.append(cpu() - c)
            t, c = time.perf_counter(), cpu()
            matching_index(d, simulate=False)
            pap_w.append(time.perf_counter() - t)
            pap_c.append(cpu() - c)
            t, c = time.perf_counter(), cpu()
            prev_paper = matching_index(d, simulate=False, near=prev_paper)
            pnear_w.append(time.perf_counter() - t)
            pnear_c.append(cpu() - c)
            t = time.perf_counter()
            critical_delay_info(d)
            cd_w.append(time.perf_counter() - t)
    med = statistics.median
    print(f"headline index at a neighbouring design (EI +{step:.1%} steps, {len(near_w)} "
          "designs):")
    print(f"  point-wise index      {med(full_w):.3f} s wall, {med(full_c):.3f} s CPU")
    print(f"  near=previous         {med(near_w):.3f} s wall, {med(near_c):.3f} s CPU")
    print(f"  paper part only       {med(pap_w):.3f} s wall, {med(pap_c):.3f} s CPU")
    print(f"  paper part, near=     {med(pnear_w):.3f} s wall, {med(pnear_c):.3f} s CPU "
          f"(the cycle continued)")
    print(f"  of every index: the critical delay of the controller {med(cd_w):.3f} s wall "
          "(recomputed in full, near= or not)")
    print(f"  ratio (point-wise / near): {med(full_w) / med(near_w):.2f}x wall; simulated "
          f"part {med(full_w) - med(pap_w):.3f} -> {med(near_w) - med(pnear_w):.3f} s wall, "
          f"paper part {med(pap_w):.3f} -> {med(pnear_w):.3f} s (target: the whole index "
          f"under 0.1 s: {'met' if med(near_w) < 0.1 else 'missed'})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=9)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--basin", action="store_true")
    ap.add_argument("--neighbour-only", action="store_true",
                    help="only the neighbouring-design timing")
    ap.add_argument("--step", type=float, default=1e-3,
                    help="relative EI step of the neighbouring designs")
    a = ap.parse_args()
    print(f"python {platform.python_version()}, {platform.machine()}")
    with open("/proc/loadavg") as fh:
        print("load before:", fh.read().split()[:3])
    P = load_preset("turnout-soft")
    n = a.points
    pts = [P.replace(EI=P.EI * (0.98 + 0.04 * k / (n - 1))) for k in range(n)]
    if not a.neighbour_only:
        row(pts, 1, a.repeat, "grazing row (turnout-soft, EI 0.98..1.02, beam down)")
    neighbour(5, a.repeat, a.step)
    if a.basin:
        pts = [P.replace(omega1=om) for om in (117.0, 117.5, 118.0, 118.5)]
        row(pts, -1, 1, "basin-boundary row (turnout-soft, omega1 117..118.5, beam up)")
    with open("/proc/loadavg") as fh:
        print("load after:", fh.read().split()[:3])


if __name__ == "__main__":
    main()
