"""Several PTZs: the exact assignment (against brute force), hysteresis, hand-offs, spare PTZs, dwell
locks, holding on through a missed detection, and the operator's and the zones' tiers."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from runtime.realtime.assignment import CameraAssigner, PairValues, assign_exact, miss_probability
from runtime.realtime.tracker import Track


def _brute_force(value, allowed):
    """The best assignment by enumeration: the most pairs first, then the largest total value."""
    R, C = value.shape
    best = (-1, -np.inf)
    for cols in itertools.product(range(-1, C), repeat=R):
        taken = [c for c in cols if c >= 0]
        if len(set(taken)) < len(taken) or any(c >= 0 and not allowed[r, c] for r, c in enumerate(cols)):
            continue
        best = max(best, (len(taken), sum(value[r, c] for r, c in enumerate(cols) if c >= 0)))
    return best


def _score(value, cols):
    return (int((cols >= 0).sum()), sum(value[r, c] for r, c in enumerate(cols) if c >= 0))


@pytest.mark.parametrize("shape", [(1, 4), (2, 3), (3, 3), (3, 5), (4, 2), (4, 6)])
def test_exact_against_brute_force_and_scipy(shape):
    """Random values with forbidden pairs (seed fixed): as many pairs as can be, then the largest total,
    as enumeration finds it; without forbidden pairs it is SciPy's maximum-weight assignment."""
    rng = np.random.default_rng(26)
    for _ in range(25):
        value = rng.uniform(0.0, 3.0, shape)
        allowed = rng.uniform(size=shape) < 0.6
        cols = assign_exact(value, allowed, columns=8)
        assert all(c < 0 or allowed[r, c] for r, c in enumerate(cols))
        n, total = _score(value, cols)
        bn, btotal = _brute_force(value, allowed)
        assert n == bn and total == pytest.approx(btotal, rel=1e-9)
        rows, cs = linear_sum_assignment(value, maximize=True)
        full = assign_exact(value, np.ones(shape, bool), columns=8)
        assert _score(value, full)[1] == pytest.approx(value[rows, cs].sum(), rel=1e-9)


def _track(i, x=0.0):
    tr = Track(id=i, x=np.array([x, 0.0, 0.0, 0.0]), P=np.eye(4), t=0.0)
    tr.trusted = True
    return tr


def _pairs(face, framable=None, slew=None, probability=0.99):
    """PairValues from a face table (K, n) px; every pair framable unless said."""
    face = np.asarray(face, float)
    return lambda cands: PairValues(
        framable=np.ones(face.shape, bool) if framable is None else np.asarray(framable, bool),
        probability=np.full(face.shape, probability), face_px=face,
        slew_s=np.zeros(face.shape) if slew is None else np.asarray(slew, float))


def _ids(targets):
    return [None if t is None else t.id for t in targets]


def test_as_many_people_as_can_be_then_the_best_faces():
    """Two PTZs, three people: two are covered, those whose faces the PTZs frame best; a PTZ that only
    one person's aim reaches takes them even if the other PTZ frames them better."""
    a = CameraAssigner(2, dwell_s=2.0)
    people = [_track(1), _track(2), _track(3)]
    faces = [[200, 60, 180], [190, 50, 170]]
    assert sorted(_ids(a.choose(0.0, people, [False, False], _pairs(faces)))) == [1, 3]
    b = CameraAssigner(2, dwell_s=2.0)
    only = [[True, True, False], [True, False, False]]  # PTZ 1 can frame person 1 only
    assert _ids(b.choose(0.0, people, [False, False], _pairs([[200, 100, 0], [150, 0, 0]], only))) == [2, 1]


def test_hysteresis_keeps_a_person_on_their_ptz_until_another_frames_them_clearly_better():
    """One person, two PTZs: whichever frames them better is in charge; small changes do not swap the
    PTZ in charge (the other follows as the spare); a clear lead does, and counts one hand-off."""
    a = CameraAssigner(2, dwell_s=0.0)
    person = [_track(1)]
    settled = [True, True]
    a.choose(0.0, person, settled, _pairs([[150], [140]]))
    assert a.primary == {1: 0}
    for t, faces in enumerate(([[140], [150]], [[130], [155]], [[150], [140]]), start=1):  # within 25 %
        assert _ids(a.choose(float(t), person, settled, _pairs(faces))) == [1, 1]
        assert a.primary == {1: 0}
    assert a.choose(4.0, person, settled, _pairs([[100], [160]])) and a.primary == {1: 1}
    assert [c.handoffs for c in a.cameras] == [0, 1] and [c.handed_over for c in a.cameras] == [1, 0]


def test_a_person_walking_from_one_ptzs_region_into_anothers_is_handed_over_once():
    """Two people far apart, each in one PTZ's good region; person 1 walks into PTZ 1's region (PTZ 0
    can no longer frame them at p_contain there) while person 2 walks into PTZ 0's: the PTZs swap their
    people once, at the crossing, and not back and forth."""
    a = CameraAssigner(2, dwell_s=0.5)
    people = [_track(1), _track(2)]
    history = []
    for step in range(40):
        s = step / 39.0  # 0 -> 1 along the walk
        faces = [[200 * (1 - s) + 40 * s, 40 * (1 - s) + 200 * s],
                 [40 * (1 - s) + 200 * s, 200 * (1 - s) + 40 * s]]
        framable = [[s < 0.8, s > 0.2], [s > 0.2, s < 0.8]]
        history.append(_ids(a.choose(0.25 * step, people, [True, True], _pairs(faces, framable))))
    assert history[0] == [1, 2] and history[-1] == [2, 1]
    changes = sum(h != g for h, g in zip(history, history[1:]))
    assert changes == 1
    assert [c.handoffs for c in a.cameras] == [1, 1] and [c.handed_over for c in a.cameras] == [1, 1]


