import os
import tempfile

# A fresh persistent JAX compilation cache per test session (shared by the subprocesses and
# Dask workers the tests start), so compiled code is reused within the run but a stale cache
# from an earlier run can never mask anything. CI sets its own fresh folder.
os.environ.setdefault("MAGLEV_MATCH_CACHE", tempfile.mkdtemp(prefix="maglev-match-jax-"))
