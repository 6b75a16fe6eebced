"""The loop's jitted kernels: `perceive` (detection and the tracker's floor measurements under the
aim pipeline's sigma rule) and `control_step` (the tracker and the aim pipeline fused). The
background's life has its own tests (tests/omnijax/test_life.py)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from omnijax import learn_background, line_background
from omnijax.geometry import floor_measurement, floor_radius
from runtime.realtime.loop import perceive
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
    dets, _, z, R = perceive(paper_detector, paper_rig, frame, lines)
    valid = np.asarray(dets.valid)
    assert valid.sum() == 1
    k = int(np.argmax(valid))
    r_f, th = float(dets.r_f[k]), float(dets.theta_f[k])
    hyp_r_f = paper_detector.polar.hyp_r_f
    step_r = float(hyp_r_f[i + 1] - hyp_r_f[i])  # within one hypothesis of the painted one
    assert r_f == pytest.approx(float(hyp_r_f[i]), abs=1.01 * step_r)
    d = paper_rig.detection
    # the rule: the detector's sigmas scaled by the rig's gains, widened by its extra and range terms
    o = paper_rig.omni
    R_f = max(float(floor_radius(r_f, o.r_m, o.H_o, o.profile)[0]), float(d.min_floor_radius))
    s_r = math.hypot(float(d.sigma_gain_r_f) * float(dets.sigma_r_f[k]), float(d.sigma_extra_r_f),
                     float(d.sigma_extra_r_f_per_m) * R_f)
    s_t = math.hypot(float(d.sigma_gain_theta_f) * float(dets.sigma_theta_f[k]), float(d.sigma_extra_theta_f),
                     float(d.sigma_lateral_m) / R_f)
    assert s_t > float(dets.sigma_theta_f[k])
    z0, R0 = floor_measurement(paper_rig, r_f, th, s_r, s_t)
    np.testing.assert_allclose(np.asarray(z[k]), np.asarray(z0), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(R[k]), np.asarray(R0), rtol=1e-12)
    assert z.shape == (dets.r_f.shape[0], 2) and R.shape == (dets.r_f.shape[0], 2, 2)


def test_control_step_is_the_tracker_and_the_aim_pipeline_fused(paper_detector, paper_rig, scene):
    """The one per-frame call against its parts called one by one: a confirmed track near the painted
    person is updated as Tracker.step updates it, and aimed at as aim_at_floor aims at its head
    predicted over the slew time from the last command to where a first aim points, with the floor
    covariance the prediction's plus the covariance of the detection the track took, and that
    detection's coupling of the foot to the person's height."""
    import copy

    from omnijax import aim_at_floor, height_coupling
    from omnijax.zoom import ZOOM_RULES
    from runtime.realtime import kalman
    from runtime.realtime.control import Slew, control_step, pan_tilt_slew_s
    from runtime.realtime.tracker import Track, Tracker

    bg, lines, frame, _ = scene
    dets, _, z, R = perceive(paper_detector, paper_rig, frame, lines)
    valid = np.asarray(dets.valid)
    k = int(np.argmax(valid))
    zk = np.asarray(z[k])
    tracker = Tracker("kalman")
    tracker.tracks = [Track(id=1, x=np.r_[zk + [0.05, -0.03], 0.2, 0.1], P=np.diag([0.02, 0.02, 0.3, 0.3]),
                            t=0.96, hits=2),
                      Track(id=2, x=np.array([9.0, 9.0, 0.0, 0.0]), P=np.eye(4), t=0.96, hits=5)]
    reference = copy.deepcopy(tracker)
    sent = (0.3, -0.6)
    slew = Slew(known=jnp.asarray(True), pan=jnp.asarray(sent[0]), tilt=jnp.asarray(sent[1]),
                pan_deg_s=jnp.asarray(300.0), tilt_deg_s=jnp.asarray(125.0), latency_s=jnp.asarray(0.03))
    c = control_step(paper_detector, paper_rig, frame, lines, tracker.slots(32), jnp.asarray(1.0), 1.5, 0.8,
                     slew, mode="kalman", confirm=2)
    assign = np.asarray(c.assign)
    assert assign[0] == k and (assign[1:] == -1).all()
    reference.step(1.0, np.asarray(z)[valid], np.asarray(R)[valid])
    tr = reference.tracks[0]
    np.testing.assert_allclose(np.asarray(c.x[0]), tr.x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(np.asarray(c.P[0]), tr.P, rtol=1e-12, atol=1e-14)
    assert np.asarray(c.aim_ok).tolist() == [True] + [False] * (len(valid) - 1) and int(c.aim_slot[0]) == 0
    now = aim_at_floor(paper_rig, jnp.asarray(tr.x[:2]), jnp.asarray(tr.P[:2, :2]), ZOOM_RULES).pointing
    lead = 0.03 + float(pan_tilt_slew_s(now.pan, now.tilt, *sent, 300.0, 125.0))
    assert lead > 0.0 and float(c.lead[0, 0]) == pytest.approx(lead, rel=1e-12)
    xp, Pp = kalman.predict(jnp.asarray(tr.x), jnp.asarray(tr.P), lead, 1.5)
    coupling = height_coupling(paper_rig, dets.height_r_f[k], dets.from_head[k])
    assert float(coupling) != 0.0  # the paper rig's shares are fitted: the coupling is carried, not zero
    want = aim_at_floor(paper_rig, xp[:2], Pp[:2, :2] + R[k], ZOOM_RULES, coupling=coupling)
    uncoupled = aim_at_floor(paper_rig, xp[:2], Pp[:2, :2] + R[k], ZOOM_RULES)
    assert abs(float(want.covariance.cov[1, 1]) / float(uncoupled.covariance.cov[1, 1]) - 1) > 1e-4
    got = jax.tree.map(lambda a: a[0, 0], c.aims)  # the rig's one PTZ, the first confirmed track
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.asarray(c.floor_sd[0, 0]), np.sqrt(np.diagonal(np.asarray(Pp[:2, :2] + R[k]))),
                               rtol=1e-12)


def test_perceive_drops_a_detection_whose_foot_is_off_the_floor(paper_detector, paper_rig, scene):
    """The painted person's foot, with the room's outline moved 2 m away from it: no person there
    (a change on a wall); with ``off_floor_m`` beyond that distance it is kept."""
    import equinox as eqx

    _, lines, frame, _ = scene
    dets, _, z, _ = perceive(paper_detector, paper_rig, frame, lines)
    zk = np.asarray(z[int(np.argmax(np.asarray(dets.valid)))])
    away = zk + 2.0 * zk / np.linalg.norm(zk) + np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    # the rig's exclude zones go 100 m away, not out of the rig, and off_floor_m keeps its dtype: the
    # same pytree as the rig's, so perceive is not compiled again
    zones = tuple(jnp.asarray(z) + 100.0 for z in paper_rig.room.exclude)
    rig = eqx.tree_at(lambda r: (r.room.outline, r.room.exclude), paper_rig, (jnp.asarray(away), zones))
    far = float(rig.room.outside_by(zk[0], zk[1]))
    assert 1.4 < far < 2.6
    dropped, _, _, _ = perceive(paper_detector, rig, frame, lines)
    assert not np.asarray(dropped.valid).any()
    off = paper_rig.detection.off_floor_m
    lenient = eqx.tree_at(lambda r: r.detection.off_floor_m, rig, jnp.asarray(far + 0.1, off.dtype))
    kept, _, _, _ = perceive(paper_detector, lenient, frame, lines)
    np.testing.assert_array_equal(np.asarray(kept.valid), np.asarray(dets.valid))
