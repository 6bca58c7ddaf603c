"""Benchmark: simulation with limits (diffrax kernel) vs SciPy solve_ivp DOP853 with a NumPy
right-hand side at the same tolerances, in the same process.

Cases: 5 s of model A (alpha1, x5(0) = -1.5 mm), 5 s of model B (turnout-soft, pressed
onto the free beam), and a batch of 256 model-A runs (x5(0) from -0.5 to -8 mm).
Both sides stop at a gap-limit collision (SciPy: terminal events). Prints medians, ratios
and the first-call (compile) time. ``--quick``: fewer repeats, SciPy batch on 32 runs
scaled to 256. The old path (diffrax's loop over the Runge-Kutta stages,
``unroll_stages=False``) is timed too, for model A and the batch. Then: a run with other gap
limits (traced arguments: no new compilation), and the simulated critical disturbance of
model A (both directions) and model B (beam lifted) with the default sizes per round
against the previous default of 16 sizes per round, in the same process.

The process runs as the command line does (``MAGLEV_MATCH_THREADS=1``: one thread, pinned
to its core); ``--auto-threads`` leaves threads and affinity to the libraries.

    .venv/bin/python bench/bench_simulate.py [--quick] [--auto-threads]
"""

from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("MAGLEV_MATCH_CACHE", "")  # measure real compile times
os.environ.setdefault("MAGLEV_MATCH_THREADS", "auto" if "--auto-threads" in sys.argv else "1")

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from maglev_match import load_preset  # noqa: E402
from maglev_match.analyses.simulation import initial_state  # noqa: E402
from maglev_match.dynamics.integrate.simulate import (  # noqa: E402
    SimulationOptions,
    simulate,
    simulate_batch,
)
from maglev_match.maglev import vehicle as vm  # noqa: E402
from maglev_match.maglev.limits import gap_limit_events  # noqa: E402
from maglev_match.maglev.models import build_system  # noqa: E402
from maglev_match.maglev.unit import gap as unit_gap  # noqa: E402
from maglev_match.maglev.vehicle import gap_function as vehicle_gap_function  # noqa: E402

RTOL, ATOL = 1e-8, 1e-8  # ATOL in units of each state's typical size (both sides)


# ----------------------------------------------------------------------------- NumPy RHS
def unit_rhs_numpy(P):
    m, M = P.m, P.M
    K, c0, i0 = P.K, P.c0, P.i0
    r0 = i0 / c0
    w1, xi1, sig = P.omega1, P.xi1, P.sigma

    def f(t, x):
        x1, x2, x3, x4, x5, x6, x7, x8, x9 = x
        c = x1 - x5 + c0
        i = x7 + i0
        r = max(i, 0.0) / c
        dF = 0.5 * K * (r - r0) * (r + r0)
        susp = P.cs * (x2 - x4) + P.ks * (x1 - x3)
        err = x1 - x5 - x8
        di = r * (x2 - x6) + P.ke * c / K * (P.kP * x8 + P.kD * (x9 + x2) - x7)
        if i <= 0.0 and di < 0.0:
            di = 0.0
        return np.array([x2, -dF / m - susp / m, x4, susp / M, x6,
                         -(w1**2) * x5 - 2 * xi1 * w1 * x6 + sig * dF, di,
                         x9 + x2 + 2 * P.xi0 * P.omega0 * err, P.omega0**2 * err])

    def gap(x):
        return np.array([x[0] - x[4] + c0])

    return f, gap


