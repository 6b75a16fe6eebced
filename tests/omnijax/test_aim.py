"""The aim pipeline: the sigma rule, its entry points against each other and against the loop's
aim before the pipeline existed, the zero offsets, the rules, vmap and gradients."""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from omnijax import (
    aim,
    aim_at_floor,
    aim_detection,
    aim_from_image,
    choose_zoom,
    detection_sigmas,
    floor_from_detections,
)
from omnijax.geometry import floor_measurement, floor_radius, floor_to_image
from omnijax.zoom import ZOOM_RULES

# Floor points (m) with covariances (m^2: XX, XY, YY) and what main's loop (`aim_at_floor` in
# runtime/realtime/loop.py at f6498d6, before this pipeline) sent for them: pan, tilt (rad), the
# paper and calibrated zooms, and the pointing's sd (rad) of pan and tilt. The pipeline reproduced
# all of 400 random points per rig bit for bit when it replaced that function.
MAIN_LOOP = {
    "paper": [
        ((0.46830116110734377, -1.3812797174167781), (0.1939525863668138, -0.04627179947996902, 0.14552905680045403),
         (-0.4994541995118505, -0.12076880587846368, 1.0, 1.0388817337779044, 0.1542440672025047,
          0.024001006738481087)),
        ((-2.2503145274365584, -0.5226219439146438), (0.2803838328545526, 0.10362240353665977, 0.6180096207050124),
         (-0.09921424913415762, -0.06623780411213624, 1.0, 1.1311581636149064, 0.14611749255841813,
          0.012056493560533487)),
        ((-1.325807155013412, -2.9981958593584626),
         (0.0001621345984122119, 0.0006360194004492711, 0.0066139876915246275),
         (-0.6060767732947434, -0.06640109158971602, 4.836470033540754, 7.172073902763129, 0.01617450049335644,
          0.009907730787667936)),
        ((-3.7607419087828973, -2.970603510068546), (0.3161240039951322, -0.027216277454318923, 0.02126563087989945),
         (-0.4139958399002165, -0.04736057722388675, 2.1904561126900015, 3.8166082371312604, 0.040782026158217036,
          0.007736299709546614)),
        ((-1.128333278099125, 0.07289471772540246),
         (0.0003508148195379469, -0.0013936531725080095, 0.01003950852335017),
         (0.017655343845948142, -0.08456460683500476, 3.035476656306592, 5.1922910105501145, 0.02420752064768229,
          0.012666963179168633)),
        ((3.0056388803350833, -0.24683658611050197),
         (0.0006475966334710664, 0.000499704745592905, 0.0016885966228793144),
         (-1.5936369429299746, -0.9564344276417124, 1.0, 1.0, 0.42272914043414794, 0.10478132444629333)),
    ],
    "office_fisheye": [
        ((1.369616873214543, -1.8417062898890375), (0.1939525863668138, -0.04627179947996902, 0.14552905680045403),
         (-0.6139267700871626, -0.2427550241401996, 1.1658385931654252, 1.8991629817260904, 0.11897765240411266,
          0.02817990949864801)),
        ((-2.115787855687895, -0.6968292585528584), (0.2803838328545526, 0.10362240353665977, 0.6180096207050124),
         (0.0798234850204561, -0.17029778792254918, 1.0, 1.8843306917665685, 0.12103787245929899,
          0.02360664064486538)),
        ((-0.9305219936069387, -3.9975944791446167),
         (0.0001621345984122119, 0.0006360194004492711, 0.0066139876915246275),
         (-0.4437132441551508, -0.13947691695541284, 4.675191511042508, 8.030526204442769, 0.008219643448987896,
          0.011545606978339104)),
        ((-4.052233216388331, -3.960804680091395), (0.3161240039951322, -0.027216277454318923, 0.02126563087989945),
         (-0.1549309491896021, -0.1072938082986882, 2.5692306328436088, 4.950133582202301, 0.04484861943599612,
          0.010109353871556155)),
        ((-0.6773503565373398, 0.09719295696720298),
         (0.0003508148195379469, -0.0013936531725080095, 0.01003950852335017),
         (0.10433645605338364, -0.23684396686017525, 2.6920304278615497, 4.769241181484835, 0.024038294295494513,
          0.01919030038516829)),
        ((4.622613949147542, -0.32911544814733595),
         (0.0006475966334710664, 0.000499704745592905, 0.0016885966228793144),
         (-1.7005336065134014, -0.35814262014970716, 1.7285324134069648, 3.231380614148835, 0.027405767920505378,
          0.027826072984816305)),
    ],
}


