"""Floor <-> image with covariances (omnijax/geometry/_floor.py: the tracker's measurements and the
aim pipeline's way back to the image) against a closed form, Monte Carlo, check_grads and each other."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from omnijax.geometry import floor_measurement, floor_to_image, image_position
from tests.tolerances import CLOSED_FORM

#: Monte Carlo: samples per point and the bound on the whitened sample covariance's entries. Each
#: entry of a sample covariance of n standard normals has sd sqrt(2 / n) (diagonal) or sqrt(1 / n)
#: (off it): 0.0032 and 0.0022 at n = 200 000; the bound is 5 of them. The covariances are first
#: order: where the error ellipse bends (R_p sigma_theta^2 comparable to the radial sd, or close to
#: the horizon) the sample covariance departs from them by more (3 % at 3 px, 3 deg and 0.8 of the
#: paraboloid's rim; more where the radial sd is small against R_p sigma_theta^2), so the points
#: below stay where the first order holds to a few 1e-3.
MC_N = 200_000
MC_BOUND_DIAG, MC_BOUND_OFF = 5 * math.sqrt(2 / MC_N), 5 * math.sqrt(1 / MC_N)


@pytest.fixture(params=["paper", "office_fisheye"])
def rig(request, paper_rig, fisheye_rig):
    return {"paper": paper_rig, "office_fisheye": fisheye_rig}[request.param]


def _detections(rig, n, seed):
    """n detections inside the image (10 % to 80 % of the rim) with sigmas of 0.2-3 px and 0.2-3 deg."""
    rng = np.random.default_rng(seed)
    rim = float(rig.omni.rim)
    return (rng.uniform(0.1, 0.8, n) * rim, rng.uniform(-math.pi, math.pi, n), rng.uniform(0.2, 3.0, n),
            np.radians(rng.uniform(0.2, 3.0, n)))


def _whitened_covariance(samples, cov):
    """The sample covariance of ``samples`` (n, 2) whitened by ``cov``: the identity if ``cov`` is theirs."""
    L = np.linalg.cholesky(cov)
    w = np.linalg.solve(L, (samples - samples.mean(0)).T)
    return np.cov(w)


def _assert_identity(S):
    assert abs(S[0, 0] - 1) < MC_BOUND_DIAG and abs(S[1, 1] - 1) < MC_BOUND_DIAG, S
    assert abs(S[0, 1]) < MC_BOUND_OFF, S


def test_floor_measurement_is_the_closed_form_on_the_paraboloid(paper_rig):
    """Eq 1, R_p = H_o 2 r_m r / (r_m^2 - r^2), and its derivative 2 H_o r_m (r_m^2 + r^2) / (r_m^2 - r^2)^2:
    (X, Y) = R_p (cos, sin) theta and R = J diag(sigma^2) J^T with J written out by hand."""
    H, rm = float(paper_rig.omni.H_o), float(paper_rig.omni.r_m)
    r, th, s_r, s_t = _detections(paper_rig, 20, 0)
    z, R = (np.asarray(a) for a in floor_measurement(paper_rig, r, th, s_r, s_t))
    Rp = H * 2 * rm * r / (rm**2 - r**2)
    dRp = H * 2 * rm * (rm**2 + r**2) / (rm**2 - r**2) ** 2
    c, s = np.cos(th), np.sin(th)
    J = np.stack([np.stack([dRp * c, -Rp * s], -1), np.stack([dRp * s, Rp * c], -1)], -2)
    expect = J @ (np.stack([s_r**2, s_t**2], -1)[:, :, None] * np.swapaxes(J, 1, 2))
    np.testing.assert_allclose(z, np.stack([Rp * c, Rp * s], -1), rtol=CLOSED_FORM, atol=1e-12)
    np.testing.assert_allclose(R, expect, rtol=CLOSED_FORM, atol=CLOSED_FORM * np.abs(expect).max())


def test_floor_measurement_against_monte_carlo(rig):
    """Detections with the rig's default sigmas (1 px, 1 deg: those of an aim without a detection) drawn from
    N((r_f, theta_f), diag(sigma^2)) at 20 % to 70 % of the rim (n = 200 000 per point, seed 0) and
    mapped to the floor: their sample covariance is R (whitened: the identity within MC_BOUND)."""
    rng = np.random.default_rng(0)
    r, th, _, _ = _detections(rig, 4, 1)
    r = np.linspace(0.2, 0.7, 4) * float(rig.omni.rim)
    s_r = np.full(4, float(rig.detection.sigma_r_f))
    s_t = np.full(4, float(rig.detection.sigma_theta_f))
    z, R = (np.asarray(a) for a in floor_measurement(rig, r, th, s_r, s_t))
    for k in range(4):
        rs = r[k] + s_r[k] * rng.standard_normal(MC_N)
        ts = th[k] + s_t[k] * rng.standard_normal(MC_N)
        zs = np.asarray(floor_measurement(rig, rs, ts, 0.0, 0.0)[0])
        _assert_identity(_whitened_covariance(zs, R[k]))


def test_image_position_against_monte_carlo(rig):
    """Floor positions drawn from N(xy, C) with correlated C (sd 3-10 cm, n = 200 000 per point,
    seed 0) and mapped to the image: their sample covariance is image_position's."""
    rng = np.random.default_rng(0)
    r, th, _, _ = _detections(rig, 4, 2)
    xy = np.asarray(floor_measurement(rig, r, th, 0.0, 0.0)[0])
    for k in range(4):
        sd = rng.uniform(0.03, 0.10, 2)
        rho = rng.uniform(-0.8, 0.8)
        C = np.array([[sd[0] ** 2, rho * sd[0] * sd[1]], [rho * sd[0] * sd[1], sd[1] ** 2]])
        rt, C_rt = (np.asarray(a) for a in image_position(rig, jnp.asarray(xy[k]), jnp.asarray(C)))
        samples = rng.multivariate_normal(xy[k], C, MC_N)
        img = np.array(floor_to_image(rig, jnp.asarray(samples)))
        img[:, 1] = rt[1] + np.angle(np.exp(1j * (img[:, 1] - rt[1])))  # azimuth about its mean, unwrapped
        _assert_identity(_whitened_covariance(img, C_rt))


