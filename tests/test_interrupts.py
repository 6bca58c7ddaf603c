"""Ctrl-C ends every long command within seconds, in every phase, on a busy machine.

A terminal's Ctrl-C sends SIGINT to the whole process group; the tests do the same. Each
command is interrupted twice: while its first kernels compile (an empty compilation cache
of its own, so a compile is certainly under way when the first piece of work starts) and
during the work (after its first piece is finished). The process must end with exit code
130, print one "stopped: ..." line that says what is kept and how to resume (where the
command resumes), and no traceback, within a bound that holds on a loaded machine: the
interrupt guard's grace (:data:`maglev_match.cli.interrupts.GRACE_S`) plus a generous
margin. No test depends on how fast the machine is: the signal is sent when the command's
own progress line says the phase has begun, and the bound is an upper limit only.

A phase that cannot be interrupted at all (a long C call that never looks for signals, as a
single XLA compile) is simulated by a call that releases the GIL and ignores signals for
minutes: the guard's watchdog must end the process anyway.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from maglev_match.cli.interrupts import GRACE_S
from maglev_match.core import interrupts

#: The longest wait for exit after SIGINT that the tests accept: the watchdog's grace plus a
#: margin for a machine with both cores busy (the normal path takes 0.1 s in-process and
#: about 4 s with a local Dask cluster on a quiet machine).
BOUND_S = GRACE_S + 40.0

MAP = ["map", "--x", "omega1=100:140:6", "--y", "sigma=3e-4:5e-4:200", "--rows-per-tile", "1",
       "--out", "OUT/m.nc"]
SPEED = ["speed", "--from", "0", "--to", "150", "--step", "5"]
DESIGN = ["design", "--vary", "EI=5e9:4e10", "--minimize", "EI", "--require", "chi>=5"]
MONTE_CARLO = ["index", "--scatter", "kD=5", "--monte-carlo", "64", "--workers", "1"]


def _interrupt(args: list[str], trigger: str, tmp_path: Path, *, cold: bool,
               program: list[str] | None = None, settle: float = 0.5
               ) -> tuple[int, str, float]:
    """Run ``maglev-match ARGS`` (files under ``tmp_path/out``: ``OUT`` in ARGS, else
    ``--out``), wait for a progress line matching ``trigger``, send SIGINT to its process
    group ``settle`` s later and return (exit code, stderr, seconds from the signal to the
    exit)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    if cold:  # an empty compilation cache: the first piece of work compiles its kernels
        env["MAGLEV_MATCH_CACHE"] = str(tmp_path / "cache")
    cmd = program or [sys.executable, "-m", "maglev_match.cli"]
    out = str(tmp_path / "out")
    args = [a.replace("OUT", out) for a in args] + ([] if "--out" in args else ["--out", out])
    proc = subprocess.Popen([*cmd, *args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env=env, start_new_session=True, cwd=tmp_path)
    lines: list[str] = []
    seen = threading.Event()

    def read() -> None:
        for line in proc.stderr:
            lines.append(line)
            if re.search(trigger, line):
                seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        while not seen.wait(0.2):
            assert proc.poll() is None, "".join(lines)[-3000:]
        time.sleep(settle)
        t = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=BOUND_S + 60)
        elapsed = time.monotonic() - t
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    reader.join(10)
    return proc.returncode, "".join(lines), elapsed


def _check_stopped(code: int, err: str, elapsed: float, resume: str | None) -> None:
    assert code == 130, err[-3000:]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-3000:]
    stopped = [line for line in err.splitlines() if line.startswith("stopped: ")]
    assert len(stopped) == 1, err[-3000:]
    if resume:
        assert resume in stopped[0] and "--resume" in stopped[0], stopped
    assert elapsed < BOUND_S, (elapsed, err[-3000:])