@pytest.fixture(params=sorted(MAIN_LOOP))
def rig(request, paper_rig, fisheye_rig):
    return {"paper": paper_rig, "office_fisheye": fisheye_rig}[request.param], MAIN_LOOP[request.param]


def _sigma_defaults(rig):
    return float(rig.detection.sigma_r_f), float(rig.detection.sigma_theta_f)


# ---------------------------------------------------------------------------------------------
# The sigma rule


def _with_rule(rig, gain_r, extra_r, gain_t, extra_t, per_m=0.0, lateral_m=0.0):
    return eqx.tree_at(lambda r: (r.detection.sigma_gain_r_f, r.detection.sigma_extra_r_f,
                                  r.detection.sigma_gain_theta_f, r.detection.sigma_extra_theta_f,
                                  r.detection.sigma_extra_r_f_per_m, r.detection.sigma_lateral_m),
                       rig, tuple(jnp.asarray(v, float) for v in (gain_r, extra_r, gain_t, extra_t, per_m, lateral_m)))


def test_sigma_rule_scales_the_detectors_sigmas_and_adds_the_extra_term(paper_rig):
    rig = _with_rule(paper_rig, 1.5, 0.4, 2.0, 0.003)
    s_r, s_t = detection_sigmas(rig, jnp.array([0.0, 1.0, 30.0]), jnp.array([0.2, 0.0, 0.004]))
    np.testing.assert_allclose(np.asarray(s_r), np.hypot(1.5 * np.array([0.0, 1.0, 30.0]), 0.4), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(s_t), np.hypot(2.0 * np.array([0.2, 0.0, 0.004]), 0.003), rtol=1e-12)
    s_r, s_t = detection_sigmas(rig)  # no detection: the rig's defaults as they are
    assert (float(s_r), float(s_t)) == _sigma_defaults(rig)
    # the bound part (a foot the detector could not see) is added as it is, not scaled by the gain
    s_r, s_t = detection_sigmas(rig, jnp.array([2.0, 2.0]), jnp.array([0.1, 0.1]), jnp.array([0.0, 5.0]),
                                jnp.array([0.0, 0.5]))
    np.testing.assert_allclose(np.asarray(s_r), np.sqrt((1.5 * 2.0) ** 2 + np.array([0.0, 25.0]) + 0.4**2), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(s_t), np.sqrt((2.0 * 0.1) ** 2 + np.array([0.0, 0.25]) + 0.003**2),
                               rtol=1e-12)


def test_sigma_rule_range_terms_grow_the_radius_far_and_the_azimuth_near(paper_rig):
    """With a detection's r_f, sigma_r_f gains ``per_m * R`` and sigma_theta_f ``lateral / R`` in quadrature,
    R its foot's floor distance by eq 1 (at least min_floor_radius); without r_f, neither."""
    rig = _with_rule(paper_rig, 1.5, 0.4, 2.0, 0.003, per_m=0.8, lateral_m=0.01)
    r_f = jnp.array([2.0, 60.0, 140.0])
    s_r, s_t = jnp.array([1.0, 1.0, 1.0]), jnp.array([0.01, 0.01, 0.01])
    got_r, got_t = detection_sigmas(rig, s_r, s_t, 0.0, 0.0, r_f)
    o = rig.omni
    R = np.maximum(np.asarray(floor_radius(r_f, o.r_m, o.H_o, o.profile)[0]), float(rig.detection.min_floor_radius))
    assert R[0] == float(rig.detection.min_floor_radius) and R[2] > 2.0  # under the camera: clamped
    np.testing.assert_allclose(np.asarray(got_r), np.sqrt(1.5**2 + 0.4**2 + (0.8 * R) ** 2), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(got_t), np.sqrt(0.02**2 + 0.003**2 + (0.01 / R) ** 2), rtol=1e-12)
    assert np.all(np.diff(np.asarray(got_r)) > 0) and np.all(np.diff(np.asarray(got_t)) < 0)
    no_r, no_t = detection_sigmas(rig, s_r, s_t)
    np.testing.assert_allclose(np.asarray(no_r), np.hypot(1.5, 0.4), rtol=1e-12)
    # the tracker's measurements carry them
    _, cov = floor_from_detections(rig, r_f, jnp.zeros(3), s_r, s_t)
    _, cov0 = floor_measurement(rig, r_f, jnp.zeros(3), got_r, got_t)
    np.testing.assert_allclose(np.asarray(cov), np.asarray(cov0), rtol=1e-12)


