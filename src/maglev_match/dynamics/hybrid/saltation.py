"""Saltation matrices: the first-order map of perturbations across a switch of a hybrid
system.

With the reset R (the projection into the new mode), the guard h and the fields f- before
and f+ after the switch, the saltation matrix is S = R_x + (f+ - R_x f-) h_x / (h_x f-)
(Aizerman & Gantmakher 1958; Leine & Nijmeijer 2004, *Dynamics and Bifurcations of
Non-smooth Mechanical Systems*, sec. 3.5, eq. 3.77; di Bernardo, Budd, Champneys & Kowalczyk
2008, *Piecewise-smooth Dynamical Systems*, sec. 2.5). :func:`switch_parts` gives its
ingredients (and the parameter derivatives R_p, h_p) at a switch, compiled once per system.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64)
from maglev_match.dynamics.hybrid.system import HybridSystem, identity_project

__all__ = ["saltation_matrix", "switch_parts"]


@cache
def switch_parts(rhs: Callable, guards: Callable, project: Callable) -> Callable:
    """(f-, f+, x+, R_x, h_x, R_p, h_p) at a switch of switch j from mode s into s_new."""

    def parts(x, p, s, s_new, j):
        f_old = rhs(x, p, s)
        x_new = project(x, p, s_new)
        f_new = rhs(x_new, p, s_new)
        Rx, Rp = jax.jacfwd(project, argnums=(0, 1))(x, p, s_new)
        hx, hp = jax.grad(lambda xx, qq: guards(xx, qq, s)[j], argnums=(0, 1))(x, p)
        return f_old, f_new, x_new, Rx, hx, Rp, hp

    return jax.jit(parts)


def saltation_matrix(hs: HybridSystem, x: np.ndarray, s: np.ndarray, j: int,
                     p: np.ndarray | None = None) -> np.ndarray:
    """The saltation matrix of toggling switch ``j`` at the state ``x`` (on its surface) from
    mode ``s``: S = R_x + (f+ - R_x f-) h_x / (h_x f-) (Leine & Nijmeijer 2004, eq. 3.77;
    di Bernardo et al. 2008, sec. 2.5), R the projection into the new mode, h the guard,
    f-/f+ the fields before/after. The first-order map of perturbations across the switch."""
    s = np.asarray(s, float)
    s_new = s.copy()
    s_new[j] = 1.0 - s_new[j]
    f_old, f_new, _, Rx, hx, _, _ = (np.asarray(a) for a in switch_parts(
        hs.rhs, hs.guards, hs.project or identity_project)(
        jnp.asarray(x, float), hs.param_array(p), jnp.asarray(s), jnp.asarray(s_new), int(j)))
    return Rx + np.outer(f_new - Rx @ f_old, hx) / float(hx @ f_old)

