"""The foveal camera of the synthetic world: pan/tilt conventions, head in frame, face pixels, its image."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

from omnijax import chromaticity, face_pixels, pointing
from omnijax.world import foveal_head, head_in_view, ptz_view, render_foveal


def _true_inputs(world, t, i):
    tr, rig = world.frame(t).truth, world.true_rig
    return jnp.stack([tr.r_f[i], tr.theta_f[i], rig.omni.H_o, rig.foveal.H_f, rig.foveal.D_c, rig.foveal.theta_c,
                      rig.omni.r_m, tr.H_p[i], tr.R_h[i]])


@pytest.mark.slow
def test_pointing_at_the_true_head_puts_it_at_the_centre(six_world):
    """eq 1-4 with the true rig and the true person aim the PTZ at the head's centre: it falls on the
    image centre ((W - 1) / 2, (H - 1) / 2) to 1e-6 px, for every person in several frames."""
    rig = six_world.true_rig
    W, H = rig.foveal.lens.image_size
    checked = 0
    for t in (0, 150, 300):
        for i in range(six_world.people.count):
            aim = pointing(_true_inputs(six_world, t, i), rig.omni.profile)
            if not bool(aim.valid):
                continue
            view = foveal_head(six_world, t, i, aim.pan, aim.tilt, 4.0)
            np.testing.assert_allclose(np.asarray(view.pixel), [(W - 1) / 2, (H - 1) / 2], atol=1e-6)
            assert float(view.distance) == pytest.approx(float(aim.slant), rel=1e-9)
            assert float(view.face_px) == pytest.approx(
                float(face_pixels(rig.foveal.lens, 4.0, aim.slant, _true_inputs(six_world, t, i)[8])), rel=1e-12)
            checked += 1
    assert checked >= 12


@pytest.mark.parametrize("zoom", [1.0, 4.0, 12.0, 18.0])
def test_whole_head_inside_the_frame(paper_rig, zoom):
    """A head straight ahead at distance d, turned away by delta: inside exactly when
    fov_h / 2 - delta >= asin(R_h / d) (the sphere clears the frame's side plane)."""
    rig, R_h, d = paper_rig, 0.1, 4.0
    fov_h, _ = rig.foveal.lens.fov(zoom)
    half, ang = float(fov_h) / 2, math.asin(R_h / d)
    pan0 = 0.3
    for delta in np.linspace(0.0, half + ang + 0.01, 41):
        view = ptz_view(rig, pan0 + delta, 0.0, zoom)
        centre = jnp.asarray(ptz_view(rig, pan0, 0.0, zoom).position) + d * ptz_view(rig, pan0, 0.0, zoom).forward
        got = head_in_view(rig, pan0 + delta, 0.0, zoom, centre, R_h)
        assert bool(got.inside) == (half - delta >= ang + 1e-12) or abs(half - delta - ang) < 1e-9
        assert view.size == rig.foveal.lens.image_size


def test_ptz_conventions_match_pointing(paper_rig):
    """Pan 0, tilt 0 looks horizontally at the omni camera's axis; for feet all around the room
    (pan beyond +-90 deg included) the view at ``pointing``'s pan and tilt looks straight at the
    head's centre (angle < 1e-9 rad)."""
    rig = paper_rig
    view = ptz_view(rig, 0.0, 0.0, 1.0)
    c = math.cos(float(rig.foveal.theta_c)), math.sin(float(rig.foveal.theta_c))
    np.testing.assert_allclose(np.asarray(view.forward), [-c[0], -c[1], 0.0], atol=1e-12)
    om = rig.omni
    for r_f in (20.0, 80.0, 140.0):
        for theta_f in np.linspace(-math.pi, math.pi, 9):
            x = rig.input_mean(r_f, theta_f)
            aim = pointing(x, om.profile)
            R_p = float(aim.radius)
            head = np.array([R_p * math.cos(theta_f), R_p * math.sin(theta_f), float(rig.person.H_p - rig.person.R_h)])
            v = ptz_view(rig, aim.pan, aim.tilt, 1.0)
            to_head = head - np.asarray(v.position)
            cosang = float(np.dot(np.asarray(v.forward), to_head) / np.linalg.norm(to_head))
            assert math.acos(min(1.0, cosang)) < 1e-7


@pytest.mark.slow
def test_foveal_image_shows_the_head_at_its_centre(six_world):
    """The rendered foveal view (same scene and light) has the person's skin or hair at its centre."""
    t, i = 150, 1
    rig = six_world.true_rig
    aim = pointing(_true_inputs(six_world, t, i), rig.omni.profile)
    img = np.asarray(render_foveal(six_world, t, aim.pan, aim.tilt, 8.0, size=(160, 120)), float)
    centre = img[58:62, 78:82].reshape(-1, 3).mean(0)
    s = np.asarray(six_world.scenario.lighting.spectrum) * 255
    head = [np.asarray(chromaticity(np.asarray(six_world.people.skin[i]) * s)),
            np.asarray(chromaticity(np.asarray(six_world.people.hair[i]) * s))]
    got = np.asarray(chromaticity(centre))
    assert min(np.linalg.norm(got - h) for h in head) < 0.03