# ----- while the first kernels compile (an empty cache) ---------------------------------
@pytest.mark.parametrize("args, trigger, resume", [
    pytest.param([*MAP, "--workers", "0"], r"0/200 tiles done", "of 200 tiles",
                 id="map-here"),
    pytest.param([*MAP, "--workers", "1"], r"0/200 tiles done", "of 200 tiles",
                 id="map-dask"),
    pytest.param([*SPEED, "--workers", "1"], r"0/31 speeds done", "of 31 tiles",
                 id="speed"),
    pytest.param(DESIGN, r"coarse grid", None, id="design"),
    # (the Monte Carlo index is interrupted during its work below; cold, it reached its own
    # first compile only after the whole index had compiled: ~45 s of the suite)
])
def test_ctrl_c_while_the_first_kernels_compile(tmp_path, args, trigger, resume):
    code, err, elapsed = _interrupt(args, trigger, tmp_path, cold=True)
    _check_stopped(code, err, elapsed, resume)
    if args[0] == "map":
        assert not (tmp_path / "out" / "m.nc").exists()  # no map from an unfinished map


# ----- during the work (after the first piece) ------------------------------------------
@pytest.mark.parametrize("args, trigger, resume", [
    pytest.param([*MAP, "--workers", "0"], r"1/200 tiles done", "of 200 tiles",
                 id="map-here"),
    pytest.param([*MAP, "--workers", "1"], r"1/200 tiles done", "of 200 tiles",
                 id="map-dask"),
    pytest.param([*SPEED, "--workers", "1"], r"1/31 speeds done", "of 31 tiles",
                 id="speed"),
    pytest.param(DESIGN, r"optimiser from grid point", None, id="design"),
    # (the chunks are under way on the worker from the first count on)
    pytest.param(MONTE_CARLO, r"0/4 chunks done", "of 4 Monte Carlo chunks",
                 id="index-monte-carlo"),
])
def test_ctrl_c_during_the_work(tmp_path, args, trigger, resume):
    code, err, elapsed = _interrupt(args, trigger, tmp_path, cold=False, settle=2.0)
    _check_stopped(code, err, elapsed, resume)


# ----- a phase that never looks for signals ---------------------------------------------
STALLED_MAP = """
import hashlib, sys
import maglev_match.analyses.maps.tiles as tiles  # where run_map looks compute_tile up

compute = tiles.compute_tile

def stalled(spec, rows):
    sys.stderr.write("entering a phase that ignores signals\\n")
    sys.stderr.flush()
    # minutes in C with the GIL released and no look at signals, as a single XLA compile
    hashlib.pbkdf2_hmac("sha256", b"x", b"y", 2**31 - 1)
    return compute(spec, rows)

tiles.compute_tile = stalled
from maglev_match.cli import main
sys.exit(main())
"""


def test_ctrl_c_in_a_phase_that_ignores_signals_is_ended_by_the_watchdog(tmp_path):
    script = tmp_path / "stalled_map.py"
    script.write_text(STALLED_MAP)
    code, err, elapsed = _interrupt([*MAP, "--workers", "0"], "ignores signals", tmp_path,
                                    cold=False, program=[sys.executable, str(script)])
    _check_stopped(code, err, elapsed, "0 of 200 tiles")
    # the checkpoint folder stays, ready for --resume; no map from an unfinished map
    assert (tmp_path / "out" / "m.nc.tiles" / "spec.json").is_file()
    assert not (tmp_path / "out" / "m.nc").exists()


# ----- the stop note --------------------------------------------------------------------
def test_stop_note_is_the_innermost_running_job_and_never_raises():
    assert interrupts.stop_note() == "interrupted"
    count = [3]
    with interrupts.on_interrupt(lambda: f"outer {count[0]}"):
        count[0] = 4
        assert interrupts.stop_note() == "outer 4"  # read at the moment of the interrupt
        with interrupts.on_interrupt(lambda: 1 / 0):
            assert interrupts.stop_note("plain") == "plain"
        assert interrupts.stop_note() == "outer 4"
    assert interrupts.stop_note() == "interrupted"
