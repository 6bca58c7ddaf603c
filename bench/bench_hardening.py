"""What the hardening of issue 24 costs: netCDF built in memory before it is written (the
fix for HDF5's crash on a full disk) against HDF5 writing the file itself, and the checks
of a user model file (the guard, the neighbourhood of X0) within its load.

Ratios of interleaved runs in the same process (CPU time, ``time.process_time``), median of
``--repeat`` runs; nothing here fails.

    PYTHONPATH=src python bench/bench_hardening.py [--repeat 7]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


def _map_dataset(n: int):
    import xarray as xr

    rng = np.random.default_rng(0)
    names = ["chi", "h", "w0", "stable", "max_real_part", "hopf_distance", "case",
             "current_reverses", "resolved", "reason"]
    return xr.Dataset({k: (("sigma", "omega1"), rng.normal(size=(n, n))) for k in names},
                      coords={"sigma": np.linspace(2e-4, 6e-4, n),
                              "omega1": np.linspace(40, 190, n)},
                      attrs={"title": "benchmark map"})


def _cpu(fn) -> float:
    t = time.process_time()
    fn()
    return time.process_time() - t


def bench_netcdf(repeat: int, folder: Path) -> None:
    from maglev_match.core.io import atomic_write, atomic_write_netcdf

    for n in (20, 100, 300):
        ds = _map_dataset(n)
        path = folder / f"m{n}.nc"
        direct, memory = [], []
        for _ in range(repeat):  # interleaved
            direct.append(_cpu(lambda ds=ds, path=path: atomic_write(
                path, lambda tmp: ds.to_netcdf(tmp, engine="h5netcdf"))))
            memory.append(_cpu(lambda ds=ds, path=path: atomic_write_netcdf(path, ds)))
        d, m = statistics.median(direct), statistics.median(memory)
        print(f"netCDF {n}x{n} map ({path.stat().st_size / 1e6:.2f} MB): HDF5 to the file "
              f"{d * 1e3:.1f} ms, in memory then written {m * 1e3:.1f} ms (ratio {m / d:.2f})")


LORENZ = '''import jax.numpy as jnp
STATES = ["x", "y", "z"]
PARAMS = {"sigma": 10.0, "rho": 28.0, "beta": 8.0 / 3.0}
X0 = [8.0, 8.0, 27.0]
SCALES = [8.0, 8.0, 20.0]
def rhs(x, p):
    return jnp.array([p["sigma"] * (x[1] - x[0]), p["rho"] * x[0] - x[1] - x[0] * x[2],
                      x[0] * x[1] - p["beta"] * x[2]])
'''


def bench_model_load(repeat: int, folder: Path) -> None:
    import maglev_match.maglev.user as U

    full, check = [], []
    for k in range(repeat):
        path = folder / f"lorenz{k}.py"  # a new file each time: no cached trace
        path.write_text(LORENZ)
        full.append(_cpu(lambda path=path: U.load_model(path)))
        m = U.load_model(path)
        check.append(_cpu(lambda m=m, path=path: U._check_neighbourhood(
            path, U._vectorised(m.rhs, m.param_names, path), m.x0,
            np.array(list(m.params.values())), m.scales, m.states)))
    f, c = statistics.median(full), statistics.median(check)
    print(f"user model load (Lorenz): {f * 1e3:.0f} ms CPU in all, of which the "
          f"neighbourhood check {c * 1e3:.0f} ms ({c / f:.0%})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bench_netcdf(a.repeat, Path(tmp))
        bench_model_load(a.repeat, Path(tmp))


if __name__ == "__main__":
    main()
