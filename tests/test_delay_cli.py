"""The delay on the command line: --set tau, hopf --param tau, the critical delay in the
index, user model files with DELAYS, and the bad inputs (exit 2, one line)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from maglev_match.cli import main
from maglev_match.core.params import load_preset
from maglev_match.dynamics.delay import critical_delay
from maglev_match.maglev.unit import unit_dde

# x' = -a x(t - tau): Hopf at tau = pi / (2 a) with frequency a
LINEAR_DDE = '''\
import jax.numpy as jnp

STATES = ["x"]
PARAMS = {"a": 2.0, "tau": 0.0}
DELAYS = ("tau",)


def rhs(x, xd, p):
    return -p["a"] * xd[0]
'''


def write(tmp_path: Path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def run(capsys, *args):
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_hopf_along_tau_from_zero_gives_the_critical_delay(capsys):
    code, out, err = run(capsys, "hopf", "--param", "tau", "--from", "0", "--to", "0.02",
                         "--json")
    assert code == 0, err
    doc = json.loads(out)
    cd = critical_delay(unit_dde(load_preset("turnout-soft")), tau_max=0.02)
    (pt,) = doc["points"]
    assert pt["tau"] == pytest.approx(cd.value, rel=1e-12)
    assert pt["frequency"] == pytest.approx(cd.frequency, rel=1e-12)
    assert pt["l1"] == pytest.approx(cd.l1, rel=1e-12) and pt["kind"] == "supercritical"
    assert doc["delay"]["axis"] and doc["delay"]["dimension"] == 9 + doc["delay"]["nodes"]
    # supercritical, but the stable cycles fold back just beyond: the practical margin
    pr = doc["delay"]["practical"]
    assert pr["basis"] == "fold" and 1.01 < pr["value"] / cd.value < 1.02


def test_index_states_the_critical_delay_and_loses_stability_beyond_it(capsys):
    code, out, err = run(capsys, "index", "--set", "tau=0.002", "--no-simulation")
    assert code == 0, err
    assert "critical delay of the controller: tau = 1.438 ms (omega = 139.44 rad/s, " \
           "supercritical, l1 = -2.57e-05); at tau = 2 ms the equilibrium is unstable" in out
    assert "equilibrium: unstable" in out and "chi = 0" in out


def test_index_gives_the_practical_margin_of_a_supercritical_delay(capsys, tmp_path):
    """Supercritical at tau_c = 1.438 ms, but the stable cycles fold back at 1.016 tau_c:
    `index` gives that fold as the practical margin (issue 32's edge: it read out
    'supercritical' alone), and it is the LPC of an independent `cycles` run along tau on
    a finer mesh (80 intervals against 40)."""
    # one run: the text on the terminal, the JSON in the file it writes (the same answer)
    code, text, err = run(capsys, "index", "--set", "tau=0.001", "--no-simulation",
                          "--out", str(tmp_path))
    assert code == 0, err
    saved = json.loads((tmp_path / "index_unit.json").read_text())
    pr = saved["critical_delay"]["practical"]
    cd_value = saved["critical_delay"]["value"]
    assert pr["basis"] == "fold" and pr["value"] == pr["fold"]
    assert 1.01 < pr["value"] / cd_value < 1.02
    code, out, err = run(capsys, "cycles", "--param", "tau", "--to", "0.0016",
                         "--set", "tau=0.001", "--json", "--out", str(tmp_path / "c"))
    assert code == 0, err
    lpc = [sp for sp in json.loads(out)["special_points"] if sp["type"] == "LPC"]
    assert len(lpc) == 1 and lpc[0]["tau"] == pytest.approx(pr["value"], rel=1e-6)
    assert f"practical margin of the delay: tau = {pr['value'] * 1e3:.4g} ms" in text


@pytest.mark.parametrize("args, words", [
    (("index", "--set", "tau=-0.001", "--no-simulation"), ["tau", ">= 0"]),
    (("stability", "--set", "tau=0.5"), ["'tau' = 0.5", "at most", "Chebyshev"]),
    (("hopf", "--param", "tau", "--from", "-0.01", "--to", "0.01"), ["tau", ">= 0"]),
])
def test_bad_delays_exit_2_with_one_line(capsys, args, words):
    code, out, err = run(capsys, *args)
    assert code == 2 and out == ""
    line = err.strip()
    assert line.count("\n") == 0 and "Traceback" not in err
    assert all(w in line for w in words), line


# ---------------------------------------------------------------------------------------
# user models with DELAYS
# ---------------------------------------------------------------------------------------
def test_a_delay_model_file_gives_its_hopf_point(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, "dde.py", LINEAR_DDE)
    code, out, err = run(capsys, "hopf", "--model", "dde.py", "--param", "tau", "--from", "0",
                         "--to", "2", "--json")
    assert code == 0, err
    (pt,) = json.loads(out)["points"]
    assert abs(pt["tau"] - math.pi / 4) < 1e-10 and abs(pt["frequency"] - 2.0) < 1e-10
    # with the delay set, stability is that of the discretised system
    code, out, err = run(capsys, "stability", "--model", "dde.py", "--set", "tau=1.0",
                         "--json")
    assert code == 0, err
    assert json.loads(out)["stable"] is False  # tau > pi / 4


BAD_FILES = {
    "unknown name": (LINEAR_DDE.replace('DELAYS = ("tau",)', 'DELAYS = ("lag",)'),
                     "DELAYS entry 'lag' is not a name in PARAMS"),
    "negative default": (LINEAR_DDE.replace('"tau": 0.0', '"tau": -1.0'),
                         "PARAMS['tau'] = -1.0 is a delay (in DELAYS) and must be >= 0"),
    "ode rhs with DELAYS": (LINEAR_DDE.replace("def rhs(x, xd, p):\n    return -p[\"a\"] * xd[0]",
                                               "def rhs(x, p):\n    return -p[\"a\"] * x"),
                            "defines rhs(x, xd, p)"),
    "delayed rhs without DELAYS": (LINEAR_DDE.replace('DELAYS = ("tau",)\n', ""),
                                   "the file defines no DELAYS"),
    "wrong shape": (LINEAR_DDE.replace('return -p["a"] * xd[0]',
                                       'return jnp.stack([xd[0, 0], xd[0, 0]])'),
                    "rhs returns shape (2,), expected (1,)"),
    "not a tuple": (LINEAR_DDE.replace('DELAYS = ("tau",)', 'DELAYS = "tau"'),
                    "must be a non-empty tuple of PARAMS names"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_delay_model_files_exit_2_naming_the_problem(capsys, tmp_path, case):
    text, words = BAD_FILES[case]
    path = write(tmp_path, "bad.py", text)
    code, out, err = run(capsys, "stability", "--model", path)
    assert code == 2 and out == "", err
    assert words in err and "Traceback" not in err and err.strip().count("\n") == 0


def test_negative_delay_set_on_a_model_file_exits_2(capsys, tmp_path):
    path = write(tmp_path, "dde.py", LINEAR_DDE)
    code, out, err = run(capsys, "stability", "--model", path, "--set", "tau=-0.5")
    assert code == 2 and "tau" in err and ">= 0" in err


def test_simulating_a_delay_model_file_reports_the_models_own_states(capsys, tmp_path):
    # x' = -a x(t - tau) from a constant past x = 1: by the method of steps
    # x(t) = 1 - a t + a^2 (t - tau)^2 / 2 on [tau, 2 tau]; at t = 0.15 (a = 2, tau = 0.1)
    # x = 0.705. The run integrates the discretised past, but reports the model's one state.
    model = write(tmp_path, "dde1.py", 'STATES = ["x"]\nPARAMS = {"a": 2.0, "tau": 0.1}\n'
                  'DELAYS = ("tau",)\nX0 = [1.0]\n\n\ndef rhs(x, xd, p):\n'
                  '    return -p["a"] * xd[0]\n')
    code, out, err = run(capsys, "simulate", "--model", model, "--t", "0.15", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert list(doc["final_state"]) == ["x"]
    assert doc["final_state"]["x"] == pytest.approx(0.705, rel=1e-5)
