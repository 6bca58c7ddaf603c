"""`cycle-curve` and :func:`maglev_match.api.cycle_curve`: the curve of model A passes
through the special points of independent one-parameter `cycles` branches; the command
answers for a user model file (the Bautin normal form, whose fold of cycles is known in
closed form) with its table, CSV, netCDF and figure; bad input is refused naming the
option, the value and the rule."""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

from maglev_match import api
from maglev_match.cli import main

# model A, alpha1 with xi0 = 0.7: the branch of cycles along omega1 at sigma = 4e-4 has a
# period doubling (omega1 ~ 80.5) and a fold of cycles (omega1 ~ 70.6) beyond the current
# limit (the branches below ignore it, as the command does by default)
CASE = {"xi0": 0.7}
SIGMAS = (3.6e-4, 4.2e-4, 4.4e-4)


@pytest.mark.parametrize("kind", ["LPC", "PD"])
def test_model_a_curve_passes_through_the_branch_points(kind):
    st = api.cycle_curve("alpha1", kind, "omega1", "sigma", at={"sigma": 4e-4},
                         bounds={"sigma": (3.55e-4, 4.45e-4)}, marks=SIGMAS, **CASE)
    cv = st.curve
    assert cv.ok and not cv.warnings, (cv.stopped_reason, cv.warnings)
    assert st.start_label == f"{kind}1"
    assert cv.p2.min() == pytest.approx(3.55e-4, rel=1e-12)
    assert cv.p2.max() == pytest.approx(4.45e-4, rel=1e-12)
    on_curve = {round(c.values[1], 15): c.values[0] for c in cv.points if c.kind == "mark"}
    assert len(on_curve) == len(SIGMAS)
    for sigma in SIGMAS:
        br = api.cycle_study("alpha1", "omega1", ignore_current=True, sigma=sigma,
                             **CASE).branches[0]
        ref = [sp.value for sp in br.special_points if sp.type == kind]
        assert ref, (sigma, [sp.label for sp in br.special_points])
        assert on_curve[round(sigma, 15)] == pytest.approx(ref[0], rel=1e-7), sigma
    # the result's table, dataset and figure
    rows = st.rows()
    assert len(rows) == len(cv.points) and "gap_deviation_max" in rows[0]
    ds = st.to_xarray()
    assert ds["omega1"].attrs["units"] == "rad/s"
    assert ds.attrs["kind"] == kind and ds.attrs["model"] == "unit"


BAUTIN_FILE = '''import jax.numpy as jnp

STATES = ["x", "y"]
PARAMS = {"mu": -0.1, "l1": 1.0}
X0 = [0.0, 0.0]


def rhs(x, p):
    r2 = x[0] ** 2 + x[1] ** 2
    g = p["mu"] + p["l1"] * r2 - r2 * r2
    return jnp.array([g * x[0] - 2.0 * x[1], 2.0 * x[0] + g * x[1]])
'''


