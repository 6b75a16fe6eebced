"""Camera models: r <-> phi round trips, eq 1 and eq 2, pixels <-> polar, and OCamCalib on real data."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st

from omnijax import (
    Equidistant,
    Equisolid,
    OCamCalib,
    OmniCamera,
    Paraboloid,
    floor_radius,
    head_image_radius,
    parse_ocamcalib,
)
from tests.paths import shared_data
from tests.tolerances import EXACT

IDEAL = [Paraboloid(), Equidistant(), Equisolid()]


@pytest.mark.parametrize("profile", IDEAL, ids=lambda p: p.name)
@given(phi=st.floats(0.0, math.radians(100)))
def test_round_trip_phi(profile, phi):
    assert float(profile.phi(profile.u(phi))) == pytest.approx(phi, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("profile", IDEAL, ids=lambda p: p.name)
def test_horizon_is_r_m(profile):
    assert float(profile.u(math.pi / 2)) == pytest.approx(1.0, rel=EXACT[np.float64])


@given(r_f=st.floats(0.0, 219.0), r_m=st.floats(150.0, 400.0), H_o=st.floats(2.0, 4.0))
def test_paraboloid_floor_radius_is_eq_1(r_f, r_m, H_o):
    r_f = min(r_f, 0.97 * r_m)
    a = 2 * r_m * r_f / (r_m**2 - r_f**2)
    R_p, valid = floor_radius(r_f, r_m, H_o, Paraboloid())
    assert bool(valid)
    assert float(R_p) == pytest.approx(a * H_o, rel=1e-12, abs=1e-12)


@given(r_f=st.floats(1.0, 200.0))
def test_paraboloid_head_radius_is_eq_2(r_f):
    """Eq 2: R_p = b (H_o - H_p), b = 2 r_m r_h / (r_m^2 - r_h^2), with R_p from eq 1."""
    r_m, H_o, H_p = 220.0, 2.7, 1.75
    R_p = float(floor_radius(r_f, r_m, H_o, Paraboloid())[0])
    r_h = float(head_image_radius(r_f, r_m, H_o, H_p, Paraboloid()))
    b = 2 * r_m * r_h / (r_m**2 - r_h**2)
    assert b * (H_o - H_p) == pytest.approx(R_p, rel=1e-10)
    assert r_h > r_f


def test_fisheye_profiles_against_their_definitions():
    phi = np.linspace(0, 1.6, 50)
    f = 300 / (math.pi / 2)
    np.testing.assert_allclose(300 * Equidistant().u(phi), f * phi, rtol=1e-13)
    f_es = 300 / (2 * math.sin(math.pi / 4))
    np.testing.assert_allclose(300 * Equisolid().u(phi), 2 * f_es * np.sin(phi / 2), rtol=1e-13)


def _camera(affine=(1.0, 0.0, 0.0)):
    return OmniCamera(profile=Paraboloid(), center=jnp.array([320.0, 240.0]), r_m=jnp.array(220.0),
                      rim=jnp.array(220.0), H_o=jnp.array(2.7), affine=jnp.array(affine), image_size=(640, 480))


@pytest.mark.parametrize("affine", [(1.0, 0.0, 0.0), (1.02, 0.01, -0.015)])
@given(r=st.floats(0.0, 230.0), theta=st.floats(-math.pi, math.pi))
def test_pixel_polar_round_trip(affine, r, theta):
    cam = _camera(affine)
    x, y = cam.to_pixel(r, theta)
    r2, t2 = cam.to_polar(x, y)
    assert float(r2) == pytest.approx(r, abs=1e-9)
    if r > 1e-6:  # the pixel holds ~1e-13 px of rounding (a few ulp of 320 px): the angle ~1e-13 / r rad of it
        assert math.remainder(float(t2) - theta, 2 * math.pi) == pytest.approx(0.0, abs=1e-9 + 4e-13 / r)


def test_theta_is_measured_from_the_image_x_axis_towards_y():
    cam = _camera()
    x, y = cam.to_pixel(100.0, math.pi / 2)
    assert (float(x), float(y)) == pytest.approx((320.0, 340.0))


# -- OCamCalib, against an independent NumPy transcription of its C functions (ocam_functions.c)


def _cam2world(calib, row, col):
    c, d, e = calib.affine
    invdet = 1.0 / (c - d * e)
    xp = invdet * ((row - calib.center_row) - d * (col - calib.center_col))
    yp = invdet * (-e * (row - calib.center_row) + c * (col - calib.center_col))
    r = np.hypot(xp, yp)
    zp = sum(a * r**i for i, a in enumerate(calib.ss))
    n = np.sqrt(xp**2 + yp**2 + zp**2)
    return xp / n, yp / n, zp / n


def _world2cam(calib, x, y, z):
    c, d, e = calib.affine
    norm = np.hypot(x, y)
    theta = np.arctan(z / norm)
    rho = sum(a * theta**i for i, a in enumerate(calib.invpol))
    u, v = x / norm * rho, y / norm * rho
    return u * c + v * d + calib.center_row, u * e + v + calib.center_col


@pytest.fixture(scope="module")
def ocam():
    text = shared_data("catadioptric_office", "calib_results.txt").read_text()
    calib = parse_ocamcalib(text)
    prof = OCamCalib(ss=jnp.asarray(calib.ss), invpol=jnp.asarray(calib.invpol), rho0=calib.horizon_radius)
    cam = OmniCamera(profile=prof, center=jnp.array([calib.center_col, calib.center_row]),
                     r_m=jnp.array(calib.horizon_radius), rim=jnp.array(calib.roi_max),
                     H_o=jnp.array(1.0), affine=jnp.asarray(calib.affine), image_size=(calib.width, calib.height))
    return calib, cam


@pytest.mark.realdata
def test_ocamcalib_file_parses(ocam):
    calib, _ = ocam
    assert calib.ss[0] == pytest.approx(-266.588) and len(calib.invpol) == 12
    assert (calib.height, calib.width, calib.crop_left, calib.crop_right) == (1080, 1300, 300, 320)


@pytest.mark.realdata
def test_ocamcalib_reproduces_its_own_round_trip(ocam):
    """Pixels through the file's cam2world (ss) and back through its world2cam (invpol)."""
    calib, cam = ocam
    rng = np.random.default_rng(0)
    n = 2000
    rad = rng.uniform(calib.roi_min, calib.roi_max, n)
    ang = rng.uniform(-np.pi, np.pi, n)
    row = calib.center_row + rad * np.sin(ang)
    col = calib.center_col + rad * np.cos(ang)
    ref_row, ref_col = _world2cam(calib, *_cam2world(calib, row, col))
    ref_err = np.hypot(ref_row - row, ref_col - col).max()
    assert ref_err < 0.5  # the calibration's own round trip, in px
    # ours: pixel -> (r, theta) -> phi (ss) -> r (invpol) -> pixel
    r, theta = cam.to_polar(col, row)
    r2 = cam.radius(cam.angle(r))
    x2, y2 = cam.to_pixel(r2, theta)
    ours = np.hypot(np.asarray(x2) - col, np.asarray(y2) - row)
    np.testing.assert_allclose(ours, np.hypot(ref_row - row, ref_col - col), atol=1e-6)
    # and the ray direction of each pixel is the C code's
    xw, yw, zw = _cam2world(calib, row, col)
    np.testing.assert_allclose(np.asarray(cam.angle(r)), np.arctan2(np.hypot(xw, yw), -zw), atol=1e-12)
    np.testing.assert_allclose(np.asarray(theta), np.arctan2(xw, yw), atol=1e-9)


@pytest.mark.realdata
def test_ocamcalib_rim_is_where_the_image_shows_it(ocam):
    """The mirror's rim (the file's ROI max radius) is where the radial brightness falls off."""
    import cv2

    calib, _ = ocam
    img = cv2.imread(str(shared_data("catadioptric_office", "example.jpg")), cv2.IMREAD_GRAYSCALE)
    assert img.shape == (1080, 1920)
    cx, cy = calib.center_col + calib.crop_left, calib.center_row
    yy, xx = np.mgrid[: img.shape[0], : img.shape[1]]
    r = np.hypot(xx - cx, yy - cy).astype(int)
    profile = np.bincount(r.ravel(), img.ravel().astype(float)) / np.maximum(np.bincount(r.ravel()), 1)
    smooth = np.convolve(profile, np.ones(5) / 5, mode="same")
    edge = 450 + int(np.argmin(np.diff(smooth[450:700])))
    assert abs(edge - calib.roi_max) < 20, edge


def test_gradients_of_the_profiles_are_finite_at_the_edges():
    for prof in IDEAL:
        g = jax.grad(prof.phi)
        for u in (0.0, 0.999, 1.0):
            assert np.isfinite(float(g(u))), (prof.name, u)
