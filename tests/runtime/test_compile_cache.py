"""The persistent compilation cache as every ``omnijax`` process turns it on (runtime/compile_cache.py)."""

from __future__ import annotations

import os
import subprocess
import sys

from tests.paths import ROOT

PROGRAM = """
import sys
import jax, jax.numpy as jnp
from runtime.compile_cache import use_cache
use_cache(sys.argv[1])
jax.jit(lambda x: jnp.sin(x) * 2.0 + 1.0)(jnp.arange(7.0)).block_until_ready()
"""


def test_even_a_program_that_compiles_in_milliseconds_is_cached(tmp_path):
    """A demo's start-up compiles about 210 small programs; under the old 0.5-s threshold every process
    compiled them afresh (6.5 s a start-up). By default (no environment override) a one-op program is
    written to the cache folder."""
    env = {k: v for k, v in os.environ.items() if k != "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"}
    subprocess.run([sys.executable, "-c", PROGRAM, str(tmp_path)], cwd=ROOT, env=env, check=True, timeout=120)
    assert any(p.name.startswith("jit_") for p in tmp_path.iterdir()), list(tmp_path.iterdir())