def test_command_answers_for_a_user_model(tmp_path, capsys):
    model = tmp_path / "bautin.py"
    model.write_text(BAUTIN_FILE)
    out = tmp_path / "out"
    code = main(["cycle-curve", "--model", str(model), "--params", "mu,l1", "--ntst", "20",
                 "--range", "l1=0.6:1.4", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "LPC curve of cycles in (mu, l1)" in text and "reached the end of the range" in text
    nc = next(out.glob("*.nc"))
    ds = xr.load_dataset(nc, engine="h5netcdf")
    mu, l1 = ds["mu"].values, ds["l1"].values
    assert l1.min() == pytest.approx(0.6) and l1.max() == pytest.approx(1.4)
    assert np.max(np.abs(l1 ** 2 + 4 * mu)) < 1e-8  # the closed form
    assert {p.suffix for p in out.iterdir()} >= {".csv", ".nc", ".png", ".svg"}
    # the JSON answer carries the same curve
    code = main(["cycle-curve", "--model", str(model), "--params", "mu,l1", "--ntst", "20",
                 "--range", "l1=0.9:1.1", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["ok"] and res["kind"] == "LPC" and res["start"] == "LPC1"
    pts = res["points"]
    assert max(abs(p["l1"] ** 2 + 4 * p["mu"]) for p in pts) < 1e-8


def test_lpc_curve_from_a_generalised_hopf_point_of_a_user_model(tmp_path, capsys):
    """--label GH1: the LPC curve born at the GH point (mu, l1) = (0, 0) of the Hopf curve
    mu = 0, on the side l1 > 0, ends a fifth of the switching step (1 % of the range)
    before GH and on the range's other end; the closed form l1^2 + 4 mu = 0 along it. (The
    range is not centred on GH: the Hopf curve's scans start at its middle, and a GH point
    exactly there, l1 = 0 at the start, is not detected by the Hopf curve.)"""
    model = tmp_path / "bautin.py"
    model.write_text(BAUTIN_FILE)
    code = main(["cycle-curve", "--model", str(model), "--params", "mu,l1", "--label", "GH1",
                 "--from", "-1", "--to", "1", "--range", "l1=-0.4:0.5", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["ok"], res["warnings"]
    assert res["start"] == "GH1 of the Hopf curve"
    l1 = [p["l1"] for p in res["points"]]
    # the step is 1 % of the range (0.009); the GH end a fifth of it from GH
    assert min(l1) == pytest.approx(0.0018, abs=1e-12) and max(l1) == pytest.approx(0.5)
    assert max(abs(p["l1"] ** 2 + 4 * p["mu"]) for p in res["points"]) < 1e-8
    code = main(["cycle-curve", "--model", str(model), "--params", "mu,l1", "--label", "GH2",
                 "--from", "-1", "--to", "1", "--range", "l1=-0.4:0.5"])
    assert code == 2 and "GH1 to GH1" in capsys.readouterr().err


def test_a_curve_born_at_a_generalised_hopf_point_stops_at_the_physical_limits(
        monkeypatch):
    """From GH of a maglev model (alpha1: GH1 at omega1 = 136.9, kP = 3349 on the Hopf
    curve in (omega1, kP)) the LPC curve gets the model's physical limits, as a curve
    started from a branch's point does: it stops where its cycle reaches a gap limit (or
    the current limit). It used to be continued without them."""
    from maglev_match.dynamics import cycle_curves

    seen = {}

    def capture(*args, **kw):
        seen.update(kw)
        raise ValueError("captured")  # (the start is not continued here)

    monkeypatch.setattr(cycle_curves, "lpc_from_generalised_hopf", capture)
    with pytest.raises(ValueError, match="no fold of cycles found near GH1: captured"):
        api.cycle_curve("alpha1", "LPC", "omega1", "kP", label="GH1", stage=False)
    limits = seen.get("limits")
    assert limits is not None and "cycle_limit_margins" in limits.__qualname__


def test_restart_from_a_saved_branch(tmp_path, capsys):
    model = tmp_path / "bautin.py"
    model.write_text(BAUTIN_FILE)
    saved = tmp_path / "branch"
    assert main(["cycles", "--model", str(model), "--param", "mu", "--ntst", "20",
                 "--max-steps", "60", "--out", str(saved)]) == 0
    nc = next(saved.glob("*.nc"))
    capsys.readouterr()
    code = main(["cycle-curve", "--model", str(model), "--params", "mu,l1", "--restart",
                 str(nc), "--label", "LPC1", "--range", "l1=0.9:1.1", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["ok"] and res["restart_of"].startswith("LPC1 of")
    assert max(abs(p["l1"] ** 2 + 4 * p["mu"]) for p in res["points"]) < 1e-8
    # a PD curve is not started from a fold
    code = main(["cycle-curve", "--model", str(model), "--params", "mu,l1", "--restart",
                 str(nc), "--label", "LPC1", "--kind", "PD"])
    assert code == 2 and "LPC1 is a LPC" in capsys.readouterr().err


@pytest.mark.parametrize("args, words", [
    (["--kind", "TR"], ["kind", "TR", "LPC, PD, NS"]),
    (["--params", "omega1"], ["--params", "omega1", "P1,P2"]),
    (["--params", "omega1,omega1"], ["--params", "must differ"]),
    (["--range", "sigma=5e-4:3e-4"], ["--range", "low < high"]),
    (["--range", "kD=1:2"], ["--range", "kD", "omega1, sigma"]),
    (["--restart", "x.nc"], ["--restart", "--label"]),
])
def test_bad_input_is_refused(args, words, capsys):
    code = main(["cycle-curve", *args])
    err = capsys.readouterr().err
    assert code == 2, err
    for w in words:
        assert w in err, (w, err)
