"""Pieces of `omnijax validate`'s end-to-end part: Table 1's positions, its statistics, matching."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import binomtest

from runtime.validation import endtoend as e


@pytest.fixture(scope="module")
def scenario(paper_rig):
    return e.table1_scenario(paper_rig)


def test_positions_are_walkable_and_spread(paper_rig, scenario):
    p = e.table1_positions(paper_rig, scenario)
    assert p.shape == (8, 2)
    fo = paper_rig.foveal
    ptz = np.array([float(fo.D_c * np.cos(fo.theta_c)), float(fo.D_c * np.sin(fo.theta_c))])
    dist = np.hypot(*(p - ptz).T)
    assert np.all(dist >= e.NEAR_PTZ) and np.all(np.hypot(*p.T) >= e.NEAR_AXIS)
    assert np.all(np.asarray(paper_rig.room.contains(p[:, 0], p[:, 1])))
    # pairs share a direction from the PTZ, the second one farther; four different directions
    bearing = np.arctan2(p[:, 1] - ptz[1], p[:, 0] - ptz[0])
    assert np.allclose(bearing[0::2], bearing[1::2], atol=1e-9) and np.all(dist[1::2] > dist[0::2])
    assert len(np.unique(np.round(bearing, 6))) == 4


def test_positions_fail_cleanly_in_a_tiny_room(paper_rig, scenario):
    import equinox as eqx

    tiny = jnp.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    rig = eqx.tree_at(lambda r: (r.room.outline, r.room.exclude), paper_rig, (tiny, ()))
    with pytest.raises(ValueError, match="too small"):
        e.table1_positions(rig, scenario)


def test_sample_variance_and_its_standard_error():
    # Gaussian samples: var(s^2) = 2 sigma^4 / (n - 1); 400 repetitions of n = 200 at sigma = 2:
    # the mean of the s^2 lies within 4 standard errors of 4 (false failure ~6e-5)
    rng = np.random.default_rng(0)
    x = 2.0 * rng.standard_normal((400, 200))
    est = np.array([e.sample_variance(v) for v in x])
    assert abs(est[:, 0].mean() - 4.0) < 4 * math.sqrt(2 * 16 / 199 / 400)
    assert np.median(est[:, 1]) == pytest.approx(math.sqrt(2 * 16 / 199), rel=0.1)
    ms, _ = e.sample_variance(x[0] + 1.0, about_zero=True)
    assert ms == pytest.approx(np.mean((x[0] + 1.0) ** 2))


@pytest.mark.parametrize("k,n", [(0, 50), (3, 200), (50, 50), (7, 1000)])
def test_binomial_is_clopper_pearson(k, n):
    b = e.binomial(k, n)
    ci = binomtest(k, n).proportion_ci(0.95, method="exact")
    assert b["rate"] == k / n and b["lower"] == pytest.approx(ci.low) and b["upper"] == pytest.approx(ci.high)


def test_match_takes_the_sector_that_covers_the_person():
    from omnijax.detection import Detections

    z = jnp.zeros(3)
    dets = Detections(valid=jnp.array([True, True, False]), r_f=jnp.array([10.0, 20.0, 30.0]),
                      theta_f=jnp.array([1.0, 3.1, 0.5]), sigma_r_f=z + 1, sigma_theta_f=z + 0.01, contrast=z + 9,
                      r_in=z, r_out=z, theta_l=jnp.array([0.9, 3.0, 0.4]), theta_r=jnp.array([1.1, -3.0, 0.6]),
                      peak=z, region=jnp.zeros((3, 4), jnp.int32))
    m, others = e.match(dets, -3.1)  # the second sector wraps around +-pi
    assert bool(m.found) and float(m.r_f) == 20.0 and int(others) == 1
    m, others = e.match(dets, 0.5)  # only an invalid sector there: a miss, two false alarms
    assert not bool(m.found) and int(others) == 2
