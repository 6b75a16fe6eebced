"""Target selection (dwell, round-robin order, single mode, lost targets) and the dead zone."""

from __future__ import annotations

import math

import numpy as np
import pytest

from runtime.realtime.targeting import (
    GhostSites,
    TargetSelector,
    TrustRule,
    can_frame,
    is_trusted,
    outside_dead_zone,
)
from runtime.realtime.tracker import Track, Tracker


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


# ---------------------------------------------------------------------------------------------
# Trust and framability


def _run(tracker, positions, dt=0.04, hit=lambda k: True):
    """Feed ``tracker`` one detection per frame at ``positions`` (K, 2) (skipped where ``hit(k)`` is
    false, cov 0.05 m sd); returns the track that was born first."""
    R = np.array([0.05**2 * np.eye(2)])
    for k, xy in enumerate(positions):
        z = np.asarray(xy, float)[None] if hit(k) else np.zeros((0, 2))
        tracker.step(k * dt, z, R[: len(z)])
    return min(tracker.tracks, key=lambda tr: tr.id)


def test_a_static_track_on_empty_floor_is_never_trusted():
    """A ghost: detected every frame for 20 s (500 frames) at one place with 5 cm noise (seed 0)."""
    rng = np.random.default_rng(0)
    tr = _run(Tracker(), np.array([2.0, 1.0]) + 0.05 * rng.standard_normal((500, 2)))
    assert tr.hits >= 490 and tr.travel < 0.2
    assert not is_trusted(tr, TrustRule())
    assert is_trusted(tr, TrustRule(min_travel_m=0.0))  # with the travel test off, it would be


def test_a_walking_person_is_trusted_once_they_have_moved():
    """Walking at 1 m/s, detected every frame at 25 fps: trusted once 0.5 m from where the track was
    born (the filter lags a little behind), not before."""
    rule = TrustRule()  # 8 of 10 frames, 0.4 s, 0.5 m
    kt, R = Tracker(), np.array([0.05**2 * np.eye(2)])
    first = None
    for k in range(40):
        kt.step(k * 0.04, np.array([[0.04 * k, 0.0]]), R)
        if first is None and is_trusted(kt.tracks[0], rule):
            first = k
    assert first is not None and 12 <= first <= 16, first


def test_trust_needs_m_of_n_hits_and_the_minimum_age():
    walk = np.c_[np.linspace(0.0, 2.0, 50), np.zeros(50)]
    flicker = _run(Tracker(max_misses=3), walk, hit=lambda k: k % 2 == 0)  # detected in 5 of every 10 frames
    assert flicker.travel > 1.0 and not is_trusted(flicker, TrustRule(hits=8, window=10))
    assert is_trusted(flicker, TrustRule(hits=5, window=10))
    young = _run(Tracker(), walk[:8])  # 0.28 s old
    assert not is_trusted(young, TrustRule(min_age_s=0.4, min_travel_m=0.1))
    assert is_trusted(young, TrustRule(min_age_s=0.2, min_travel_m=0.1))
    with pytest.raises(ValueError, match="trust hits"):
        TrustRule(hits=11, window=10)


def test_stopping_keeps_trust():
    rule = TrustRule()
    kt = Tracker()
    walk = np.c_[np.linspace(0.0, 1.5, 40), np.zeros(40)]
    tr = _run(kt, walk)
    assert is_trusted(tr, rule)
    tr = _run(kt, np.repeat(walk[-1:], 200, axis=0))  # then stands for 8 s
    assert tr.trusted and is_trusted(tr, rule)


def test_untrusted_tracks_are_never_targeted_and_the_hold_says_why():
    sel = TargetSelector("round-robin", dwell_s=1.0, trust=TrustRule())
    tracks = _tracks(1, 2)
    assert sel.choose(0.0, tracks, settled=False) is None and sel.held == "untrusted"
    tracks[1].trusted = True
    assert _ids(sel.choose(0.1, tracks, settled=False)) == 2 and sel.held is None
    assert sel.choose(0.2, [], settled=False) is None and sel.held is None  # nobody: no hold


def test_tracks_the_ptz_cannot_frame_are_skipped():
    sel = TargetSelector("round-robin", dwell_s=1.0)
    tracks = _tracks(1, 2, 3)
    cannot = {1}

    def framable(tr):
        return tr.id not in cannot

    assert _ids(sel.choose(0.0, tracks, settled=False, framable=framable)) == 2
    cannot = {2}  # the target walks under the PTZ: the next one that can be framed
    assert _ids(sel.choose(0.1, tracks, settled=False, framable=framable)) == 1
    cannot = {1, 2, 3}
    assert sel.choose(0.2, tracks, settled=False, framable=framable) is None and sel.held == "unframeable"
    cannot = {1, 2}
    assert _ids(sel.choose(0.3, tracks, settled=True, framable=framable)) == 3
    assert _ids(sel.choose(0.4, tracks, settled=True, framable=framable)) == 3  # settled at 0.4
    assert _ids(sel.choose(1.5, tracks, settled=True, framable=framable)) == 3  # dwelt, nobody else: stays
    assert tracks[2].captured


