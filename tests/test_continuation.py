"""The one continuation driver: options checked on construction, the step rule, events
located by solving inside their step (never outside), parameter bounds solved exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_match.dynamics.continuation import (
    ContinuationOptions,
    StopReason,
    continuation,
    dense_bordered_newton,
)


class Circle:
    """H(x, lam) = x^2 + lam^2 - 1 (a closed curve through two folds in lam); test
    functions: the tangent's lam component ("LP", zero at lam = +-1) and x - 0.3."""

    weights = np.ones(2)

    def __init__(self):
        self.calls = 0

    def fun(self, u):
        self.calls += 1
        return np.array([u[0] ** 2 + u[1] ** 2 - 1.0]), np.array([[2 * u[0], 2 * u[1]]])

    def correct(self, u_pred, row, target, max_iter):
        return dense_bordered_newton(self.fun, u_pred, row, target, 1e-12, max_iter)

    def parameter(self, u):
        return float(u[1])

    def test_functions(self, pt):
        return {"LP": float(pt.t[-1]), "X": float(pt.u[0] - 0.3)}

    def event_kind(self, name):
        return name


@pytest.mark.parametrize("field,value", [("ds", -1.0), ("ds_min", 0.0), ("ds", 10.0),
                                         ("max_steps", 0), ("shrink", 1.5),
                                         ("newton_tol", float("nan")),
                                         ("param_bounds", (1.0, 0.0))])
def test_options_are_checked_on_construction(field, value):
    with pytest.raises(ValueError, match=f"ContinuationOptions.{field} = "):
        ContinuationOptions(**{field: value})


def test_events_are_solved_inside_their_step():
    prob = Circle()
    opt = ContinuationOptions(ds=0.05, ds_max=0.3, max_steps=150, event_tol=1e-12)
    res = continuation(prob, np.array([1.0, 0.0]), np.array([0.0, 1.0]), opt)
    lps = [e for e in res.events if e.name == "LP"]
    xs = [e for e in res.events if e.name == "X"]
    assert len(lps) >= 2 and len(xs) >= 2
    for e in lps + xs:
        assert e.located == "solved"
        assert 0 < e.s  # inside the step after point e.step
        a, b = res.points[e.step].u, res.points[e.step + 1].u
        ang = [math.atan2(v[1], v[0]) % (2 * math.pi) for v in (a, e.point.u, b)]
        lo, hi = sorted((ang[0], ang[2]))
        if hi - lo < math.pi:  # the event's angle lies between its step's end points
            assert lo - 1e-12 <= ang[1] <= hi + 1e-12
    for e in lps:
        assert abs(abs(e.point.u[1]) - 1.0) < 1e-12 and abs(e.point.u[0]) < 1e-6
    for e in xs:
        assert e.point.u[0] == pytest.approx(0.3, abs=1e-12)
        assert np.hypot(*e.point.u) == pytest.approx(1.0, abs=1e-12)  # on the branch


def test_bound_is_solved_and_stops_the_branch():
    opt = ContinuationOptions(ds=0.05, ds_max=0.2, param_bounds=(-0.5, 0.5))
    res = continuation(Circle(), np.array([1.0, 0.0]), np.array([0.0, 1.0]), opt)
    assert res.stop_reason == StopReason.BOUND
    assert res.points[-1].value == pytest.approx(0.5, abs=1e-12)
    assert all(-0.5 - 1e-12 <= p.value <= 0.5 + 1e-12 for p in res.points)


def test_step_rule_grows_to_ds_max_and_fails_below_ds_min():
    opt = ContinuationOptions(ds=0.01, ds_max=0.1, max_steps=12, fast_iterations=4)
    res = continuation(Circle(), np.array([1.0, 0.0]), np.array([0.0, 1.0]), opt)
    pts = res.points
    steps = [np.linalg.norm(b.u - a.u) for a, b in zip(pts[:-1], pts[1:], strict=True)]
    assert max(steps) == pytest.approx(0.1, rel=1e-2) and steps[0] < 0.02
    assert res.stop_reason == StopReason.MAX_STEPS and len(res.points) == 13

    class Broken(Circle):
        def correct(self, u_pred, row, target, max_iter):
            return None if abs(u_pred[1]) > 0.2 else super().correct(u_pred, row, target,
                                                                    max_iter)

    res = continuation(Broken(), np.array([1.0, 0.0]), np.array([0.0, 1.0]),
                       ContinuationOptions(ds=0.05, ds_max=0.1, ds_min=1e-4))
    assert res.stop_reason == StopReason.STEP_TOO_SMALL
    assert "ds_min" in res.message and res.rejected > 0
    assert all(abs(p.value) <= 0.2 for p in res.points)