def test_jacobians_against_numerical_differences(rig):
    """The maps whose Jacobians build the covariances, and the floor covariance itself (which the
    layout optimiser differentiates), in both modes against numerical differences (check_grads)."""
    r, th, _, _ = _detections(rig, 2, 3)
    to_floor = jax.jit(lambda r_f, t: floor_measurement(rig, r_f, t, 0.0, 0.0)[0])
    to_image = jax.jit(lambda x, y: floor_to_image(rig, jnp.stack([x, y])))
    cov = jax.jit(lambda r_f, t: floor_measurement(rig, r_f, t, 1.5, 0.02)[1])
    for k in range(2):
        check_grads(to_floor, (r[k], th[k]), order=1, modes=("fwd", "rev"))
        xy = to_floor(r[k], th[k])
        check_grads(to_image, (xy[0], xy[1]), order=1, modes=("fwd", "rev"))
        check_grads(cov, (r[k], th[k]), order=1, modes=("fwd", "rev"))


def test_floor_and_image_are_inverses(rig):
    """Detection -> floor -> image returns the detection and diag(sigma^2); floor point -> image ->
    floor returns the point, and the image covariance pushed back through the floor Jacobian is C."""
    r, th, s_r, s_t = _detections(rig, 50, 4)
    z, R = floor_measurement(rig, r, th, s_r, s_t)
    rt, C = (np.array(a) for a in image_position(rig, z, R))
    np.testing.assert_allclose(rt[:, 0], r, rtol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (rt[:, 1] - th))), 0.0, atol=1e-12)
    np.testing.assert_allclose(C[:, 0, 0], s_r**2, rtol=1e-9)
    np.testing.assert_allclose(C[:, 1, 1], s_t**2, rtol=1e-9)
    assert np.all(np.abs(C[:, 0, 1]) <= 1e-9 * s_r * s_t)

    rng = np.random.default_rng(5)
    A = rng.normal(0, 0.1, (50, 2, 2))
    Cxy = A @ np.swapaxes(A, 1, 2) + 1e-4 * np.eye(2)
    rt, C_rt = image_position(rig, z, jnp.asarray(Cxy))
    back = np.asarray(floor_measurement(rig, rt[:, 0], rt[:, 1], 0.0, 0.0)[0])
    np.testing.assert_allclose(back, np.asarray(z), rtol=1e-12, atol=1e-12)
    J = jax.vmap(jax.jacfwd(lambda v: floor_measurement(rig, v[0], v[1], 0.0, 0.0)[0]))(rt)
    np.testing.assert_allclose(np.asarray(J @ C_rt @ jnp.swapaxes(J, 1, 2)), Cxy, rtol=1e-9, atol=1e-15)


def test_batches_broadcast(paper_rig):
    """Any leading shape, each element as alone."""
    r, th, s_r, s_t = (a.reshape(2, 3) for a in _detections(paper_rig, 6, 6))
    z, R = floor_measurement(paper_rig, r, th, s_r, s_t)
    assert z.shape == (2, 3, 2) and R.shape == (2, 3, 2, 2)
    z1, R1 = floor_measurement(paper_rig, r[1, 2], th[1, 2], s_r[1, 2], s_t[1, 2])
    np.testing.assert_allclose(np.asarray(z[1, 2]), np.asarray(z1), rtol=1e-14)
    np.testing.assert_allclose(np.asarray(R[1, 2]), np.asarray(R1), rtol=1e-14)
    rt, C = image_position(paper_rig, z, R)
    assert rt.shape == (2, 3, 2) and C.shape == (2, 3, 2, 2)
    np.testing.assert_allclose(np.asarray(floor_to_image(paper_rig, z)), np.asarray(rt), rtol=1e-14)
