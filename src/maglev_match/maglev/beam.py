"""Beam and vehicle data to model parameters, as JAX functions (exact derivatives).

The models take omega1 and sigma (and model B also L, mbar, s, s0) as parameters; a
designer varies the beam (span L, bending stiffness EI, mass per length mbar) and the
vehicle (length l, unit count k). omega1 and sigma follow the simply supported
Euler-Bernoulli beam unless set explicitly (Timoshenko & Young, *Vibration Problems in
Engineering*):

    omega1 = (pi / L)^2 sqrt(EI / mbar),
    sigma = 8 k L / (pi^2 l^2 mbar) sin^2(pi l / (2 L)),
    h_max = gap_max - c0,

and w0 is the static mid-span deflection: model A w0 = sigma (m + M) g / omega1^2;
model B the modal sum (Clough & Penzien, *Dynamics of Structures*, ch. 18)

    w0 = sum_n q_n* sin(n pi / 2),
    q_n* = 2 / (mbar L omega_n^2) sum_j F sin(n pi x_j / L),  omega_n = n^2 omega1,

with F the weight per levitation point and x_j the six points' positions on the span.

The sensitivities (:mod:`maglev_match.analyses.sensitivity`) differentiate the index by
the values of :func:`unit_engineering_names` / :func:`vehicle_engineering_names` through
these maps (a model's :meth:`~maglev_match.maglev.base.MaglevModel.derived_map`).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import jax.numpy as jnp

from maglev_match.core.params import Params
from maglev_match.maglev import unit, vehicle

__all__ = ["unit_engineering_names", "vehicle_engineering_names", "unit_derived_map",
           "vehicle_derived_map", "first_frequency"]

BEAM_OMEGA = ("L", "EI", "mbar")  # the beam data omega1 derives from
BEAM_SIGMA = ("L", "mbar", "l", "k")  # ... and sigma
LIMITS = ("gap_max",)


def unit_engineering_names(params: Params) -> tuple[str, ...]:
    """Model A's d chi / d p parameters: its own, with omega1 and sigma replaced by L, EI,
    mbar, l, k where they are derived, and gap_max."""
    derived_w = "omega1" not in params.explicit
    out = [n for n in unit.PARAM_NAMES if n not in ("omega1", "sigma")]
    derived_s = "sigma" not in params.explicit
    beam = [n for n in ("L", "EI", "mbar", "l", "k")
            if (derived_w and n in BEAM_OMEGA) or (derived_s and n in BEAM_SIGMA)]
    out += beam
    out += [n for n, d in (("omega1", derived_w), ("sigma", derived_s)) if not d]
    out += list(LIMITS)
    return tuple(out)


def vehicle_engineering_names(params: Params) -> tuple[str, ...]:
    """Model B's: omega1 becomes EI where it is derived (L and mbar are parameters of the
    vehicle model already: mode shapes and modal masses; sigma does not enter model B),
    and gap_max."""
    derived_w = "omega1" not in params.explicit
    out = [n for n in vehicle.PARAM_NAMES if n != "omega1"]
    out.append("EI" if derived_w else "omega1")
    return tuple(out + list(LIMITS))


def first_frequency(v: dict, derived_w: bool):
    """omega1 = (pi / L)^2 sqrt(EI / mbar) from the beam's values in ``v`` (traced), or
    ``v["omega1"]`` when omega1 was given explicitly."""
    if derived_w:
        return (jnp.pi / v["L"]) ** 2 * jnp.sqrt(v["EI"] / v["mbar"])
    return v["omega1"]


def unit_derived_map(params: Params) -> Callable:
    """q (values of :func:`unit_engineering_names`) -> (model A's parameter vector, w0,
    h_max)."""
    return _unit_map("omega1" not in params.explicit, "sigma" not in params.explicit)


def vehicle_derived_map(params: Params) -> Callable:
    """q (values of :func:`vehicle_engineering_names`) -> (model B's parameter vector, w0,
    h_max)."""
    return _vehicle_map("omega1" not in params.explicit, int(params.n_modes))


@cache
def _unit_map(derived_w: bool, derived_s: bool) -> Callable:
    names = unit_engineering_names(Params(**({} if derived_w else {"omega1": 100.0}),
                                          **({} if derived_s else {"sigma": 4e-4})))
    pos = {n: i for i, n in enumerate(names)}

    def fmap(q):
        v = {n: q[i] for n, i in pos.items()}
        w1 = first_frequency(v, derived_w)
        if derived_s:
            sg = (8.0 * v["k"] * v["L"] / (jnp.pi**2 * v["l"] ** 2 * v["mbar"])
                  * jnp.sin(jnp.pi * v["l"] / (2.0 * v["L"])) ** 2)
        else:
            sg = v["sigma"]
        full = dict(v, omega1=w1, sigma=sg)
        p = jnp.stack([full[n] for n in unit.PARAM_NAMES])
        w0 = sg * (v["m"] + v["M"]) * v["g"] / w1**2
        return p, w0, v["gap_max"] - v["c0"]

    return fmap


@cache
def _vehicle_map(derived_w: bool, n_modes: int) -> Callable:
    names = vehicle_engineering_names(Params(**({} if derived_w else {"omega1": 100.0})))
    pos = {n: i for i, n in enumerate(names)}
    mid = jnp.sin(jnp.arange(1, n_modes + 1, dtype=jnp.float64) * jnp.pi / 2.0)

    def fmap(q):
        v = {n: q[i] for n, i in pos.items()}
        w1 = first_frequency(v, derived_w)
        full = dict(v, omega1=w1)
        p = jnp.stack([full[n] for n in vehicle.PARAM_NAMES])
        q_static = vehicle.geometry(p, n_modes)[-1]
        return p, q_static @ mid, v["gap_max"] - v["c0"]

    return fmap