def test_the_rig_files_carry_fitted_coefficients(paper_rig):
    """configs/paper.toml holds the coefficients benchmarks/fit_detection_sigmas.py fitted (not the
    schema's identity defaults), and a detector's sigmas are never reduced below the extra term."""
    d = paper_rig.detection
    assert float(d.sigma_gain_theta_f) != 1.0 and float(d.sigma_extra_r_f) > 0
    assert float(d.sigma_gain_r_f) != 1.0 and float(d.sigma_lateral_m) > 0
    assert float(d.sigma_extra_r_f_per_m) >= 0  # fitted to 0 since the feet the head placed carry a bound
    s_r, s_t = detection_sigmas(paper_rig, jnp.zeros(3), jnp.zeros(3))
    assert np.all(np.asarray(s_r) == float(d.sigma_extra_r_f))
    assert np.all(np.asarray(s_t) == float(d.sigma_extra_theta_f))


def test_floor_measurements_use_the_sigma_rule(paper_rig):
    """The tracker's measurements carry the rule's sigmas, not the detector's raw ones."""
    rig = _with_rule(paper_rig, 1.5, 0.4, 2.0, 0.003)
    r_f, th = jnp.array([60.0, 110.0, 140.0]), jnp.array([0.3, -2.0, 2.9])
    s_r, s_t = jnp.array([0.0, 4.0, 0.2]), jnp.array([0.0, 0.0, 0.05])
    z, R = floor_from_detections(rig, r_f, th, s_r, s_t)
    z0, R0 = floor_measurement(rig, r_f, th, jnp.hypot(1.5 * s_r, 0.4), jnp.hypot(2.0 * s_t, 0.003))
    np.testing.assert_array_equal(np.asarray(z), np.asarray(z0))
    np.testing.assert_allclose(np.asarray(R), np.asarray(R0), rtol=1e-12)


def test_a_detection_is_aimed_with_the_rule_sigmas(paper_rig):
    d_r, d_t = _sigma_defaults(paper_rig)
    s_r, s_t = detection_sigmas(paper_rig, 0.0, 3.0 * d_t, 0.0, 0.0, 100.0)  # the range terms at r_f = 100 px
    a = aim_detection(paper_rig, 100.0, 0.7, 0.0, 3.0 * d_t)
    b = aim_from_image(paper_rig, 100.0, 0.7, jnp.diag(jnp.stack([s_r**2, s_t**2])))
    np.testing.assert_array_equal(np.asarray(a.covariance.cov), np.asarray(b.covariance.cov))
    assert float(a.zoom.zoom) == float(b.zoom.zoom)


# ---------------------------------------------------------------------------------------------
# What the loop sends


def test_aim_at_floor_sends_what_mains_loop_sent(rig):
    """`run` and `demo` send what they sent before the pipeline (pan, tilt, both zooms, the sds the
    dead zone uses), at 1e-12 relative (bit for bit on the machine they were recorded on)."""
    rig, rows = rig
    for xy, (cxx, cxy, cyy), expect in rows:
        a = aim_at_floor(rig, jnp.asarray(xy), jnp.array([[cxx, cxy], [cxy, cyy]]), ZOOM_RULES)
        cov = np.asarray(a.covariance.cov)
        got = (float(a.pointing.pan), float(a.pointing.tilt), float(a.zooms["paper"].zoom),
               float(a.zooms["calibrated"].zoom), math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1]))
        np.testing.assert_allclose(got, expect, rtol=1e-12, atol=0)
        assert bool(a.pointing.valid)


