"""Start-up: answers that need no computation (``--version``, ``--help``, ``presets``, every
usage error) come without importing JAX, and the table of commands the program lists
without loading their modules is the program's real set of commands."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Runs the program in a fresh interpreter and reports its exit code and which heavy
# modules it imported.
PROBE = """
import contextlib, io, json, sys
from maglev_match.cli import main
out, err = io.StringIO(), io.StringIO()
with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
    code = main(sys.argv[1:])
heavy = sorted(m for m in ("jax", "scipy", "matplotlib", "xarray", "diffrax", "dask", "numpy",
                           "pydantic") if m in sys.modules)
print(json.dumps({"code": code, "heavy": heavy, "out": out.getvalue(), "err": err.getvalue()}))
"""


def _probe(*argv: str) -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT / "src"), *filter(None, [os.environ.get("PYTHONPATH")])]), COLUMNS="100")
    proc = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True,
                          text=True, env=env, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("argv, code", [
    (["--version"], 0),
    (["--help"], 0),
    (["presets"], 0),
    (["index", "--set", "nosuch=1"], 2),
    (["stability", "--set", "kD=-5"], 2),
    (["cycles", "--ntst", "2"], 2),
    (["simulate", "--t", "-1"], 2),
    (["hopf", "--from", "50", "--to", "40"], 2),
    (["map", "--x", "omega1=1:2"], 2),
    (["nosuchcommand"], 2),
    (["report", "--out", "r.txt"], 2),
    (["speed", "--from", "-1"], 2),
    (["design", "--vary", "g=1:20", "--maximize", "chi"], 2),
], ids=lambda v: " ".join(v) if isinstance(v, list) else str(v))
def test_answers_without_computing_do_not_import_jax(argv, code):
    r = _probe(*argv)
    assert r["code"] == code, r
    # NumPy (0.1 s) is allowed where a command's module needs it; the answers that touch no
    # command module, and the table of presets, import none of it.
    no_numpy = argv[0] in ("--version", "--help", "presets", "nosuchcommand")
    heavy = [m for m in r["heavy"] if m != "numpy" or no_numpy]
    assert heavy == [], f"{' '.join(argv)} imported {r['heavy']}"
    if code == 2:
        assert len(r["err"].strip().splitlines()) == 1, r["err"]  # one line, no traceback
    if argv == ["--version"]:
        from maglev_match import __version__

        assert r["out"].strip() == f"maglev-match {__version__}"


# every command that takes --set, with the other options it needs to get that far
SET_COMMANDS = {
    "stability": (), "root-locus": (), "hopf": (), "hopf-curve": (), "cycles": (),
    "simulate": (), "index": (), "report": (),
    "sensitivity": (), "speed": (), "cycle-curve": (),
    "map": ("--x", "omega1=40:190:3", "--y", "sigma=2e-4:6e-4:3"),
    "design": ("--vary", "EI=5e9:4e10", "--maximize", "chi"),
    "iso-curve": ("chi=5",),
    "explore": ("--no-browser",),
}


@pytest.mark.parametrize("command", sorted(SET_COMMANDS))
def test_a_bad_set_is_refused_before_jax_in_every_command(command):
    """A misspelt parameter is the commonest usage error: every command refuses it in one
    line before its numerics (JAX) or its figures (matplotlib) load."""
    r = _probe(command, "--set", "nosuch=1", *SET_COMMANDS[command])
    assert r["code"] == 2, r
    assert "nosuch" in r["err"] and len(r["err"].strip().splitlines()) == 1, r["err"]
    assert not {"jax", "matplotlib", "pydantic"} & set(r["heavy"]), r["heavy"]


def test_set_commands_cover_every_command_with_a_set_option():
    from maglev_match.cli import all_commands

    with_set = {name for name, cmd in all_commands().items()
                if any("--set" in p.opts for p in cmd.params)}
    assert with_set == set(SET_COMMANDS)


def test_root_help_lists_every_command_with_its_first_sentence():
    r = _probe("--help")
    from maglev_match.cli import COMMANDS

    for name in COMMANDS:
        assert f" {name} " in r["out"], name


def test_command_table_matches_the_registered_commands():
    """COMMANDS (read by --help without importing) names exactly the registered commands,
    each in the module that defines it, with the first paragraph of its docstring."""
    from maglev_match.cli import COMMANDS, all_commands, app

    commands = all_commands()
    assert set(commands) == set(COMMANDS)
    for info in app.registered_commands:
        name = info.name
        module, short = COMMANDS[name]
        assert info.callback.__module__ == f"maglev_match.cli.{module}", name
        first = " ".join(inspect.getdoc(info.callback).split("\n\n")[0].split())
        assert short == first, name


def test_a_command_runs_after_lazy_loading(capsys):
    """The lazily loaded command parses and runs like an eagerly registered one."""
    from maglev_match.cli import main

    assert main(["presets", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert any(p["name"] == "turnout-soft" for p in data["presets"])


def test_preload_imports_jax_before_its_thread_starts():
    """Two threads importing JAX at once can deadlock on JAX's circular imports, which
    Python breaks with "partially initialized module 'jax'" (an internal error of
    `cycles`, seen twice): the background preload starts only once JAX is imported in
    the calling thread. Checked in a fresh process where nothing imported JAX yet."""
    import subprocess
    import sys

    code = (
        "import sys, threading\n"
        "import maglev_match.cli.common as c\n"
        "assert 'jax' not in sys.modules\n"
        "seen = []\n"
        "start = threading.Thread.start\n"
        "def spy(self):\n"
        "    seen.append('jax' in sys.modules and 'jax.numpy' in sys.modules)\n"
        "    return start(self)\n"
        "threading.Thread.start = spy\n"
        "c.preload('xarray')\n"
        "print(seen)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT / "src")})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[True]"


def test_index_json_imports_no_module_it_does_not_use():
    """`index --json` (model A) prints numbers: it needs neither the figures (matplotlib),
    the gridded results (xarray, pandas), the parallel maps (dask) nor scipy.optimize (whose
    only use on this path, matching the characteristic roots of the critical delay, has one
    candidate per side for model A). Each of them costs 0.1-0.5 s of a process start."""
    code = (
        "import contextlib, io, json, sys\n"
        "from maglev_match.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "    code = main(['index', '--json'])\n"
        "chi = json.loads(out.getvalue())['chi']\n"
        "print(json.dumps({'code': code, 'chi': chi, 'modules': sorted(sys.modules)}))\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT / "src"), *filter(None, [os.environ.get("PYTHONPATH")])]))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["code"] == 0 and r["chi"] > 0, r
    assert "jax" in r["modules"]  # the probe sees the modules of a real computation
    unwanted = ("matplotlib", "xarray", "pandas", "dask", "distributed", "scipy.optimize")
    found = [m for m in r["modules"] if m in unwanted]
    assert found == [], f"index --json imported {found}"
