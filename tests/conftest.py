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


# ---------------------------------------------------------------------------------------
# Longest files first. pytest-xdist (--dist loadfile) hands whole files to the two workers
# in collection order; a file of minutes handed out last keeps one core busy while the other
# idles. Listing the longest files first (longest-processing-time-first scheduling) keeps
# the two workers' ends close. Only the order changes: the other files keep theirs, every
# test runs. The list is by the measured durations of a full run (--durations=0), longest
# first; a file missing from it only runs later.
LONGEST_FILES = ("test_iso_curves.py", "test_speed_delay.py", "test_irregularities.py",
                 "test_sensitivity_vehicle.py", "test_maps.py", "test_recorded_outputs.py",
                 "test_explore_browser.py", "test_matching.py", "test_delay_maglev.py",
                 "test_interrupts.py", "test_readme.py", "test_cycle_curve_command.py")


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable
