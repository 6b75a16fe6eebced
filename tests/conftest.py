"""Shared fixtures: the rigs in configs/, the real data in ../shared/data (skipped where absent)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "configs"
SHARED_DATA = ROOT.parent / "shared" / "data"

settings.register_profile(
    "omnijax", deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("omnijax")


@pytest.fixture(scope="session")
def paper_rig():
    from runtime.config_io import load_rig

    return load_rig(CONFIGS / "paper.toml")


@pytest.fixture(scope="session")
def fisheye_rig():
    from runtime.config_io import load_rig

    return load_rig(CONFIGS / "office_fisheye.toml")


def shared_data(*parts: str) -> Path:
    """Path into ../shared/data, or a clean skip naming what is missing (a user's clone has none)."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data not available: {path} (only in the project's shared checkout)")
    return path


@pytest.fixture(scope="session")
def paper_detector(paper_rig):
    """The detector of configs/paper.toml (built once per test session: thresholds are simulated)."""
    from omnijax import build_detector

    return build_detector(paper_rig)


@pytest.fixture(scope="session")
def six_world():
    """The six-people scenario (paper rig) with 400 frames of walking: built once per test session
    (building and compiling a world takes ~20 s)."""
    from omnijax import build_world
    from runtime.config_io import load_scenario

    rig, sc = load_scenario(CONFIGS / "scenarios" / "six_people.toml")
    return build_world(rig, sc, n_frames=400)
