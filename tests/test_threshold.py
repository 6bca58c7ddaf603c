"""The batched threshold search on a system whose return/collision threshold is known in
closed form: x' = -a x (1 - x / c) has a stable equilibrium at 0 and an unstable one at c,
so from x(0) = d a run returns for d < c and escapes (collides with the limit x = 2c) for
d > c: the threshold is c, exactly, for every a > 0."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from maglev_match.analyses.simulation import critical_disturbance_of_system
from maglev_match.dynamics.integrate.threshold import (
    ThresholdOptions,
    ThresholdStatus,
    bracket_thresholds,
)
from maglev_match.dynamics.system import System

TOL = 1e-3
OPTS = ThresholdOptions(tol=TOL, t_max=10.0, chunk=8)


def _rhs(x, p):
    a, c = p[0], p[1]
    return jnp.stack([-a * x[0] * (1.0 - x[0] / c), -x[1]])


def _events(x, p):
    return jnp.reshape(2.0 * p[1] - x[0], (1,))  # negative once x passed 2c


SYSTEM = System(rhs=_rhs, p=np.array([3.0, 0.5]), param_names=("a", "c"),
                state_names=("x", "y"), state_scale=np.ones(2), name="threshold")


def _x0(idx, sizes):
    x = np.zeros((len(idx), 2))
    x[:, 0] = sizes
    return x


def _search(c, guesses=None, spreads=None, a=3.0, upper=1.0):
    P = np.column_stack([np.full(len(c), a), c])
    return bracket_thresholds(SYSTEM, P, _x0, np.full(len(c), upper), guesses=guesses,
                              spreads=spreads, events=_events, x_ref=np.zeros(2),
                              options=OPTS)


def test_cold_and_warm_lines_bracket_the_closed_form_threshold():
    c = np.array([0.3, 0.55, 0.8, 0.42, 0.42, 0.42, 0.42, 0.42])
    g = np.array([np.nan, np.nan, np.nan, 0.42, 0.42 + 0.3 * TOL, 0.42 - 5 * TOL,
                  0.42 + 300 * TOL, 0.42 - 0.2])
    e = np.array([0, 0, 0, 0, 0, 2 * TOL, 0, 0.0])
    res = _search(c, g, e)
    assert all(s == ThresholdStatus.BRACKETED for s in res.status)
    assert np.all(res.largest_return < c) and np.all(c < res.smallest_collision)
    assert np.all(res.smallest_collision - res.largest_return <= TOL * (1 + 1e-6))
    assert np.all(np.abs(res.size - c) <= TOL / 2)
    assert not res.nonmonotone.any() and np.all(res.unresolved == 0)
    # a guess within half the tolerance settles the line with two runs; cold lines spend
    # the point-wise search's three rounds; a far guess costs more than a near one
    assert res.runs[3] == 2 and res.runs[4] == 2
    assert np.all(res.runs[:3] >= 20)
    assert res.runs[6] > res.runs[4] and res.runs[7] > res.runs[4]


def test_agrees_with_the_point_wise_search_within_the_tolerance():
    c = 0.37
    ref = critical_disturbance_of_system(
        dataclasses.replace(SYSTEM, p=np.array([3.0, c])),
        lambda d: _x0(np.zeros(len(d), int), d), 1.0, events=_events, x_ref=np.zeros(2),
        tol=TOL, t_max=10.0, batch=10)
    mine = _search(np.array([c, c]), np.array([np.nan, c + 2 * TOL]))
    assert ref.status == "bracketed"
    assert np.all(np.abs(mine.size - ref.critical) <= TOL)


def test_all_return_all_collide_and_undecided_lines():
    # threshold above the largest size searched (10/11 of the range): every size returns
    # and the supported size is the whole range; below the tolerance: every size collides
    res = _search(np.array([0.95, 0.5 * TOL]), np.array([np.nan, 0.1]))
    assert list(res.status) == [ThresholdStatus.ALL_RETURN, ThresholdStatus.ALL_COLLIDE]
    assert res.size[0] == 1.0 and res.size[1] == 0.0
    # runs that neither settle nor escape within the longest horizon (4 x 10 s): a = 0.01
    slow = _search(np.array([0.5]), np.array([0.5]), a=0.01)
    assert slow.status[0] == ThresholdStatus.OPEN and np.isnan(slow.size[0])
    assert slow.unresolved[0] >= OPTS.max_unresolved


def test_options_check_themselves():
    with pytest.raises(ValueError, match="tol"):
        ThresholdOptions(tol=0.0)
    with pytest.raises(ValueError, match="chunk"):
        ThresholdOptions(chunk=0)
    with pytest.raises(ValueError, match="top_fraction"):
        ThresholdOptions(top_fraction=1.5)
