import os

# Tests use their own persistent-cache-free JAX set-up so a stale cache can't mask anything.
os.environ.setdefault("MAGLEV_MATCH_CACHE", "")