def test_can_frame_needs_valid_pointing_and_a_feasible_zoom():
    from types import SimpleNamespace as NS

    def aim(valid, feasible):
        return NS(pointing=NS(valid=np.bool_(valid)), zooms={"calibrated": NS(feasible=np.bool_(feasible))})

    assert can_frame(aim(True, True), "calibrated")
    assert not can_frame(aim(False, True), "calibrated") and not can_frame(aim(True, False), "calibrated")


def test_settling_runs_on_the_frames_clock_not_the_wall_clock(monkeypatch):
    """The loop's settle estimate (when the PTZ reaches a command, which starts the dwell) is the frame's
    stamp plus the slew time, whatever the wall clock says: a ``--pace all`` run chooses the same
    targets however fast the machine is."""
    from types import SimpleNamespace as NS

    from runtime.ptz import default_profile
    from runtime.realtime import ptz_link as link_module
    from runtime.realtime.loop import Command
    from runtime.realtime.ptz_link import PtzLink

    wall = iter(np.random.default_rng(0).uniform(0, 1e6, 1000))
    monkeypatch.setattr(link_module, "time", NS(monotonic=lambda: float(next(wall)), sleep=lambda _s: None))
    link = PtzLink(0, None, default_profile("visca"))
    assert not link.settled(0.0)
    link.send(Command(track=1, pan=0.0, tilt=-0.5, zoom=1.0, zooms={}, sd_pan=0.01, sd_tilt=0.01, sent=True,
                      t_predicted=0.0), stamp=0.0)
    to = (math.pi / 2, -0.5, 1.0)
    slew = link.slew_time(to)
    assert slew > 0.1
    link.send(Command(track=1, pan=to[0], tilt=to[1], zoom=to[2], zooms={}, sd_pan=0.01, sd_tilt=0.01, sent=True,
                      t_predicted=10.0), stamp=10.0)
    assert not link.settled(10.0 + slew - 1e-6)
    assert link.settled(10.0 + slew)


def test_a_command_is_handed_only_when_the_devices_rate_limit_lets_it_through_at_once(monkeypatch):
    """The profile's ``min_interval_s`` (one target per 50 ms for the shipped VISCA camera) on the frames'
    clock: at 25 fps a command follows the last one sent two frames later, not one (it would wait in the
    driver 10 ms for its slot) when no wait is allowed (``--rate-wait-ms 0``); allowed to wait, it leaves at
    its slot, the slots never come sooner than the rate limit, the head is predicted to the slot and the PTZ
    is expected there its slew time after it; the wall clock plays no part."""
    from types import SimpleNamespace as NS

    from runtime.ptz import default_profile
    from runtime.realtime import ptz_link as link_module
    from runtime.realtime.loop import Command
    from runtime.realtime.ptz_link import PtzLink

    wall = iter(np.random.default_rng(1).uniform(0, 1e6, 1000))
    monkeypatch.setattr(link_module, "time", NS(monotonic=lambda: float(next(wall)), sleep=lambda _s: None))
    profile = default_profile("visca")
    assert profile.link.min_interval_s == 0.05

    def send(link, stamp):
        link.send(Command(track=1, pan=0.1 * stamp, tilt=-0.5, zoom=1.0, zooms={}, sd_pan=0.01, sd_tilt=0.01,
                          sent=True, t_predicted=stamp), stamp=stamp)

    link = PtzLink(0, None, profile)
    assert link.ready(0.0)  # nothing sent yet
    send(link, 0.0)
    assert not link.ready(0.04) and link.ready(0.08)  # 25 fps: every second frame
    assert link.ready(0.04, wait_s=0.01) and not link.ready(0.04, wait_s=0.0099)
    # the head is predicted to when the command leaves: the profile's command latency and the wait for the slot
    assert float(link.slew(0.04).latency_s) == pytest.approx(profile.link.command_latency_s + 0.01, abs=1e-12)
    assert float(link.slew(0.2).latency_s) == profile.link.command_latency_s
    sent = []
    for stamp in 0.04 * np.arange(2, 40):  # allowed 10 ms: two frames of three, each slot 50 ms or more apart
        if link.ready(stamp, wait_s=0.01):
            slew = link.slew_time((0.1 * stamp, -0.5, 1.0))
            send(link, stamp)
            assert link.slot - stamp <= 0.01 + 1e-12
            sent.append(link.slot)
    assert np.all(np.diff(sent) >= 0.05 - 1e-12) and len(sent) == 26
    assert link.arrive_at == pytest.approx(link.slot + slew, abs=1e-12)
    # every frame's command (the default): the driver sends the latest target at each slot, so a command
    # handed before the last one left replaces it there, and no wait grows beyond the interval
    every = PtzLink(0, None, profile)
    slots = []
    for stamp in 0.04 * np.arange(0, 100):
        assert every.wait(stamp) <= 0.05 + 1e-12
        send(every, stamp)
        slots.append(every.slot)
    distinct = np.unique(np.round(slots, 9))
    assert np.all(np.diff(distinct) >= 0.05 - 1e-9) and len(distinct) == 81  # 0 .. 4 s, one target per 50 ms
    free = PtzLink(0, None, None)  # no profile: no rate limit known
    send(free, 0.0)
    assert free.ready(0.0)