def vehicle_rhs_numpy(P):
    n = P.n_modes
    L = vm.layout(n)
    b = vm.FRAME_SIGN * P.s0
    a = vm.POINT_SIGN * P.s
    xj = P.L / 2 + b[vm.POINT_FRAME] + a
    modes = np.arange(1, n + 1)
    phi = np.sin(np.outer(modes, xj) * np.pi / P.L)
    omega = modes**2 * P.omega1
    K = P.K
    load = (P.m_s / 2 + P.m_b / 6) * P.g
    i0 = P.c0 * np.sqrt(load / K)
    q_static = 2.0 / (P.mbar * P.L * omega**2) * (phi @ (load * np.ones(6)))
    r0 = i0 / P.c0

    def kin(x):
        body, bd = x[L["body"]], x[L["body_dot"]]
        z, th, zd, thd = body[0:6:2], body[1:6:2], bd[0:6:2], bd[1:6:2]
        u = z[vm.POINT_FRAME] + a * th[vm.POINT_FRAME]
        ud = zd[vm.POINT_FRAME] + a * thd[vm.POINT_FRAME]
        c = P.c0 + u - (x[L["q"]] - q_static) @ phi
        cd = ud - x[L["q_dot"]] @ phi
        return ud, c, cd

    def f(t, x):
        body, bd = x[L["body"]], x[L["body_dot"]]
        ud, c, cd = kin(x)
        i, y1, v = x[L["i"]], x[L["y1"]], x[L["v"]]
        r = np.maximum(i, 0.0) / c
        F = K * (r - r0) * (r + r0)
        z, zd = body[0:6:2], bd[0:6:2]
        d = z - body[6] - b * body[7]
        dd = zd - bd[6] - b * bd[7]
        susp = P.k2 * d + P.c2 * dd
        Fp = F.reshape(3, 2)
        z_acc = (-(Fp[:, 0] + Fp[:, 1]) - susp) / P.m_s
        th_acc = P.s * (Fp[:, 0] - Fp[:, 1]) / P.j_s
        acc = np.array([z_acc[0], th_acc[0], z_acc[1], th_acc[1], z_acc[2], th_acc[2],
                        susp.sum() / P.m_b, (b * susp).sum() / P.j_b])
        qd = x[L["q_dot"]]
        q_acc = (-2 * P.xi1 * omega * qd - omega**2 * (x[L["q"]] - q_static)
                 + 2.0 / (P.mbar * P.L) * (phi @ F))
        err = c - P.c0 - y1
        di = r * cd + P.ke * c / K * (P.kP * y1 + P.kD * (v + ud) - i + i0)
        di = np.where((i <= 0) & (di < 0), 0.0, di)
        return np.concatenate([bd, acc, qd, q_acc, di,
                               v + ud + 2 * P.xi0 * P.omega0 * err, P.omega0**2 * err])

    def gap(x):
        return kin(x)[1]

    return f, gap


def scipy_run(f, gap, P, x0, t_end, scale):
    n_pts = len(gap(x0))
    events = []
    for j in range(n_pts):
        def lo(t, x, j=j):
            return gap(x)[j] - P.gap_min

        def hi(t, x, j=j):
            return P.gap_max - gap(x)[j]

        lo.terminal = hi.terminal = True
        events += [lo, hi]
    return solve_ivp(f, (0.0, t_end), x0, method="DOP853", rtol=RTOL, atol=ATOL * scale,
                     events=events)


CPU: dict[str, float] = {}


