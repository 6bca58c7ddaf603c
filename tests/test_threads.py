"""The package's thread setting (one BLAS thread; see maglev_match.core.jax_setup) holds
also when NumPy was imported first, as in a notebook or a test module: the BLAS pool it
started before the package was imported is limited to one thread, unless the user chose
(a thread variable set, or MAGLEV_MATCH_THREADS=auto)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

PROBE = """
import json, numpy
before = [d["num_threads"] for d in __import__("threadpoolctl").threadpool_info()
          if d["user_api"] == "blas"]
import maglev_match.core.jax_setup
after = [d["num_threads"] for d in __import__("threadpoolctl").threadpool_info()
         if d["user_api"] == "blas"]
print(json.dumps([before, after]))
"""


def _threads(**env: str) -> tuple[list[int], list[int]]:
    clean = {k: v for k, v in os.environ.items()
             if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                          "MAGLEV_MATCH_THREADS")}
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                         env={**clean, "PYTHONPATH": os.pathsep.join(sys.path), **env},
                         check=True, timeout=300).stdout
    before, after = json.loads(out.splitlines()[-1])
    return before, after


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: the pool has one thread")
def test_numpy_imported_first_gets_one_blas_thread_unless_the_user_chose():
    before, after = _threads()
    assert before and max(before) > 1  # NumPy alone starts a pool per core
    assert after == [1] * len(before)
    assert _threads(MAGLEV_MATCH_THREADS="auto") == (before, before)
    assert _threads(OPENBLAS_NUM_THREADS="2", OMP_NUM_THREADS="2") == ([2] * len(before),
                                                                        [2] * len(before))