def test_a_track_that_stops_on_a_ghost_site_loses_trust_and_regains_it_by_walking_on():
    """A ghost track static at (2, 1) for 1.2 s marks a ghost site; a trusted track that comes to it
    loses its trust there (while the ghost is still seen, and for site_life_s after), and regains it
    once min_travel_m beyond the site."""
    rule = TrustRule(site_s=1.0, site_radius_m=0.4, site_life_s=10.0)
    sites = GhostSites(rule)
    ghost = Track(id=1, x=np.array([2.0, 1.0, 0, 0]), P=np.eye(4), t=0.0)
    person = Track(id=2, x=np.array([0.0, 1.0, 0, 0]), P=np.eye(4), t=0.0, trusted=True)
    ghost.t = person.t = 1.2
    sites.update(1.2, [ghost, person])
    assert sites.near((2.1, 1.1)) and not sites.near((2.5, 1.0)) and is_trusted(person, rule)
    person.x[:2] = (1.9, 1.05)  # the person's track took over the ghost's detections
    sites.update(1.3, [person])
    assert not is_trusted(person, rule) and person.travel == 0.0
    person.t = 5.0
    sites.update(5.0, [person])  # a static untrusted track on the site keeps it alive
    sites.update(14.9, [])
    assert sites.near((2.0, 1.0))
    sites.update(15.1, [])  # nothing static there for 10 s: the site is forgotten
    assert not sites.near((2.0, 1.0))
    person.travel, person.recent = 0.6, 0b1111111111  # the tracker measures travel from where trust was taken
    assert is_trusted(person, rule)
    off = GhostSites(TrustRule(site_radius_m=0.0))
    off.update(5.0, [ghost])
    assert not off.near((2.0, 1.0))


def test_a_person_walking_through_a_ghost_site_leaves_no_trail_of_sites():
    """Walking at 1 m/s through a site: the track loses trust there and regains it 0.5 m beyond;
    while untrusted it keeps moving, so it marks no site of its own (25 fps, 3 s)."""
    rule = TrustRule()
    sites = GhostSites(rule)
    sites.sites = np.array([[1.0, 0.0, 0.0]])
    tr = Track(id=1, x=np.array([0.0, 0.0, 1.0, 0.0]), P=np.eye(4), t=0.0, trusted=True, recent=(1 << 32) - 1)
    trusted = []
    for k in range(75):
        t = 0.04 * k
        tr.x[:2], tr.t = (t, 0.0), t
        tr.travel = max(tr.travel, float(np.linalg.norm(tr.position - tr.origin)))
        sites.update(t, [tr])
        trusted.append(is_trusted(tr, rule))
    assert len(sites.sites) == 1
    lost = [0.04 * k for k, ok in enumerate(trusted) if not ok]
    # untrusted from 0.6 m (the site's edge) until 0.5 m beyond its far edge (1.4 m): 1.3 s at 1 m/s
    assert lost[0] == pytest.approx(0.6, abs=0.05) and lost[-1] == pytest.approx(1.86, abs=0.05)


def test_priority_zone_people_come_first_and_take_the_ptz_at_once():
    """A person standing in a priority zone is chosen before the others, and takes the PTZ from a
    target outside one without waiting for its dwell; within the zones the usual order holds."""
    sel = TargetSelector("round-robin", dwell_s=2.0)
    tracks = _tracks(1, 2, 3)
    sel.priority = lambda xy: xy[0] >= 3.0  # track 3 stands in the zone
    assert _ids(sel.choose(0.0, tracks, settled=False)) == 3
    sel.priority = lambda xy: xy[0] >= 2.0  # track 2 walks into it too: 3 keeps the PTZ until dwelt
    assert _ids(sel.choose(0.5, tracks, settled=True)) == 3
    assert _ids(sel.choose(2.5, tracks, settled=True)) == 2  # 3 captured, 2 (in a zone) before 1
    sel.priority = None
    assert _ids(sel.choose(4.5, tracks, settled=True)) == 2  # settled at 2.5 (not yet dwelt: 4.5 - 2.5 < 2) ...
    sel.priority = lambda xy: xy[0] <= 1.0  # ... but 1 walks into a zone: it takes the PTZ now
    assert _ids(sel.choose(4.75, tracks, settled=True)) == 1