def timed(fn, repeats, key=None):
    """Median wall time (s) of ``repeats`` calls and the last result; the median CPU time
    of the process goes to CPU[key]."""
    out, ts, cs = None, [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
        cs.append(time.process_time() - c0)
    if key:
        CPU[key] = float(np.median(cs))
    return float(np.median(ts)), out


def main(quick: bool) -> None:
    rep = 3 if quick else 7
    opts = SimulationOptions(rtol=RTOL, atol=ATOL)
    from maglev_match.core import jax_setup

    print(f"# bench_simulate  rtol={RTOL} atol={ATOL}*state_scale  quick={quick}  "
          f"pinned to cpu {jax_setup.PINNED_CPU}  load {os.getloadavg()[0]:.2f}")
    old = SimulationOptions(rtol=RTOL, atol=ATOL, unroll_stages=False)

    # ---------------- model A, 5 s
    PA = load_preset("alpha1")
    SA = build_system(PA, "unit", limited=True)
    evA = gap_limit_events(unit_gap, PA.gap_min, PA.gap_max)
    xA = initial_state(PA, "unit", x5=-1.5e-3)
    fA, gA = unit_rhs_numpy(PA)
    for _ in range(3):  # the NumPy RHS is the same vector field
        x = xA + np.random.default_rng(0).standard_normal(9) * SA.state_scale
        assert np.allclose(fA(0, x), SA.f(x), rtol=1e-10, atol=1e-12)
    t0 = time.perf_counter()
    simulate(SA, xA, 5.0, event_fn=evA, options=opts, n_save=2001)
    compile_A = time.perf_counter() - t0
    ours_A, rA = timed(lambda: simulate(SA, xA, 5.0, event_fn=evA, options=opts, n_save=2001),
                       rep, "A")
    simulate(SA, xA, 5.0, event_fn=evA, options=old, n_save=2001)
    old_A, oA = timed(lambda: simulate(SA, xA, 5.0, event_fn=evA, options=old, n_save=2001),
                      rep, "A old")
    assert np.array_equal(oA.x, rA.x, equal_nan=True)  # the same numbers, bit for bit
    sp_A, sA = timed(lambda: scipy_run(fA, gA, PA, xA, 5.0, SA.state_scale), rep, "A scipy")
    print(f"model A 5 s: ours {ours_A * 1e3:.1f} ms ({rA.accepted} steps, {rA.outcome}), "
          f"SciPy DOP853 {sp_A * 1e3:.1f} ms ({sA.t.size - 1} steps), ratio "
          f"{sp_A / ours_A:.1f}x; first call (compile) {compile_A:.2f} s; "
          f"final-state diff {np.max(np.abs(rA.final_state - sA.y[:, -1]) / SA.state_scale):.1e}"
          " (scaled)")
    print(f"  model A old path (diffrax stage loop) {old_A * 1e3:.1f} ms: new/old "
          f"{old_A / ours_A:.2f}x; CPU ours {CPU['A'] * 1e3:.1f} ms, old "
          f"{CPU['A old'] * 1e3:.1f} ms, SciPy {CPU['A scipy'] * 1e3:.1f} ms "
          f"(CPU ratio {CPU['A scipy'] / CPU['A']:.1f}x)")

    # ---------------- model B, 5 s
    PB = load_preset("turnout-soft")
    SB = build_system(PB, "vehicle", limited=True)
    evB = gap_limit_events(vehicle_gap_function(PB.n_modes), PB.gap_min, PB.gap_max)
    xB = initial_state(PB, "vehicle", initial="pressed")
    fB, gB = vehicle_rhs_numpy(PB)
    x = xB + np.random.default_rng(1).standard_normal(SB.dim) * SB.state_scale * 0.1
    assert np.allclose(fB(0, x), SB.f(x), rtol=1e-9, atol=1e-9)
    t0 = time.perf_counter()
    simulate(SB, xB, 5.0, event_fn=evB, options=opts, n_save=2001)
    compile_B = time.perf_counter() - t0
    ours_B, rB = timed(lambda: simulate(SB, xB, 5.0, event_fn=evB, options=opts, n_save=2001),
                       rep, "B")
    sp_B, sB = timed(lambda: scipy_run(fB, gB, PB, xB, 5.0, SB.state_scale),
                     1 if quick else 3)
    print(f"model B 5 s: ours {ours_B * 1e3:.1f} ms ({rB.accepted} steps, {rB.outcome}), "
          f"SciPy DOP853 {sp_B * 1e3:.1f} ms ({sB.t.size - 1} steps), ratio "
          f"{sp_B / ours_B:.1f}x; first call (compile) {compile_B:.2f} s; "
          f"final-state diff {np.max(np.abs(rB.final_state - sB.y[:, -1]) / SB.state_scale):.1e}"
          " (scaled)")

    # ---------------- batch of 256 model-A runs
    nb = 256
    x0 = np.zeros((nb, 9))
    x0[:, 4] = -np.linspace(0.5e-3, 8e-3, nb)
    t0 = time.perf_counter()
    simulate_batch(SA, x0, 5.0, event_fn=evA, options=opts)
    compile_batch = time.perf_counter() - t0
    ours_b, bb = timed(lambda: simulate_batch(SA, x0, 5.0, event_fn=evA, options=opts),
                       max(rep // 2, 1), "batch")
    simulate_batch(SA, x0, 5.0, event_fn=evA, options=old)
    old_b, ob = timed(lambda: simulate_batch(SA, x0, 5.0, event_fn=evA, options=old),
                      max(rep // 2, 1), "batch old")
    # vmapped runs sum the stages elementwise (rounding differs from diffrax's loop in the
    # last bits, and a step accepted by one may be rejected by the other): the same
    # outcomes, collision times within the integration tolerance
    assert np.array_equal(ob.outcome_code, bb.outcome_code)
    dt_ev = float(np.nanmax(np.abs(ob.event_time - bb.event_time)))
    n_ev_diff = int(np.sum(np.abs(ob.event_time - bb.event_time) > 1e-12))
    assert dt_ev < 1e-6, dt_ev
    n_sp = 32 if quick else nb
    idx = np.linspace(0, nb - 1, n_sp).astype(int)
    t0, c0 = time.perf_counter(), time.process_time()
    sp_out = [scipy_run(fA, gA, PA, x0[k], 5.0, SA.state_scale) for k in idx]
    sp_b = (time.perf_counter() - t0) * nb / n_sp
    sp_b_cpu = (time.process_time() - c0) * nb / n_sp
    agree = sum((s.status == 1) == (bb.outcome[k] == "collision")
                for s, k in zip(sp_out, idx, strict=True))
    sp_dt = max((abs(s.t[-1] - bb.event_time[k]) for s, k in zip(sp_out, idx, strict=True)
                 if s.status == 1 and bb.outcome[k] == "collision"), default=float("nan"))
    print(f"batch of {nb} model-A runs (5 s): ours {ours_b:.3f} s, SciPy "
          f"{'(32 runs scaled) ' if quick else ''}{sp_b:.2f} s, ratio {sp_b / ours_b:.1f}x; "
          f"first call (compile) {compile_batch:.2f} s; outcomes: "
          f"{int(np.sum(bb.outcome == 'collision'))} collisions; collision yes/no agrees with "
          f"SciPy in {agree}/{n_sp}")
    print(f"  batch old path {old_b:.3f} s: new/old {old_b / ours_b:.2f}x; CPU ours "
          f"{CPU['batch']:.3f} s, old {CPU['batch old']:.3f} s; outcomes equal, collision "
          f"times differ by <= {dt_ev:.1e} s ({n_ev_diff} runs by > 1e-12 s; ours vs SciPy <= "
          f"{sp_dt:.1e} s); SciPy CPU {sp_b_cpu:.2f} s, CPU ratio "
          f"{sp_b_cpu / CPU['batch']:.1f}x")

    # ---------------- gap limits are traced: another limit value compiles nothing
    ev2 = gap_limit_events(unit_gap, PA.gap_min, 0.9 * PA.gap_max)
    t0 = time.perf_counter()
    r2 = simulate(SA, xA, 5.0, event_fn=ev2, options=opts, n_save=2001)
    print(f"other gap limit (gap_max x 0.9), first call: {(time.perf_counter() - t0) * 1e3:.1f}"
          f" ms ({r2.outcome}; a compilation would take seconds)")

    # ---------------- simulated critical disturbance (the index's h_simulation)
    from functools import partial

    from maglev_match.analyses.simulation import critical_disturbance

    vehicle_critical_disturbance = partial(critical_disturbance, model="vehicle")
    vehicle_critical_disturbance.__name__ = "vehicle_critical_disturbance"

    def crit(fn, P, direction, batch, reps):
        fn(P, direction=direction, batch=batch)  # compile
        return timed(lambda: fn(P, direction=direction, batch=batch), reps,
                     f"crit {fn.__name__} {direction} {batch}")

    for label, fn, P, dirs, new_batch, reps in (
            ("model A", critical_disturbance, PA, (-1, 1), 10, rep),
            ("model B", vehicle_critical_disturbance, PB, (-1,), 8, 1 if quick else 3)):
        for d in dirs:
            t_new, c_new = crit(fn, P, d, new_batch, reps)
            t_old, c_old = crit(fn, P, d, 16, reps)
            k_new, k_old = (f"crit {fn.__name__} {d} {b}" for b in (new_batch, 16))
            print(f"critical disturbance {label}, direction {d:+d} (tol {c_new.tol:g} m): "
                  f"{new_batch} sizes/round {t_new:.3f} s ({CPU[k_new]:.3f} s CPU, "
                  f"{c_new.rounds} rounds, {c_new.runs} runs), 16 sizes/round {t_old:.3f} s "
                  f"({CPU[k_old]:.3f} s CPU, {c_old.rounds} rounds); critical "
                  f"{c_new.critical * 1e3:.4f} mm vs {c_old.critical * 1e3:.4f} mm "
                  f"({c_new.status}/{c_old.status})")
            assert abs(c_new.critical - c_old.critical) <= c_new.tol
    print(f"# load at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main("--quick" in sys.argv)