def test_a_detection_through_the_floor_is_aimed_as_the_detection(rig):
    """Detection -> floor measurement (the tracker's) -> back to the image: the same aim as the
    detection aimed directly (floor and image conversions are inverses, covariances included)."""
    rig, _ = rig
    rng = np.random.default_rng(3)
    rim = float(rig.omni.rim)
    r_f = rng.uniform(0.2, 0.8, 12) * rim
    th = rng.uniform(-math.pi, math.pi, 12)
    s_r, s_t = rng.uniform(0.0, 3.0, 12), rng.uniform(0.0, 0.05, 12)
    z, R = floor_from_detections(rig, r_f, th, s_r, s_t)
    for k in range(12):
        a = aim_detection(rig, r_f[k], th[k], s_r[k], s_t[k], ZOOM_RULES)
        b = aim_at_floor(rig, z[k], R[k], ZOOM_RULES)
        np.testing.assert_allclose(np.asarray(b.x), np.asarray(a.x), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.asarray(b.covariance.cov), np.asarray(a.covariance.cov), rtol=1e-9,
                                   atol=1e-12 * float(np.abs(a.covariance.cov).max()))
        for rule in ZOOM_RULES:
            assert float(b.zooms[rule].zoom) == pytest.approx(float(a.zooms[rule].zoom), rel=1e-9)


def test_a_floor_point_without_covariance_is_a_detection_with_the_default_sigmas(paper_rig):
    """The optimiser's and calibration's floor points: the full-covariance core agrees with the
    diagonal autodiff method of `omnijax variance` (two ways of writing J Sigma J^T)."""
    for xy in ((1.0, 0.5), (-2.0, 1.5), (2.5, -2.0)):
        a = aim_at_floor(paper_rig, jnp.asarray(xy))
        rt = floor_to_image(paper_rig, jnp.asarray(xy))
        b = aim(paper_rig, rt[0], rt[1])
        np.testing.assert_allclose(np.asarray(a.covariance.cov), np.asarray(b.covariance.cov), rtol=1e-12,
                                   atol=1e-15)
        assert float(a.zoom.zoom) == pytest.approx(float(b.zoom.zoom), rel=1e-10)
        assert float(a.pointing.radius) == pytest.approx(math.hypot(*xy), rel=1e-12)


# ---------------------------------------------------------------------------------------------
# Rules, zero offsets, vmap and gradients


@pytest.mark.slow
def test_rules(paper_rig):
    only = aim_detection(paper_rig, 100.0, 0.7)
    assert set(only.zooms) == {paper_rig.zoom_rule} and only.zoom is only.zooms[paper_rig.zoom_rule]
    both = aim_detection(paper_rig, 100.0, 0.7, rules=ZOOM_RULES)
    assert set(both.zooms) == set(ZOOM_RULES)
    p, c = both.pointing, both.covariance.cov
    for rule in ZOOM_RULES:
        direct = jax.jit(choose_zoom, static_argnums=1)(paper_rig.foveal.lens, rule, c, p.distance, p.tilt, p.slant,
                                                        paper_rig.person.R_h, paper_rig.p_contain)
        assert float(both.zooms[rule].zoom) == pytest.approx(float(direct.zoom), rel=1e-12)
    paper = dataclasses.replace(paper_rig, zoom_rule="paper")
    assert float(aim_detection(paper, 100.0, 0.7).zoom.zoom) == pytest.approx(float(both.zooms["paper"].zoom),
                                                                               rel=1e-12)
    with pytest.raises(ValueError, match="zoom rules must be among"):
        aim_detection(paper_rig, 100.0, 0.7, rules=("widest",))


def test_zero_offset_sigmas_add_to_pan_and_tilt(paper_rig):
    """A zero offset adds to the angle turned to: var(pan) and var(tilt) grow by its variance,
    var(sin pan) by cos^2(pan) times it, cov(pan, tilt) not at all."""
    s_pan, s_tilt = 0.01, 0.02
    a = aim_at_floor(paper_rig, jnp.array([2.0, -1.0]))
    b = aim_at_floor(paper_rig, jnp.array([2.0, -1.0]), zero_sigma=jnp.array([s_pan, s_tilt]))
    ca, cb = np.asarray(a.covariance.cov), np.asarray(b.covariance.cov)
    pan = float(a.pointing.pan)
    assert cb[0, 0] - ca[0, 0] == pytest.approx(s_pan**2, rel=1e-12)
    assert cb[1, 1] - ca[1, 1] == pytest.approx(s_tilt**2, rel=1e-12)
    assert cb[2, 2] - ca[2, 2] == pytest.approx(math.cos(pan) ** 2 * s_pan**2, rel=1e-12)
    assert cb[0, 1] == pytest.approx(ca[0, 1], rel=1e-12)
    assert float(b.zoom.zoom) < float(a.zoom.zoom)


