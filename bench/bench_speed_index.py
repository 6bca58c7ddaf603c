"""Benchmark: the matching index at speed chi(v) (maglev_match.analyses.speed.index) for the
unit on turnout-soft (three modes per span) at one speed (default 60 km/h), target < 10 s.

The periodic response is solved once (not timed); then chi(v) (three positions of the
vehicle in the span, both directions, bracketing rounds and the grazing solves) is timed
``--repeat`` times (median wall and CPU time), against the baseline in the same process:
the entry disturbance (the span deflected before entry, the read-out chi(v) was before),
timed the same way. The first call of each (compilation or loading of the kernels) is
reported apart. Prints the machine load (``os.getloadavg``) before and after.

    .venv/bin/python bench/bench_speed_index.py [--kmh 60] [--repeat 3] [--preset NAME]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

from maglev_match import load_preset
from maglev_match.analyses.speed.critical import critical_disturbance_at_speed
from maglev_match.analyses.speed.grid import KMH
from maglev_match.analyses.speed.index import index_at_speed
from maglev_match.analyses.speed.options import SpeedOptions
from maglev_match.analyses.speed.point import periodic_response

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/_timing.py
from _timing import timed_once as timed  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--kmh", type=float, default=60.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--preset", default="turnout-soft")
    a = ap.parse_args()
    print(f"load before: {os.getloadavg()}")
    p = load_preset(a.preset)
    v = a.kmh * KMH
    opts = SpeedOptions()
    sol = periodic_response(p, "unit", v, SpeedOptions(critical=False))
    rows = {}
    for name, fn in (
            ("chi(v), index at speed", lambda: index_at_speed(p, "unit", v, sol, opts)),
            ("entry disturbance (baseline)",
             lambda: critical_disturbance_at_speed(p, "unit", v, sol.x0, opts))):
        first, c1, w1 = timed(fn)
        walls, cpus = [], []
        for _ in range(a.repeat):
            _, c, w = timed(fn)
            walls.append(w)
            cpus.append(c)
        rows[name] = (statistics.median(walls), statistics.median(cpus), w1, first)
        print(f"{name:30s} median wall {statistics.median(walls):7.2f} s, CPU "
              f"{statistics.median(cpus):7.2f} s (first call {w1:.2f} s wall)")
    ix = rows["chi(v), index at speed"][3]
    print(f"\nunit on {a.preset}, {a.kmh:g} km/h: chi(v) = {ix.chi:.4f} (h = {ix.h * 1e3:.4f} mm),"
          f" decided at {ix.fraction:g} L, direction {ix.direction:+d}")
    base = rows["entry disturbance (baseline)"][0]
    print(f"ratio chi(v) / entry disturbance (median wall): "
          f"{rows['chi(v), index at speed'][0] / base:.2f}")
    print(f"target < 10 s: {'met' if rows['chi(v), index at speed'][0] < 10 else 'NOT met'}")
    print(f"load after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
