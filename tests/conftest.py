"""Shared fixtures: float64 on, the rigs in configs/, a detector and a world built once per session."""

from __future__ import annotations

import jax
import pytest
from hypothesis import HealthCheck, settings

from tests.paths import CONFIGS

# float64 for the whole test session, as the `omnijax` command has it (omnijax's import leaves it alone)
jax.config.update("jax_enable_x64", True)

settings.register_profile(
    "omnijax", deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("omnijax")


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
