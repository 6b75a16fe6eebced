"""The perception scorer (runtime.validation.perception) on hand-made truth: matching, a miss and a
false alarm with their causes, a ghost's age after its person left, a standing person's frames."""

from __future__ import annotations

import json

import numpy as np
import pytest

from runtime.validation.perception import History, PerceptionScore, match_feet

FPS = 10.0


def _history(feet, moving, learning=(0, 1, 2)):
    feet = np.asarray(feet, float)
    return History(feet=feet, moving=np.asarray(moving, bool), floor_like=np.zeros(feet.shape[1], bool),
                   learning_frames=np.asarray(learning), fps=FPS)


def _truth(frame, feet):
    return {"frame": frame, "persons": [
        {"id": p, "foot_m": list(xy), "in_image": True, "foot_visible": True, "r_f": 50.0, "theta_f": 0.0}
        for p, xy in enumerate(feet)]}


def _people(n):
    return [{"r_f": 50.0, "theta_f": 0.0, "theta_l": -0.05, "theta_r": 0.05} for _ in range(n)]


def test_match_feet_is_one_to_one_and_gated():
    z = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 5.0]])
    foot = np.array([[0.05, 0.0], [0.3, 0.0]])
    pairs = sorted(match_feet(z, foot))
    assert [(r, c) for r, c, _ in pairs] == [(0, 0), (1, 1)]  # least total distance, the far one left out


def test_a_ghost_ages_from_when_its_person_left_and_a_standing_person_counts():
    """Person 0 stands at (2, 0) through the learning (frames 0-2) and frame 3, then is 1 m away from
    frame 4 on; a detection stays at (2, 0) from frame 4 to 7: a ghost of the learning, seen for 4 frames
    after its person left (0.4 s at 10 fps). Person 1 stands at (-2, 0) from frame 3 on (still from
    frame 3: standing, PAUSE_S = 1 s, from frame 12) and is detected in every frame but frame 13."""
    T = 16
    feet = np.zeros((T, 2, 2))
    feet[:, 0] = [2.0, 0.0]
    feet[4:, 0] = [2.0, 1.5]
    feet[:, 1] = [-2.0, 0.0]
    moving = np.zeros((T, 2), bool)
    moving[:3, 1] = True
    moving[3:5, 0] = True
    hist = _history(feet, moving)
    score = PerceptionScore()
    for f in range(3, T):
        z = [feet[f, 0]] + ([[2.0, 0.0]] if 4 <= f <= 7 else []) + ([feet[f, 1]] if f != 13 else [])
        z = np.array(z)
        out = score.add_frame(f, _truth(f, feet[f]), _people(len(z)), z, np.ones((len(z), 2)), hist)
        if f == 5:
            assert [x["cause"] for x in out["false"]] == ["ghost_learning"]
        if f == 13:
            assert [x["id"] for x in out["missed"]] == [1]
    s = score.summary()
    assert s["false_alarms"] == 4 and s["fa_causes"]["ghost_learning"] == 4
    assert s["ghost_gone_s"] == pytest.approx(0.4)
    assert s["misses"] == 1
    # standing: person 1 in frames 12-15, person 0 (still again from frame 5) in 14-15; one missed
    assert s["standing_frames"] == 6 and s["standing_detected_rate"] == pytest.approx(5 / 6)


def test_a_ghost_is_an_episode_and_a_false_alarm_at_a_place_left_long_ago_is_not_one_that_lasted():
    """Person 0 stands at (2, 0) through the learning (frames 0-2), then walks 1.5 m off at frame 4 and
    stays there; a detection stays at (2, 0) in frames 4-6 (a ghost of the learning that lasted 0.3 s at
    10 fps), is gone in frames 7-39, and shows for one frame at frame 40 (3.7 s after the person left: a
    false alarm at an old place, the standing_start 9188 case). ``ghost_gone_s`` is the 0.3 s the ghost
    lasted, the frame-40 one an episode apart (``ghost_returns``), and ``ghost_age_max_s`` the old figure."""
    T = 41
    feet = np.zeros((T, 1, 2))
    feet[:, 0] = [2.0, 0.0]
    feet[4:, 0] = [2.0, 1.5]
    moving = np.zeros((T, 1), bool)
    moving[3:5, 0] = True
    hist = _history(feet, moving)
    score = PerceptionScore()
    for f in range(3, T):
        z = np.array([feet[f, 0]] + ([[2.0, 0.0]] if 4 <= f <= 6 or f == 40 else []))
        out = score.add_frame(f, _truth(f, feet[f]), _people(len(z)), z, np.ones((len(z), 2)), hist)
        if f in (4, 40):
            assert [x["cause"] for x in out["false"]] == ["ghost_learning"]
    s = score.summary()
    assert s["false_alarms"] == 4 and s["fa_causes"]["ghost_learning"] == 4  # still false alarms, all of them
    assert s["ghost_gone_s"] == pytest.approx(0.3)
    assert s["ghost_returns"] == 1 and s["ghost_age_max_s"] == pytest.approx(3.7)
    json.dumps(s)  # what perception_sweep.py --json writes: plain numbers, no NumPy scalars


