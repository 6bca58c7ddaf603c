"""Benchmark: a Neimark-Sacker (torus) curve of cycles with 100 points against the
one-parameter branch of cycles it starts from, on the same mesh (NTST 40, NCOL 4), both
warm, in one process: the medians of the CPU times (``time.process_time``), per point.

The system: a Hopf cycle (radius sqrt(beta), period 2 pi / (1 + beta)) with a transverse
oscillator (multipliers exp((gamma - beta^2) T) e^{+-i T / 2}): NS curve gamma = beta^2.

    .venv/bin/python bench/bench_ns_curves.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time

import jax.numpy as jnp
import numpy as np

from maglev_match.dynamics.cycle_curves import cycle_curve, start_from
from maglev_match.dynamics.cycles import cycle_branch, hopf_start
from maglev_match.dynamics.system import System


def ns_system() -> System:
    def rhs(x, p):
        beta, gamma = p[0], p[1]
        r2 = x[0] ** 2 + x[1] ** 2
        om = 1.0 + r2
        a = gamma - r2 * r2
        q2 = x[2] ** 2 + x[3] ** 2
        return jnp.stack([beta * x[0] - om * x[1] - x[0] * r2,
                          om * x[0] + beta * x[1] - x[1] * r2,
                          a * x[2] - 0.5 * x[3] - q2 * x[2],
                          0.5 * x[2] + a * x[3] - q2 * x[3]])

    return System(rhs=rhs, p=np.array([0.0, 0.36]), param_names=("beta", "gamma"),
                  state_names=("x", "y", "u", "w"), name="NS benchmark")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    S = ns_system()
    q = np.array([1.0, -1.0j, 0.0, 0.0]) / math.sqrt(2.0)
    start = hopf_start(S, np.zeros(4), S.p, "beta", 1.0, q, None)

    def branch():
        return cycle_branch(S, start, "beta", ntst=40, ncol=4, stop_at=0.8, max_steps=300)

    def curve(orbit):
        return cycle_curve(S, orbit, "NS", ("beta", "gamma"), max_steps=99,
                           ranges={"beta": (0.05, 50.0)})

    br = branch()  # warm-up (compilation)
    orbit = start_from(br, "NS1")
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
    err = float(np.max(np.abs(cv.p2 - cv.p1 ** 2)))
    print(f"load {os.getloadavg()[0]:.2f}; branch: {len(br.points)} points, {b:.2f} s CPU "
          f"(median of {args.repeats}); NS curve: {len(cv.points)} points "
          f"({cv.stopped_reason}), {cv.newton_iterations} Newton iterations, {c:.2f} s CPU; "
          f"per point: curve / branch {(c / len(cv.points)) / (b / len(br.points)):.2f}; "
          f"max |gamma - beta^2| {err:.1e}; special points "
          f"{[s.label for s in cv.special_points]}")


if __name__ == "__main__":
    main()
