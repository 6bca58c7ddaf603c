"""Benchmark: the controller's delay (issue 23).

Times, after compilation (warm), in this process, model A on the soft turnout beam:
  1. the critical delay (crossings of the characteristic equation, l1 from the
     characteristic matrix) -- target under 1 s warm; baseline: the delay-free Hopf scan
     along omega1 in [30, 300] (equilibrium continuation, refinement, l1);
  2. the cycle branch in tau from the critical delay (discretised system for tau <= 10 ms,
     N = 20 nodes, 29 states; NTST 80 as `cycles`; until the physical limit) -- target under
     10 s; baseline: the delay-free branch in omega1 from its Hopf point (same settings);
  3. Floquet multipliers of one cycle of that branch: the "dominant" method the discretised
     system uses against the default "auto" (grouped periodic QZ), same transfer matrices;
  4. model B's critical delay (information: 40 states, six delayed signals).
Ratios are against the baselines measured in the same run; CPU times of this process are
printed beside the wall times (fairer on a shared machine).

Usage: .venv/bin/python bench/bench_delay.py [--repeat 3] [--skip-vehicle]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

from maglev_match.core.params import load_preset
from maglev_match.dynamics.cycles import cycle_branch
from maglev_match.dynamics.delay import critical_delay, delay_hopf_points
from maglev_match.dynamics.equilibria import find_equilibrium
from maglev_match.dynamics.hopf import locate_hopf_points
from maglev_match.maglev.limits import cycle_limit_margins
from maglev_match.maglev.models import build_system
from maglev_match.maglev.unit import unit_dde
from maglev_match.maglev.vehicle import vehicle_dde

CPU: dict[str, float] = {}


def timed(fn, repeat: int, label: str) -> tuple[float, object]:
    """Median wall time of ``repeat`` warm runs (one run first, not timed, to compile);
    the median CPU time is kept in CPU[label]."""
    out = fn()
    times, cpu = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    CPU[label] = statistics.median(cpu)
    return statistics.median(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-vehicle", action="store_true")
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.2f}")
    params = load_preset("turnout-soft")
    dde = unit_dde(params)
    ode = build_system(params, "unit")
    limits = cycle_limit_margins(params)

    t_cd, cd = timed(lambda: critical_delay(dde, tau_max=1.0), args.repeat, "critical")
    t_scan, scan = timed(lambda: locate_hopf_points(ode, "omega1", 30.0, 300.0),
                         args.repeat, "scan")
    print(f"critical delay of model A: tau = {cd.value * 1e3:.6g} ms, omega = "
          f"{cd.frequency:.6g} rad/s, l1 = {cd.l1:.4g} ({cd.kind})")
    print(f"  {t_cd:.3f} s wall ({CPU['critical']:.3f} s CPU)  [target < 1 s]; delay-free "
          f"Hopf scan along omega1 {t_scan:.3f} s ({CPU['scan']:.3f} s CPU): ratio "
          f"{t_cd / t_scan:.2f}")

    system = build_system(params, "unit", tau_max=0.01)
    hp = delay_hopf_points(system, "tau", 0.0, 0.01).points[0]
    t_br, br = timed(lambda: cycle_branch(system, hp, "tau", ntst=80, ncol=4, max_steps=300,
                                          limits=limits), args.repeat, "branch")
    hp0 = [h for h in scan.points if h.converged][0]
    t_br0, br0 = timed(lambda: cycle_branch(ode, hp0, "omega1", ntst=80, ncol=4,
                                            max_steps=300, limits=limits),
                       args.repeat, "branch0")
    print(f"cycle branch in tau (N = {system.nodes}, {system.dim} states, NTST 80): "
          f"{len(br.points)} cycles, stopped: {br.stopped_reason}, special points "
          f"{[s.type for s in br.special_points]}")
    print(f"  {t_br:.3f} s wall ({CPU['branch']:.3f} s CPU)  [target < 10 s]; delay-free "
          f"branch in omega1 ({len(br0.points)} cycles) {t_br0:.3f} s ({CPU['branch0']:.3f} s "
          f"CPU): ratio {t_br / t_br0:.2f}")

    from maglev_match.dynamics.cycles import CollocationBVP, blocks_at
    from maglev_match.dynamics.floquet import floquet_multipliers_from_blocks

    c = br.points[len(br.points) // 2]
    prob = CollocationBVP(system=system, ipar=system.param_index("tau"), p0=c.orbit.p,
                    mesh=c.orbit.mesh, m=c.orbit.ncol, scale=system.state_scale,
                    T_scale=c.period, lam_scale=1.0)
    J, Tb, h = blocks_at(prob, prob.pack(c.orbit.states, c.period, c.value), prob.mesh)
    t_dom, mu_d = timed(lambda: floquet_multipliers_from_blocks(J, Tb, h, 4, method="dominant"),
                        args.repeat, "dominant")
    t_qz, mu_q = timed(lambda: floquet_multipliers_from_blocks(J, Tb, h, 4, method="auto"),
                       1, "auto")
    diff = max(float(min(abs(mu_q - z))) for z in mu_d[abs(mu_d) > 1e-8])
    print(f"Floquet multipliers of one cycle ({system.dim} states, NTST 80): dominant "
          f"{t_dom:.3f} s ({CPU['dominant']:.3f} s CPU), auto (periodic QZ) {t_qz:.3f} s "
          f"({CPU['auto']:.3f} s CPU): ratio {t_qz / t_dom:.1f}; largest difference of the "
          f"multipliers above 1e-8: {diff:.1e}")

    if not args.skip_vehicle:
        vdde = vehicle_dde(params)
        x = find_equilibrium(vdde.ode_system()).x
        t_v, vcd = timed(lambda: critical_delay(vdde, x=x, tau_max=1.0), args.repeat,
                         "vehicle")
        print(f"critical delay of model B: tau = {vcd.value * 1e3:.6g} ms, omega = "
              f"{vcd.frequency:.6g} rad/s, l1 = {vcd.l1:.4g}; {t_v:.3f} s wall "
              f"({CPU['vehicle']:.3f} s CPU); ratio to model A {t_v / t_cd:.2f}")
    print(f"load at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