def test_someone_standing_since_before_the_learning_is_never_seen_free():
    """The learning takes frames 1-3. Person 0 stands at (2, 0) from frame 0 to frame 6 and walks from
    frame 7; person 1 walks in frames 0-1 and stands from frame 2 on. Nobody is detected in frames 4-9:
    person 0 is ``never_seen_free`` in 4-6 only (no learning frame saw the floor under them); person 1
    was off their spot in learning frame 1, and is never ``never_seen_free``. The miss rate over the
    people seen free leaves those 3 person-frames out."""
    T = 10
    feet = np.zeros((T, 2, 2))
    feet[:, 0] = [2.0, 0.0]
    feet[7:, 0] = [[2.0, 0.3], [2.0, 0.6], [2.0, 0.9]]
    feet[:, 1] = [-2.0, 0.0]
    moving = np.zeros((T, 2), bool)
    moving[7:, 0] = True
    moving[:2, 1] = True
    hist = _history(feet, moving, learning=(1, 2, 3))
    score = PerceptionScore()
    causes = {0: [], 1: []}
    for f in range(4, T):
        out = score.add_frame(f, _truth(f, feet[f]), [], np.zeros((0, 2)), np.zeros((0, 2)), hist)
        for m in out["missed"]:
            causes[m["id"]].append(m["cause"])
    assert causes[0][:3] == ["never_seen_free"] * 3 and "never_seen_free" not in causes[0][3:]
    assert "never_seen_free" not in causes[1]
    s = score.summary()
    assert s["miss_causes"]["never_seen_free"] == 3 and s["misses"] == 12
    assert s["miss_rate_seen"] == pytest.approx(9 / 9)


def test_the_standing_figure_without_those_never_seen_free():
    """Person 0 stands at (2, 0) from frame 0 (the learning takes frames 1-3: never seen free) and is
    never detected; person 1 walks in frames 0-1, stands from frame 2 on and is detected in every frame.
    Standing (still for PAUSE_S = 1 s, the frame itself counted) from frame 9 for person 0, 11 for
    person 1: over frames 4-19 the standing figure counts both (9 of 20 detected), the seen figure
    person 1 only (9 of 9)."""
    T = 20
    feet = np.zeros((T, 2, 2))
    feet[:, 0] = [2.0, 0.0]
    feet[:, 1] = [-2.0, 0.0]
    moving = np.zeros((T, 2), bool)
    moving[:2, 1] = True
    hist = _history(feet, moving, learning=(1, 2, 3))
    score = PerceptionScore()
    for f in range(4, T):
        z = np.array([feet[f, 1]])
        score.add_frame(f, _truth(f, feet[f]), _people(1), z, np.ones((1, 2)), hist)
    s = score.summary()
    assert s["standing_frames"] == 20 and s["standing_detected_rate"] == pytest.approx(9 / 20)
    assert s["standing_seen_frames"] == 9 and s["standing_detected_rate_seen"] == pytest.approx(1.0)


@pytest.mark.parametrize("spectrum, cause", [([0.8, 0.9, 1.0], "shadow"), ([1.0, 0.93, 0.8], "other")])
def test_a_false_alarm_in_a_coloured_shadow(spectrum, cause):
    """A lamp 3 m up over the origin and a person 1.5 m tall at (1, 0) cast a shadow on the floor from
    (1, 0) to (2, 0). A false alarm at (1.8, 0.1) lies in it (0.8 m from the person: no fragment): a
    shadow when the lamp's spectrum is another colour than the ambient light's, 'other' when it is the
    same (a shadow under one spectrum changes only the brightness). One at (1.8, 1.0) is 'other' either way."""
    feet = np.array([[[1.0, 0.0]]] * 4)
    world = {"people": [{"floor_like": False, "H_p_m": 1.5}], "fps": FPS,  # world.json's keys
             "lamps": [{"position_m": [0.0, 0.0, 3.0], "intensity": 900.0, "spectrum": spectrum}],
             "ambient_spectrum": [1.0, 0.93, 0.8]}
    lines = [{"frame": f, "persons": [{"id": 0, "foot_m": [1.0, 0.0], "moving": False}]} for f in range(4)]
    hist = History.from_truth_lines(lines, world, learning_frames=[0])
    score = PerceptionScore()
    z = np.array([[1.0, 0.0], [1.8, 0.1], [1.8, 1.0]])
    out = score.add_frame(3, _truth(3, feet[3]), _people(3), z, np.ones((3, 2)), hist)
    assert [x["cause"] for x in out["false"]] == [cause, "other"]


def test_merged_means_another_detection_covers_the_missed_person():
    """Two people at (2, 0) (azimuth 0) and (1, 0.3) (azimuth 0.29 rad), only the first detected.
    Its run 0.10 rad wide holds azimuth 0 only: the second person is missed for no company ('other');
    a run of 0.6 rad covers both ('merged'). The same second person dressed like the floor is
    'floor_coloured' either way: the measure cannot see them, whoever stands beside them."""
    feet = np.array([[[2.0, 0.0], [1.0, 0.3]]] * 4)
    theta = [0.0, float(np.arctan2(0.3, 1.0))]
    for half, floor_like, cause in [(0.05, False, "other"), (0.3, False, "merged"),
                                    (0.05, True, "floor_coloured"), (0.3, True, "floor_coloured")]:
        hist = _history(feet, np.ones((4, 2), bool))
        hist.floor_like[1] = floor_like
        truth = _truth(3, feet[3])
        for q, t in zip(truth["persons"], theta):
            q["theta_f"] = t
        people = [{"r_f": 50.0, "theta_f": 0.0, "theta_l": -half, "theta_r": half}]
        out = PerceptionScore().add_frame(3, truth, people, np.array([[2.0, 0.0]]), np.ones((1, 2)), hist)
        assert out["missed"] == [{"id": 1, "cause": cause}], (half, floor_like)
