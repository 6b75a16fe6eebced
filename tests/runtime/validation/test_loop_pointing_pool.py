"""benchmarks/loop_pointing.py's pooling: the people are the units of the loop's pointing NEES."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest


def _module():
    path = Path(__file__).resolve().parents[3] / "benchmarks" / "loop_pointing.py"
    spec = importlib.util.spec_from_file_location("loop_pointing", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _runs(rng, n_runs, n_people, frames=300):
    """Runs whose people's NEES are persistent draws under a right covariance: chi-square(2) / 2 each, the
    same for all of a person's frames (the extreme of docs/validation.md's per-person errors)."""
    runs = []
    for seed in range(n_runs):
        v = rng.chisquare(2, n_people) / 2
        people = [{"person": k, "frames": frames, "nees_mean": float(x), "pan_nees_mean": float(x),
                   "tilt_nees_mean": float(x)} for k, x in enumerate(v)]
        curve = [{"rule": "calibrated", "p_contain": p, "rate": p, "trials": n_people * frames}
                 for p in (0.9, 0.95, 0.99)]
        runs.append({"scene": "s", "seed": seed, "pointing": {"people": people, "curve": curve,
                                                              "nees_mean": float(v.mean())}})
    return runs


def test_pooled_nees_and_its_standard_error_are_over_the_people():
    """400 runs of 3 people (n = 1200 persistent draws, seed 23): the pooled NEES within 3 of its standard
    errors of 1, that standard error the people's (sqrt(1 / 1200) = 0.029, not the frames' 0.0017), the share
    of people over 2 near exp(-2), and the runs' spread what drawing three people gives."""
    lp = _module()
    pooled = lp.pool(_runs(np.random.default_rng(23), 400, 3))
    assert pooled["people"] == 1200 and pooled["frames"] == 1200 * 300
    assert pooled["nees_mean_se"] == pytest.approx(math.sqrt(1 / 1200), rel=0.15)
    assert abs(pooled["nees_mean"] - 1) < 3 * pooled["nees_mean_se"]
    assert pooled["people_over_2"] == pytest.approx(math.exp(-2), abs=0.03)
    assert pooled["containment"] == pytest.approx({"0.9": 0.9, "0.95": 0.95, "0.99": 0.99})
    spread = pooled["run_spread"]["s"]
    assert spread["people_a_run"] == 3
    assert spread["drawn_people_sd"] == pytest.approx(spread["runs_sd"], rel=0.15)
    assert spread["drawn_people_sd"] == pytest.approx(math.sqrt(1 / 3), rel=0.15)
