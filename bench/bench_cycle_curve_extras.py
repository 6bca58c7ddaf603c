"""Benchmark: what the PD curve's flip coefficient costs, and the LPC curve of a delay
model.

* ``flip``: the PD curve of model A (preset alpha1, xi0 = 0.7) in (omega1, sigma), 20
  points, NTST 80: the CPU time of the curve (each point's flip coefficient included) and
  of the flip coefficients alone (recomputed on the curve's cycles), both warm, medians;
  the share of the coefficient in the curve.
* ``delay``: the LPC curve in (tau, kD) of the soft turnout beam with the delay (tau =
  1.4 ms), 20 points, NTST 40, against the one-parameter branch of cycles along tau it
  starts from (the same mesh), warm, medians and their ratio.

    .venv/bin/python bench/bench_cycle_curve_extras.py [flip|delay] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import statistics

from _timing import cpu

from maglev_match.core.params import load_preset
from maglev_match.dynamics.cycle_curves import cycle_curve, flip_coefficient, start_from
from maglev_match.dynamics.cycles import cycle_branch
from maglev_match.dynamics.hopf import locate_hopf_points
from maglev_match.maglev.limits import cycle_limit_margins
from maglev_match.maglev.models import build_system


def _median(fn, repeats):
    out, ts = None, []
    for _ in range(repeats):
        c0 = cpu()
        out = fn()
        ts.append(cpu() - c0)
    return out, statistics.median(ts)


def flip(repeats: int) -> None:
    params = load_preset("alpha1").replace(sigma=4e-4, xi0=0.7)
    system = build_system(params, "unit")
    hopf = locate_hopf_points(system, "omega1", 90.0, 150.0, n_scan=40).points[0]
    limits = cycle_limit_margins(params, include_current=False)
    br = cycle_branch(system, hopf, "omega1", ntst=80, ncol=4, limits=limits)
    orbit = start_from(br, "PD1")

    def curve():
        return cycle_curve(system, orbit, "PD", ("omega1", "sigma"), max_steps=19,
                           ranges={"sigma": (1e-4, 1e-3)})

    curve()  # warm-up
    cv, tc = _median(curve, repeats)
    orbits = [c.orbit for c in cv.points]
    _, tf = _median(lambda: [flip_coefficient(system, o) for o in orbits], repeats)
    print(f"load {os.getloadavg()[0]:.2f}; PD curve: {len(cv.points)} points, {tc:.2f} s CPU"
          f" (median of {repeats}); their flip coefficients alone {tf:.2f} s CPU "
          f"({100 * tf / tc:.0f} % of the curve); c from {cv.points[0].flip:.4g} to "
          f"{cv.points[-1].flip:.4g}; special points {[s.label for s in cv.special_points]}")


def delay(repeats: int) -> None:
    params = load_preset("turnout-soft").replace(tau=0.0014)
    system = build_system(params, "unit")
    hopf = locate_hopf_points(system, "tau", 1e-4, 3e-3, n_scan=20).points[0]
    limits = cycle_limit_margins(params, include_current=False)

    def branch():
        return cycle_branch(system, hopf, "tau", ntst=40, ncol=4, limits=limits)

    br = branch()  # warm-up
    orbit = start_from(br, "LPC1")

    def curve():
        return cycle_curve(system, orbit, "LPC", ("tau", "kD"), max_steps=19,
                           ranges={"kD": (50.0, 300.0)})

    curve()
    br, tb = _median(branch, repeats)
    cv, tc = _median(curve, repeats)
    print(f"load {os.getloadavg()[0]:.2f}; delay branch along tau: {len(br.points)} points, "
          f"{tb:.2f} s CPU; LPC curve (tau, kD): {len(cv.points)} points, {tc:.2f} s CPU "
          f"(medians of {repeats}); ratio {tc / tb:.2f}, per point "
          f"{(tc / len(cv.points)) / (tb / len(br.points)):.2f}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("which", nargs="?", choices=("flip", "delay"), default="flip")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    (flip if args.which == "flip" else delay)(args.repeats)


if __name__ == "__main__":
    main()
