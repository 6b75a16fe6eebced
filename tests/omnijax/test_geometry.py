"""Eqs 1-4: pan by atan2, and finite values and gradients at every singular place."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st

from omnijax import D_P_MIN, floor_radius, image_to_floor, pointing, pointing_outputs, world_to_image


def _x(rig, r_f, theta_f):
    return rig.input_mean(r_f, theta_f)


def _finite_everywhere(rig, x):
    return bool(_all_finite(x, rig.omni.profile))


@eqx.filter_jit
def _all_finite(x, profile):
    """Values, Jacobian and Hessian of the pointing outputs all finite: one compiled program for the module's
    tests, as the pipeline runs them (op by op, the first test that checked took 165 compilations, 40 s on a
    loaded machine)."""
    y = pointing_outputs(x, profile)
    J = jax.jacfwd(pointing_outputs)(x, profile)
    H = jax.hessian(pointing_outputs)(x, profile)
    return jnp.all(jnp.isfinite(y)) & jnp.all(jnp.isfinite(J)) & jnp.all(jnp.isfinite(H))


@pytest.mark.slow
def test_under_the_omni_camera(paper_rig):
    x = _x(paper_rig, 0.0, 0.3)
    p = pointing(x, paper_rig.omni.profile)
    assert bool(p.valid) and float(p.radius) == 0.0
    assert float(p.distance) == pytest.approx(float(paper_rig.foveal.D_c))
    assert float(p.pan) == 0.0
    assert _finite_everywhere(paper_rig, x)


@pytest.mark.parametrize("r_f", [219.0, 219.999999, 220.0, 220.000001, 260.0, -1.0])
def test_at_and_beyond_the_horizon(paper_rig, r_f):
    x = _x(paper_rig, r_f, 1.0)
    p = pointing(x, paper_rig.omni.profile)
    assert not bool(p.valid)  # R_p > 100 H_o: beyond the usable floor
    assert _finite_everywhere(paper_rig, x)


@pytest.mark.parametrize("offset", [0.0, 1e-9, 0.01, D_P_MIN * 0.99])
def test_person_at_the_ptz_foot(paper_rig, offset):
    rig = paper_rig
    D_c, th = float(rig.foveal.D_c), float(rig.foveal.theta_c)
    # the foot image radius whose floor point is D_c - offset from the omni axis, towards the PTZ
    from scipy.optimize import brentq

    R = D_c - offset
    r_f = brentq(lambda r: float(floor_radius(r, rig.omni.r_m, rig.omni.H_o, rig.omni.profile)[0]) - R, 0, 219)
    x = _x(rig, r_f, th)
    p = pointing(x, rig.omni.profile)
    assert not bool(p.valid)
    assert _finite_everywhere(rig, x)


def test_just_outside_the_ptz_foot_is_valid(paper_rig):
    rig = paper_rig
    x = _x(rig, 60.0, float(rig.foveal.theta_c) + 0.5)
    assert bool(pointing(x, rig.omni.profile).valid)


@given(r_f=st.floats(0.0, 200.0), theta=st.floats(-math.pi, math.pi))
def test_sin_pan_is_eq_4_and_D_p_is_eq_3(paper_rig, r_f, theta):
    rig = paper_rig
    x = _x(rig, r_f, theta)
    p = pointing(x, rig.omni.profile)
    if not bool(p.valid):
        return
    R, D_c, vt = float(p.radius), float(rig.foveal.D_c), theta - float(rig.foveal.theta_c)
    D_p = math.sqrt(D_c**2 + R**2 - 2 * D_c * R * math.cos(vt))  # eq 3 as printed
    assert float(p.distance) == pytest.approx(D_p, rel=1e-9, abs=1e-9)
    assert math.sin(float(p.pan)) == pytest.approx(R / D_p * math.sin(vt), abs=1e-12)  # eq 4
    aim = float(rig.person.H_p - rig.person.R_h - rig.foveal.H_f)
    assert math.tan(float(p.tilt)) == pytest.approx(aim / D_p, rel=1e-12)  # eq 4


def test_pan_beyond_90_degrees(paper_rig):
    """A person behind the PTZ (seen from the omni axis) needs |pan| > 90 deg; asin would fold it."""
    rig = paper_rig
    D_c = float(rig.foveal.D_c)
    # floor point at (D_c + 0.2, 0.7): beyond the PTZ, slightly to one side
    X, Y = D_c + 0.2, 0.7
    px, py = world_to_image(rig.omni, X, Y, 0.0)
    r, theta = rig.omni.to_polar(px, py)
    p = pointing(_x(rig, r, theta), rig.omni.profile)
    assert bool(p.valid)
    assert float(p.pan) == pytest.approx(math.atan2(0.7, -0.2), abs=1e-9)
    assert abs(math.degrees(float(p.pan))) > 90


@given(X=st.floats(-4.0, 4.0), Y=st.floats(-3.0, 3.0))
def test_world_image_round_trip(paper_rig, X, Y):
    px, py = world_to_image(paper_rig.omni, X, Y, 0.0)
    X2, Y2, ok = image_to_floor(paper_rig.omni, px, py)
    assert bool(ok)
    assert (float(X2), float(Y2)) == pytest.approx((X, Y), abs=1e-9)


def test_room_contains_matches_matplotlib(paper_rig):
    from matplotlib.path import Path

    rng = np.random.default_rng(1)
    pts = rng.uniform([-6, -4], [5, 4], (5000, 2))
    room = paper_rig.room
    ours = np.asarray(room.contains(pts[:, 0], pts[:, 1]))
    ref = Path(np.asarray(room.outline)).contains_points(pts)
    for zone in room.exclude:
        ref &= ~Path(np.asarray(zone)).contains_points(pts)
    np.testing.assert_array_equal(ours, ref)


def test_room_outside_by_is_the_distance_to_the_floor_a_person_can_stand_on(paper_rig):
    """Against a brute force: the least distance to 20 000 points along each polygon's edges, for
    points outside the outline and inside an excluded zone; 0 on the floor (2000 points, seed 2)."""
    from matplotlib.path import Path

    rng = np.random.default_rng(2)
    pts = rng.uniform([-6, -4], [5, 4], (2000, 2))
    room = paper_rig.room
    ours = np.asarray(room.outside_by(pts[:, 0], pts[:, 1]))

    def edge_points(poly):
        poly = np.asarray(poly)
        t = np.linspace(0.0, 1.0, 20000 // len(poly), endpoint=False)[:, None]
        return np.concatenate([a + t * (b - a) for a, b in zip(poly, np.roll(poly, -1, 0))])

    def nearest(poly):
        # every point against every edge point, by blocks of 50 points and per coordinate: the same numbers as
        # the whole (2000, 20 000, 2) table at once, which took 15-30 s per polygon to allocate and sum
        e = edge_points(poly)
        return np.concatenate([np.sqrt((p[:, None, 0] - e[None, :, 0]) ** 2 + (p[:, None, 1] - e[None, :, 1]) ** 2)
                               .min(1) for p in np.array_split(pts, 40)])

    ref = np.where(Path(np.asarray(room.outline)).contains_points(pts), 0.0, nearest(room.outline))
    for zone in room.exclude:
        ref = np.maximum(ref, np.where(Path(np.asarray(zone)).contains_points(pts), nearest(zone), 0.0))
    np.testing.assert_allclose(ours, ref, atol=2e-3)
    assert (ours == 0).mean() > 0.3 and (ours > 0.5).any()
