"""Exact sensitivities of the vehicle's (model B's) index: central finite differences of the
full vehicle index where a cycle sets h, closed forms where a case rule does, the stability
boundary against the Hopf point, and the CLI.

The point with a cycle: the soft turnout beam stiffened to EI = 3.2e10 N m^2 (omega1 =
124.4 rad/s, 2.9 % below the vehicle's subcritical Hopf point at omega1 = 127.97): an unstable
cycle of gap deviation 5.34 mm bounds the basin there. At the preset itself (EI = 1.96e10)
the cycle branch touches a gap limit first, so the case rule sets h.
"""

from __future__ import annotations

import json
import math

import jax.numpy as jnp
import numpy as np
import pytest

from maglev_match.analyses.matching import matching_index
from maglev_match.analyses.sensitivity import (
    DerivativeStatus,
    derived_map,
    engineering_names,
    index_sensitivity,
    linearised_spread,
)
from maglev_match.cli import main
from maglev_match.core.params import load_preset
from maglev_match.dynamics.equilibria import stability
from maglev_match.maglev.models import VehicleModel
from maglev_match.maglev.vehicle import vehicle_system

CYCLE_POINT = load_preset("turnout-soft").replace(EI=3.2e10)


@pytest.fixture(scope="module")
def cyc():
    p = CYCLE_POINT
    idx = matching_index(p, model="vehicle", simulate=False)
    return p, index_sensitivity(p, idx, boundaries=False)


def _fd(params, name, rel=1e-4):
    v = float(getattr(params, name))
    d = rel * v
    cp = matching_index(params.replace(**{name: v + d}), model="vehicle", simulate=False)
    cm = matching_index(params.replace(**{name: v - d}), model="vehicle", simulate=False)
    assert cp.case == cm.case == "unstable_cycle"
    return (cp.chi - cm.chi) / (2 * d)


def test_vehicle_names_replace_omega1_by_the_beam_stiffness():
    p = load_preset("turnout-soft")
    names = engineering_names(p, "vehicle")
    assert "EI" in names and "omega1" not in names and "sigma" not in names
    assert {"L", "mbar", "kD", "m_b", "gap_max"} <= set(names)
    explicit = engineering_names(p.replace(omega1=100.0), "vehicle")
    assert "omega1" in explicit and "EI" not in explicit


def test_vehicle_w0_formula_and_its_derivatives():
    p = load_preset("turnout-soft")
    names = engineering_names(p, "vehicle")
    q = np.array([float(getattr(p, n)) for n in names])
    import jax

    fmap = derived_map(p, "vehicle")
    pm, w0, hmax = fmap(jnp.asarray(q))
    # the same number as the index's w0 (there from the solved equilibrium)
    assert float(w0) == pytest.approx(VehicleModel(p).pressed_geometry[2], rel=1e-12)
    np.testing.assert_allclose(np.asarray(pm), vehicle_system(p).p, rtol=1e-14)
    assert float(hmax) == pytest.approx(p.gap_max - p.c0, rel=1e-14)
    dw0 = np.asarray(jax.jacfwd(lambda x: fmap(x)[1])(jnp.asarray(q)))
    at = {n: i for i, n in enumerate(names)}
    # every modal deflection ~ load / (mbar L omega_n^2) ~ 1 / EI and ~ load ~ g: elasticity
    # exactly -1 in EI and +1 in g; independent of the controller
    assert dw0[at["EI"]] * p.EI / float(w0) == pytest.approx(-1.0, rel=1e-12)
    assert dw0[at["g"]] * p.g / float(w0) == pytest.approx(1.0, rel=1e-12)
    assert dw0[at["kD"]] == 0.0 and dw0[at["gap_max"]] == 0.0


@pytest.mark.parametrize("name", ["EI", "kD", "m_b"])
def test_vehicle_dchi_matches_finite_differences_of_the_index(cyc, name):
    p, sens = cyc
    assert sens.index.case == "unstable_cycle"
    assert sens.status == DerivativeStatus.EXACT
    assert sens.system.solve_residual < 1e-10
    assert sens.system.h == pytest.approx(sens.index.h, rel=1e-7)
    assert sens.dchi(name) == pytest.approx(_fd(p, name), rel=1e-4)


def test_vehicle_margin_derivative_and_spread(cyc):
    p, sens = cyc
    d = 1e-4 * p.kD
    mp = stability(vehicle_system(p.replace(kD=p.kD + d))).margin
    mm = stability(vehicle_system(p.replace(kD=p.kD - d))).margin
    assert sens.dmargin("kD") == pytest.approx((mp - mm) / (2 * d), rel=1e-5)
    spread = linearised_spread(sens, {"EI": 2.0, "kD": 5.0})
    expect = math.hypot(sens.dchi("EI") * p.EI * 0.02, sens.dchi("kD") * p.kD * 0.05)
    assert spread["sd"] == pytest.approx(expect, rel=1e-14)