def test_vmap_is_the_same_as_one_at_a_time(paper_rig):
    xy = jnp.array([[1.0, 0.5], [-2.0, 1.5], [2.5, -2.0], [-3.5, -2.0]])
    cov = jnp.broadcast_to(jnp.array([[0.01, 0.002], [0.002, 0.02]]), (4, 2, 2))
    many = jax.vmap(lambda p, c: aim_at_floor(paper_rig, p, c, ZOOM_RULES))(xy, cov)
    for k in range(4):
        one = aim_at_floor(paper_rig, xy[k], cov[k], ZOOM_RULES)
        np.testing.assert_allclose(np.asarray(many.covariance.cov[k]), np.asarray(one.covariance.cov), rtol=1e-13)
        for rule in ZOOM_RULES:
            assert float(many.zooms[rule].zoom[k]) == pytest.approx(float(one.zooms[rule].zoom), rel=1e-12)


def test_gradients_through_the_pipeline(paper_rig):
    """The optimiser differentiates the calibrated zoom through the pipeline with respect to the
    PTZ's placement (jax.grad): reverse mode against numerical differences (check_grads; the zoom
    is a root found to 1e-12 in its normal score, hence the 1e-4 step and 1e-5 tolerance). Forward
    mode through the same pipeline is checked by tests/optimise (jacfwd of every objective)."""
    @jax.jit
    def log_zoom(D_c, H_f):
        r = eqx.tree_at(lambda r: (r.foveal.D_c, r.foveal.H_f), paper_rig, (D_c, H_f))
        a = aim_at_floor(r, jnp.array([1.2, -2.1]), jnp.array([[0.004, 0.001], [0.001, 0.006]]))
        return jnp.log(a.zoom.zoom)

    a = aim_at_floor(paper_rig, jnp.array([1.2, -2.1]), jnp.array([[0.004, 0.001], [0.001, 0.006]]))
    assert bool(a.zoom.feasible) and 1.0 < float(a.zoom.zoom) < 18.0  # the root, not a clamp
    check_grads(log_zoom, (paper_rig.foveal.D_c, paper_rig.foveal.H_f), order=1, modes=("rev",),
                eps=1e-4, rtol=1e-5, atol=1e-7)



def test_a_foot_from_the_head_is_coupled_to_the_height(fisheye_rig):
    """A foot placed from the head's top with the prior's height errs with the person's height, and the aim's
    height (the prior's) errs the other way: the prediction with ``cov(r_f, H_p) = -height_r_f sigma_H^2``
    matches a Monte Carlo of the exact map (n = 4000 heights from the prior, seed 46; the mean square's
    standard error about 2.2 %) within 10 %; without it the tilt is over-predicted 1.5-3x. The fisheye rig,
    calibration and head-radius sigmas zero (only the height varies), a person 3 m out behind the omni
    axis from the PTZ and 2.5 m out to its side."""
    from omnijax import point_image_radius, pointing
    from runtime.validation.endtoend import fixed_rig
    from tests.person_model import head_placed_foot

    rig = eqx.tree_at(lambda r: r.sigmas.R_h, fixed_rig(fisheye_rig), jnp.zeros_like(fisheye_rig.sigmas.R_h))
    placed = head_placed_foot(rig)
    o = rig.omni
    foot = lambda R: point_image_radius(R, 0.0, o.r_m, o.H_o, o.profile)
    H_p, s_H = float(rig.person.H_p), float(rig.sigmas.H_p)
    n = 4000
    H = H_p + s_H * np.random.default_rng(46).standard_normal(n)
    tan_tilt = jax.vmap(lambda x: pointing(x, rig.omni.profile).tan_tilt)
    for R, theta in ((3.0, math.pi), (2.5, math.pi / 2)):
        c = float((placed(R, H_p + 1e-4) - placed(R, H_p - 1e-4)) / 2e-4)
        assert 100.0 < c < 140.0  # px a metre of height, 2.5-3 m out on this rig
        x_used = rig.input_mean(placed(R, jnp.asarray(H)), jnp.full(n, theta))
        x_true = rig.input_mean(jnp.full(n, foot(R)), jnp.full(n, theta)).at[:, 7].set(jnp.asarray(H))
        mse = float(np.mean(np.asarray(tan_tilt(x_used) - tan_tilt(x_true)) ** 2))
        cov = jnp.diag(jnp.array([(c * s_H) ** 2, 1e-12]))
        coupled, independent = (float(aim_from_image(rig, foot(R), theta, cov, coupling=h).covariance.var_tan_tilt)
                                for h in (c, 0.0))
        assert coupled / mse == pytest.approx(1.0, abs=0.10), (R, theta)
        assert independent / mse > 1.4, (R, theta)


