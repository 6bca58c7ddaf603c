"""Numerical options that check themselves (bounds shared by the library and the CLI).

The command line enforces the same bounds while parsing (``maglev_match.cli.common``), so a
bad value stops before any work; library callers get the same rule from these objects'
``__post_init__``. Errors are :class:`~maglev_match.core.params.ParameterError` naming the option.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from maglev_match.core.params import ParameterError

__all__ = ["CollocationMesh", "MonteCarloOptions", "NTST_MIN", "NTST_MAX", "NCOL_MIN",
           "NCOL_MAX", "TOL_MAX", "STEPS_MAX", "MC_SAMPLES_MAX", "SEED_MAX", "WORKERS_MAX",
           "SCATTER_PCT_MAX", "check_tolerance", "check_scatter_percent"]

# Smallest collocation mesh accepted. Measured on a map row of model A (turnout-soft,
# omega1 110..140 rad/s, sigma 4e-4, NCOL 4) against NTST 60: the bounding cycle's h agrees
# within 6e-4 relative for NTST >= 4, is off by 0.5 % at NTST 3 and by 36 % at NTST 2
# (NTST 1 gave chi = 25.4 instead of 6.59 on a full map, marked resolved). NTST 8 keeps a
# factor-2 margin over the last mesh that still resolved the cycles. Gauss collocation with
# NCOL points per interval has error O(h^NCOL) at the mesh points (de Boor & Swartz 1973), so
# the bound matters most for the least accurate NCOL = 2.
NTST_MIN = 8
NTST_MAX = 2000
NCOL_MIN, NCOL_MAX = 2, 7  # Gauss-Legendre points per mesh interval, as in AUTO (Doedel)
STEPS_MAX = 100_000  # continuation steps
TOL_MAX = 0.1  # tolerances lie in (0, 0.1]: a relative tolerance of 1 accepts any step
# Monte Carlo studies (--monte-carlo): each sample is one index computation (0.1-1 s of CPU
# for model A), so a million samples is already days of work on a small cluster; larger
# counts are typing mistakes (99999999999999999999 once reached numpy as an array size).
MC_SAMPLES_MAX = 1_000_000
# Seeds of the sample generator: numpy's SeedSequence takes any non-negative integer; the
# bound keeps a seed to 32 bits, short to write down and repeat.
SEED_MAX = 2**32 - 1
WORKERS_MAX = 256  # local Dask worker processes (maps, Monte Carlo)
# Relative standard deviation of a scattered parameter (--scatter NAME=PCT), percent. A
# normal relative scatter of 50 % already draws a negative value (not a parameter set) in
# 2.3 % of the samples, and the linearised spread assumes chi linear over the spread; a
# larger scatter is refused rather than turned into a meaningless "chi +- sd".
SCATTER_PCT_MAX = 50.0


@dataclass(frozen=True)
class CollocationMesh:
    """Mesh of the periodic-orbit collocation: ``ntst`` intervals with ``ncol`` Gauss points
    each, continued for at most ``max_steps`` steps. Checked on construction."""

    ntst: int = 30
    ncol: int = 4
    max_steps: int = 300

    def __post_init__(self) -> None:
        for name, value, lo, hi in (("--ntst", self.ntst, NTST_MIN, NTST_MAX),
                                    ("--ncol", self.ncol, NCOL_MIN, NCOL_MAX),
                                    ("--max-steps", self.max_steps, 1, STEPS_MAX)):
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                raise ParameterError(name, value, f"must be a whole number in [{lo}, {hi}]")


@dataclass(frozen=True)
class MonteCarloOptions:
    """A Monte Carlo study's counts, checked on construction (the command line enforces the
    same bounds while parsing; these are the library's check).

    samples : parameter sets drawn, in [2, MC_SAMPLES_MAX].
    seed : seed of the generator, in [0, SEED_MAX].
    workers : local Dask worker processes in [0, WORKERS_MAX] (0: in this process; None:
        one per core).
    chunk : samples per checkpointed chunk, >= 1.
    """

    samples: int
    seed: int = 0
    workers: int | None = None
    chunk: int = 16

    def __post_init__(self) -> None:
        checks = (("--monte-carlo", self.samples, 2, MC_SAMPLES_MAX,
                   " (each sample is one index computation)"),
                  ("--seed", self.seed, 0, SEED_MAX, ""),
                  ("--workers", self.workers, 0, WORKERS_MAX, " (0: compute in this process)"),
                  ("chunk", self.chunk, 1, MC_SAMPLES_MAX, ""))
        for name, value, lo, hi, why in checks:
            if value is None and name == "--workers":
                continue
            if (isinstance(value, bool) or not isinstance(value, numbers.Integral)
                    or not lo <= value <= hi):
                raise ParameterError(name, value, f"must be a whole number in [{lo}, {hi}]"
                                     + why)


def check_scatter_percent(name: str, pct: float) -> float:
    """A relative standard deviation (percent) must be finite and in [0, SCATTER_PCT_MAX]."""
    if not (isinstance(pct, int | float) and math.isfinite(pct)
            and 0.0 <= pct <= SCATTER_PCT_MAX):
        raise ParameterError("--scatter", f"{name}={pct:g}",
                             f"the percentage must be in [0, {SCATTER_PCT_MAX:g}] (a relative "
                             "standard deviation; larger spreads draw negative values and "
                             "make the linearised spread meaningless)")
    return float(pct)


def check_tolerance(name: str, value: float) -> float:
    """A solver tolerance must be a finite number in (0, TOL_MAX]."""
    if not (isinstance(value, int | float) and math.isfinite(value) and 0 < value <= TOL_MAX):
        raise ParameterError(name, value, f"must be a number in (0, {TOL_MAX:g}]")
    return float(value)
