"""The synthetic world against its ground truth: projection, silhouettes, draws, walks, light, noise."""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

from omnijax import chromaticity, chromaticity_covariance, world_to_image
from omnijax.world import (
    body,
    body_distance,
    build_world,
    draw_people,
    draw_true_rig,
    effective_sigma,
    omni_rays,
    render_frame,
    render_frames,
    walk,
    walkable,
    xyz,
)
from runtime.files import load_scenario
from tests.paths import CONFIGS

SCEN = CONFIGS / "scenarios"


def _world(name: str, n_frames: int, **kw):
    rig, sc = load_scenario(SCEN / f"{name}.toml")
    return build_world(rig, sc, n_frames=n_frames, **kw)


@pytest.fixture(scope="module")
def six(six_world):
    return six_world


@pytest.fixture(scope="module")
def fisheye():
    """The fisheye office at half resolution (640 x 480, r_m 220 px): the same equidistant model,
    a quarter of the rays to cast."""
    rig, sc = load_scenario(SCEN / "fisheye_office.toml")
    om = rig.omni
    small = eqx.tree_at(lambda r: (r.omni.center, r.omni.r_m, r.omni.rim), rig, (om.center / 2, om.r_m / 2, om.rim / 2))
    small = eqx.tree_at(lambda r: r.omni, small, replace_fn=lambda o: dataclasses.replace(o, image_size=(640, 480)))
    return build_world(small, sc, n_frames=30)


def _truths(world, ts):
    """The truths of frames ``ts``, stacked (NumPy)."""
    return jax.tree.map(lambda *v: np.stack([np.asarray(x) for x in v]), *[world.frame(t).truth for t in ts])


# --------------------------------------------------------------------------------------
# Truth against the camera model
# --------------------------------------------------------------------------------------


FISHEYE_SLOW = pytest.param("fisheye", marks=pytest.mark.slow)  # a second world to compile: ~30 s


@pytest.mark.parametrize("name", [pytest.param("six", marks=pytest.mark.slow), FISHEYE_SLOW])
def test_truth_foot_is_the_camera_models_projection(request, name):
    """truth's (r_f, theta_f, pixel) against the foundation's world_to_image of the true foot (< 0.01 px),
    and the renderer's inverse mapping (pixel -> ray -> floor) lands on the foot (< 0.01 px)."""
    world = request.getfixturevalue(name)
    tr = _truths(world, np.arange(0, 30, 3))
    om = world.true_rig.omni
    X, Y = tr.foot[..., 0], tr.foot[..., 1]
    x, y = (np.asarray(v) for v in world_to_image(om, X, Y, 0.0))
    r, theta = (np.asarray(v) for v in om.to_polar(x, y))
    assert np.max(np.hypot(x - tr.pixel[..., 0], y - tr.pixel[..., 1])) < 0.01
    assert np.max(np.abs(r - tr.r_f)) < 0.01
    assert np.max(np.abs(np.angle(np.exp(1j * (theta - tr.theta_f))) * r)) < 0.01
    d, inside = omni_rays(om, tr.pixel[..., 0], tr.pixel[..., 1])
    d = np.asarray(d)
    t = float(om.H_o) / -d[..., 2]
    miss_m = np.hypot(t * d[..., 0] - X, t * d[..., 1] - Y)
    px_per_m = np.asarray(world_to_image(om, X + 1e-3, Y, 0.0)[0] - x) / 1e-3  # local scale, x direction
    assert np.all(np.asarray(inside) == tr.in_image)
    assert np.max(miss_m * np.abs(px_per_m).max()) < 0.01


