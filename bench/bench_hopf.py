"""Benchmark: the Hopf curve of model A and l1 along it (issue 3).

Times, after compilation, in this process:
  1. the full Hopf curve over sigma in [1e-4, 8e-4] (both branches met at sigma = 4.5e-4,
     omega1 in [30, 400]) by pseudo-arclength continuation, with l1 at every point;
  2. l1 at 200 curve points: our batched-real-form l1 against the same formula evaluated
     with System.B / System.C (one jitted call per real/imaginary combination);
  3. baseline for the curve: gridding max Re(lambda) on a 400 x 200 (omega1, sigma) grid
     (vmapped Jacobians + eigenvalues), which only resolves the curve to the grid spacing.

Usage: .venv/bin/python bench/bench_hopf.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np

from maglev_match.core.params import load_preset
from maglev_match.dynamics.hopf import (
    first_lyapunov_coefficient,
    hopf_eigenvectors,
    locate_hopf_points,
)
from maglev_match.dynamics.hopf_curve import hopf_curve, stability_grid
from maglev_match.maglev.models import build_system

CPU: dict[str, float] = {}


def timed(fn, repeat: int, label: str = "") -> tuple[float, object]:
    """Median wall time; the median CPU time of this process is kept in CPU[label] (a
    fairer figure when other jobs share the machine)."""
    times, cpu, out = [], [], None
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    CPU[label] = statistics.median(cpu)
    return statistics.median(times), out


def l1_with_system_forms(system, x, p, omega) -> float:
    """The same l1 formula written with System.B / System.C (reference implementation)."""
    J = system.jacobian(x, p)
    q, pa = hopf_eigenvectors(J, omega)
    qb = np.conj(q)
    h11 = -np.linalg.solve(J, system.B(x, p, q, qb))
    h20 = np.linalg.solve(2j * omega * np.eye(len(x)) - J, system.B(x, p, q, q))
    g = np.vdot(pa, system.C(x, p, q, q, qb) + 2 * system.B(x, p, q, h11)
                + system.B(x, p, qb, h20))
    return float(g.real / (2 * omega))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    repeat = 2 if args.quick else 5
    system = build_system(load_preset("turnout-soft"), "unit")
    bounds = {"omega1": (30.0, 400.0), "sigma": (1e-4, 8e-4)}
    scan = locate_hopf_points(system, "omega1", 30.0, 400.0,
                              system.params_with(sigma=4.5e-4), n_scan=100)
    starts = scan.points

    def full_curve():
        return [hopf_curve(system, ("omega1", "sigma"), hp, bounds) for hp in starts]

    t0 = time.perf_counter()
    full_curve()  # compile
    t_compile = time.perf_counter() - t0
    t_curve, curves = timed(full_curve, repeat, "curve")
    n_pts = sum(len(c.points) for c in curves)

    # l1 at 200 points along the curve
    pts = [(c, pt) for c in curves for pt in c.points]
    sel = [pts[k] for k in np.linspace(0, len(pts) - 1, 200).astype(int)]
    args_l1 = [(pt.x, system.params_with(omega1=pt.values[0], sigma=pt.values[1]),
                pt.frequency) for _, pt in sel]
    first_lyapunov_coefficient(system, *args_l1[0])
    l1_with_system_forms(system, *args_l1[0])
    t_l1, ours = timed(lambda: [first_lyapunov_coefficient(system, *a) for a in args_l1],
                       repeat, "l1")
    t_ref, ref = timed(lambda: [l1_with_system_forms(system, *a) for a in args_l1], repeat,
                       "ref")
    err = float(np.max(np.abs(np.array(ours) - np.array(ref)) / np.abs(np.array(ref))))

    # baseline: gridding max Re(lambda)
    g1, g2 = np.linspace(30, 400, 400), np.linspace(1e-4, 8e-4, 200)
    stability_grid(system, ("omega1", "sigma"), g1[:4], g2[:4])
    t_grid, _ = timed(lambda: stability_grid(system, ("omega1", "sigma"), g1, g2), repeat,
                      "grid")

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}, load average {load:.1f}")
    print(f"first run (compilation included): {t_compile:.2f} s")
    print(f"Hopf curve, both branches, sigma in [1e-4, 8e-4]: {n_pts} points with l1, "
          f"median {t_curve:.3f} s wall, {CPU['curve']:.3f} s CPU "
          f"({1e3 * t_curve / n_pts:.2f} ms/point)")
    print(f"l1 at 200 points: ours {t_l1:.3f} s ({CPU['l1']:.3f} s CPU), System.B/C "
          f"reference {t_ref:.3f} s ({CPU['ref']:.3f} s CPU), "
          f"ratio {t_ref / t_l1:.1f}x, max rel. difference {err:.1e}")
    print(f"baseline grid 400 x 200 of max Re(lambda): {t_grid:.3f} s "
          f"({CPU['grid']:.3f} s CPU) "
          f"(resolution {g1[1] - g1[0]:.2f} rad/s, {g2[1] - g2[0]:.2e} 1/kg); "
          f"continuation/grid time ratio {t_curve / t_grid:.2f}")


if __name__ == "__main__":
    main()
