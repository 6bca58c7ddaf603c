"""Engineering quantities (span L, bending stiffness EI, beam mass per length mbar, vehicle
length l, unit count k, unit spacings s, s0) as the varied parameter of a one-parameter study.

The models take omega1 and sigma (and, for model B, L, mbar, s, s0) as parameters; a beam or
vehicle quantity changes several of them at once, nonlinearly: by the Euler-Bernoulli beam
formulas (Timoshenko & Young, *Vibration Problems in Engineering*, simply supported beam)

    omega1 = (pi / L)^2 sqrt(EI / mbar),
    sigma  = 8 k L / (pi^2 l^2 mbar) sin^2(pi l / (2 L)).

Such a quantity E becomes a continuation parameter through
:func:`maglev_match.dynamics.paths.path_system`: the model's parameter vectors P(E_0), ...,
P(E_{n-1}) at equally spaced values of E are the nodes of a piecewise-linear path with the
single parameter t (t = j gives exactly P(E_j)). Between nodes the path is a chord of the
true curve P(E), so a Hopf point found on it is refined on ever shorter chords around it
(each one 10^-2 times the previous, widened
when it misses the crossing) until the chord is shorter than 10^-7 |E|; the chord
error, O(chord^2), is then far below the Newton tolerance. Results are reported in E.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import cache

import jax.numpy as jnp
import numpy as np

from maglev_match.core.params import ParameterError, Params
from maglev_match.dynamics.hopf import HopfPoint, HopfScan, locate_hopf_points
from maglev_match.dynamics.paths import PATH_PARAM, interpolate_path, path_system
from maglev_match.dynamics.system import System

__all__ = ["ENGINEERING_PARAMS", "PARAM_HELP", "is_engineering", "engineering_nodes",
           "engineering_hopf_points", "engineering_system"]

#: Beam and vehicle quantities from which the model parameters omega1, sigma (and model B's
#: geometry) derive; each may be the varied parameter of hopf, root-locus and cycles.
ENGINEERING_PARAMS = ("L", "EI", "mbar", "l", "k", "s", "s0")

#: Help text of a ``--param`` option that accepts them.
PARAM_HELP = ("Parameter to vary: a model parameter (omega1, sigma, kD ...) or beam/vehicle "
              "data L, EI, mbar, l, k, s, s0 (omega1 and sigma follow).")

# Relative length of the last chord of the refinement (see the module docstring).
CHORD_RTOL = 1e-7


def is_engineering(name: str) -> bool:
    """Whether ``name`` is an engineering quantity (model B also has L, mbar, s, s0 in its
    parameter vector; varying them through this module keeps omega1 and sigma derived)."""
    return name in ENGINEERING_PARAMS


def _model_vector(params: Params, model: str, name: str, value: float) -> np.ndarray:
    from maglev_match.maglev.models import build_system

    value = int(round(value)) if name == "k" else float(value)
    return np.asarray(build_system(params.replace(**{name: value}), model).p, float)


def engineering_nodes(params: Params, model: str, name: str,
                      values: Sequence[float] | np.ndarray, option: str = "--param"
                      ) -> np.ndarray:
    """The model's parameter vectors at each value of the engineering quantity ``name``
    (shape (len(values), n_params)).

    Raises :class:`ParameterError` when a value breaks its rule, or when the quantity moves
    no model parameter (e.g. L while omega1 and sigma are set explicitly in the preset)."""
    nodes = np.array([_model_vector(params, model, name, v) for v in values])
    if np.all(nodes == nodes[0]):
        fixed = sorted(params.explicit & {"omega1", "sigma", "s", "s0"})
        if fixed:
            why = (f"{', '.join(fixed)} set explicitly override it; use a preset that "
                   "derives them from the beam, e.g. turnout-soft")
        else:
            why = "it does not enter this model"
        raise ParameterError(option, name,
                             f"changes no parameter of model '{model}': {why}")
    return nodes


def engineering_hopf_points(params: Params, model: str, name: str, start: float,
                            stop: float, n_scan: int = 200) -> tuple[HopfScan, System]:
    """Hopf points of the equilibrium as the engineering quantity ``name`` runs from
    ``start`` to ``stop``.

    Parameters
    ----------
    params : the parameter set (omega1, sigma must derive from the beam for L, EI, mbar,
        l, k to move them).
    model : 'unit' (model A) or 'vehicle' (model B).
    name : one of :data:`ENGINEERING_PARAMS` (SI units: m, N m^2, kg/m, m, -, m, m).
    start, stop : the interval of ``name``.
    n_scan : values of the bracketing scan (and nodes of the path).

    Returns
    -------
    (scan, system) : the :class:`HopfScan` with each point's ``param``/``value`` in the
    engineering quantity, ``p`` the model's parameter vector there and ``crossing_speed``
    d Re(lambda)/d name; and the model's System (read omega1, sigma off ``p`` with it).
    """
    from maglev_match.maglev.models import build_system

    system = build_system(params, model)
    values = np.linspace(start, stop, int(n_scan))
    nodes = engineering_nodes(params, model, name, values)
    path = path_system(system, nodes)
    scan = locate_hopf_points(path, PATH_PARAM, 0.0, len(values) - 1.0, n_scan=len(values))
    step = values[1] - values[0]
    points: list[HopfPoint] = []
    warnings = list(scan.warnings)
    for hp in scan.points:
        value = start + hp.value * step
        chord = abs(step)
        refined = hp
        tries = 0
        while refined.converged and chord > CHORD_RTOL * max(abs(value), 1e-300):
            lo, hi = value - chord, value + chord
            sub = path_system(system, engineering_nodes(params, model, name, [lo, hi]))
            found = locate_hopf_points(sub, PATH_PARAM, 0.0, 1.0, n_scan=3).points
            found = [f for f in found if f.converged]
            if not found:  # the previous chord's error exceeded this chord: widen it
                tries += 1
                if tries > 4:
                    warnings.append(f"Hopf point near {name} = {value:.8g}: refinement on "
                                    f"a chord of {2 * chord:.3g} lost the crossing; value "
                                    "kept at the coarser chord's precision")
                    break
                chord *= 4.0
                continue
            tries = 0
            refined = min(found, key=lambda f: abs(f.frequency - hp.frequency))
            value = lo + refined.value * (hi - lo)
            refined = dataclasses.replace(refined, crossing_speed=refined.crossing_speed
                                          / (hi - lo))
            chord = max(chord * 1e-2, 0.5 * CHORD_RTOL * abs(value))
        if refined is hp:
            refined = dataclasses.replace(hp, crossing_speed=hp.crossing_speed / step)
        n_m = len(system.param_names)
        t = refined.p[0]
        nodes_here = refined.p[1:].reshape(-1, n_m)
        k = int(np.clip(np.floor(t), 0, len(nodes_here) - 2))
        p_model = (1 - (t - k)) * nodes_here[k] + (t - k) * nodes_here[k + 1]
        points.append(dataclasses.replace(refined, param=name, value=float(value),
                                          p=p_model))
    out = HopfScan(param=name, start=start, stop=stop, points=points, scan_values=values,
                   max_real_part=scan.max_real_part, warnings=tuple(warnings))
    return out, system


@cache
def _quantity_rhs(rhs, n_nodes: int, n_params: int):
    def quantity_rhs(x, q):
        t = (q[0] - q[1]) / q[2]
        return rhs(x, interpolate_path(jnp.concatenate([t[None], q[3:]]), n_nodes, n_params))

    return quantity_rhs


def engineering_system(params: Params, model: str, name: str, start: float, stop: float,
                       n_nodes: int = 201) -> System:
    """The model with the engineering quantity ``name`` as its first parameter.

    The parameter vector is [E, E_start, dE, P_0, ..., P_{n-1}] with P_j the model's
    parameter vector at E_j = E_start + j dE (``n_nodes`` equally spaced values over
    [start, stop]); the vector field at E is the model's at the piecewise-linear
    interpolation of the P_j (exact at the nodes, chord error O(dE^2) between them; beyond
    [start, stop] the end chords are extended linearly). Every one-parameter tool
    (``locate_hopf_points``, ``cycle_branch``) then works in E directly, with E's value
    at the parameter set's own value of ``name`` (clipped into [start, stop]).
    """
    from maglev_match.maglev.models import build_system

    system = build_system(params, model)
    values = np.linspace(start, stop, int(n_nodes))
    nodes = engineering_nodes(params, model, name, values)
    n, m = nodes.shape
    names = (name, f"{name}_start", f"{name}_step") + tuple(
        f"node{k}_{p}" for k in range(n) for p in system.param_names)
    e0 = float(np.clip(float(getattr(params, name)), min(start, stop), max(start, stop)))
    p = np.concatenate([[e0, values[0], values[1] - values[0]], nodes.ravel()])
    return System(
        rhs=_quantity_rhs(system.rhs, n, m),
        p=p,
        param_names=names,
        state_names=system.state_names,
        x_guess=system.x_guess,
        state_scale=system.state_scale,
        observables={k: _quantity_rhs(g, n, m) for k, g in system.observables.items()},
        name=f"{system.name} along {name}",
    )
