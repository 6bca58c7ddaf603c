"""Numerical options that check themselves (bounds shared by the library and the CLI).

The command line enforces the same bounds while parsing (``maglev_match.cli.common``), so a
bad value stops before any work; library callers get the same rule from these objects'
``__post_init__``. Errors are :class:`~maglev_match.params.ParameterError` naming the option.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from maglev_match.params import ParameterError

__all__ = ["CollocationMesh", "NTST_MIN", "NTST_MAX", "NCOL_MIN", "NCOL_MAX", "TOL_MAX",
           "STEPS_MAX", "check_tolerance"]

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


def check_tolerance(name: str, value: float) -> float:
    """A solver tolerance must be a finite number in (0, TOL_MAX]."""
    if not (isinstance(value, int | float) and math.isfinite(value) and 0 < value <= TOL_MAX):
        raise ParameterError(name, value, f"must be a number in (0, {TOL_MAX:g}]")
    return float(value)
