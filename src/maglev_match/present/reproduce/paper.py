"""The paper's printed values (:data:`PAPER`: claims to check, never targets), one claim
beside this software's value (:class:`Claim`) and the verdict rule.

Verdict rule for numbers: "agree" when the relative difference is within 1 % (the paper
prints 3 to 4 digits), "close" within 5 %, otherwise "differ"; qualitative statements agree
or differ. The difference is always shown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "PAPER",
    "Claim",
    "relative_difference",
    "numeric_claim",
    "qualitative_claim",
]

# The paper's printed values (claims to check, never targets).
PAPER = {
    "omega1_stiff": 104.51, "omega1_soft": 97.33, "sigma": 4.7e-4,
    "omega2_stiff": 418.04, "omega3_stiff": 940.591,
    "omega2_soft": 389.307, "omega3_soft": 875.941,
    "w0_soft": 0.826e-3, "h_soft": 3.43e-3, "chi_soft": 4.15,
    "t_collide_alpha1": 1.62, "t_collide_alpha2": 1.16,
    "sigma_tangency": 0.7e-4,
    "alpha1": (100.0, 4e-4), "alpha2": (105.0, 5e-4), "alpha3": (85.0, 3.7e-4),
    "x5_alpha1": (-1.5e-3, -2.2e-3), "x5_alpha2": -0.1e-3, "x5_alpha3": -4e-3,
    "q1_fig13b": 3e-3,
    "engineering_omega1": (40.0, 190.0), "engineering_sigma": (2e-4, 6e-4),
}


@dataclass(frozen=True)
class Claim:
    """One statement of the paper beside this software's value."""

    key: str
    source: str  # where in the paper
    claim: str
    paper: str
    ours: str
    verdict: str  # "agree" | "close" | "differ" | "not computed"
    difference: str
    note: str = ""


def relative_difference(ours: float, paper: float) -> float:
    """(ours - paper) / paper (infinite when the paper's value is 0)."""
    return (ours - paper) / paper if paper != 0 else math.inf


def numeric_claim(key: str, source: str, claim: str, paper: float, ours: float, unit: str,
                  scale: float = 1.0, digits: int = 4, note: str = "") -> Claim:
    """A numeric claim with its verdict by the rule above; values and the difference shown
    times ``scale`` in ``unit`` with ``digits`` significant digits."""
    r = relative_difference(ours, paper)
    verdict = "agree" if abs(r) <= 0.01 else ("close" if abs(r) <= 0.05 else "differ")
    diff = f"{(ours - paper) * scale:+.{digits}g} {unit} ({100 * r:+.2f} %)".strip()
    return Claim(key, source, claim, f"{paper * scale:.{digits}g} {unit}".strip(),
                 f"{ours * scale:.{digits}g} {unit}".strip(), verdict, diff, note)


def qualitative_claim(key: str, source: str, claim: str, paper: str, ours: str, holds: bool,
                      difference: str = "", note: str = "") -> Claim:
    """A qualitative claim: "agree" when the statement ``holds``, else "differ"."""
    return Claim(key, source, claim, paper, ours, "agree" if holds else "differ",
                 difference or ("-" if holds else "opposite outcome"), note)
