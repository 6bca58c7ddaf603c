"""JAX configuration shared by the whole package: float64 everywhere and a persistent
compilation cache, so the command line does not recompile the models on every run.

Set ``MAGLEV_MATCH_CACHE`` to choose the cache folder (default ``~/.cache/maglev-match/jax``),
or to an empty string to switch the persistent cache off.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_platforms", os.environ.get("JAX_PLATFORMS", "cpu") or "cpu")

_cache = os.environ.get("MAGLEV_MATCH_CACHE", str(Path.home() / ".cache" / "maglev-match" / "jax"))
if _cache:
    try:
        Path(_cache).mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", _cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except OSError:  # read-only home: run without the persistent cache
        pass
