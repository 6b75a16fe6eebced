"""Target selection (dwell, round-robin order, single mode, lost targets) and the dead zone."""

from __future__ import annotations

import math

import numpy as np
import pytest

from runtime.realtime.targeting import TargetSelector, outside_dead_zone
from runtime.realtime.tracker import Track


def _tracks(*ids):
    return [Track(id=i, x=np.array([float(i), 0.0, 0.0, 0.0]), P=np.eye(4), t=0.0) for i in ids]


def _ids(choice):
    return None if choice is None else choice.id


def test_round_robin_dwells_after_settling_then_moves_on_in_order():
    """A target is kept until the PTZ has dwelt ``dwell_s`` on it after settling (not after it was
    chosen); its face is then captured and the next is the uncaptured one, lowest id first; when
    all are captured, the one that waited longest."""
    sel = TargetSelector("round-robin", dwell_s=2.0)
    tracks = _tracks(1, 2, 3)
    assert _ids(sel.choose(0.0, tracks, settled=False)) == 1
    assert _ids(sel.choose(5.0, tracks, settled=False)) == 1  # never settled: no dwell
    assert _ids(sel.choose(5.5, tracks, settled=True)) == 1  # settled at 5.5
    assert _ids(sel.choose(7.25, tracks, settled=True)) == 1  # 1.75 s of dwell
    assert sel.captures == 0 and not tracks[0].captured
    assert _ids(sel.choose(7.5, tracks, settled=True)) == 2  # 2.0 s: captured, next
    assert tracks[0].captured and sel.captures == 1
    assert _ids(sel.choose(7.75, tracks, settled=True)) == 2  # settling starts anew: 7.75
    assert _ids(sel.choose(9.75, tracks, settled=True)) == 3  # 1 and 2 captured: 3 was not
    assert _ids(sel.choose(10.0, tracks, settled=True)) == 3
    assert _ids(sel.choose(12.0, tracks, settled=True)) == 1  # all captured: 1 waited longest (since 7.5)
    assert sel.captures == 3
    assert _ids(sel.choose(12.25, tracks, settled=True)) == 1
    assert _ids(sel.choose(14.25, tracks, settled=True)) == 2  # then 2 (left at 9.75), not 3 (left at 12)
    assert sel.captures == 3  # a face is counted once


def test_round_robin_with_one_person_stays_on_them():
    sel = TargetSelector("round-robin", dwell_s=1.0)
    (one,) = tracks = _tracks(4)
    sel.choose(0.0, tracks, settled=False)
    assert _ids(sel.choose(0.5, tracks, settled=True)) == 4 and not one.captured
    assert _ids(sel.choose(3.0, tracks, settled=True)) == 4 and one.captured and sel.captures == 1


def test_single_follows_one_person_until_lost():
    sel = TargetSelector("single", dwell_s=1.0)
    tracks = _tracks(1, 2)
    assert _ids(sel.choose(0.0, tracks, settled=True)) == 1
    for t in (1.0, 5.0, 50.0):
        assert _ids(sel.choose(t, tracks, settled=True)) == 1
    assert tracks[0].captured and sel.captures == 1
    assert _ids(sel.choose(51.0, tracks[1:], settled=True)) == 2  # 1 lost


def test_a_lost_target_is_replaced_and_no_tracks_means_no_target():
    sel = TargetSelector("round-robin", dwell_s=2.0)
    tracks = _tracks(1, 2, 3)
    assert _ids(sel.choose(0.0, tracks, settled=False)) == 1
    assert _ids(sel.choose(0.1, [tracks[2], tracks[1]], settled=False)) == 2  # 1 lost: lowest id next
    assert sel.current == 2 and sel.settled_at is None
    assert sel.choose(0.2, [], settled=True) is None
    assert sel.current is None
    assert _ids(sel.choose(0.3, tracks[2:], settled=False)) == 3


def test_unknown_mode_is_refused():
    with pytest.raises(ValueError, match="target mode"):
        TargetSelector("random")


# ---------------------------------------------------------------------------------------------
# Dead zone


def test_first_command_is_always_sent():
    assert outside_dead_zone((0.1, -0.2, 3.0), None, 1.0, 1.0)


@pytest.mark.parametrize("axis", [0, 1])
def test_pan_and_tilt_move_by_k_sds(axis):
    sent = (0.3, -0.2, 3.0)
    sd = (0.01, 0.02)
    for k, step, expect in ((1.0, 0.99, False), (1.0, 1.01, True), (2.0, 1.5, False), (2.0, 2.01, True)):
        new = list(sent)
        new[axis] -= step * sd[axis]
        assert outside_dead_zone(tuple(new), sent, *sd, k=k) is expect, (k, step)


def test_zoom_moves_by_a_ratio():
    sent = (0.3, -0.2, 4.0)
    assert not outside_dead_zone((0.3, -0.2, 4.0 * math.exp(0.079)), sent, 0.01, 0.01)
    assert outside_dead_zone((0.3, -0.2, 4.0 * math.exp(0.081)), sent, 0.01, 0.01)
    assert outside_dead_zone((0.3, -0.2, 4.0 * math.exp(-0.081)), sent, 0.01, 0.01)
    assert not outside_dead_zone((0.3, -0.2, 4.0 * math.exp(0.15)), sent, 0.01, 0.01, zoom_rel=0.2)


def test_pan_wraps_around():
    """Pan just below +180 deg and just above -180 deg are 0.008 rad apart, not 2 pi."""
    sent = (math.pi - 0.004, 0.0, 2.0)
    new = (-math.pi + 0.004, 0.0, 2.0)
    assert not outside_dead_zone(new, sent, 0.01, 0.01)
    assert outside_dead_zone(new, sent, 0.005, 0.01)
    assert not outside_dead_zone((3 * math.pi - 0.002, 0.0, 2.0), sent, 0.01, 0.01)  # a full turn on
