"""Shared fixtures: float64 on, the rigs in configs/, a detector and a world built once per session;
compiled programs shared through a persistent cache."""

from __future__ import annotations

import os
import shutil
import tempfile

# XLA's CPU compiler without its newer fusion emitters, for this process and every `omnijax` child it starts
# (they inherit the environment): the suite is mostly compiling, and the older emitters compile the same
# programs in about half the time (control_step 33.4 -> 17.0 s on one core of this 2-core host;
# the whole suite 516 -> 456 s back to back), to the same results. The CLI, the demo and the benchmarks
# keep XLA's defaults: the newer emitters' code runs steps 1-3 of the detector faster (docs/runtime.md).
# Read when JAX first uses the CPU, after this module is imported; a flag the caller set is kept.
if "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_use_fusion_emitters=false").strip()

import jax
import pytest
from hypothesis import HealthCheck, settings

from tests.paths import CONFIGS

# One persistent compilation cache for the whole run: the `omnijax` child processes that CLI tests
# start (and pytest-xdist's workers) inherit it through the environment, so a program compiled once
# (the detector, the renderer, the loop's kernels) is not compiled again by the next process, nor by
# a test that builds the same program from a new function. Removed at the end by the process that
# made it; a JAX_COMPILATION_CACHE_DIR already set is used as it is.
_OWN_CACHE = None
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    _OWN_CACHE = os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="omnijax-tests-xla-")
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
jax.config.update("jax_persistent_cache_min_compile_time_secs",
                  float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]))

# float64 for the whole test session, as the `omnijax` command has it (omnijax's import leaves it alone)
jax.config.update("jax_enable_x64", True)

settings.register_profile(
    "omnijax", deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("omnijax")


#: The test files with the longest child processes (the console's demo, its browser and calibration
#: sessions; `omnijax validate`): collected first, so that one of `make test`'s two workers
#: (pytest-xdist, one file at a time) starts them at once and the other works through the short
#: files meanwhile, instead of waiting for them at the end. The demo's file stays in its place: run
#: beside `validate` on a loaded machine, its PTZ emulator answered too late for the driver to
#: reconnect after the injected unplug.
LONGEST_FIRST = ("tests/runtime/console/test_console.py", "tests/runtime/cli/test_variance_validate.py")


def pytest_collection_modifyitems(config, items):
    rank = {path: k for k, path in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))


def pytest_unconfigure(config):
    if _OWN_CACHE is not None:
        shutil.rmtree(_OWN_CACHE, ignore_errors=True)


@pytest.fixture(scope="session")
def paper_rig():
    from runtime.files import load_rig

    return load_rig(CONFIGS / "paper.toml")


@pytest.fixture(scope="session")
def fisheye_rig():
    from runtime.files import load_rig

    return load_rig(CONFIGS / "office_fisheye.toml")


@pytest.fixture(scope="session")
def paper_detector(paper_rig):
    """The detector of configs/paper.toml (built once per test session: thresholds are simulated)."""
    from omnijax import build_detector

    return build_detector(paper_rig)


@pytest.fixture(scope="session")
def six_world():
    """The six-people scenario (paper rig) with 400 frames of walking: built once per test session
    (building and compiling a world takes ~20 s)."""
    from omnijax.world import build_world
    from runtime.files import load_scenario

    rig, sc = load_scenario(CONFIGS / "scenarios" / "six_people.toml")
    return build_world(rig, sc, n_frames=400)
