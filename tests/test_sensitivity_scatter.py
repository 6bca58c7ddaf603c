"""`index --scatter`: the linearised spread of chi from the sensitivity table, the sampled
spread with --monte-carlo, and one-line errors for bad scatter options."""

from __future__ import annotations

import json
import math

import pytest

from maglev_match.cli import main


def test_index_scatter_is_the_root_sum_of_squares_of_the_sensitivity_table(capsys, tmp_path):
    assert main(["index", "--no-simulation", "--scatter", "EI=5", "--scatter", "kD=10",
                 "--scatter", "m=2", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert main(["sensitivity", "--no-boundaries", "--no-simulation", "--json", "--out",
                 str(tmp_path)]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)["rows"]}
    pct = {"EI": 5.0, "kD": 10.0, "m": 2.0}
    parts = {n: rows[n]["dchi"] * rows[n]["value"] * p / 100 for n, p in pct.items()}
    expect = math.sqrt(sum(v * v for v in parts.values()))
    assert expect > 0
    assert data["spread"]["sd"] == pytest.approx(expect, rel=1e-10)
    assert data["spread"]["chi"] == data["chi"]
    for n, v in parts.items():
        assert data["spread"]["contributions"][n] == pytest.approx(abs(v), rel=1e-10)
    assert data["monte_carlo"] is None


def test_index_scatter_text_and_monte_carlo(capsys, tmp_path):
    args = ["index", "--no-simulation", "--scatter", "EI=0.1", "--monte-carlo", "2",
            "--workers", "0", "--out", str(tmp_path)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "linearised spread: chi = " in text and "sampled (2 sets)" in text
    assert len(list((tmp_path / "monte-carlo").glob("chunk_*.npz"))) == 1  # (atomic, fingerprinted)
    assert main(args + ["--json", "--resume"]) == 0
    mc = json.loads(capsys.readouterr().out)["monte_carlo"]
    assert mc["n"] == 2 and mc["failed"] == 0 and mc["invalid"] == 0
    assert math.isfinite(mc["mean"]) and mc["linearised"]["sd"] > 0


@pytest.mark.parametrize("args, field, value", [
    (["--scatter", "EI"], "--scatter", "EI"),
    (["--scatter", "EI=abc"], "--scatter", "EI=abc"),
    (["--scatter", "EI=-1"], "--scatter", "EI=-1"),
    (["--scatter", "nope=3"], "--scatter", "nope"),
    (["--scatter", "omega1=3"], "--scatter", "omega1"),  # derived from the beam: no row
    (["--model", "vehicle", "--scatter", "sigma=3"], "--scatter", "sigma"),  # not in model B
    (["--monte-carlo", "4"], "--monte-carlo", "4"),
])
def test_index_bad_scatter_exits_2_naming_the_field(capsys, args, field, value):
    assert main(["index", "--no-simulation", *args]) == 2
    err = capsys.readouterr().err
    assert field in err and value in err and len(err.strip().splitlines()) == 1
