"""Zoom: the lens table, eq 15 as printed, and the calibrated rule against SciPy and simulation."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.stats import multivariate_normal, norm

from omnijax import (
    aim,
    choose_zoom,
    containment_probability,
    face_pixels,
    head_half_size,
    paper_fov,
    rectangle_probability,
)
from tests.autodiff import assert_jacobians_close
from tests.tolerances import FINITE_DIFF


def _scipy_rectangle(cov, a, b):
    mvn = multivariate_normal(mean=[0, 0], cov=cov)
    return mvn.cdf([a, b]) - mvn.cdf([-a, b]) - mvn.cdf([a, -b]) + mvn.cdf([-a, -b])


@settings(max_examples=200)
@given(sx=st.floats(0.01, 2.0), sy=st.floats(0.01, 2.0), rho=st.floats(-0.95, 0.95),
       a=st.floats(0.01, 5.0), b=st.floats(0.01, 5.0))
def test_rectangle_probability_against_scipy(sx, sy, rho, a, b):
    cov = np.array([[sx * sx, rho * sx * sy], [rho * sx * sy, sy * sy]])
    ours = float(rectangle_probability(jnp.asarray(cov), a, b))
    assert ours == pytest.approx(_scipy_rectangle(cov, a, b), abs=2e-5)


def test_rectangle_probability_independent_axes_is_a_product():
    cov = jnp.diag(jnp.array([0.3**2, 0.7**2]))
    expect = (2 * norm.cdf(0.5 / 0.3) - 1) * (2 * norm.cdf(1.1 / 0.7) - 1)
    assert float(rectangle_probability(cov, 0.5, 1.1)) == pytest.approx(expect, abs=1e-12)


def test_lens_table_is_exact_at_its_entries_and_invertible(paper_rig):
    lens = paper_rig.foveal.lens
    for z, f in zip(np.asarray(lens.zoom), np.asarray(lens.fov_h)):
        assert float(lens.fov(z)[0]) == pytest.approx(f, rel=1e-12)
    zs = np.geomspace(1.0, 18.0, 57)
    back = np.asarray(lens.zoom_for_tan_half_fov_h(jnp.tan(0.5 * lens.fov(zs)[0])))
    np.testing.assert_allclose(back, zs, rtol=1e-10)
    fh, fv = (np.asarray(v) for v in lens.fov(zs))
    assert np.all(np.diff(fh) < 0)
    np.testing.assert_allclose(np.tan(fv / 2), np.tan(fh / 2) * 480 / 640, rtol=1e-12)


def test_paper_factor_is_5_15_for_99_percent():
    """f_v / 2 = Phi^-1((1 + 0.99) / 2) = 2.576, so eq 15 adds 5.15 sigma."""
    f = 2 * norm.ppf(0.5 * (1 + 0.99))
    assert f == pytest.approx(5.1517, abs=1e-4)
    R_h, D, tilt, var = 0.1, 3.0, -0.1, 1e-4
    gh, gv = paper_fov(4 * var, var, D, tilt, R_h, 0.99)
    Dp = D / math.cos(tilt)
    assert float(gv) == pytest.approx(2 * math.atan((R_h + f * 1e-2 * Dp) / math.hypot(R_h, Dp)), rel=1e-12)
    assert float(gh) == pytest.approx(2 * math.atan((R_h + f * 2e-2 * Dp) / math.hypot(R_h, Dp)), rel=1e-12)


@pytest.mark.parametrize("r_f,theta", [(40.0, 2.5), (100.0, 0.7), (130.0, -2.0), (60.0, 0.15)])
def test_calibrated_zoom_is_the_largest_that_meets_p_contain(paper_rig, r_f, theta):
    a = aim(paper_rig, r_f, theta)
    lens, z = paper_rig.foveal.lens, float(a.zoom.zoom)
    p = lambda zz: float(containment_probability(
        lens, zz, a.covariance.pan_tilt, a.pointing.tilt, a.pointing.slant, paper_rig.person.R_h))
    assert float(a.zoom.probability) == pytest.approx(p(z))
    if bool(a.zoom.feasible):
        assert p(z) >= 0.99 - 1e-9
        if z < float(lens.zoom_range[1]) * (1 - 1e-6):
            assert p(z * 1.001) < 0.99
    else:
        assert z == pytest.approx(float(lens.zoom_range[0]))


def test_zoom_is_clamped_to_the_device_range(paper_rig):
    lens = paper_rig.foveal.lens
    tiny = jnp.diag(jnp.array([1e-12, 1e-12, 1e-12, 1e-12]))
    huge = jnp.diag(jnp.array([1.0, 1.0, 1.0, 1.0]))
    for rule in ("paper", "calibrated"):
        far = choose_zoom(lens, rule, tiny, 10.0, -0.05, 10.0, 0.1, 0.99)
        near = choose_zoom(lens, rule, huge, 1.0, -0.3, 1.1, 0.1, 0.99)
        assert float(far.zoom) == pytest.approx(18.0)
        assert float(near.zoom) == pytest.approx(1.0)
        assert not bool(near.feasible)


def test_paper_rule_is_more_conservative_than_calibrated(paper_rig):
    """Eq 15 adds 5.15 sigma per axis where a joint 99 % needs about 2.8: it zooms out further."""
    import dataclasses

    paper = dataclasses.replace(paper_rig, zoom_rule="paper")
    for r_f, th in [(60.0, 2.0), (110.0, 1.0), (140.0, -2.5)]:
        zp, zc = float(aim(paper, r_f, th).zoom.zoom), float(aim(paper_rig, r_f, th).zoom.zoom)
        assert zp < zc


def _pinhole_offset(pan_c, tilt_c, pan_t, tilt_t):
    """Normalised image coordinates of the direction (pan_t, tilt_t) in a camera aimed at (pan_c, tilt_c)."""
    h = np.stack([np.cos(tilt_t) * np.cos(pan_t), np.cos(tilt_t) * np.sin(pan_t), np.sin(tilt_t)], -1)
    f = np.stack([np.cos(tilt_c) * np.cos(pan_c), np.cos(tilt_c) * np.sin(pan_c), np.sin(tilt_c)], -1)
    right = np.stack([-np.sin(pan_c), np.cos(pan_c), np.zeros_like(pan_c)], -1)
    up = np.stack([-np.sin(tilt_c) * np.cos(pan_c), -np.sin(tilt_c) * np.sin(pan_c), np.cos(tilt_c)], -1)
    z = (h * f).sum(-1)
    return (h * right).sum(-1) / z, (h * up).sum(-1) / z


@pytest.mark.parametrize("r_f,theta", [(100.0, 0.7), (130.0, -2.0), (45.0, 2.8)])
def test_containment_probability_matches_simulated_pinhole_frames(paper_rig, r_f, theta):
    """n = 40000 Gaussian pointing errors through an exact pinhole PTZ: the empirical rate of whole-head
    frames matches the predicted probability within 0.004 (binomial sd <= 0.0005 near 0.99; the
    rest is the small-angle mapping's bias)."""
    rig = paper_rig
    a = aim(rig, r_f, theta)
    cov = np.asarray(a.covariance.pan_tilt)
    rng = np.random.default_rng(0)
    err = rng.multivariate_normal([0, 0], cov, 40_000)
    pan_t, tilt_t = float(a.pointing.pan), float(a.pointing.tilt)
    x, y = _pinhole_offset(pan_t + err[:, 0], tilt_t + err[:, 1], pan_t, tilt_t)
    fov_h, fov_v = float(a.zoom.fov_h), float(a.zoom.fov_v)
    rho = float(head_half_size(a.pointing.slant, rig.person.R_h))
    inside = (np.abs(x) + rho <= math.tan(fov_h / 2)) & (np.abs(y) + rho <= math.tan(fov_v / 2))
    assert inside.mean() == pytest.approx(float(a.zoom.probability), abs=0.004)


def test_face_pixels(paper_rig):
    lens = paper_rig.foveal.lens
    px = float(face_pixels(lens, 4.0, 3.0, 0.1))
    expect = 640 * (0.1 / math.sqrt(9 - 0.01)) / math.tan(math.radians(12.9) / 2)
    assert px == pytest.approx(expect, rel=1e-12)


def test_zoom_is_jittable_and_vmappable(paper_rig):
    r = jnp.linspace(20.0, 150.0, 16)
    th = jnp.linspace(-3.0, 3.0, 16)
    out = jax.vmap(lambda a, b: aim(paper_rig, a, b))(r, th)
    assert out.zoom.zoom.shape == (16,)
    assert bool(jnp.all(jnp.isfinite(out.zoom.zoom)))


def _log_zoom(u, lens, cov4, distance, tilt, slant, R_h, p_contain):
    """log of the calibrated zoom after relative changes ``u`` of (c00, c11, c01, tilt, slant, 1 - p_contain)."""
    scale = jnp.ones((4, 4)).at[0, 0].set(1 + u[0]).at[1, 1].set(1 + u[1]).at[0, 1].set(1 + u[2]).at[1, 0].set(1 + u[2])
    p = 1.0 - (1.0 - p_contain) * (1 + u[5])
    return jnp.log(choose_zoom(lens, "calibrated", cov4 * scale, distance, tilt * (1 + u[3]), slant * (1 + u[4]),
                               R_h, p).zoom)


@pytest.mark.parametrize("r_f,theta", [pytest.param(100.0, 0.7, marks=pytest.mark.slow),
                                       pytest.param(130.0, -2.0, marks=pytest.mark.slow), (45.0, 2.8)])
def test_calibrated_zoom_gradient_matches_finite_differences(paper_rig, r_f, theta):
    """The implicit-function-theorem derivatives of the calibrated zoom, forward and reverse mode,
    against central differences of the root itself, w.r.t. relative changes (step 1e-4) of the
    pan/tilt covariance (c00, c11, c01 kept symmetric), tilt, slant and 1 - p_contain (the scale on
    which the zoom changes). The root is found to 1e-12 in its normal score, so the differences
    carry ~1e-8 of noise: entries are compared to FINITE_DIFF relative plus 1e-7 absolute."""
    a = aim(paper_rig, r_f, theta)
    lens = paper_rig.foveal.lens
    assert bool(a.zoom.feasible) and 1.0 < float(a.zoom.zoom) < 18.0
    assert np.min(np.abs(np.log(float(a.zoom.zoom) / np.asarray(lens.zoom)))) > 1e-3  # off the table's kinks
    at = (lens, a.covariance.cov, a.pointing.distance, a.pointing.tilt, a.pointing.slant, paper_rig.person.R_h,
          paper_rig.p_contain)
    assert_jacobians_close(_log_zoom, np.zeros(6), args=at, step=1e-4, rtol=FINITE_DIFF, atol=1e-7)


def test_calibrated_zoom_gradient_is_zero_and_finite_where_clamped(paper_rig):
    lens = paper_rig.foveal.lens
    chosen = jax.jit(lambda c: choose_zoom(lens, "calibrated", c, 10.0, -0.03, 10.0, 0.1, 0.99).zoom)
    slope = jax.jit(jax.grad(chosen))
    for var, zoom in ((1e-12, 18.0), (1.0, 1.0)):  # the longest zoom holds the head; even the widest cannot
        cov4 = jnp.diag(jnp.full(4, var))
        assert float(chosen(cov4)) == zoom
        assert np.all(np.asarray(slope(cov4)) == 0.0)
