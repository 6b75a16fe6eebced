"""JAX's persistent compilation cache, as every ``omnijax`` process turns it on.

Programs that took at least ``$JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS`` to compile (default
:data:`MIN_COMPILE_S`) are written to the cache folder and read back by the next process that builds
them. The test suite sets 0, so that its many ``omnijax`` child processes compile each program once.
"""

from __future__ import annotations

import os

import jax

#: Seconds of compilation a program must take to be cached, unless the environment says otherwise. Every
#: program: a demo's start-up compiles about 210 small ones (eager one-op programs, the world's and the
#: life's small jitted functions) that took 6.5 s together and were compiled afresh by every process under
#: a threshold of 0.5 s; cached, a warm `omnijax demo --frames 300` starts in 22.0-22.8 s against
#: 25.6-25.8 s (docs/runtime.md), for a cache about a third larger (4.2 against 3.2 MB).
MIN_COMPILE_S = 0.0


def use_cache(path: str) -> None:
    """Cache compiled programs in the folder ``path`` (which must exist)."""
    raw = os.environ.get("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS")
    try:
        min_s = float(raw) if raw else MIN_COMPILE_S
    except ValueError:
        min_s = MIN_COMPILE_S
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", min_s)
