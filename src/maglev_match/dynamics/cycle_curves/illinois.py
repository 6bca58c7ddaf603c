"""The Illinois variant of regula falsi on the arclength of one continuation step, shared
by the solves of the curves' special points (codimension-two points, the cusp of cycles,
the contact with a physical limit): each evaluation is a point corrected onto the curve,
so the iteration keeps a bracket and never steps outside the step (Dowell & Jarratt 1971,
BIT 11:168: the stale end's value is halved, which keeps the convergence superlinear)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["illinois"]


def illinois(at: Callable[[float], tuple[Any, float]], lo: float, hi: float, flo: float,
             fhi: float, tol: float, ftol: float, max_iter: int = 60
             ) -> tuple[Any, float, bool]:
    """Zero of f on the bracket (lo, hi) with f(lo) = ``flo``, f(hi) = ``fhi`` of opposite
    signs; ``at(s)`` returns (payload, f(s)), payload None where the point could not be
    corrected. Stops where |f| < ``ftol`` or the bracket is shorter than ``tol``. Returns
    (payload, f, done) of the last evaluation: payload None (or f not finite) if an
    evaluation failed, ``done`` False if ``max_iter`` iterations did not meet a criterion
    (and also on a failed evaluation)."""
    best, f = None, np.nan
    for _ in range(max_iter):
        s = hi - fhi * (hi - lo) / (fhi - flo)
        best, f = at(s)
        if best is None or not np.isfinite(f):
            return best, f, False
        if f * fhi < 0:
            lo, flo = hi, fhi
        else:
            flo *= 0.5
        hi, fhi = s, f
        if abs(f) < ftol or abs(hi - lo) < tol:
            return best, f, True
    return best, f, False