@pytest.mark.parametrize("name", [pytest.param("six", marks=pytest.mark.slow), FISHEYE_SLOW])
def test_drawn_silhouette_starts_at_the_body_edge(request, name):
    """Along the radial line through the foot, the first labelled pixel is the body's nearest floor
    point (truth.r_inner) within a pixel; it lies inside r_f by the body radius's image."""
    world = request.getfixturevalue(name)
    om = world.true_rig.omni
    lows, inner, r_f = [], [], []
    for t in range(0, 30, 5):
        f = world.frame(t)
        lab, tr = np.asarray(f.labels), jax.tree.map(np.asarray, f.truth)
        for i in np.flatnonzero(tr.in_image & tr.foot_visible):
            rs = np.arange(0.0, tr.r_f[i] + 20.0, 0.05)
            px, py = (np.rint(np.asarray(v)).astype(int) for v in om.to_pixel(rs, tr.theta_f[i]))
            ok = (px >= 0) & (px < lab.shape[1]) & (py >= 0) & (py < lab.shape[0])
            hit = np.zeros(rs.shape, bool)
            hit[ok] = lab[py[ok], px[ok]] == i
            if hit.any():
                lows.append(rs[np.argmax(hit)])
                inner.append(tr.r_inner[i])
                r_f.append(tr.r_f[i])
    lows, inner, r_f = map(np.asarray, (lows, inner, r_f))
    assert len(lows) >= 10
    assert np.max(np.abs(lows - inner)) < 1.0
    assert np.all(r_f - lows > 2.0)


def test_people_are_drawn_in_depth_order(six):
    """Labels equal a brute-force nearest hit of every pixel's central ray with every person,
    on pixels whose 3 x 3 neighbourhood has one label (edges depend on the coverage)."""
    om = six.true_rig.omni
    W, H = om.image_size
    yy, xx = np.mgrid[0:H, 0:W]
    d, inside = omni_rays(om, xx, yy)
    d = jnp.asarray(d, jnp.float32)
    eye = six.background.eye
    checked = 0
    for t in range(0, 400, 40):
        f = six.frame(t)
        foot = jnp.asarray(six.paths.position[t], jnp.float32)
        dist = jnp.stack([body_distance(body(six.people, i, foot[i]), xyz(eye), xyz(d))
                          for i in range(six.people.count)])
        nearest = jnp.argmin(dist, axis=0)
        seen = (jnp.min(dist, axis=0) < six.background.depth) & jnp.asarray(inside)
        brute = np.asarray(jnp.where(seen, nearest, -1))
        pad = np.pad(brute, 1, constant_values=-2)
        same = np.ones_like(brute, bool)
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                same &= pad[dy:dy + H, dx:dx + W] == brute
        lab = np.asarray(f.labels)
        assert np.array_equal(lab[same], brute[same])
        checked += int(np.sum(same & (brute >= 0)))
    assert checked > 5000


# --------------------------------------------------------------------------------------
# Draws: the true rig and the people
# --------------------------------------------------------------------------------------


def test_true_rig_draw_statistics(paper_rig):
    """n = 4000 draws: each drawn value's mean within 4 sigma / sqrt(n) of the configured value and its
    standard deviation within 4 / sqrt(2n) (relative) of the configured sigma; 10 checks, false-failure
    probability about 6e-4. A zero sigma leaves the value as configured."""
    n = 4000
    rigs = jax.vmap(lambda k: draw_true_rig(paper_rig, k))(jax.random.split(jax.random.key(0), n))
    s = paper_rig.sigmas
    for got, mean, sigma in [
        (rigs.omni.H_o, paper_rig.omni.H_o, s.H_o), (rigs.omni.r_m, paper_rig.omni.r_m, s.r_m),
        (rigs.foveal.H_f, paper_rig.foveal.H_f, s.H_f), (rigs.foveal.D_c, paper_rig.foveal.D_c, s.D_c),
    ]:
        got, mean, sigma = np.asarray(got), float(mean), float(sigma)
        assert abs(got.mean() - mean) < 4 * sigma / math.sqrt(n)
        assert abs(got.std(ddof=1) / sigma - 1) < 4 / math.sqrt(2 * n)
    assert np.all(np.asarray(rigs.foveal.theta_c) == float(paper_rig.foveal.theta_c))  # sigma_theta_c = 0
    np.testing.assert_allclose(np.asarray(rigs.omni.rim), np.asarray(rigs.omni.r_m))


