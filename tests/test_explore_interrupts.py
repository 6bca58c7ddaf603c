"""Ctrl-C stops `maglev-match explore --no-browser` cleanly in every phase: while the
program starts (its imports) and while the first release compiles its kernels (an empty
compilation cache of its own, so a compile is under way when the signal comes). The process
ends with exit code 130, one "stopped: ..." line and no traceback, within the interrupt
guard's bound (as tests/test_interrupts.py checks the other long commands). No assertion
depends on the machine's speed: the bound is an upper limit only."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

from maglev_match.cli.interrupts import GRACE_S

BOUND_S = GRACE_S + 40.0


def _start(tmp_path: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path),
           "MAGLEV_MATCH_CACHE": str(tmp_path / "cache")}  # cold: the release compiles
    return subprocess.Popen([sys.executable, "-m", "maglev_match", "explore", "--no-browser",
                             "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, start_new_session=True, cwd=tmp_path)


def _stop(proc: subprocess.Popen) -> tuple[int, str, float]:
    t = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    try:
        code = proc.wait(BOUND_S + 60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return code, proc.stderr.read(), time.monotonic() - t


def _check(code: int, err: str, elapsed: float) -> None:
    assert code == 130, err[-3000:]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-3000:]
    assert len([ln for ln in err.splitlines() if ln.startswith("stopped")]) == 1, err[-3000:]
    assert elapsed < BOUND_S, (elapsed, err[-3000:])


def test_ctrl_c_while_the_first_release_compiles(tmp_path):
    proc = _start(tmp_path)
    line = proc.stdout.readline()
    assert "http://127.0.0.1:" in line, line
    base = line.split()[2].split("/?")[0]
    started = threading.Event()

    def release() -> None:  # the first release: the index's kernels compile
        started.set()
        try:
            urllib.request.urlopen(base + "/api/release?preset=turnout-soft&seq=1",
                                   timeout=600).read()
        except OSError:
            pass  # the server stops under it

    threading.Thread(target=release, daemon=True).start()
    started.wait(10)
    time.sleep(1.0)  # the request has reached the server's worker
    _check(*_stop(proc))


def test_ctrl_c_while_the_program_starts(tmp_path):
    proc = _start(tmp_path)
    time.sleep(0.5)  # its imports are under way (the address is not printed yet)
    _check(*_stop(proc))
