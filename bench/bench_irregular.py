"""Benchmark: runs over an irregular guideway (maglev_match.analyses.speed.irregular).

For the unit (and, without ``--skip-vehicle``, the vehicle) on turnout-soft at 60 and 120
km/h: the median CPU time of one run of 20 spans with the limits on over the smooth
guideway (the baseline, the run an irregular read-out needs anyway) and over a random
profile of the German 'low' spectrum with 64 and with 400 waves (the default), as ratios
to the baseline in the same process; and the linear route's rms (the unit), in ms. The
first call of each (compilation) is left out of the medians. Prints the machine load
(``os.getloadavg``) before and after.

    .venv/bin/python bench/bench_irregular.py [--skip-vehicle] [--repeat N]
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


def main() -> None:
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