def test_person_draw_statistics(paper_rig):
    """n = 4000 people: H_p and R_h follow the rig's person priors (same bounds as the rig draw)."""
    _, sc = load_scenario(SCEN / "one_person.toml")
    n = 4000
    people = jax.vmap(lambda k: draw_people(paper_rig, sc, k))(jax.random.split(jax.random.key(1), n))
    pr, s = paper_rig.person, paper_rig.sigmas
    for got, mean, sigma in [(people.H_p, pr.H_p, s.H_p), (people.R_h, pr.R_h, s.R_h)]:
        got, mean, sigma = np.asarray(got).ravel(), float(mean), float(sigma)
        assert abs(got.mean() - mean) < 4 * sigma / math.sqrt(n)
        assert abs(got.std(ddof=1) / sigma - 1) < 4 / math.sqrt(2 * n)
        assert np.all(np.abs(got - mean) <= 4 * sigma + 1e-12)


@pytest.mark.slow
def test_seeds_repeat_and_differ(six):
    """The same seed gives the same world, frame for frame (bit for bit); another seed another
    true rig, other people and other frames."""
    again = _world("six_people", 400)
    for t in (0, 237):
        a, b = six.frame(t), again.frame(t)
        assert np.array_equal(np.asarray(a.image), np.asarray(b.image))
        assert np.array_equal(np.asarray(a.truth.foot), np.asarray(b.truth.foot))
    other = _world("six_people", 400, seed=int(six.seed) + 1)
    assert float(other.true_rig.omni.H_o) != float(six.true_rig.omni.H_o)
    assert float(other.people.H_p[0]) != float(six.people.H_p[0])
    assert not np.array_equal(np.asarray(other.frame(0).image), np.asarray(six.frame(0).image))
    assert not np.array_equal(np.asarray(six.frame(1).image), np.asarray(six.frame(2).image))


def test_frame_index_outside_the_walk_is_an_error(six):
    with pytest.raises(Exception, match="frame index outside"):
        six.frame(400).image.block_until_ready()


# --------------------------------------------------------------------------------------
# Walks
# --------------------------------------------------------------------------------------


def test_people_never_overlap_and_stay_on_the_walkable_floor():
    """Six people for 2000 frames (80 s): bodies always at least 2 radius + gap apart, always on
    walkable floor, walking most of the time but sometimes standing, speed capped."""
    rig, sc = load_scenario(SCEN / "six_people.toml")
    people = draw_people(rig, sc, jax.random.key(5))
    paths = walk(rig, sc, people, jax.random.key(6), 2000)
    pos = np.asarray(paths.position)
    n = pos.shape[1]
    d = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1) + np.eye(n) * 1e9
    r = float(people.radius)
    assert d.min() >= 2 * r + float(sc.crowd.gap) - 1e-9
    assert np.all(np.asarray(walkable(rig, sc.furniture, pos[..., 0], pos[..., 1], r - 1e-9)))
    moving = np.asarray(paths.moving)
    assert 0.5 < moving.mean() < 0.97 and np.all(moving.mean(axis=0) < 1.0)
    speed = np.linalg.norm(np.diff(pos, axis=0), axis=-1) * sc.fps
    assert speed.max() <= 1.3 * float(people.speed.max()) + 1e-6
    facing = np.linalg.norm(np.asarray(paths.facing), axis=-1)
    np.testing.assert_allclose(facing, 1.0, atol=1e-6)


# --------------------------------------------------------------------------------------
# Light and noise
# --------------------------------------------------------------------------------------


def _unshadowed(world, t):
    """The frame's background without the people's shadows (noise-free grey levels)."""
    bg, sched = world.background, world.schedule
    lamps = sum(sched.lamp_light[t, k] * bg.irradiance[k] for k in range(bg.lamps.shape[0]))
    return np.asarray(bg.colour * (sched.ambient[t] + lamps)[..., None])


def _shadowed_pixels(world, t):
    lin = np.asarray(world.linear(t))
    lab = np.asarray(world.frame(t).labels)
    ref = _unshadowed(world, t)
    share = lin.sum(-1) / np.maximum(ref.sum(-1), 1e-6)
    clear = ~ndimage.binary_dilation(lab >= 0, iterations=2)  # label -1 still includes thin edge coverage
    mask = clear & (np.asarray(world.background.gain) > 0) & (share < 0.85) & (ref.sum(-1) > 60)
    return lin, ref, mask


