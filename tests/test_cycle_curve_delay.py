"""`cycle-curve` on a delay model (the discretised delay system is an ODE to the curve):
the fold of cycles in (tau, kD) on the soft turnout beam, whose point at the preset's kD
is the practical margin of the delay (the fold of the stable cycles born at the critical
delay, 1.46126 ms, docs/delay.md), passes through the fold located on an independent
branch of cycles along tau at another kD.
"""

from __future__ import annotations

import pytest

from maglev_match import api

KD_OTHER = 149.0


def test_lpc_curve_in_tau_and_kd_passes_through_the_branch_fold():
    st = api.cycle_curve("turnout-soft", "LPC", "tau", "kD", bounds={"kD": (148.5, 151.5)},
                         marks=(KD_OTHER,), ntst=40, max_steps=20, tau=0.0014)
    cv = st.curve
    assert cv.ok and not cv.warnings, (cv.stopped_reason, cv.warnings)
    assert st.start_label == "LPC1"
    start = next(c for c in cv.points if c.kind == "start")
    assert start.values[0] == pytest.approx(1.46126e-3, rel=1e-5)  # the practical margin
    mark = [c for c in cv.points if c.kind == "mark"]
    assert len(mark) == 1 and mark[0].values[1] == pytest.approx(KD_OTHER, rel=1e-12)
    br = api.cycle_study("turnout-soft", "tau", ignore_current=True, ntst=40, tau=0.0014,
                         kD=KD_OTHER).branches[0]
    ref = [sp.value for sp in br.special_points if sp.type == "LPC"]
    assert ref, [sp.label for sp in br.special_points]
    assert mark[0].values[0] == pytest.approx(ref[0], rel=1e-6)
