"""The design search: a synthetic problem with a closed-form cheapest parameter, model A's
cheapest soft beam re-checked by the index, parsing and CLI errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from systems import NF_DESIGN as DESIGN
from systems import normal_form_system

from maglev_match.analyses.design import (
    DesignProblem,
    DesignStatus,
    Goal,
    MaglevEvaluator,
    Quantity,
    Requirement,
    SystemEvaluator,
    Variable,
    optimise_design,
    parse_requirement,
    parse_vary,
)
from maglev_match.analyses.matching import matching_index
from maglev_match.cli import main
from maglev_match.core.params import ParameterError, load_preset

W0 = 0.1


def _nf_evaluator():
    def make(v):
        return normal_form_system(a=float(v[0])), W0, 10.0, {"a": (0.5, 4.0)}, None

    return SystemEvaluator(["a"], make)


@pytest.mark.parametrize("chi_min", [5.0, 8.0])
def test_cheapest_parameter_of_the_normal_form(chi_min):
    # chi = sqrt((a - mu) / l1) / w0 >= X  <=>  a >= mu + l1 (X w0)^2
    expected = DESIGN["mu"] + DESIGN["l1"] * (chi_min * W0) ** 2
    prob = DesignProblem((Variable("a", 1.1, 3.0),), Goal.MINIMIZE, "a",
                         (Requirement(Quantity.CHI, chi_min),))
    res = optimise_design(prob, _nf_evaluator())
    assert res.status == DesignStatus.FEASIBLE
    assert res.values["a"] == pytest.approx(expected, abs=1e-6)
    assert res.index.chi >= chi_min
    assert res.active == (f"chi >= {chi_min:g}",)


def test_unreachable_requirement_is_reported_with_the_best_found():
    prob = DesignProblem((Variable("a", 1.1, 1.4),), Goal.MINIMIZE, "a",
                         (Requirement(Quantity.CHI, 9.0),))  # chi <= sqrt(0.2) / 0.1 = 4.47
    res = optimise_design(prob, _nf_evaluator(), grid=5, starts=1)
    assert res.status == DesignStatus.INFEASIBLE
    assert res.values["a"] == pytest.approx(1.4, abs=1e-6)  # the largest chi in the box
    assert res.candidates[0].violation == pytest.approx(1 - math.sqrt(0.2) / 0.1 / 9, rel=1e-6)


def test_model_a_cheapest_soft_beam_is_rechecked():
    base = load_preset("turnout-soft")
    prob = DesignProblem((Variable("EI", 5e9, 4e10),), Goal.MINIMIZE, "EI",
                         (Requirement(Quantity.CHI, 5.0),))
    res = optimise_design(prob, MaglevEvaluator(base, ["EI"], simulate=False), grid=5,
                          starts=1)
    assert res.status == DesignStatus.FEASIBLE
    ei = res.values["EI"]
    again = matching_index(base.replace(EI=ei), simulate=False)
    assert again.chi >= 5.0 and again.chi == res.index.chi
    assert matching_index(base.replace(EI=0.99 * ei), simulate=False).chi < 5.0
    # here no cycle bounds the basin within the gap range: chi = (gap_max - c0) / w0 with
    # w0 = sigma (m + M) g mbar L^4 / (pi^4 EI), so the cheapest EI has a closed form
    assert again.case == "no_cycle_within_limits"
    b = base
    closed = 5.0 * b.sigma * (b.m + b.M) * b.g * b.mbar * b.L**4 / (
        math.pi**4 * (b.gap_max - b.c0))
    assert ei == pytest.approx(closed, rel=1e-6)


def test_parsing_and_problem_errors():
    assert parse_vary("EI=5e9:4e10") == Variable("EI", 5e9, 4e10)
    assert parse_requirement("margin>=0.2") == Requirement(Quantity.MARGIN, 0.2)
    for bad in ("EI=4e10:5e9", "EI5e9:4e10", "nope=1:2", "EI=a:b", "k=10:14"):
        with pytest.raises(ParameterError):
            parse_vary(bad)
    for bad in ("chi>5", "size>=3", "chi>=x"):
        with pytest.raises(ParameterError):
            parse_requirement(bad)
    with pytest.raises(ParameterError, match="--minimize"):
        DesignProblem((Variable("EI", 1, 2),), Goal.MINIMIZE, "kD")
    with pytest.raises(ParameterError, match="only chi"):
        DesignProblem((Variable("EI", 1, 2),), Goal.MAXIMIZE, "EI")


@pytest.mark.parametrize("args, field", [
    (["design", "--vary", "EI=5e9:4e10", "--require", "chi>=5"], "--minimize/--maximize"),
    (["design", "--vary", "EI=-1:4e10", "--minimize", "EI"], "EI"),
    (["design", "--vary", "EI=5e9:4e10", "--minimize", "kD"], "--minimize"),
    (["sensitivity", "--model", "tram"], "--model"),
    (["design", "--vary", "EI=5e9:4e10", "--minimize", "EI", "--model", "tram"], "--model"),
    (["sensitivity", "--scatter", "EI"], "--scatter"),
])
def test_cli_user_errors_exit_2(capsys, args, field):
    assert main(args) == 2
    err = capsys.readouterr().err
    assert field in err and len(err.strip().splitlines()) == 1


def test_cli_sensitivity_json(capsys, tmp_path):
    assert main(["sensitivity", "--no-boundaries", "--no-simulation", "--json", "--out",
                 str(tmp_path), "--scatter", "EI=5"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["status"] == "exact" and data["case"] == "unstable_cycle"
    rows = data["rows"]
    ela = [abs(r["elasticity"]) for r in rows]
    assert ela == sorted(ela, reverse=True)
    ei = next(r for r in rows if r["name"] == "EI")
    assert data["spread"]["sd"] == pytest.approx(abs(ei["dchi"]) * ei["value"] * 0.05,
                                                 rel=1e-12)
    assert all((tmp_path / f"tornado.{s}").exists() for s in ("png", "svg"))
    assert np.isfinite([r["dchi"] for r in rows]).all()


def test_cli_design_without_a_feasible_design_exits_3(capsys, tmp_path):
    """No candidate can reach chi >= 1000 (chi is at most (gap_max - c0) / w0 ~ 12 here):
    the best design is printed and the exit code says 'no feasible design' (3), distinct
    from a usage error (2) or a failure (1)."""
    from maglev_match.cli.design import NO_FEASIBLE_DESIGN

    code = main(["design", "--vary", "kD=120:180", "--maximize", "chi", "--require",
                 "chi>=1000", "--grid", "3", "--starts", "1", "--no-simulation", "--json",
                 "--out", str(tmp_path)])
    assert code == NO_FEASIBLE_DESIGN == 3
    data = json.loads(capsys.readouterr().out)
    assert data["status"] != "feasible" and data["index"]["chi"] < 1000


def test_paper_only_design_is_a_beam_the_simulation_rejects():
    """The paper's chi alone (`design ... --no-simulation`) answers a beam about three times
    softer than the headline's (the README example; the headline answer itself is checked
    by tests/test_readme.py on the README's own run): there the full index reads
    chi_simulation well below the required 5, so the headline index rejects it."""
    base = load_preset("turnout-soft")
    prob = DesignProblem((Variable("EI", 5e9, 4e10),), Goal.MINIMIZE, "EI",
                         (Requirement(Quantity.CHI, 5.0),))
    paper_only = optimise_design(prob, MaglevEvaluator(base, ["EI"], simulate=False), grid=5,
                                 starts=1)
    assert paper_only.status == DesignStatus.FEASIBLE, paper_only.message
    ei = paper_only.values["EI"]
    assert paper_only.index.chi_paper == pytest.approx(5.0, rel=1e-3)
    full = matching_index(base.replace(EI=ei))
    assert full.chi_simulation < 3.0 and full.chi == full.chi_simulation < 5.0


def test_cli_chi_simulation_requirement_without_simulation_is_refused(capsys):
    """A requirement on an index that was switched off is a usage error naming both."""
    code = main(["design", "--vary", "EI=5e9:4e10", "--minimize", "EI", "--require",
                 "chi_simulation>=3", "--no-simulation"])
    assert code == 2
    err = capsys.readouterr().err
    assert "chi_simulation>=3" in err and "--no-simulation" in err
    assert len(err.strip().splitlines()) == 1


def test_cli_sensitivity_differentiates_the_headline(capsys, tmp_path):
    """At the soft turnout beam the headline is chi_simulation: `sensitivity` gives its
    derivative (implicit function theorem on the solved grazing condition) as d chi/dp, with
    the paper's chi's beside it."""
    assert main(["sensitivity", "--no-boundaries", "--json", "--out", str(tmp_path)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["reading_basis"] == "simulation" and data["status"] == "solved"
    assert data["chi"] == data["chi_simulation"] < data["chi_paper"]
    assert "grazing" in data["simulation_status"]
    for r in data["rows"]:
        assert r["dchi"] == r["dchi_simulation"] and np.isfinite(r["dchi_paper"])


def test_an_evaluation_next_to_the_previous_one_continues_its_index():
    """The evaluator passes the previous evaluation as ``near`` when every varied
    parameter moved by at most NEAR_STEP: the critical disturbances are continued (said in
    the index), and chi equals the point-wise index's to 1e-7 relative; a farther point is
    searched in full (no continuation recorded)."""
    from maglev_match.analyses.design.problem import NEAR_STEP

    base = load_preset("turnout-soft")
    ev = MaglevEvaluator(base, ["EI"])
    ei = base.EI
    ev.evaluate(np.array([ei]), gradient=False)
    nxt = ev.evaluate(np.array([ei * (1 + NEAR_STEP / 5)]), gradient=False).index
    for key in ("up", "down"):
        assert nxt.simulation[key]["continuation"] == {"continued": True}
    full = matching_index(base.replace(EI=ei * (1 + NEAR_STEP / 5)))
    assert nxt.chi == pytest.approx(full.chi, rel=1e-7)
    assert nxt.reading_basis == full.reading_basis
    far = ev.evaluate(np.array([ei * (1 + 3 * NEAR_STEP)]), gradient=False).index
    assert "continuation" not in far.simulation["up"]
