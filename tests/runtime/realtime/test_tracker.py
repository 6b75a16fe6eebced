"""The floor tracker: the constant-velocity Kalman filter against a hand calculation, assignment and
gating, the confirm and drop rules, and the paper's nearest neighbour."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from runtime.realtime.tracker import GATE, Track, Tracker, constant_velocity


def _tracker(mode="kalman", **kw):
    return Tracker(mode, accel_sd=kw.pop("accel_sd", 1.5), speed_sd=kw.pop("speed_sd", 1.0), **kw)


def _track(id_, x, P, t=0.0, hits=2):
    return Track(id=id_, x=np.asarray(x, float), P=np.asarray(P, float), t=t, hits=hits)


def _with_tracks(kt, *tracks):
    """``kt`` holding ``tracks`` (ids 1, 2, ...), new tracks numbered after them."""
    kt.tracks = list(tracks)
    kt._ids = itertools.count(len(tracks) + 1)
    return kt


def test_constant_velocity_model():
    """White acceleration a over dt: per axis Q = a^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]], axes independent."""
    F, Q = constant_velocity(0.2, 1.5)
    np.testing.assert_array_equal(F, [[1, 0, 0.2, 0], [0, 1, 0, 0.2], [0, 0, 1, 0], [0, 0, 0, 1]])
    a2 = 2.25
    expect = np.zeros((4, 4))
    for p, v in ((0, 2), (1, 3)):
        expect[p, p], expect[p, v] = a2 * 0.2**4 / 4, a2 * 0.2**3 / 2
        expect[v, p], expect[v, v] = a2 * 0.2**3 / 2, a2 * 0.2**2
    np.testing.assert_allclose(Q, expect, rtol=1e-15)
    F0, Q0 = constant_velocity(0.0, 1.5)
    np.testing.assert_array_equal(F0, np.eye(4))
    np.testing.assert_array_equal(Q0, 0)


def test_predict_and_update_against_a_hand_calculation():
    """One track, one detection 0.2 s later; with diagonal covariances the filter splits into one
    (position, velocity) filter per axis, written out here by hand."""
    tr = _track(1, [1.0, 2.0, 0.5, -0.25], np.diag([0.04, 0.09, 0.25, 0.16]))
    kt = _with_tracks(_tracker(), tr)
    # predicted: x + dt v; per axis P = [[p + dt^2 v + q11, dt v + q12], [., v + q22]]
    q11, q12, q22 = 2.25 * 0.2**4 / 4, 2.25 * 0.2**3 / 2, 2.25 * 0.2**2
    x_pred, P_pred = tr.predict(0.2, kt.accel_sd)
    np.testing.assert_allclose(x_pred, [1.1, 1.95, 0.5, -0.25], rtol=1e-15)
    axis = {0: (0.04, 0.25), 1: (0.09, 0.16)}
    for p, (pp, vv) in axis.items():
        v = p + 2
        assert P_pred[p, p] == pytest.approx(pp + 0.04 * vv + q11, rel=1e-14)
        assert P_pred[p, v] == pytest.approx(0.2 * vv + q12, rel=1e-14)
        assert P_pred[v, v] == pytest.approx(vv + q22, rel=1e-14)
    assert P_pred[0, 1] == P_pred[0, 3] == P_pred[2, 3] == 0.0

    z, R = np.array([1.2, 1.9]), np.diag([0.01, 0.02])
    kt.step(0.2, z[None], R[None])
    assert tr.t == 0.2 and tr.hits == 3 and tr.misses == 0 and tr.detection == 0
    for p, (pp, vv), r in ((0, axis[0], 0.01), (1, axis[1], 0.02)):
        v = p + 2
        Ppp, Ppv, Pvv = pp + 0.04 * vv + q11, 0.2 * vv + q12, vv + q22
        S = Ppp + r
        innovation = z[p] - x_pred[p]
        assert tr.x[p] == pytest.approx(x_pred[p] + Ppp / S * innovation, rel=1e-13)
        assert tr.x[v] == pytest.approx(x_pred[v] + Ppv / S * innovation, rel=1e-13)
        assert tr.P[p, p] == pytest.approx(Ppp * r / S, rel=1e-12)
        assert tr.P[p, v] == pytest.approx(Ppv * r / S, rel=1e-12)
        assert tr.P[v, v] == pytest.approx(Pvv - Ppv**2 / S, rel=1e-12)
    assert abs(tr.P[0, 1]) < 1e-15 and abs(tr.P[2, 3]) < 1e-15


def test_a_new_track_starts_at_the_detection_at_rest():
    kt = _tracker(speed_sd=0.7)
    R = np.array([[0.02, 0.005], [0.005, 0.03]])
    kt.step(1.0, np.array([[2.0, -1.0]]), R[None])
    (tr,) = kt.tracks
    np.testing.assert_array_equal(tr.x, [2.0, -1.0, 0.0, 0.0])
    np.testing.assert_array_equal(tr.P[:2, :2], R)
    np.testing.assert_allclose(tr.P[2:, 2:], 0.49 * np.eye(2))
    assert np.all(tr.P[:2, 2:] == 0) and tr.t == 1.0 and tr.hits == 1 and tr.detection == 0


def test_gate_is_the_chi2_999_quantile():
    """chi-square(2) quantile 0.999 = -2 ln(0.001)."""
    assert GATE == pytest.approx(-2 * math.log(0.001), rel=1e-12)


@pytest.mark.parametrize("factor,updated", [(0.99, True), (1.01, False)])
def test_gating(factor, updated):
    """At dt = 0 the innovation covariance is P + R = 0.04 I: a detection within sqrt(GATE * 0.04)
    updates the track, one beyond it starts a new track."""
    kt = _with_tracks(_tracker(), _track(1, [0.0, 0.0, 0.0, 0.0], np.diag([0.03, 0.03, 1.0, 1.0])))
    d = factor * math.sqrt(GATE * 0.04)
    kt.step(0.0, np.array([[d / math.sqrt(2), d / math.sqrt(2)]]), np.array([0.01 * np.eye(2)]))
    if updated:
        assert [tr.id for tr in kt.tracks] == [1] and kt.tracks[0].hits == 3
    else:
        assert [tr.id for tr in kt.tracks] == [1, 2]
        assert kt.tracks[0].misses == 1 and kt.tracks[0].detection is None and kt.tracks[1].detection == 0


def _two_tracks(mode):
    P = np.diag([0.09, 0.09, 1.0, 1.0])
    return _with_tracks(_tracker(mode), _track(1, [0.0, 0.0, 0.0, 0.0], P), _track(2, [1.0, 0.0, 0.0, 0.0], P))


@pytest.mark.parametrize("order", [(0, 1), (1, 0)])
def test_kalman_assignment_is_the_best_joint_one(order):
    """Tracks at x = 0 and 1, detections at 0.55 and 1.6 (innovation variance 0.1): the nearest pair
    (track 2 and 0.55) would leave 1.6 to track 1, beyond its gate; the optimal assignment gives 0.55
    to track 1 and 1.6 to track 2, whatever the detections' order."""
    kt = _two_tracks("kalman")
    z = np.array([[0.55, 0.0], [1.6, 0.0]])[list(order)]
    kt.step(0.0, z, np.broadcast_to(0.01 * np.eye(2), (2, 2, 2)))
    assert [tr.id for tr in kt.tracks] == [1, 2]
    by_id = {tr.id: tr for tr in kt.tracks}
    assert z[by_id[1].detection, 0] == 0.55 and z[by_id[2].detection, 0] == 1.6
    assert 0.0 < by_id[1].x[0] < 0.55 and 1.0 < by_id[2].x[0] < 1.6