def test_the_coupling_stays_a_covariance(paper_rig):
    """``input_covariance`` holds the foot-height correlation to at most 1 in size, whatever the coupling."""
    from omnijax.aiming import input_covariance

    for h in (0.0, 50.0, 1e6, -1e6):
        s = np.asarray(input_covariance(paper_rig, jnp.diag(jnp.array([4.0, 1e-4])), h))
        assert np.all(np.linalg.eigvalsh(s) > -1e-12), h
        assert abs(s[0, 7]) <= 2.0 * float(paper_rig.sigmas.H_p) + 1e-15
        np.testing.assert_array_equal(s, s.T)
    s = np.asarray(input_covariance(paper_rig, jnp.diag(jnp.array([4.0, 1e-4])), 20.0))  # correlation 0.5
    assert s[0, 7] == pytest.approx(-20.0 * float(paper_rig.sigmas.H_p) ** 2)


def test_the_rule_couples_a_foot_by_its_share_seen_or_from_the_head(paper_rig):
    from omnijax import height_coupling

    shares = lambda r: (r.detection.height_share_r_f, r.detection.height_share_head_r_f)
    rig = eqx.tree_at(shares, paper_rig, (jnp.asarray(0.25), jnp.asarray(0.75)))
    got = np.asarray(height_coupling(rig, jnp.array([80.0, 80.0]), jnp.array([True, False])))
    np.testing.assert_allclose(got, [60.0, 20.0], rtol=1e-15)
    a, b = (aim_detection(rig, 90.0, 0.4, 2.0, 0.01, height_r_f=80.0, from_head=f) for f in (True, False))
    c = aim_detection(eqx.tree_at(lambda r: r.detection.height_share_r_f, rig, jnp.asarray(0.75)), 90.0, 0.4, 2.0,
                      0.01, height_r_f=80.0)
    np.testing.assert_allclose(np.asarray(a.covariance.cov), np.asarray(c.covariance.cov), rtol=1e-12)
    assert float(a.covariance.var_tan_tilt) != pytest.approx(float(b.covariance.var_tan_tilt), rel=1e-3)


def test_the_height_shares_fit_recovers_known_shares(paper_rig):
    """benchmarks/fit_detection_sigmas.py's ``fit_height_share`` on records drawn with known shares (0.3 seen,
    0.8 from the head; n = 20000 feet, seed 46, noise 2 px against a height part of about 3 px): each within
    0.02 (its standard error about 0.004)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "fit_detection_sigmas.py"
    spec = importlib.util.spec_from_file_location("fit_detection_sigmas", path)
    fit = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fit)
    rng = np.random.default_rng(46)
    n, H_p = 20000, float(paper_rig.person.H_p)
    head = rng.random(n) < 0.3
    h = rng.uniform(40.0, 80.0, n)
    H = H_p + float(paper_rig.sigmas.H_p) * rng.standard_normal(n)
    e_r = np.where(head, 0.8, 0.3) * h * (H - H_p) + 2.0 * rng.standard_normal(n)
    data = {"e_r": e_r, "H": H, "height_r_f": h, "from_head": head}
    (seen, n_seen), (from_head, n_head) = (fit.fit_height_share(paper_rig, data, f) for f in (False, True))
    assert seen == pytest.approx(0.3, abs=0.02) and n_seen == int((~head).sum())
    assert from_head == pytest.approx(0.8, abs=0.02) and n_head == int(head.sum())
    assert math.isnan(fit.fit_height_share(paper_rig, {"e_r": e_r}, False)[0])