def test_the_operator_chooses_or_pauses():
    """``manual``: the operator's track, trusted or not, while it is there and framable, then the selector's
    own choice again; ``paused``: no target, ``held`` says so (only when there are tracks)."""
    sel = TargetSelector("round-robin", dwell_s=1.0, trust=TrustRule(hits=8, window=10, min_age_s=0.4,
                                                                       min_travel_m=0.5))
    tracks = _tracks(1, 2)
    for tr in tracks:
        tr.trusted = True
    stranger = _tracks(9)[0]  # never trusted: the selector would never choose it
    everyone = [*tracks, stranger]
    assert _ids(sel.choose(0.0, everyone, settled=False)) == 1
    assert _ids(sel.choose(0.1, everyone, settled=False, manual=9)) == 9
    assert _ids(sel.choose(0.2, everyone, settled=True, manual=9)) == 9
    assert _ids(sel.choose(1.3, everyone, settled=True, manual=9)) == 9 and stranger.captured  # dwelt: face
    assert _ids(sel.choose(1.4, everyone, settled=True, manual=9, framable=lambda tr: tr.id != 9)) in (1, 2)
    assert _ids(sel.choose(1.5, tracks, settled=True, manual=9)) in (1, 2)  # gone: automatic again
    assert sel.choose(1.6, everyone, settled=True, paused=True) is None and sel.held == "paused"
    assert sel.choose(1.7, [], settled=True, paused=True) is None and sel.held is None
    assert _ids(sel.choose(1.8, everyone, settled=False)) in (1, 2) and sel.held is None


def test_operator_state_is_replaced_whole_and_a_pointing_ends():
    from runtime.realtime.operator import Operator, ZoneSwap

    op = Operator()
    s0 = op.state
    op.choose(4)
    assert op.state.target == 4 and op.state.version == s0.version + 1 and s0.target is None
    st = op.point(0.1, -0.2, 2.0, seconds=5.0)
    assert st.pointing(st.point_until - 1.0) == (0.1, -0.2, 2.0) and st.pointing(st.point_until) is None
    assert op.release().point is None and op.pause(True).paused
    with pytest.raises(ValueError):
        op.point(float("nan"), 0.0, 1.0)
    assert op.take_zones() is None
    op.offer_zones(ZoneSwap(None, None, (), 1))
    op.offer_zones(ZoneSwap(None, None, (), 2))
    assert op.take_zones().version == 2 and op.take_zones() is None


def test_detects_pipeline_takes_trust_on_a_ghost_site_as_the_loop_does(paper_rig, paper_detector, monkeypatch):
    """``omnijax detect``'s pipeline (Perception) tells the background's keeper the loop's trust: a
    trusted track that comes onto a place where an untrusted track stood still (a moved chair a
    passer-by's track took over) is not trusted there, so the keeper does not protect it from
    absorption (without the ghost sites, chair_moved 9031's chair stayed detected all of its 104 s)."""
    from omnijax import learn_background
    from runtime.realtime.perception import Perception

    rng = np.random.default_rng(3)
    W, H = paper_rig.omni.image_size
    floor = np.clip(rng.normal(120.0, 3.0, (4, H, W, 3)), 0, 255).astype(np.uint8)
    perception = Perception(paper_rig, learn_background(floor), 25.0, 4.0, detector=paper_detector)
    chair = Track(id=1, x=np.array([1.0, 0.5, 0, 0]), P=np.eye(4), t=0.0)
    walker = Track(id=2, x=np.array([-1.0, 0.5, 0, 0]), P=np.eye(4), t=0.0, trusted=True)
    seen = []
    monkeypatch.setattr(perception.keeper, "trusted", lambda tracks, *_: seen.append(
        [is_trusted(tr, perception.keeper.trust) for tr in tracks]) or np.zeros(paper_detector.max_people, bool))
    for k, (tracks, xy) in enumerate((([chair, walker], (-1.0, 0.5)), ([chair, walker], (-1.0, 0.5)),
                                      ([walker], (1.05, 0.5)))):
        walker.x[:2] = xy
        chair.t = walker.t = 0.6 * (k + 1)
        monkeypatch.setattr(perception.tracker, "step", lambda t, z, R, tracks=tracks: tracks)
        perception.step(floor[0], 0.6 * (k + 1))
    assert seen[0] == [False, True] and seen[-1] == [False]