def test_nearest_neighbour_is_greedy_and_gated_in_metres():
    """The paper's rule on the same scene: closest pair first (track 2 takes 0.55), then 1.6 is 1.6 m
    from track 1, beyond nearest_gate_m (0.8): track 1 misses and 1.6 starts a track."""
    kt = _two_tracks("nearest")
    z = np.array([[0.55, 0.0], [1.6, 0.0]])
    R = np.broadcast_to(0.01 * np.eye(2), (2, 2, 2))
    kt.step(0.5, z, R)
    by_id = {tr.id: tr for tr in kt.tracks}
    assert set(by_id) == {1, 2, 3}
    assert by_id[1].misses == 1 and by_id[2].detection == 0 and by_id[3].detection == 1
    np.testing.assert_array_equal(by_id[2].x, [0.55, 0.0, 0.0, 0.0])  # a track is its last position
    np.testing.assert_array_equal(by_id[2].P[:2, :2], R[0])
    assert by_id[2].t == 0.5


def test_confirm_and_drop():
    """Confirmed after `confirm` hits and only while not missing; dropped after more than
    `max_misses` frames without a detection; a person who comes back gets a new id."""
    kt = _tracker(confirm=3, max_misses=2)
    z, R = np.array([[1.0, 1.0]]), np.array([0.01 * np.eye(2)])
    none, none_R = np.zeros((0, 2)), np.zeros((0, 2, 2))
    kt.step(0.00, z, R)
    assert kt.confirmed() == []
    kt.step(0.04, z, R)
    assert kt.confirmed() == []
    kt.step(0.08, z, R)
    assert [tr.id for tr in kt.confirmed()] == [1]
    kt.step(0.12, none, none_R)
    assert kt.confirmed() == [] and [tr.id for tr in kt.tracks] == [1]  # missing: kept, not confirmed
    kt.step(0.16, z, R)
    assert [tr.id for tr in kt.confirmed()] == [1]  # found again: confirmed at once
    for k in range(2):
        kt.step(0.20 + 0.04 * k, none, none_R)
        assert [tr.id for tr in kt.tracks] == [1]
    kt.step(0.28, none, none_R)  # the third miss in a row: dropped
    assert kt.tracks == []
    kt.step(0.32, z, R)
    assert [tr.id for tr in kt.tracks] == [2]


def test_unknown_mode_is_refused():
    with pytest.raises(ValueError, match="tracker mode"):
        Tracker("hungarian")