def test_a_spare_ptz_gives_the_weakest_framed_person_a_second_view():
    """Three PTZs, two people: each person gets one PTZ; the third goes to the person whose PTZ frames
    them worst (the highest chance that it misses them), not to the one already framed well."""
    a = CameraAssigner(3, dwell_s=2.0)
    people = [_track(1), _track(2)]
    faces = [[200, 10], [10, 60], [150, 150]]  # PTZ 0 frames 1 well, PTZ 1 frames 2 poorly, PTZ 2 both
    assert _ids(a.choose(0.0, people, [False] * 3, _pairs(faces))) == [1, 2, 2]
    strength = PairValues(np.ones((3, 2), bool), np.full((3, 2), 0.99), np.asarray(faces, float),
                          np.zeros((3, 2))).strength(180.0)
    miss = miss_probability(strength, np.array([0, 1, 1]))
    assert miss[1] == pytest.approx((1 - 0.99 * 60 / 180) * (1 - 0.99 * 150 / 180))


def test_no_two_ptzs_on_one_person_while_a_framable_person_has_none():
    """A spare PTZ on a person leaves them for a new person at once, whatever the values or dwell locks."""
    a = CameraAssigner(2, dwell_s=5.0)
    one = [_track(1)]
    assert _ids(a.choose(0.0, one, [True, True], _pairs([[200], [200]]))) == [1, 1]
    two = [_track(1), _track(2)]
    targets = _ids(a.choose(0.1, two, [True, True], _pairs([[200, 20], [200, 20]])))
    assert sorted(targets) == [1, 2] and a.doubled_while_waiting == 0


def test_fewer_ptzs_than_people_dwell_then_move_to_who_waited_longest():
    """One PTZ of two (the other frames nobody), three people: the PTZ stays on its person until it has
    stood on them dwell_s (their face is captured then), then goes to the person who has waited longest."""
    a = CameraAssigner(2, dwell_s=1.0)
    people = [_track(1), _track(2), _track(3)]
    framable = [[True] * 3, [False] * 3]
    faces = [[200, 200, 200], [0, 0, 0]]
    seen = [_ids(a.choose(0.1 * k, people, [k > 0, False], _pairs(faces, framable)))[0] for k in range(40)]
    first = seen[0]
    assert seen[:11] == [first] * 11  # settled at 0.1 s, dwelt 1 s at 1.1 s
    assert next(tr for tr in people if tr.id == first).captured and a.captures >= 1
    order = [k for k, _ in itertools.groupby(seen)]
    assert len(order) >= 3 and set(order[:3]) == {1, 2, 3}  # everyone in turn


def test_a_missed_detection_does_not_take_the_person_from_their_ptz():
    """The person's track is not confirmed this frame (no detection) but still alive: the PTZ holds on to
    them (no new command) and the other PTZ does not double up or swap."""
    a = CameraAssigner(2, dwell_s=2.0)
    p1, p2 = _track(1), _track(2)
    assert _ids(a.choose(0.0, [p1, p2], [True, True], _pairs([[200, 50], [50, 200]]))) == [1, 2]
    got = _ids(a.choose(0.04, [p1], [True, True], _pairs([[200], [50]]), alive=[p1, p2]))
    assert got == [1, 2] and a.holding == [False, True]
    assert _ids(a.choose(0.08, [p1, p2], [True, True], _pairs([[200, 50], [50, 200]]))) == [1, 2]
    assert sum(c.handoffs for c in a.cameras) == 0


def test_the_operator_priority_zones_and_pause():
    """The operator's chosen track is covered even against better faces; a person in a priority zone
    takes a PTZ from a dwell lock; paused: no targets."""
    a = CameraAssigner(2, dwell_s=5.0)
    people = [_track(1), _track(2, x=5.0), _track(3)]
    faces = [[200, 20, 200], [200, 20, 200]]
    assert 2 in _ids(a.choose(0.0, people, [False, False], _pairs(faces), manual=2))
    b = CameraAssigner(2, dwell_s=5.0)
    assert sorted(_ids(b.choose(0.0, people, [True, True], _pairs(faces)))) == [1, 3]
    b.priority = lambda xy: xy[0] > 4.0
    assert 2 in _ids(b.choose(0.1, people, [True, True], _pairs(faces)))
    assert _ids(b.choose(0.2, people, [True, True], _pairs(faces), paused=True)) == [None, None]
    assert b.held == ["paused", "paused"]


def test_untrusted_tracks_are_never_assigned():
    from runtime.realtime.targeting import TrustRule

    a = CameraAssigner(2, trust=TrustRule())
    blob = Track(id=9, x=np.zeros(4), P=np.eye(4), t=0.0)
    assert _ids(a.choose(0.0, [blob], [False, False], _pairs([[200], [200]]))) == [None, None]
    assert a.held == ["untrusted", "untrusted"]
