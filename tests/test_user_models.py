"""User models from a Python file: loading, the checks on it, and every analysis command."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from maglev_match.cli import main
from maglev_match.maglev.user import ModelFileError, load_model

LORENZ = '''\
import jax.numpy as jnp

STATES = ["x", "y", "z"]
PARAMS = {"sigma": 10.0, "rho": 28.0, "beta": 8.0 / 3.0}
X0 = [8.0, 8.0, 27.0]
SCALES = [8.0, 8.0, 20.0]


def rhs(x, p):
    return jnp.array([
        p["sigma"] * (x[1] - x[0]),
        p["rho"] * x[0] - x[1] - x[0] * x[2],
        x[0] * x[1] - p["beta"] * x[2],
    ])


OBSERVABLES = {"z": lambda x, p: x[2]}
'''

# Hopf normal form x' = a x - w y - x r^2, y' = w x + a y - y r^2: eigenvalues a +- i w at 0
NORMAL_FORM = '''\
import jax.numpy as jnp

STATES = ["x", "y"]
PARAMS = {"a": -0.3, "w": 2.0}


def rhs(x, p):
    r2 = x[0] ** 2 + x[1] ** 2
    return jnp.array([p["a"] * x[0] - p["w"] * x[1] - x[0] * r2,
                      p["w"] * x[0] + p["a"] * x[1] - x[1] * r2])
'''

DECAY = '''\
import jax.numpy as jnp

STATES = ["u"]
PARAMS = {"k": 1.5}


def rhs(x, p):
    return -p["k"] * x
'''


def write(tmp_path: Path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def run(capsys, *args):
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


# ---------------------------------------------------------------------------------------
# the loaded model
# ---------------------------------------------------------------------------------------
def test_loaded_model_gives_a_system_with_exact_derivatives(tmp_path):
    m = load_model(write(tmp_path, "lorenz.py", LORENZ))
    assert m.name == "lorenz" and m.states == ("x", "y", "z")
    assert m.defaults == {"sigma": 10.0, "rho": 28.0, "beta": 8.0 / 3.0}
    s = m.system({"rho": 20.0})
    assert s.param_names == ("sigma", "rho", "beta") and s.param("rho") == 20.0
    x = np.array([1.0, 2.0, 3.0])
    assert np.allclose(s.f(x), [10.0, 20.0 - 2.0 - 3.0, 2.0 - 8.0])
    assert np.allclose(s.jacobian(x), [[-10, 10, 0], [20 - 3, -1, -1], [2, 1, -8 / 3]])
    assert np.allclose(s.param_derivative(x, None, "rho"), [0.0, 1.0, 0.0])
    assert np.allclose(s.state_scale, [8, 8, 20]) and np.allclose(s.x_guess, [8, 8, 27])
    with pytest.raises(ValueError, match="sigma, rho, beta"):
        m.system({"r": 1.0})


# ---------------------------------------------------------------------------------------
# commands on a user model
# ---------------------------------------------------------------------------------------
def test_hopf_on_a_lorenz_file_matches_the_closed_form(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, "lorenz.py", LORENZ)
    code, out, err = run(capsys, "hopf", "--model", "lorenz.py", "--param", "rho",
                         "--from", "2", "--to", "30", "--json")
    assert code == 0, err
    doc = json.loads(out)
    sigma, beta = 10.0, 8.0 / 3.0
    rho_h = sigma * (sigma + beta + 3.0) / (sigma - beta - 1.0)
    assert doc["model"] == "lorenz" and len(doc["points"]) == 1
    pt = doc["points"][0]
    assert pt["rho"] == pytest.approx(rho_h, rel=1e-8)
    # at the Hopf point lambda = i omega solves the characteristic polynomial:
    # omega^2 = beta (rho + sigma)
    assert pt["frequency"] == pytest.approx(math.sqrt(beta * (rho_h + sigma)), rel=1e-8)
    assert pt["l1"] > 0  # subcritical (Kuznetsov 2004, example 5.4 on Lorenz)
    # the text form names the model and the value
    code, out, _ = run(capsys, "hopf", "--model", "lorenz.py", "--param", "rho",
                       "--from", "2", "--to", "30")
    assert code == 0 and "lorenz" in out and "24.7368" in out


def test_hopf_curve_of_a_lorenz_file_is_the_closed_form_curve(capsys, tmp_path):
    """rho = sigma (sigma + beta + 3) / (sigma - beta - 1), omega^2 = beta (rho + sigma)."""
    path = write(tmp_path, "lorenz.py", LORENZ)
    code, out, err = run(capsys, "hopf-curve", "--model", path, "--params", "rho,sigma",
                         "--range", "rho=2:60", "--range", "sigma=5:20", "--grid", "0",
                         "--out", str(tmp_path / "hc"), "--json")
    assert code == 0, err
    doc = json.loads(out)
    rho = np.array([p["rho"] for p in doc["points"]])
    sig = np.array([p["sigma"] for p in doc["points"]])
    om = np.array([p["frequency"] for p in doc["points"]])
    beta = 8.0 / 3.0
    assert len(rho) > 20 and np.ptp(sig) > 5.0
    assert np.allclose(rho, sig * (sig + beta + 3) / (sig - beta - 1), rtol=1e-8, atol=0)
    assert np.allclose(om, np.sqrt(beta * (rho + sig)), rtol=1e-8, atol=0)
    assert all(p["l1"] > 0 for p in doc["points"])
    code, _, err = run(capsys, "hopf-curve", "--model", path)  # no default plane for a file
    assert code == 2 and "--params" in err


def test_stability_of_a_user_model_is_its_hand_computed_eigenvalues(capsys, tmp_path):
    path = write(tmp_path, "nf.py", NORMAL_FORM)
    code, out, err = run(capsys, "stability", "--model", path, "--set", "a=-0.5", "--json")
    assert code == 0, err
    doc = json.loads(out)
    eig = sorted((complex(*z) for z in doc["eigenvalues"]), key=lambda z: z.imag)
    assert np.allclose(eig, [-0.5 - 2.0j, -0.5 + 2.0j], rtol=0, atol=1e-12)
    assert doc["stable"] is True and doc["parameters"] == {"a": -0.5, "w": 2.0}
    assert doc["state_names"] == ["x", "y"] and np.allclose(doc["equilibrium"], 0.0)
    code, out, _ = run(capsys, "stability", "--model", path, "--set", "a=0.25")
    assert code == 0 and "UNSTABLE" in out and "nf" in out


def test_root_locus_of_a_user_model(capsys, tmp_path):
    path = write(tmp_path, "nf.py", NORMAL_FORM)
    code, out, err = run(capsys, "root-locus", "--model", path, "--param", "a", "--from",
                         "-1", "--to", "0.5", "--steps", "15", "--out", str(tmp_path / "rl"),
                         "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert np.allclose(doc["max_real_part"], np.linspace(-1, 0.5, 15), atol=1e-12)
    assert doc["stability_changes"] == [pytest.approx(0.0, abs=1e-12)]


def test_simulate_a_user_model_follows_the_exact_solution(capsys, tmp_path):
    path = write(tmp_path, "decay.py", DECAY)
    code, out, err = run(capsys, "simulate", "--model", path, "--x0", "2.0", "--t", "1.0",
                         "--set", "k=0.7", "--n-save", "11", "--out",
                         str(tmp_path / "h.csv"), "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["final_state"]["u"] == pytest.approx(2.0 * math.exp(-0.7), rel=1e-6)
    hist = np.loadtxt(tmp_path / "h.csv", delimiter=",", skiprows=1)
    assert np.allclose(hist[:, 1], 2.0 * np.exp(-0.7 * hist[:, 0]), rtol=1e-6)


@pytest.mark.slow
def test_cycles_of_a_user_model_have_the_normal_form_amplitude_and_period(capsys, tmp_path):
    """Supercritical Hopf normal form: cycles r = sqrt(a), period 2 pi / w, multipliers
    {1, exp(-2 a T)}."""
    path = write(tmp_path, "nf.py", NORMAL_FORM)
    code, out, err = run(capsys, "cycles", "--model", path, "--param", "a", "--from", "-0.5",
                         "--to", "0.5", "--ntst", "20", "--max-steps", "12", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["hopf_points"][0]["a"] == pytest.approx(0.0, abs=1e-10)
    rows = doc["branches"][0]["branch"]
    assert len(rows) > 3
    for r in rows[1:]:
        assert r["period"] == pytest.approx(2 * math.pi / 2.0, rel=1e-8)
        assert r["stable"] and r["trivial_multiplier_error"] < 1e-8


# ---------------------------------------------------------------------------------------
# bad model files: exit code 2, one line naming the file, never a traceback
# ---------------------------------------------------------------------------------------
BAD_FILES = {
    "syntax": ("STATES = ['x']\ndef rhs(x, p)\n    return x\n", "syntax error at line 2"),
    "import_error": ("import no_such_module_xyz\nSTATES = ['x']\n",
                     "error while loading (line 1): ModuleNotFoundError"),
    "raises": ("STATES = ['x']\nPARAMS = {}\nraise RuntimeError('boom')\n",
               "error while loading (line 3): RuntimeError: boom"),
    "no_rhs": ("STATES = ['x']\nPARAMS = {'a': 1.0}\n", "missing rhs"),
    "no_states_params": ("def rhs(x, p):\n    return x\n", "missing STATES, PARAMS"),
    "states_type": ("STATES = 'xy'\nPARAMS = {}\ndef rhs(x, p):\n    return x\n",
                    "STATES must be a non-empty list"),
    "params_type": ("STATES = ['x']\nPARAMS = [1.0]\ndef rhs(x, p):\n    return x\n",
                    "PARAMS must be a dict"),
    "params_value": ("STATES = ['x']\nPARAMS = {'a': 'big'}\ndef rhs(x, p):\n    return x\n",
                     "PARAMS['a'] = 'big' must be a finite number"),
    "rhs_not_callable": ("STATES = ['x']\nPARAMS = {}\nrhs = 3\n", "rhs must be a function"),
    "uses_numpy": ("import numpy as np\nSTATES = ['x']\nPARAMS = {'a': 1.0}\n"
                   "def rhs(x, p):\n    return np.sin(x)\n",
                   "rhs is not JAX-traceable (line 5): TracerArrayConversionError"),
    "uses_float": ("STATES = ['x']\nPARAMS = {'a': 1.0}\n"
                   "def rhs(x, p):\n    return x * float(p['a'])\n",
                   "rhs is not JAX-traceable (line 4): ConcretizationTypeError"),
    "python_if": ("STATES = ['x']\nPARAMS = {'a': 1.0}\n"
                  "def rhs(x, p):\n    if x[0] > 0:\n        return -x\n    return x\n",
                  "rhs is not JAX-traceable (line 4): TracerBoolConversionError"),
    "wrong_shape": ("import jax.numpy as jnp\nSTATES = ['x', 'y']\nPARAMS = {}\n"
                    "def rhs(x, p):\n    return jnp.array([x[0], x[1], 0.0])\n",
                    "rhs returns shape (3,), expected (2,)"),
    "not_finite": ("STATES = ['x']\nPARAMS = {}\ndef rhs(x, p):\n    return 1.0 / x\n",
                   "rhs is not finite at X0"),
    "x0_length": ("STATES = ['x']\nPARAMS = {}\nX0 = [1.0, 2.0]\n"
                  "def rhs(x, p):\n    return -x\n", "X0 has 2 entries, expected 1"),
    "scales": ("STATES = ['x', 'y']\nPARAMS = {}\nSCALES = [1.0, 0.0]\n"
               "def rhs(x, p):\n    return -x\n", "SCALES must be positive"),
    "unknown_name": ("STATES = ['x']\nPARAMS = {}\ndef rhs(x, p):\n    return -x * p['k']\n",
                     "rhs failed at X0 and the default parameters (line 4): KeyError"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_model_file_is_one_clear_line_and_exit_code_2(capsys, tmp_path, case):
    text, expected = BAD_FILES[case]
    path = write(tmp_path, f"{case}.py", text)
    with pytest.raises(ModelFileError, match="model file .*" + case):
        load_model(path)
    code, out, err = run(capsys, "stability", "--model", path)
    assert code == 2
    # the console wraps long lines (even inside a path): compare without white space
    assert f"{case}.py" in "".join(err.split()), err
    assert "".join(expected.split()) in "".join(err.split()), err
    assert "Traceback" not in err + out


def test_missing_file_and_directory(capsys, tmp_path):
    code, _, err = run(capsys, "hopf", "--model", str(tmp_path / "nowhere.py"), "--param", "a")
    flat = "".join(err.split())
    assert code == 2 and "nowhere.py:nosuchfile" in flat
    (tmp_path / "pkg.py").mkdir()
    code, _, err = run(capsys, "stability", "--model", str(tmp_path / "pkg.py"))
    assert code == 2 and "pkg.py:isadirectory" in "".join(err.split())
    assert "Traceback" not in err


def test_set_with_an_unknown_name_lists_the_valid_ones(capsys, tmp_path):
    path = write(tmp_path, "lorenz.py", LORENZ)
    code, _, err = run(capsys, "stability", "--model", path, "--set", "r=20")
    msg = " ".join(err.split())
    assert code == 2 and "'r'" in msg and "valid names: sigma, rho, beta" in msg
    code, _, err = run(capsys, "stability", "--model", path, "--set", "rho=abc")
    assert code == 2 and "must be a number" in err


@pytest.mark.parametrize("command", ["index", "map", "report", "reproduce"])
def test_maglev_only_commands_refuse_a_model_file(capsys, tmp_path, command):
    path = write(tmp_path, "lorenz.py", LORENZ)
    extra = ["--x", "omega1=40:190:3", "--y", "sigma=2e-4:6e-4:3"] if command == "map" else []
    code, _, err = run(capsys, command, *extra, "--model", path)
    msg = " ".join(err.split())
    assert code == 2 and "works on the maglev models only" in msg
    assert "Traceback" not in err


def test_builtin_models_still_resolve(capsys):
    code, out, _ = run(capsys, "stability", "--model", "unit", "--json")
    assert code == 0 and json.loads(out)["model"] == "unit"
    code, _, err = run(capsys, "stability", "--model", "lorenz")
    assert code == 2 and "a model file ending in .py" in " ".join(err.split())


# ---------------------------------------------------------------------------------------
# the guard around a model file (issue 24); more cases in tests/bad_inputs.py
# ---------------------------------------------------------------------------------------
def test_loading_guard_restores_the_process_and_names_the_exit(tmp_path):
    """A file that calls sys.exit while loading is a ModelFileError naming the call and its
    line; the stand-in for os._exit and the redirection of stdout end with the load."""
    import os
    import sys

    exit_before, stdout_before = os._exit, sys.stdout
    path = write(tmp_path, "quits.py", "STATES = ['x']\nPARAMS = {}\nimport sys\nsys.exit(3)\n")
    with pytest.raises(ModelFileError, match=r"called sys.exit\(3\) \(line 4\)"):
        load_model(path)
    assert os._exit is exit_before and sys.stdout is stdout_before
    with pytest.raises(ModelFileError, match="did not finish within 0.5 s"):
        load_model(write(tmp_path, "spins.py", "while True:\n    pass\n"), timeout=0.5)
    assert os._exit is exit_before and sys.stdout is stdout_before


def test_numerical_problem_names_an_overflow_not_a_verdict(tmp_path):
    m = load_model(write(tmp_path, "lorenz.py", LORENZ))
    assert m.numerical_problem() is None and m.numerical_problem({"rho": 20.0}) is None
    text = m.numerical_problem({"rho": 1e308})
    assert text.startswith("the right-hand side is not finite at X0 with rho = 1e+308")
    # a field that is finite at X0 (k sin 0 = 0) with an overflowing Jacobian (2 k)
    head = "import jax.numpy as jnp\nSTATES = ['x']\nPARAMS = {'k': 1.0}\n"
    m = load_model(write(tmp_path, "j.py", head + "def rhs(x, p):\n"
                         "    return p['k'] * (jnp.sin(x) * 2.0)\n"))
    assert m.numerical_problem({"k": 1e308}).startswith("the Jacobian of the right-hand side "
                                                        "is not finite at X0 with k = 1e+308")


def test_complex_and_locally_undefined_fields_are_refused(tmp_path):
    head = "import jax.numpy as jnp\nSTATES = ['x', 'y']\nPARAMS = {'a': 1.0}\n"
    with pytest.raises(ModelFileError, match="returns complex numbers"):
        load_model(write(tmp_path, "c.py", head + "def rhs(x, p):\n    return 1j * x\n"))
    # finite at X0 = 0 only: the log of a negative number is NaN everywhere else
    with pytest.raises(ModelFileError, match="not finite near X0"):
        load_model(write(tmp_path, "n.py", head + "def rhs(x, p):\n"
                         "    return jnp.where(x == 0.0, 0.0, jnp.log(-jnp.abs(x)))\n"))
    # a genuine singularity a little away from X0 is fine (the neighbourhood is small)
    ok = load_model(write(tmp_path, "s.py", head + "X0 = [1.0, 1.0]\ndef rhs(x, p):\n"
                          "    return 1.0 / (x - 0.999) - 1000.0\n"))
    assert ok.system().dim == 2


def test_a_run_that_blows_up_is_a_failure_with_exit_code_1(capsys, tmp_path):
    # x' = a x^3 from x = 1 reaches infinity at t = 1 / (2 a) = 0.01 s: the integrator
    # cannot pass it, and the command says so (exit 1), text and JSON alike
    path = tmp_path / "blow.py"
    path.write_text('STATES = ["x"]\nPARAMS = {"a": 50.0}\nX0 = [1.0]\n\n\n'
                    'def rhs(x, p):\n    return [p["a"] * x[0] ** 3]\n')
    for extra in ((), ("--json",)):
        code = main(["simulate", "--model", str(path), "--t", "1", *extra])
        out = capsys.readouterr()
        assert code == 1, out.err
        assert "error: the simulation failed at t = 0.01" in out.err
    doc = json.loads(out.out)
    assert doc["outcome"] == "failed"
    assert doc["final_time"] == pytest.approx(1 / (2 * 50.0), rel=1e-6)
