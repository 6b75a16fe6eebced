"""Benchmark plumbing: pin the process to one core, and time calls into median / p90 / p99."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable

import numpy as np

_ONE_CORE_XLA = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def pin_to_one_core(core: int = 0) -> None:
    """Restrict this process (and XLA's CPU thread pools) to one core.

    Must run before jax is imported: XLA reads its flags once.
    """
    if "jax" in sys.modules:
        raise RuntimeError("pin_to_one_core() must run before jax is imported")
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + _ONE_CORE_XLA).strip()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {core})


def time_calls(fn: Callable[[], object], repeats: int, warmup: int = 3) -> dict[str, float]:
    """Wall time of ``fn()`` in milliseconds over ``repeats`` calls after ``warmup``: p50, p90, p99."""
    for _ in range(warmup):
        fn()
    t = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter()
        fn()
        t[i] = time.perf_counter() - t0
    ms = 1e3 * t
    return {"p50": float(np.median(ms)), "p90": float(np.percentile(ms, 90)),
            "p99": float(np.percentile(ms, 99)), "n": repeats}
