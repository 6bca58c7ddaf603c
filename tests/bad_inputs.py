"""Bad inputs on the surfaces of issue 24 — user model files, restart files, counts and
percentages, design ranges, the environment — each with the outcome it must have.

Run as a script, every case runs in a fresh process and the outcomes are summarised by class
of input and by how each ended::

    PYTHONPATH=src python tests/bad_inputs.py            # all cases
    PYTHONPATH=src python tests/bad_inputs.py --list     # the cases, without running them

Imported by ``tests/test_hardening.py``, which runs the cases that need a process of their own
(exits, endless loops, the environment) in one and the others in-process.

Every case expects one of: a refusal (exit code 2, one ``error:`` line naming the option or
file, the value and the rule), or a result with one ``warning:`` line (exit code 0) where the
input is a usable but costly environment. Never exit 0 with no output, never a traceback,
never a hang.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

# ----------------------------------------------------------------------------------------
# fixture files
# ----------------------------------------------------------------------------------------
_HEAD = 'import jax.numpy as jnp\nSTATES = ["x", "y"]\nPARAMS = {"a": -0.3, "w": 2.0}\n'
_RHS = ("def rhs(x, p):\n    r2 = x[0] ** 2 + x[1] ** 2\n"
        "    return jnp.array([p['a'] * x[0] - p['w'] * x[1] - x[0] * r2,\n"
        "                      p['w'] * x[0] + p['a'] * x[1] - x[1] * r2])\n")
LORENZ = '''import jax.numpy as jnp

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
'''

MODEL_FILES: dict[str, bytes] = {
    "good.py": (_HEAD + _RHS).encode(),
    "dde_past_end.py": (b'STATES = ["x"]\nPARAMS = {"a": 2.0, "tau": 0.1}\nDELAYS = ("tau",)\n'
                        b'\n\ndef rhs(x, xd, p):\n    return -p["a"] * xd[1]\n'),
    "lorenz.py": LORENZ.encode(),
    "exit0.py": (_HEAD + "import sys\nsys.exit(0)\n" + _RHS).encode(),
    "exit3.py": (_HEAD + "import sys\nsys.exit(3)\n" + _RHS).encode(),
    "osexit.py": (_HEAD + "import os\nos._exit(0)\n" + _RHS).encode(),
    "osexit_rhs.py": (_HEAD + "def rhs(x, p):\n    import os\n    os._exit(0)\n").encode(),
    "exit_rhs.py": (_HEAD + "def rhs(x, p):\n    raise SystemExit(0)\n").encode(),
    "loop.py": (_HEAD + "while True:\n    pass\n" + _RHS).encode(),
    "loop_rhs.py": (_HEAD + "def rhs(x, p):\n    while True:\n        pass\n").encode(),
    # an endless loop that spends half its time in a garbage-collection callback, where
    # Python ignores an exception raised by a signal handler (as in JAX's callback)
    "loop_gc.py": (_HEAD + "import gc\nimport time\n\n\ndef _cb(phase, info):\n"
                   "    time.sleep(0.001)\n\n\ngc.callbacks.append(_cb)\n\n\n"
                   "def rhs(x, p):\n    while True:\n        gc.collect(0)\n"
                   "        sum(range(20000))\n").encode(),
    "prints.py": (_HEAD + "print('hello from the model file')\n"
                  + _RHS.replace("    r2 =", "    print('tracing rhs')\n    r2 =")).encode(),
    "complex.py": (_HEAD + "def rhs(x, p):\n    return (1 + 1j) * x\n").encode(),
    "nan_off_x0.py": (_HEAD + "X0 = [1.0, 2.0]\ndef rhs(x, p):\n"
                      "    at = jnp.all(x == jnp.array([1.0, 2.0]))\n"
                      "    return jnp.where(at, jnp.array([1.0, 2.0]) - x, jnp.nan)\n").encode(),
    "jac_inf.py": (b'import jax.numpy as jnp\nSTATES = ["x"]\nPARAMS = {}\n'
                   b"def rhs(x, p):\n    return jnp.sqrt(x)\n"),
    "bom.py": b"\xef\xbb\xbf" + (_HEAD + _RHS).encode(),
    "nul.py": (_HEAD + _RHS).encode().replace(b"r2 = x", b"r2 = \x00x", 1),
    "latin1.py": b"# caf\xe9\n" + (_HEAD + _RHS).encode(),
    "greek.py": LORENZ.replace('"sigma"', '"\u03c3"').replace('"rho"', '"\u03c1"')
                      .replace('"beta"', '"\u03b2"').encode(),
    "nested_x0.py": (b'import jax.numpy as jnp\nSTATES = ["x", "y", "z"]\nPARAMS = {}\n'
                     b"X0 = [[8, 8, 27]]\ndef rhs(x, p):\n    return -x\n"),
}


#: --config files with a bad [irregularity] table (issue 33): the same rules as the option
IRREGULARITY_TOMLS: dict[str, str] = {
    "irr_negative.toml": ('kD = 120\n[irregularity]\nkind = "sine"\nwavelength = 25.0\n'
                          'amplitude = -1e-3\n'),
    "irr_nan.toml": '[irregularity]\nkind = "sine"\nwavelength = nan\namplitude = 1e-3\n',
    "irr_inf.toml": '[irregularity]\nkind = "camber"\namplitude = inf\n',
    "irr_seed.toml": '[irregularity]\nkind = "random"\nclass = "low"\nseeds = 1.5\n',
    "irr_seed_text.toml": '[irregularity]\nkind = "random"\nclass = "low"\nseed0 = "one"\n',
    "irr_kind.toml": '[irregularity]\nkind = "bumps"\nheight = 1.0\n',
    "irr_field.toml": '[irregularity]\nkind = "joint"\nstep = 1e-3\nsize = 2e-3\n',
    "irr_no_kind.toml": '[irregularity]\namplitude = 1e-3\n',
    "irr_two.toml": ('[[irregularity]]\nkind = "joint"\nstep = 1e-3\n'
                     '[[irregularity]]\nkind = "camber"\namplitude = 1e-3\n'),
    "irr_not_table.toml": 'irregularity = "joint:step=1e-3"\n',
}


def _fake_dataset(kind: str):
    import numpy as np
    import xarray as xr

    if kind == "map":
        return xr.Dataset({"chi": (("sigma", "omega1"), np.ones((2, 3))),
                           "stable": (("sigma", "omega1"), np.ones((2, 3), np.int8))},
                          coords={"sigma": [3e-4, 4e-4], "omega1": [100.0, 110.0, 120.0]})
    return xr.Dataset({"gap_deviation": (("time",), np.zeros(5))},
                      coords={"time": np.linspace(0, 1, 5)})


def damaged_branches(branch: Path, folder: Path) -> dict[str, Path]:
    """Damaged copies of a saved cycle branch (model A), one per way a file goes wrong."""
    import numpy as np
    import xarray as xr

    ds = xr.load_dataset(branch, engine="h5netcdf")
    out: dict[str, Path] = {}

    def save(name: str, d) -> None:
        path = folder / f"{name}.nc"
        d.to_netcdf(path, engine="h5netcdf")
        out[name] = path

    d = ds.copy(deep=True)
    d["r_states"][:] = np.nan
    save("all_nan", d)
    for name, value in (("zero_period", 0.0), ("negative_period", -0.05)):
        d = ds.copy(deep=True)
        d["r_period"][:] = value
        save(name, d)
    save("no_r_states", ds.drop_vars("r_states"))
    save("no_hopf_p", ds.drop_vars("hopf_p"))
    d = ds.copy(deep=True)
    d["r_states"] = (("point", "state", "node"), np.swapaxes(ds["r_states"].values, 1, 2))
    save("wrong_shape", d)
    for name, attr, value in (("param_nowhere", "param", "nope"),
                              ("param_other", "param", "kD"),
                              ("frequency_zero", "hopf_frequency", 0.0),
                              ("hopf_value_text", "hopf_value", "abc")):
        d = ds.copy(deep=True)
        d.attrs[attr] = value
        save(name, d)
    d = ds.copy(deep=True)
    del d.attrs["param"]
    save("no_param_attr", d)
    d = ds.assign_coords(state=[f"s{k}" for k in range(ds.sizes["state"])])
    save("other_model", d)
    _fake_dataset("map").to_netcdf(folder / "map.nc", engine="h5netcdf")
    out["map"] = folder / "map.nc"
    _fake_dataset("sim").to_netcdf(folder / "sim.nc", engine="h5netcdf")
    out["sim"] = folder / "sim.nc"
    data = branch.read_bytes()
    (folder / "truncated.nc").write_bytes(data[: len(data) // 2])
    out["truncated"] = folder / "truncated.nc"
    (folder / "empty.nc").write_bytes(b"")
    out["empty"] = folder / "empty.nc"
    (folder / "text.nc").write_text("not a netCDF file\n")
    out["text"] = folder / "text.nc"
    return out


def make_fixtures(folder: Path, branch: Path | None = None) -> None:
    """Write the model files (and, given a saved model-A branch, its damaged copies) into
    ``folder``; case arguments refer to them as {dir}/NAME."""
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in MODEL_FILES.items():
        (folder / name).write_bytes(data)
    fifo = folder / "fifo.py"
    if not fifo.exists() and hasattr(os, "mkfifo"):
        os.mkfifo(fifo)
    zero = folder / "zero.py"
    if not zero.is_symlink():
        zero.symlink_to("/dev/zero")
    (folder / "rfifo.nc").unlink(missing_ok=True)
    if hasattr(os, "mkfifo"):
        os.mkfifo(folder / "rfifo.nc")
    (folder / "model.toml").write_text("kD = 120\n")
    for name, text in IRREGULARITY_TOMLS.items():
        (folder / name).write_text(text)
    import h5py
    import numpy as np

    with h5py.File(folder / "plain.h5", "w") as fh:  # HDF5, but not netCDF
        fh["a"] = np.arange(3.0)
    if branch is not None:
        damaged_branches(branch, folder)


def make_branch(folder: Path) -> Path:
    """A saved model-A cycle branch (the command the restart cases continue), in a fresh
    process; returns the .nc file."""
    out = folder / "branch"
    subprocess.run([sys.executable, "-m", "maglev_match.cli", *BRANCH_ARGS, "--out", str(out)],
                   check=True, capture_output=True, text=True, timeout=600)
    return out / "cycles_unit_sigma.nc"


#: The saved branch the restart cases use (small: 20 mesh intervals, 4 steps).
BRANCH_ARGS = ("cycles", "--param", "sigma", "--at", "omega1=100", "--preset", "alpha1",
               "--from", "5e-4", "--to", "2e-3", "--scan", "5", "--ntst", "20",
               "--max-steps", "4", "--json")


# ----------------------------------------------------------------------------------------
# the cases
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    """One bad input: the command line ({dir} = the fixture folder), the exit code it must
    give, a text its error or warning line must contain, and its environment."""

    name: str
    group: str
    argv: tuple[str, ...]
    code: int
    text: str
    env: dict[str, str] = field(default_factory=dict)
    fresh: bool = False  # needs a process of its own (exits, hangs, the environment)
    slow: bool = False  # a whole index or search: in the script only, not in the tests
    json_stdout: bool = False  # stdout must be exactly one JSON object
    needs_branch: bool = False

    def args(self, folder: Path) -> list[str]:
        return [a.replace("{dir}", str(folder)) for a in self.argv]


def _m(name, file, extra, code, text, **kw) -> Case:
    return Case(name, "model file", ("stability", "--model", f"{{dir}}/{file}", *extra), code,
                text, **kw)


def _r(name, extra, code, text, file="branch/cycles_unit_sigma.nc", command="cycles",
       label=("--label", "P1")) -> Case:
    return Case(name, "restart file", (command, "--restart", f"{{dir}}/{file}", *label,
                                       "--max-steps", "1", *extra), code, text,
                needs_branch=True)


MC = ("--scatter", "EI=3", "--monte-carlo", "4", "--no-simulation")
DESIGN = ("design", "--vary", "EI=5e9:4e10", "--minimize", "EI")
TIMEOUT_ENV = {"MAGLEV_MATCH_MODEL_TIMEOUT": "2"}

CASES: tuple[Case, ...] = (
    # ---- user model files: loading under guard
    _m("sys.exit(0) at import", "exit0.py", (), 2, "called sys.exit(0)"),
    _m("sys.exit(3) at import", "exit3.py", (), 2, "called sys.exit(3)"),
    _m("os._exit(0) at import", "osexit.py", (), 2, "called os._exit(0)", fresh=True),
    _m("os._exit(0) in rhs", "osexit_rhs.py", (), 2, "rhs called os._exit(0)", fresh=True),
    _m("SystemExit in rhs", "exit_rhs.py", (), 2, "rhs called sys.exit(0)"),
    _m("endless loop at import", "loop.py", (), 2, "did not finish within 2 s",
       env=TIMEOUT_ENV, fresh=True),
    _m("endless loop in rhs", "loop_rhs.py", (), 2, "rhs did not finish within 2 s",
       env=TIMEOUT_ENV, fresh=True),
    _m("endless loop in rhs through a gc callback", "loop_gc.py", (), 2,
       "rhs did not finish within 2 s", env=TIMEOUT_ENV, fresh=True),
    _m("print() at import and in rhs, --json", "prints.py", ("--json",), 0, "",
       json_stdout=True),
    _m("complex right-hand side", "complex.py", (), 2, "returns complex numbers"),
    _m("NaN everywhere but X0", "nan_off_x0.py", (), 2, "not finite near X0"),
    _m("Jacobian infinite at X0", "jac_inf.py", (), 2, "Jacobian of rhs is not finite"),
    _m("UTF-8 byte-order mark", "bom.py", ("--json",), 0, "", json_stdout=True),
    _m("NUL byte", "nul.py", (), 2, "NUL byte at line 5"),
    _m("Latin-1 byte without a coding line", "latin1.py", (), 2,
       "is not UTF-8 text (byte 0xe9 at line 1)"),
    _m("nested X0", "nested_x0.py", (), 2, "nested list of shape (1, 3)"),
    _m("delay model reading xd[1] with one delay", "dde_past_end.py", (), 2,
       "rhs reads past the delayed states"),
    _m("a FIFO named .py", "fifo.py", (), 2, "is a FIFO"),
    _m("a link to /dev/zero", "zero.py", (), 2, "is a device"),
    _m("--set overflows the right-hand side", "lorenz.py", ("--set", "rho=1e308"), 2,
       "numerical failure"),
    _m("--preset on a user model", "lorenz.py", ("--preset", "alpha1"), 2,
       "--preset: maglev parameter presets do not apply"),
    Case("simulate --x5 on a user model", "options",
         ("simulate", "--model", "{dir}/lorenz.py", "--x5", "-1e-3"), 2, "--x5: applies to"),
    Case("simulate --initial pressed on a user model", "options",
         ("simulate", "--model", "{dir}/lorenz.py", "--initial", "pressed"), 2, "--initial"),
    Case("simulate --q1 on a user model", "options",
         ("simulate", "--model", "{dir}/lorenz.py", "--q1", "1e-3"), 2, "--q1"),
    Case("simulate --no-limits on a user model", "options",
         ("simulate", "--model", "{dir}/lorenz.py", "--no-limits"), 2, "--limits/--no-limits"),
    Case("simulate --plot on a user model", "options",
         ("simulate", "--model", "{dir}/lorenz.py", "--plot", "{dir}/s.png"), 2, "--plot"),
    Case("cycles --ignore-current on a user model", "options",
         ("cycles", "--model", "{dir}/good.py", "--param", "a", "--ignore-current"), 2,
         "--ignore-current"),
    Case("cycles --model FILE --restart of a model-A branch", "options",
         ("cycles", "--model", "{dir}/good.py", "--param", "a", "--restart",
          "{dir}/branch/cycles_unit_sigma.nc", "--label", "P1"), 2, "not for model",
         needs_branch=True),
    Case("sensitivity --model FILE.py", "options",
         ("sensitivity", "--model", "{dir}/lorenz.py"), 2, "maglev models 'unit' and "
         "'vehicle' only"),
    Case("design --model FILE.py", "options",
         (*DESIGN, "--model", "{dir}/lorenz.py"), 2, "maglev models 'unit' and 'vehicle'"),
    Case("hopf-curve --config on a user model", "options",
         ("hopf-curve", "--model", "{dir}/lorenz.py", "--params", "rho,sigma", "--config",
          "{dir}/model.toml"), 2, "--config"),
    # ---- restart files
    _r("all-NaN states", (), 2, "values are NaN or infinite", file="all_nan.nc"),
    _r("zero period", (), 2, "the period at 'P1' is 0 s", file="zero_period.nc"),
    _r("negative period", (), 2, "must be a finite number > 0", file="negative_period.nc"),
    _r("a variable dropped", (), 2, "lacks the variable 'r_states'", file="no_r_states.nc"),
    _r("the parameter vector dropped", (), 2, "lacks the variable 'hopf_p'",
       file="no_hopf_p.nc"),
    _r("states of another shape", (), 2, "has dimensions", file="wrong_shape.nc"),
    _r("param names no parameter", (), 2, "names no parameter", file="param_nowhere.nc"),
    _r("param names another parameter", (), 2, "inconsistent", file="param_other.nc"),
    _r("param attribute missing", (), 2, "attribute 'param' is missing",
       file="no_param_attr.nc"),
    _r("zero Hopf frequency", (), 2, "hopf_frequency = 0", file="frequency_zero.nc"),
    _r("Hopf value not a number", (), 2, "hopf_value", file="hopf_value_text.nc"),
    _r("another model's states", (), 2, "not for model", file="other_model.nc"),
    _r("a design map", (), 2, "it is a design map", file="map.nc"),
    _r("a simulation history", (), 2, "it is a simulation history", file="sim.nc"),
    _r("a truncated file", (), 2, "cannot be read as netCDF", file="truncated.nc"),
    _r("an empty file", (), 2, "not a netCDF file", file="empty.nc"),
    _r("a text file", (), 2, "not a netCDF file", file="text.nc"),
    _r("an HDF5 file that is not netCDF", (), 2, "not a saved cycle branch",
       file="plain.h5"),
    _r("a directory", (), 2, "is a directory", file="branch"),
    _r("a missing file", (), 2, "no such file", file="nowhere.nc"),
    _r("a FIFO", (), 2, "not a regular file", file="rfifo.nc"),
    _r("no --label", (), 2, "go together", label=()),
    _r("an unknown label", (), 2, "--label Q7: ", label=("--label", "Q7")),
    _r("--set of the continued parameter", ("--set", "sigma=3e-4"), 2,
       "sigma is the parameter the saved branch is continued in"),
    _r("--set of another value", ("--set", "kD=100"), 2, "kD = 100 given, 150 saved"),
    _r("--model vehicle on a model-A branch", ("--model", "vehicle"), 2, "not for model"),
    _r("--from on a restart", ("--from", "1e-4"), 2, "searches no Hopf point"),
    _r("--all on a restart", ("--all",), 2, "--all: a restart"),
    _r("--scan on a restart", ("--scan", "10"), 2, "--scan: a restart"),
    _r("--ntst other than saved", ("--ntst", "40"), 2, "goes on with the saved mesh"),
    _r("--param of beam data", ("--param", "L"), 2, "not along beam"),
    _r("--param unknown", ("--param", "nope"), 2, "no such parameter"),
    Case("hopf-curve --restart of a cycle branch", "restart file",
         ("hopf-curve", "--restart", "{dir}/branch/cycles_unit_sigma.nc", "--label", "P1",
          "--grid", "0"), 2, "not a saved Hopf curve (it is saved cycle branch)",
         needs_branch=True),
    # ---- counts and percentages, checked before any work
    Case("--monte-carlo 99999999999999999999", "counts", ("index", *MC[:2], "--monte-carlo",
         "99999999999999999999", "--no-simulation"), 2, "--monte-carlo"),
    Case("--monte-carlo 1", "counts", ("index", *MC[:2], "--monte-carlo", "1"), 2,
         "--monte-carlo"),
    Case("index --workers -1", "counts", ("index", *MC, "--workers", "-1"), 2, "--workers"),
    Case("sensitivity --workers -1", "counts", ("sensitivity", *MC[:4], "--workers", "-1"), 2,
         "--workers"),
    Case("design --workers 100000", "counts", (*DESIGN, *MC[:4], "--workers", "100000"), 2,
         "--workers"),
    Case("map --workers -1", "counts", ("map", "--x", "omega1=40:190:3", "--y",
                                        "sigma=2e-4:6e-4:3", "--workers", "-1"), 2,
         "--workers"),
    Case("map --x tau=0:1:2 (beyond the discretisation)", "counts",
         ("map", "--x", "tau=0:1:2", "--y", "kD=100:150:2", "--workers", "0"), 2,
         "the delay must be at most"),
    Case("--seed -1", "counts", ("index", *MC, "--seed", "-1"), 2, "--seed"),
    Case("--seed 2**40", "counts", ("index", *MC, "--seed", str(2**40)), 2, "--seed"),
    Case("--scatter EI=1e6", "counts", ("index", "--scatter", "EI=1e6", "--no-simulation"), 2,
         "the percentage must be in [0, 50]"),
    Case("--scatter EI=-1", "counts", ("index", "--scatter", "EI=-1", "--no-simulation"), 2,
         "the percentage must be in [0, 50]"),
    Case("--scatter EI=nan", "counts", ("index", "--scatter", "EI=nan", "--no-simulation"), 2,
         "the percentage must be in [0, 50]"),
    Case("--scatter twice", "counts", ("index", "--scatter", "EI=3", "--scatter", "EI=4",
                                       "--no-simulation"), 2, "given twice"),
    Case("--workers without --monte-carlo", "options", ("index", "--no-simulation",
                                                        "--workers", "2"), 2,
         "applies to a Monte Carlo study only"),
    Case("--resume without --monte-carlo", "options", ("sensitivity", "--resume"), 2,
         "--resume: applies to a Monte Carlo study only"),
    Case("design --grid 1000", "counts", (*DESIGN, "--grid", "1000"), 2, "--grid"),
    Case("design --starts 0", "counts", (*DESIGN, "--starts", "0"), 2, "--starts"),
    Case("design --starts 100000", "counts", (*DESIGN, "--starts", "100000"), 2, "--starts"),
    # ---- design ranges
    Case("design --vary g", "design", ("design", "--vary", "g=1:20", "--maximize", "chi"), 2,
         "gravity is a constant of nature"),
    Case("design --vary mu0", "design", ("design", "--vary", "mu0=1e-7:1e-6", "--maximize",
                                         "chi"), 2, "permeability is a constant"),
    Case("design --vary w0", "design", ("design", "--vary", "w0=1e-4:1e-3", "--maximize",
                                        "chi"), 2, "is derived"),
    Case("design --vary i0", "design", ("design", "--vary", "i0=20:30", "--maximize", "chi"),
         2, "is derived"),
    Case("design --vary a tiny sigma", "design", ("design", "--vary", "sigma=1e-300:1e-3",
                                                  "--maximize", "chi"), 2,
         "has no physical meaning"),
    # ---- the delay where it is not (yet) modelled, and its own rule (issue 31)
    Case("stability --set tau=1e-320", "delay", ("stability", "--set", "tau=1e-320"), 2,
         "must be 0 (no delay) or at least 1e-09 s"),
    Case("speed --set tau=0.5", "delay", ("speed", "--set", "tau=0.5", "--workers", "0"), 2,
         "the delay's discretisation resolves at most"),
    Case("speed --set tau=0.05 (beyond the discretisation at speed)", "delay",
         ("speed", "--set", "tau=0.05", "--from", "60", "--to", "60", "--workers", "0"), 2,
         "at 60 km/h the delay's discretisation resolves at most"),
    Case("simulate --speed with a delay", "delay", ("simulate", "--speed", "100", "--spans",
                                                    "2", "--set", "tau=0.001"), 2,
         "has no delay of the outer loop yet"),
    Case("sensitivity --set tau=0.001", "delay", ("sensitivity", "--set", "tau=0.001"), 2,
         "computed for the delay-free models only"),
    Case("index --scatter with a delay", "delay", ("index", "--set", "tau=0.001", "--scatter",
                                                   "kD=5"), 2,
         "computed for the delay-free models only"),
    Case("index --scatter tau", "delay", ("index", "--scatter", "tau=5"), 2,
         "the delay has no row in the sensitivity table"),
    Case("speed --from 1e-300 --to 1e-300", "counts", ("speed", "--from", "1e-300", "--to",
                                                        "1e-300", "--workers", "0"), 2,
         "must be 0 (standstill) or at least 1 km/h"),
    Case("speed --from 0.001 --to 0.001", "counts", ("speed", "--from", "0.001", "--to",
                                                      "0.001", "--workers", "0"), 2,
         "must be 0 (standstill) or at least 1 km/h"),
    Case("simulate --speed 1e-6", "counts", ("simulate", "--speed", "1e-6"), 2,
         "--speed"),
    Case("cycles --param tau --to -0.01", "delay", ("cycles", "--param", "tau", "--to",
                                                    "-0.01"), 2,
         "tau is a delay: the search range must lie at or above 0"),
    Case("hopf-curve --range tau=nan:0.01", "options", ("hopf-curve", "--params", "omega1,tau",
                                                         "--range", "tau=nan:0.01"), 2,
         "FROM and TO must be finite numbers"),
    Case("--set name with a zero-width space", "options", ("stability", "--set",
                                                           "k\u200bD=1"), 2,
         "'k\\u200bD'"),
    Case("map over a model-B quantity", "options", ("map", "--x", "omega1=120:140:2", "--y",
                                                    "s=0.5:1.5:2", "--workers", "0"), 2,
         "changes no parameter of model 'unit' over the map"),
    Case("map over L with omega1 and sigma set", "options", (
        "map", "--preset", "alpha1", "--x", "L=15:20:2", "--y", "kD=100:150:2", "--workers",
        "0"), 2, "set explicitly override it"),
    Case("map --model vehicle", "options", ("map", "--x", "omega1=120:140:2", "--y",
                                            "sigma=3e-4:4e-4:2", "--model", "vehicle",
                                            "--workers", "0"), 2,
         "maps of the standstill index are computed for unit only"),
    # ---- guideway irregularities at speed (issue 33)
    Case("speed --irregularity with a negative amplitude", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--irregularity",
        "sine:wavelength=10,amplitude=-0.001"), 2, "must be >= 0"),
    Case("speed --irregularity of an unknown kind", "irregularity", (
        "speed", "--workers", "0", "--irregularity", "bumps:height=1"), 2,
         "the kind must be one of"),
    Case("simulate --speed --irregularity below the sampling", "irregularity", (
        "simulate", "--speed", "150", "--spans", "2", "--irregularity",
        "sine:wavelength=0.01,amplitude=0.001"), 2, "resolves at this speed"),
    Case("speed --irregular-spans 0", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--irregularity",
        "joint:step=0.001", "--irregular-spans", "0"), 2, "--irregular-spans"),
    Case("simulate --speed --irregularity nan", "irregularity", (
        "simulate", "--speed", "100", "--irregularity", "sine:wavelength=nan,amplitude=0.001"),
         2, "must be finite"),
    Case("simulate --speed --irregularity seeds=1.5", "irregularity", (
        "simulate", "--speed", "100", "--irregularity", "random:class=low,seeds=1.5"), 2,
         "must be a whole number"),
    # ---- the same rules in a --config file's [irregularity] table (issue 33)
    Case("speed --config: [irregularity] with a negative amplitude", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--config",
        "{dir}/irr_negative.toml"), 2, "[irregularity] amplitude' = -0.001: must be >= 0"),
    Case("speed --config: [irregularity] wavelength = nan", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--config",
        "{dir}/irr_nan.toml"), 2, "[irregularity] wavelength' = nan: must be finite"),
    Case("simulate --speed --config: [irregularity] amplitude = inf", "irregularity", (
        "simulate", "--speed", "100", "--config", "{dir}/irr_inf.toml"), 2,
         "[irregularity] amplitude' = inf: must be finite"),
    Case("speed --config: [irregularity] seeds = 1.5", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--config",
        "{dir}/irr_seed.toml"), 2, "[irregularity] seeds' = 1.5: must be a whole number"),
    Case("speed --config: [irregularity] seed0 as text", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--config",
        "{dir}/irr_seed_text.toml"), 2,
         "[irregularity] seed0' = 'one': must be a whole number"),
    Case("speed --config: [irregularity] of an unknown kind", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--config",
        "{dir}/irr_kind.toml"), 2,
         "[irregularity] kind' = 'bumps': the kind must be one of sine, joint"),
    Case("speed --config: [irregularity] with an unknown field", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--config",
        "{dir}/irr_field.toml"), 2,
         "[irregularity] size' = 0.002: unknown field: 'joint' takes kind, step"),
    Case("speed --config: [irregularity] without a kind", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--config",
        "{dir}/irr_no_kind.toml"), 2, "[irregularity] kind' = None: missing"),
    Case("speed --config: two [[irregularity]] entries", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--config",
        "{dir}/irr_two.toml"), 2, "a run takes one guideway irregularity"),
    Case("speed --config: irregularity given as a string", "irregularity", (
        "speed", "--from", "60", "--to", "60", "--workers", "0", "--config",
        "{dir}/irr_not_table.toml"), 2, "[irregularity]' = 'joint:step=1e-3': must be a table"),
    Case("iso-curve chi=0", "options", ("iso-curve", "chi=0"), 2,
         "parameter 'TARGET' = 0.0: must be a finite number > 0"),
    Case("iso-curve chi=inf", "options", ("iso-curve", "chi=inf"), 2,
         "parameter 'TARGET' = inf: must be a finite number > 0"),
    Case("iso-curve --params EI,EI", "options", ("iso-curve", "chi=5", "--params", "EI,EI"),
         2, "parameter '--params' = 'EI,EI': the same parameter twice"),
    Case("iso-curve unknown parameter", "options", ("iso-curve", "chi=5", "--params",
                                                    "EI,kQ"), 2,
         "parameter '--params' = 'kQ': unknown parameter"),
    Case("iso-curve --range outside the valid range", "options", (
        "iso-curve", "chi=5", "--range", "kD=-5:10"), 2,
         "parameter '--range' = 'kD=-5:10': must lie inside the valid range of kD"),
    Case("iso-curve --model vehicle, a parameter not of the vehicle", "options", (
        "iso-curve", "chi=5", "--model", "vehicle", "--params", "EI,sigma"), 2,
         "parameter '--params' = 'sigma': changes no parameter of model 'vehicle'"),
    Case("iso-curve --model FILE.py", "options", (
        "iso-curve", "chi=5", "--model", "{dir}/good.py"), 2,
         "iso-chi curves are computed for the maglev models unit and vehicle"),
    # ---- the environment (a usable run with one line naming the variable)
    Case("JAX_PLATFORMS=gpu", "environment", ("stability", "--json"), 0,
         "JAX_PLATFORMS=gpu", env={"JAX_PLATFORMS": "gpu"}, fresh=True, json_stdout=True),
    Case("unwritable cache", "environment", ("stability", "--json"), 0,
         "MAGLEV_MATCH_CACHE=/proc/maglev-match-cache", fresh=True, json_stdout=True,
         env={"MAGLEV_MATCH_CACHE": "/proc/maglev-match-cache"}),
    Case("PYTHONIOENCODING=ascii", "environment", ("stability", "--model",
                                                    "{dir}/greek.py"), 0,
         "PYTHONIOENCODING=ascii", env={"PYTHONIOENCODING": "ascii"}, fresh=True),
    Case("PYTHONIOENCODING=ascii, index", "environment", ("index", "--no-simulation"), 0,
         "PYTHONIOENCODING=ascii", env={"PYTHONIOENCODING": "ascii"}, fresh=True, slow=True),
    Case("PYTHONIOENCODING=ascii, design", "environment",
         ("design", "--vary", "kD=120:180", "--maximize", "chi", "--grid", "2", "--starts",
          "1", "--out", "{dir}/design"), 0, "PYTHONIOENCODING=ascii",
         env={"PYTHONIOENCODING": "ascii"}, fresh=True, slow=True),
)


# ----------------------------------------------------------------------------------------
# running and judging
# ----------------------------------------------------------------------------------------
PROGRESS_PREFIX = "maglev-match "


def error_lines(err: str) -> list[str]:
    """The lines of stderr that are not progress lines (and not a model file's own
    printing, which goes to stderr on purpose)."""
    return [ln for ln in err.splitlines() if ln.strip() and not ln.startswith(PROGRESS_PREFIX)
            and ("error:" in ln or "warning:" in ln or "Traceback" in ln or "File " in ln)]


def judge(case: Case, code: int | None, out: str, err: str) -> str:
    """How a case ended: 'as expected' or what went wrong."""
    if code is None:
        return "hang"
    if code < 0:
        return f"crash (signal {-code})"
    if "Traceback" in err or "Traceback" in out:
        return "traceback"
    lines = error_lines(err)
    if code == 0 and case.code != 0:
        return "exit 0 after a failure" if not out.strip() else "silent answer"
    if code != case.code:
        return f"exit {code} instead of {case.code}"
    if case.code == 2:
        errors = [ln for ln in lines if "error:" in ln]
        if len(errors) != 1:
            return f"{len(errors)} error lines"
        if case.text and case.text not in errors[0]:
            return "misleading message"
    elif case.text and not any(case.text in ln for ln in lines):
        return "no line naming the variable"
    if case.json_stdout:
        try:
            json.loads(out)
        except ValueError:
            return "stdout is not one JSON object"
    return "as expected"


def run_fresh(case: Case, folder: Path, timeout: float = 300.0
              ) -> tuple[int | None, str, str]:
    """Run a case in a fresh process; (exit code or None on timeout, stdout, stderr)."""
    env = {**os.environ, **case.env}
    try:
        p = subprocess.run([sys.executable, "-m", "maglev_match.cli", *case.args(folder)],
                           capture_output=True, text=True, env=env, timeout=timeout,
                           cwd=folder)
    except subprocess.TimeoutExpired as exc:
        return None, str(exc.stdout or ""), str(exc.stderr or "")
    return p.returncode, p.stdout, p.stderr


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--list", action="store_true", help="list the cases and stop")
    ap.add_argument("--group", help="run only this group")
    ap.add_argument("--timeout", type=float, default=300.0)
    a = ap.parse_args(argv)
    cases = [c for c in CASES if a.group is None or c.group == a.group]
    if a.list:
        for c in cases:
            print(f"{c.group:14s} {c.name}: maglev-match {' '.join(c.argv)} -> exit {c.code}")
        return 0
    with tempfile.TemporaryDirectory(prefix="maglev-bad-inputs-") as tmp:
        folder = Path(tmp)
        make_fixtures(folder)
        branch = make_branch(folder) if any(c.needs_branch for c in cases) else None
        if branch is not None:
            damaged_branches(branch, folder)
        results: dict[str, Counter] = defaultdict(Counter)
        bad = []
        t0 = time.perf_counter()
        for c in cases:
            code, out, err = run_fresh(c, folder, a.timeout)
            verdict = judge(c, code, out, err)
            results[c.group][verdict] += 1
            if verdict != "as expected":
                bad.append((c, verdict, (error_lines(err) or err.splitlines() or [""])[-1]))
            print(f"{verdict:24s} {c.group:14s} {c.name}", flush=True)
        print(f"\n{len(cases)} bad inputs, each in a fresh process "
              f"({time.perf_counter() - t0:.0f} s):")
        for group, counts in results.items():
            n = sum(counts.values())
            print(f"  {group:14s} {n:3d}: " + ", ".join(f"{v} {k}" for k, v in counts.items()))
        for c, verdict, line in bad:
            print(f"  NOT AS EXPECTED: {c.name}: {verdict}: {line[:200]}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
