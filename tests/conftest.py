import os
import tempfile

# A fresh persistent JAX compilation cache per test session (shared by the subprocesses and
# Dask workers the tests start), so compiled code is reused within the run but a stale cache
# from an earlier run can never mask anything. CI sets its own fresh folder.
os.environ.setdefault("MAGLEV_MATCH_CACHE", tempfile.mkdtemp(prefix="maglev-match-jax-"))


# ---------------------------------------------------------------------------------------
# Memory mappings of compiled code. Every XLA executable keeps ~3 memory mappings of its
# machine code; a test session compiles thousands of kernels in one process, and Linux caps
# a process at vm.max_map_count mappings (65530 by default). Past the cap LLVM's allocation
# of the next kernel fails and the process dies with a segmentation fault inside
# backend_compile (seen at ~60 % of the suite). So between tests, once the process holds
# more than MAP_BUDGET mappings, the in-memory kernels are dropped (JAX's caches and the
# package's cached kernel factories); later tests reload them from the persistent cache.
MAP_BUDGET = 30_000


def _map_count() -> int:
    try:
        with open("/proc/self/maps", "rb") as fh:
            return sum(1 for _ in fh)
    except OSError:  # not Linux
        return 0


def _drop_compiled_kernels() -> None:
    import gc
    import sys

    import jax

    for name, mod in list(sys.modules.items()):
        if not name.startswith("maglev_match") or mod is None:
            continue
        for value in list(vars(mod).values()):
            clear = getattr(value, "cache_clear", None)
            if callable(clear) and getattr(value, "__module__", None) == name:
                clear()
    jax.clear_caches()
    gc.collect()


def pytest_runtest_teardown(item, nextitem):
    if "jax" in __import__("sys").modules and _map_count() > MAP_BUDGET:
        _drop_compiled_kernels()
