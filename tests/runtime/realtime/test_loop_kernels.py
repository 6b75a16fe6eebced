"""The loop's jitted kernels: `perceive` (detection and the tracker's floor measurements under the
aim pipeline's sigma rule) and `update_background` (adaptation outside the people's sectors)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from omnijax import learn_background, line_background, sector_mask
from omnijax.geometry import floor_measurement
from runtime.realtime.loop import perceive, update_background
from tests.omnijax.test_detection import _noisy, _paint_person, _textured


@pytest.fixture(scope="module")
def scene(paper_detector):
    """A textured empty room, its background, and a frame with a painted person at hypothesis i, theta."""
    rng = np.random.default_rng(11)
    base = _textured(rng, 480, 640)
    bg = learn_background(np.stack([_noisy(rng, base) for _ in range(30)]))
    i = int(np.argmin(np.abs(np.asarray(paper_detector.polar.radii) - 100.0)))
    frame = _noisy(rng, _paint_person(rng, base, paper_detector, i, 1.3))
    return bg, line_background(paper_detector, bg), jnp.asarray(frame), i


def test_perceive_measures_the_detections_on_the_floor_with_the_sigma_rule(paper_detector, paper_rig, scene):
    bg, lines, frame, i = scene
    dets, _, z, R = perceive(paper_detector, paper_rig, frame, bg, lines)
    valid = np.asarray(dets.valid)
    assert valid.sum() == 1
    k = int(np.argmax(valid))
    r_f, th = float(dets.r_f[k]), float(dets.theta_f[k])
    assert r_f == pytest.approx(float(paper_detector.polar.hyp_r_f[i]), abs=1e-6)
    d = paper_rig.detection
    # the rule: the detector's sigmas scaled by the rig's gains, widened by its extra terms
    s_r = math.hypot(float(d.sigma_gain_r_f) * float(dets.sigma_r_f[k]), float(d.sigma_extra_r_f))
    s_t = math.hypot(float(d.sigma_gain_theta_f) * float(dets.sigma_theta_f[k]), float(d.sigma_extra_theta_f))
    assert s_t > float(dets.sigma_theta_f[k])
    z0, R0 = floor_measurement(paper_rig, r_f, th, s_r, s_t)
    np.testing.assert_allclose(np.asarray(z[k]), np.asarray(z0), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(R[k]), np.asarray(R0), rtol=1e-12)
    assert z.shape == (dets.r_f.shape[0], 2) and R.shape == (dets.r_f.shape[0], 2, 2)


def test_update_background_adapts_outside_the_sectors_only(paper_detector, paper_rig, scene):
    bg, lines, frame, _ = scene
    dets = perceive(paper_detector, paper_rig, frame, bg, lines)[0]
    W, H = paper_rig.omni.image_size
    theta_map = jnp.asarray(paper_rig.omni.to_polar(*np.meshgrid(np.arange(W), np.arange(H)))[1], jnp.float32)
    rate = 0.05
    new, new_lines = update_background(paper_detector, bg, frame, theta_map, dets, rate)
    k = int(np.argmax(np.asarray(dets.valid)))
    inside = np.asarray(sector_mask(theta_map, dets))
    off = np.abs(np.angle(np.exp(1j * (np.asarray(theta_map) - float(dets.theta_f[k])))))
    assert inside[off < 0.02].all() and not inside[off > 1.0].any()  # the person's sector, and only it
    mean, old, f = np.asarray(new.mean), np.asarray(bg.mean), np.asarray(frame, np.float32)
    np.testing.assert_array_equal(mean[inside], old[inside])
    np.testing.assert_allclose(mean[~inside], (old + rate * (f - old))[~inside], rtol=1e-6, atol=1e-3)
    vf = np.asarray(new.var_factor)
    np.testing.assert_array_equal(vf[inside], np.asarray(bg.var_factor)[inside])
    np.testing.assert_allclose(vf[~inside], ((1 - rate) ** 2 * np.asarray(bg.var_factor) + rate**2)[~inside],
                               rtol=1e-6)
    for a, b in zip(jax.tree.leaves(new_lines), jax.tree.leaves(line_background(paper_detector, new))):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
