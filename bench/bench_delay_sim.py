"""Benchmark: simulating the delay system and its critical disturbance (issue 34/32/35).

Model A on the soft turnout beam with tau = 1 ms, in this process, warm (one call first):
  1. where the stiffness of the discretised delay system is: the largest |eigenvalue| of
     its Jacobian at the equilibrium, of the history block alone and of the rest;
  2. one disturbed run (limits on, 4 s, beam pressed down by 2.84 mm): steps, rejected
     steps and CPU against the same run without the delay (the baseline);
  3. the critical size from a finished search (both directions): grazing solved on the
     delay system (Newton steps) and its CPU;
  4. the headline index with the delay: point-wise, and with ``near=`` the previous design
     at a 1 % kD step (the explorer's "on release" tier), with the continued sizes against
     the point-wise solved ones.

Usage: .venv/bin/python bench/bench_delay_sim.py [--repeat 3] [--skip-index]
"""

from __future__ import annotations

import argparse
import os
import platform

import jax
import jax.numpy as jnp
import numpy as np
from _timing import load, timed

from maglev_match import api
from maglev_match.analyses.critical import critical_from_bisection
from maglev_match.analyses.simulation import critical_disturbance
from maglev_match.core.params import load_preset
from maglev_match.dynamics.integrate.simulate import SimulationOptions, simulate
from maglev_match.maglev.models import maglev_model


def stiffness(m) -> tuple[float, float, float, int, int]:
    s = m.system(limited=False)
    X = s.lift(m.equilibrium())
    J = np.asarray(jax.jacfwd(lambda z: s.rhs(z, jnp.asarray(s.p)))(jnp.asarray(X)))
    n = s.n_state
    ev = lambda A: float(np.max(np.abs(np.linalg.eigvals(A))))  # noqa: E731
    return ev(J), ev(J[n:, n:]), ev(J[:n, :n]), s.dim, s.nodes


def one_run(m, size: float):
    s = m.system(limited=True)
    x0 = m.disturbance(1).x0_of(np.array([size]))[0]
    xr = m.equilibrium()
    if x0.size != s.dim:
        x0, xr = s.lift(x0), s.lift(xr)
    return simulate(s, x0, 4.0, event_fn=m.gap_events(), x_ref=xr, n_save=0,
                    options=SimulationOptions())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-index", action="store_true")
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {load()}")
    soft = load_preset("turnout-soft")
    m0, m1 = maglev_model(soft, "unit"), maglev_model(soft.replace(tau=1e-3), "unit")

    full, hist, rest, dim, nodes = stiffness(m1)
    print(f"1. discretised system: {dim} states (N = {nodes}); max |eigenvalue| of the "
          f"Jacobian {full:.4g} 1/s, history block {hist:.4g}, the rest {rest:.4g}")

    for label, m in (("no delay", m0), ("tau = 1 ms", m1)):
        one_run(m, 2.84e-3)
        w, c, r = timed(lambda m=m: one_run(m, 2.84e-3), args.repeat)
        print(f"2. one disturbed run, {label}: {r.steps} steps ({r.rejected} rejected), "
              f"{w:.3f} s wall, {c:.3f} s CPU ({r.outcome})")

    for d in (-1, 1):
        cd = critical_disturbance(m1, direction=d)
        critical_from_bisection(m1, cd)
        w, c, r = timed(lambda cd=cd: critical_from_bisection(m1, cd), args.repeat)
        lo, hi = r.bracket
        print(f"3. direction {d:+d}: {r.mechanism} ({r.iterations} Newton steps) size "
              f"{r.size * 1e3:.10g} mm in the bracket [{lo * 1e3:.7g}, {hi * 1e3:.7g}] mm; "
              f"{w:.3f} s wall, {c:.3f} s CPU")

    if args.skip_index:
        return
    base = soft.replace(tau=1e-3)
    stepped = base.replace(kD=base.kD * 1.01)
    prev = api.matching_index(base)
    api.matching_index(stepped, near=prev)
    w_n, c_n, near = timed(lambda: api.matching_index(stepped, near=prev), args.repeat)
    w_p, c_p, point = timed(lambda: api.matching_index(stepped), 1)
    print(f"4. index at tau = 1 ms, kD +1 %: point-wise {w_p:.2f} s wall ({c_p:.2f} CPU); "
          f"near= {w_n:.2f} s wall ({c_n:.2f} CPU): {c_p / c_n:.1f}x CPU")
    for key in ("up", "down"):
        a, b = near.simulation[key], point.simulation[key]
        print(f"   {key}: continued={a.get('continuation')}, "
              f"{a['critical']['size'] * 1e3:.10g} mm against point-wise "
              f"{b['critical']['size'] * 1e3:.10g} mm ({b['critical']['mechanism']}), "
              f"difference {abs(a['critical']['size'] - b['critical']['size']):.2g} m")
    print(f"   chi {near.chi:.10g} against {point.chi:.10g}; load {load()}")


if __name__ == "__main__":
    main()