@pytest.mark.slow
def test_vehicle_case_rule_point_moves_only_through_w0_and_gap_max():
    # a smaller gap range: the same cycle (5.34 mm) no longer fits, the rule sets h
    p = CYCLE_POINT.replace(gap_max=0.012)
    sens = index_sensitivity(p, model="vehicle", boundaries=True, simulate=False)
    idx = sens.index
    assert idx.case == "no_cycle_within_limits"
    assert sens.status == DerivativeStatus.RULE
    assert idx.chi == pytest.approx((p.gap_max - p.c0) / idx.w0, rel=1e-12)
    # chi = (gap_max - c0) / w0 and w0 ~ 1/EI: elasticities +1 (EI), 0 (kD)
    assert sens.row("EI").elasticity == pytest.approx(1.0, rel=1e-10)
    assert sens.dchi("kD") == 0.0
    assert sens.row("gap_max").elasticity == pytest.approx(p.gap_max / (p.gap_max - p.c0),
                                                           rel=1e-12)
    # the distance to the case boundary: the branch's gap maximum does not depend on
    # gap_max, so that boundary is exact; the cycle case returns just beyond it
    g = sens.row("gap_max").limit_boundary
    assert g is not None and p.gap_max < g < CYCLE_POINT.gap_max
    above = matching_index(p.replace(gap_max=g * 1.001), model="vehicle", simulate=False)
    below = matching_index(p.replace(gap_max=g * 0.999), model="vehicle", simulate=False)
    assert above.case == "unstable_cycle" and below.case == "no_cycle_within_limits"
    assert above.h == pytest.approx(g - p.c0, rel=1e-5)


def test_vehicle_unstable_point_is_zero_with_the_boundary_at_the_hopf_point(cyc):
    _, stable_sens = cyc
    p = CYCLE_POINT.replace(EI=4e10)  # omega1 = 139 rad/s: past the Hopf point
    sens = index_sensitivity(p, model="vehicle", boundaries=True, simulate=False)
    assert sens.index.case == "unstable_equilibrium" and sens.index.chi == 0.0
    assert sens.status == DerivativeStatus.ZERO
    assert all(r.dchi == 0.0 for r in sens.rows)
    b = sens.row("EI").boundary
    # two methods: the margin's zero in EI (Newton on the eigenvalue) and the Hopf point in
    # omega1 (Newton on the Hopf defining system) through omega1 = (pi/L)^2 sqrt(EI/mbar)
    w_hopf = stable_sens.system.hopf_value
    ei_hopf = p.mbar * (w_hopf * p.L**2 / math.pi**2) ** 2
    assert b == pytest.approx(ei_hopf, rel=1e-8)
    assert "derivative exactly 0" in sens.row("EI").note


def test_cli_vehicle_sensitivity_text_and_json(capsys, tmp_path):
    args = ["sensitivity", "--model", "vehicle", "--set", "EI=3.2e10", "--no-boundaries",
            "--no-simulation",
            "--out", str(tmp_path), "--scatter", "EI=2", "--scatter", "kD=5"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "model B" in text and "unstable_cycle" in text and "linearised spread" in text
    assert main(args + ["--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["status"] == "exact" and data["case"] == "unstable_cycle"
    rows = {r["name"]: r for r in data["rows"]}
    assert "EI" in rows and "omega1" not in rows and "sigma" not in rows
    expect = math.hypot(rows["EI"]["dchi"] * rows["EI"]["value"] * 0.02,
                        rows["kD"]["dchi"] * rows["kD"]["value"] * 0.05)
    assert data["spread"]["sd"] == pytest.approx(expect, rel=1e-12)


@pytest.mark.slow
def test_cli_vehicle_design_meets_its_requirement_and_1pct_cheaper_does_not(capsys, tmp_path):
    # chi rises with kD at the cycle point (d chi / d kD > 0) until the cycle reaches the gap
    # limit; the least kD with chi >= 10 is an interior optimum with the chi constraint active
    code = main(["design", "--model", "vehicle", "--set", "EI=3.2e10", "--vary", "kD=140:170",
                 "--minimize", "kD", "--require", "chi>=10", "--grid", "3", "--starts", "1",
                 "--no-simulation",
                 "--json", "--out", str(tmp_path)])
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["status"] == "feasible" and data["index"]["model"] == "vehicle"
    kd = data["design"]["kD"]
    assert 150.0 < kd < 166.0 and data["active"] == ["chi >= 10"]
    p = CYCLE_POINT.replace(kD=kd)
    again = matching_index(p, model="vehicle", simulate=False)
    assert again.chi >= 10.0 and again.case == "unstable_cycle"
    assert matching_index(p.replace(kD=0.99 * kd), model="vehicle", simulate=False).chi < 10.0


def test_report_section_shows_the_vehicle_table(cyc, tmp_path):
    from dataclasses import replace

    from maglev_match.present.report import ReportContext, ReportSettings, section_sensitivity

    p, sens = cyc
    settings = replace(ReportSettings.quick_settings(), include_vehicle=True)
    ctx = ReportContext(out_dir=tmp_path, settings=settings,
                        cache={"matching": matching_index(p, simulate=False),
                               "matching_vehicle": sens.index})
    html, files, data = section_sensitivity(p, ctx)
    assert "The full vehicle (model B)" in html and files
    assert data["vehicle"]["status"] == "exact" and data["unit"]["case"] == "unstable_cycle"
    rows = {r["name"]: r["dchi"] for r in data["vehicle"]["rows"]}
    assert rows["kD"] == pytest.approx(sens.dchi("kD"), rel=1e-12)