def test_chromaticity_is_unchanged_in_shadow(six):
    """Noise-free: a floor pixel in a person's shadow has the chromaticity it has when lit (float32
    exact); with sensor noise, its difference from the lit chromaticity has eq 5's covariance
    (mean Mahalanobis d2 over n shadow pixels within 4 sqrt(4 / n) of 2)."""
    t = 30
    lin, ref, mask = _shadowed_pixels(six, t)
    assert mask.sum() > 100
    np.testing.assert_allclose(np.asarray(chromaticity(lin[mask])), np.asarray(chromaticity(ref[mask])), atol=2e-6)
    noisy = np.asarray(six.frame(t).image, float)[mask]
    sigma = effective_sigma(float(six.scenario.sensor.noise_sigma))
    diff = np.asarray(chromaticity(noisy)) - np.asarray(chromaticity(ref[mask]))
    cov = np.asarray(chromaticity_covariance(lin[mask], sigma))
    d2 = np.einsum("ni,nij,nj->n", diff, np.linalg.inv(cov), diff)
    n = len(d2)
    assert abs(d2.mean() - 2.0) < 4 * math.sqrt(4.0 / n)


def test_lamp_switch_scales_without_changing_chromaticity(six):
    """Switching lamp 0 off scales the background's pixels; chromaticity stays (noise-free, float32)."""
    t = 10
    dark = eqx.tree_at(lambda w: w.schedule.lamp_light, six, six.schedule.lamp_light.at[:, 0].set(0.0))
    before, after = np.asarray(six.linear(t)), np.asarray(dark.linear(t))
    lab = np.asarray(six.frame(t).labels)
    bright = (after.sum(-1) > 60) & ~ndimage.binary_dilation(lab >= 0, iterations=2)
    assert np.mean(after.sum(-1)[bright] < before.sum(-1)[bright] - 1) > 0.9
    np.testing.assert_allclose(np.asarray(chromaticity(after[bright])), np.asarray(chromaticity(before[bright])),
                               atol=2e-6)


@pytest.mark.slow
def test_noise_statistics_empty_room():
    """Empty room, steady light, 200 frames: per-pixel variance (mean over 40,000 pixels) equals
    sigma^2 + 1/12 (8-bit rounding) within 2 %; no correlation between neighbours or frames
    (|r| < 0.01, 4 standard errors at n = 8e6); residuals symmetric with a Gaussian's kurtosis."""
    w = _world("empty_room", 200)
    sigma = float(w.scenario.sensor.noise_sigma)
    crop = (slice(140, 340), slice(220, 420))  # 200 x 200 pixels, inside the image circle
    frames = np.stack([np.asarray(w.frame(t).image[crop], float) for t in range(200)])
    mean = frames.mean(axis=0)
    ok = (mean > 10) & (mean < 245)
    assert ok.all()
    var = frames.var(axis=0, ddof=1)
    assert abs(var.mean() / effective_sigma(sigma) ** 2 - 1) < 0.02
    res = frames - mean
    r_space = np.mean(res[:, :, :-1] * res[:, :, 1:]) / res.var()
    r_time = np.mean(res[:-1] * res[1:]) / res.var()
    assert abs(r_space) < 0.01 and abs(r_time) < 0.01
    z = res.ravel() / res.std()
    assert abs(np.mean(z**3)) < 0.02 and abs(np.mean(z**4) - 3.0) < 0.05


def test_render_frames_stacks_world_frames(six):
    """``render_frames(world, ts)`` / ``world.frames(ts)`` equal ``world.frame(t)`` stacked."""
    stacked = render_frames(six, [3, 7])
    assert stacked.image.shape == (2, 480, 640, 3) and stacked.truth.r_f.shape == (2, 6)
    assert np.array_equal(np.asarray(stacked.image[1]), np.asarray(render_frame(six, 7).image))
    assert np.array_equal(np.asarray(six.frames(np.array([3])).truth.foot[0]), np.asarray(six.frame(3).truth.foot))
