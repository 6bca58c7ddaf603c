"""Benchmark: exact sensitivities against one index, and a two-parameter design search.

* all sensitivities at one point (``index_sensitivity`` given the index, without and with the
  per-parameter stability boundaries) against one ``matching_index(..., simulate=False)``
  at the same point (target: under 20 % of the index's time, boundaries off);
* the same derivatives by central finite differences of the index (2 indices per
  parameter), the baseline the exact method replaces;
* ``optimise_design`` over two varied parameters (target: under 60 s), with the start grid
  from the design map's rows (one cycle continuation per Hopf point along each row) and, as
  the baseline in the same process, from one full index per grid point (the earlier way);
* the done-criterion problem: the cheapest EI with chi >= 5 on the soft turnout beam, one
  varied parameter.

Wall and CPU (process) times; the load average is printed, since the machine is shared.

Usage: python bench/bench_design.py [--quick] [--no-baseline]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

from maglev_match.analyses.design import (
    DesignProblem,
    Goal,
    MaglevEvaluator,
    Quantity,
    Requirement,
    Variable,
    optimise_design,
)
from maglev_match.analyses.matching import matching_index
from maglev_match.analyses.sensitivity import index_sensitivity
from maglev_match.core.params import load_preset

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/_timing.py
from _timing import timed  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="one repeat")
    ap.add_argument("--no-baseline", action="store_true",
                    help="skip the design with the earlier point-wise start grid")
    args = ap.parse_args()
    repeat = 1 if args.quick else 3
    print(f"machine: {platform.machine()}, python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.2f}")
    p = load_preset("turnout-soft")
    idx = matching_index(p, simulate=False)  # compile
    index_sensitivity(p, idx)  # compile
    w_i, c_i, idx = timed(lambda: matching_index(p, simulate=False), repeat)
    w_s, c_s, sens = timed(lambda: index_sensitivity(p, idx, boundaries=False), repeat)
    w_b, c_b, _ = timed(lambda: index_sensitivity(p, idx, boundaries=True), repeat)
    n = len(sens.rows)
    print(f"turnout-soft chi = {idx.chi:.5g} ({idx.case}), {n} parameters")
    print(f"  one index:                      wall {w_i:.3f} s, cpu {c_i:.3f} s")
    print(f"  all sensitivities:              wall {w_s:.3f} s, cpu {c_s:.3f} s "
          f"-> {c_s / c_i:.1%} of the index (cpu), {w_s / w_i:.1%} (wall)")
    print(f"  ... with stability boundaries:  wall {w_b:.3f} s, cpu {c_b:.3f} s "
          f"-> {c_b / c_i:.1%} of the index (cpu)")
    print(f"  central differences instead:    ~{2 * n} indices = ~{2 * n * c_i:.1f} s cpu "
          f"({2 * n * c_i / c_s:.0f}x the exact method)")
    prob = DesignProblem((Variable("EI", 5e9, 4e10), Variable("kD", 80.0, 250.0)),
                         Goal.MINIMIZE, "EI", (Requirement(Quantity.CHI, 5.0),))

    class PointwiseGrid(MaglevEvaluator):
        def scan(self, problem, n):  # the earlier start grid: one full index per point
            return None

    runs = [("map-row start grid", MaglevEvaluator)]
    if not args.no_baseline:
        runs.append(("baseline, one index per grid point", PointwiseGrid))
    for label, cls in runs:
        w_d, c_d, res = timed(lambda cls=cls: optimise_design(prob, cls(p, prob.names)), 1)
        print(f"design minimise EI over (EI, kD), chi >= 5 [{label}]: {res.status}, "
              f"EI = {res.values['EI']:.6g}, kD = {res.values['kD']:.5g}, chi = "
              f"{res.index.chi:.5g} ({res.index.case}); {res.evaluations} index evaluations, "
              f"{res.iterations} SLSQP iterations; wall {w_d:.1f} s, cpu {c_d:.1f} s "
              "(target 60 s)")
    one = DesignProblem((Variable("EI", 5e9, 4e10),), Goal.MINIMIZE, "EI",
                        (Requirement(Quantity.CHI, 5.0),))
    w_1, c_1, res = timed(lambda: optimise_design(one, MaglevEvaluator(p, one.names)), 1)
    print(f"design minimise EI over EI, chi >= 5: EI = {res.values['EI']:.6g}, chi = "
          f"{res.index.chi:.6g} ({res.index.case}), {res.evaluations} index evaluations; "
          f"wall {w_1:.1f} s, cpu {c_1:.1f} s")
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
