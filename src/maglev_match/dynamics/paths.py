"""A path through parameter space as a single continuation parameter.

Given parameter vectors P_0, ..., P_{n-1} (e.g. the points of one row of a design map, where
several physical parameters change together), :func:`path_system` builds a System whose only
free parameter ``t`` runs along the piecewise-linear path through them: t = k gives exactly
P_k. Hopf detection and cycle continuation in ``t`` then follow a whole row of a map with one
branch instead of starting afresh at every point. Model-agnostic.
"""

from __future__ import annotations

from functools import cache

import jax.numpy as jnp
import numpy as np

from maglev_match.dynamics.system import RHS, RegularChart, System

__all__ = ["path_system", "PATH_PARAM"]

PATH_PARAM = "t"


def interpolate_path(q, n_nodes: int, n_params: int):
    """The parameter vector at path position t = q[0] (piecewise linear through the nodes)."""
    t = q[0]
    P = q[1:].reshape(n_nodes, n_params)
    k = jnp.clip(jnp.floor(t), 0, n_nodes - 2).astype(jnp.int32)
    s = t - k
    return (1.0 - s) * P[k] + s * P[k + 1]


@cache
def _path_rhs(rhs: RHS, n_nodes: int, n_params: int):
    def path_rhs(x, q):
        return rhs(x, interpolate_path(q, n_nodes, n_params))

    return path_rhs


@cache
def _path_observable(g, n_nodes: int, n_params: int):
    def g_path(x, q):
        return g(x, interpolate_path(q, n_nodes, n_params))

    return g_path


@cache
def _path_chart(chart: RegularChart, n_nodes: int, n_params: int) -> RegularChart:
    """The system's regular chart along the path (every map and the vector field read the
    parameters at the path position)."""
    return RegularChart(
        rhs=_path_rhs(chart.rhs, n_nodes, n_params),
        to_chart=_path_observable(chart.to_chart, n_nodes, n_params),
        from_chart=_path_observable(chart.from_chart, n_nodes, n_params),
        distance=_path_observable(chart.distance, n_nodes, n_params),
        state_scale=chart.state_scale, switch_below=chart.switch_below)


def path_system(system: System, nodes: np.ndarray, t0: float = 0.0) -> System:
    """The system restricted to the piecewise-linear path through the rows of ``nodes``
    (shape (n_nodes, n_params), n_nodes >= 2); its parameter vector is [t, nodes...]. A
    regular chart of the system (:class:`~maglev_match.dynamics.system.RegularChart`)
    comes along, restricted to the same path."""
    nodes = np.asarray(nodes, float)
    if nodes.ndim != 2 or nodes.shape[0] < 2 or nodes.shape[1] != len(system.param_names):
        raise ValueError(
            f"nodes must have shape (>=2, {len(system.param_names)}), got {nodes.shape}"
        )
    n, m = nodes.shape
    names = (PATH_PARAM,) + tuple(
        f"node{k}_{name}" for k in range(n) for name in system.param_names
    )
    p = np.concatenate([[t0], nodes.ravel()])

    return System(
        rhs=_path_rhs(system.rhs, n, m),
        p=p,
        param_names=names,
        state_names=system.state_names,
        x_guess=system.x_guess,
        state_scale=system.state_scale,
        observables={k: _path_observable(g, n, m) for k, g in system.observables.items()},
        name=f"{system.name} along a path of {n} points",
        chart=None if system.chart is None else _path_chart(system.chart, n, m),
    )
