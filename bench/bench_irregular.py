"""Benchmark: runs over an irregular guideway (maglev_match.analyses.speed.irregular).

For the unit (and, without ``--skip-vehicle``, the vehicle) on turnout-soft at 60 and 120
km/h: the median CPU time of one run of 20 spans with the limits on over the smooth
guideway (the baseline, the run an irregular read-out needs anyway) and over a random
profile of the German 'low' spectrum with 64 and with 400 waves (the default), as ratios
to the baseline in the same process; and the linear route's rms (the unit), in ms. The
first call of each (compilation) is left out of the medians. Prints the machine load
(``os.getloadavg``) before and after.

``--sweep W [W ...] [--model vehicle]``: instead, the issue's target, the 31-speed sweep
of the unit (or the vehicle) (0 to 150 km/h by 5; the 30 speeds above 0 get the runs) over
one random profile ('low', one seed, 400 waves) with the linear rms, runs of 20 spans:
``irregular_sweep`` with ``workers=W`` (0: in this process; W > 0: a local Dask cluster of W
workers, started inside the timing), each in a fresh Python process, so compilation (with
the kernels on disk as they are) and, on Dask, the cluster's start are part of it. Prints
wall time and the CPU time of that process and its children (the Dask workers), with the
load before and after.

    .venv/bin/python bench/bench_irregular.py [--skip-vehicle] [--repeat N]
    .venv/bin/python bench/bench_irregular.py --sweep 0 2
    .venv/bin/python bench/bench_irregular.py --sweep 2 --model vehicle
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from maglev_match import load_preset
from maglev_match.analyses.speed.irregular import linear_gap_rms
from maglev_match.analyses.speed.spans import simulate_over_spans
from maglev_match.maglev.irregularity import parse_irregularity

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/_timing.py
from _timing import timed  # noqa: E402

KMH = 1 / 3.6


def median_cpu(fn, repeat: int) -> float:
    """Median CPU s of ``repeat`` calls after one that compiles."""
    fn()
    return timed(fn, repeat)[1]


SWEEP_PROFILE = "random:class=low"


def sweep_child(workers: int, model: str = "unit") -> None:
    """One sweep of the target in this (fresh) process; prints the per-speed seconds."""
    import numpy as np

    from maglev_match.analyses.speed.irregular import irregular_sweep

    p = load_preset("turnout-soft")
    speeds = np.arange(5, 151, 5) * KMH
    # (workers=0 is not passed: the in-process sweep of before issue 33 took no workers)
    ir = irregular_sweep(p, model, speeds, SWEEP_PROFILE, spans=20,
                         **({"workers": workers} if workers else {}))
    lin = ir.column("gap_rms_linear")
    print(f"  {ir.speeds.size} speeds, runs' seconds per speed: median "
          f"{np.median(ir.seconds):.2f}, largest {ir.seconds.max():.2f} (at "
          f"{ir.speeds[np.argmax(ir.seconds)] / KMH:g} km/h); gap_rms_linear finite at "
          f"{int(np.isfinite(lin).sum())} speeds", flush=True)


def sweep(workers_list: list[int], model: str = "unit") -> None:
    import resource
    import subprocess
    import time

    def children_cpu() -> float:
        r = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime

    for w in workers_list:
        load0 = os.getloadavg()
        c0, t0 = children_cpu(), time.perf_counter()
        subprocess.run([sys.executable, __file__, "--sweep-child", str(w), "--model", model],
                       check=True)
        wall, c = time.perf_counter() - t0, children_cpu() - c0
        print(f"{model}, workers {w}: 31-speed sweep over '{SWEEP_PROFILE}' (1 seed, 400 waves), "
              f"20 spans, with the linear rms: {wall:.1f} s wall, {c:.1f} s CPU (the "
              f"process and its workers); load before {load0[0]:.2f}, after "
              f"{os.getloadavg()[0]:.2f}", flush=True)


def main() -> None:
    model = sys.argv[sys.argv.index("--model") + 1] if "--model" in sys.argv else "unit"
    if "--sweep-child" in sys.argv:
        sweep_child(int(sys.argv[sys.argv.index("--sweep-child") + 1]), model)
        return
    if "--sweep" in sys.argv:
        workers = []
        for a in sys.argv[sys.argv.index("--sweep") + 1:]:
            if a.startswith("--"):
                break
            workers.append(int(a))
        sweep(workers or [0, 2], model)
        return
    repeat = int(sys.argv[sys.argv.index("--repeat") + 1]) if "--repeat" in sys.argv else 3
    models = ["unit"] if "--skip-vehicle" in sys.argv else ["unit", "vehicle"]
    p = load_preset("turnout-soft")
    print(f"load before: {os.getloadavg()}")
    profiles = {w: parse_irregularity(f"random:class=low,waves={w}") for w in (64, 400)}
    for model in models:
        for kmh in (60, 120):
            v = kmh * KMH
            base = median_cpu(lambda model=model, v=v: simulate_over_spans(p, model, v, 20,
                                                                          overlay=False),
                              repeat)
            line = f"{model:8s} {kmh:4d} km/h  smooth run of 20 spans {base:7.2f} s CPU"
            for w, prof in profiles.items():
                t = median_cpu(lambda prof=prof, model=model, v=v: simulate_over_spans(
                    p, model, v, 20, profile=prof, seed=1), repeat)
                line += f" | {w} waves {t:7.2f} s ({t / base:5.2f} x)"
            if model == "unit":
                t = median_cpu(lambda v=v: linear_gap_rms(p, v, profiles[400]), repeat)
                line += f" | linear rms {t * 1e3:.1f} ms"
            print(line, flush=True)
    print(f"load after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
