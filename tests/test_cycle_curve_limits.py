"""A curve of cycle bifurcations stops where its cycle reaches a physical limit, with the
point solved there and the reason, as one-parameter branches of cycles do.

On the Bautin normal form's fold-of-cycles curve l1^2 + 4 mu = 0 the cycle's radius is
sqrt(l1 / 2) (tests/test_cycle_curves.py): with a limit "radius <= 0.6" the curve followed
from l1 = 0.5 upwards must stop at l1 = 2 * 0.36 = 0.72, mu = -0.1296.
"""

from __future__ import annotations

import numpy as np
import pytest
from systems import BAUTIN_NF, CYCLE_OMEGA, Q_CRIT

from maglev_match.dynamics.cycle_curves import CurveStop, cycle_curve, start_from
from maglev_match.dynamics.cycles import cycle_branch, hopf_start
from maglev_match.dynamics.cycles.orbits import orbit_extrema

R_LIMIT = 0.6


def radius_limit(system, orbit):
    return {"radius <= 0.6": R_LIMIT - orbit_extrema(system, orbit, ["radius"])["radius"][0]}


def test_lpc_curve_stops_at_the_limit():
    p = BAUTIN_NF.params_with(mu=0.0, l1=0.5)
    br = cycle_branch(BAUTIN_NF, hopf_start(BAUTIN_NF, np.zeros(5), p, "mu", CYCLE_OMEGA,
                                            Q_CRIT, 0.5), "mu", stop_at=0.5, max_steps=200,
                      ntst=20, ncol=4)
    orbit = start_from(br, "LPC1")
    cv = cycle_curve(BAUTIN_NF, orbit, "LPC", ("mu", "l1"), ranges={"l1": (0.3, 1.6)},
                     direction=1, ds_max=1.0, max_steps=300, limits=radius_limit)
    assert cv.stopped_reason == CurveStop.CONTACT and cv.ok, cv.warnings
    assert "radius <= 0.6" in cv.message
    mu, l1 = cv.p1, cv.p2
    assert np.max(np.abs(l1 ** 2 + 4.0 * mu)) < 1e-8
    end = cv.points[-1]
    assert end.kind == "contact"
    # (the collocated radius is sqrt(l1 / 2) to 1e-7 relative on this mesh)
    assert end.values[1] == pytest.approx(2 * R_LIMIT ** 2, abs=1e-7)
    assert end.values[0] == pytest.approx(-R_LIMIT ** 4, abs=1e-7)
    assert radius_limit(BAUTIN_NF, end.orbit)["radius <= 0.6"] == pytest.approx(0.0, abs=1e-10)
    assert np.all(l1[:-1] < 2 * R_LIMIT ** 2)  # no point past the limit
    sps = [s for s in cv.special_points if s.type == "contact"]
    assert len(sps) == 1 and sps[0].located == "solved" and sps[0].values == end.values
    # without limits the same curve runs to the end of its range
    free = cycle_curve(BAUTIN_NF, orbit, "LPC", ("mu", "l1"), ranges={"l1": (0.3, 1.6)},
                       direction=1, ds_max=1.0, max_steps=300)
    assert free.stopped_reason == CurveStop.BOUND and free.p2[-1] == pytest.approx(1.6)
