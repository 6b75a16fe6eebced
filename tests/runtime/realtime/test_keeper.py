"""The background keeper (runtime.realtime.perception.BackgroundKeeper): which detections it tells the
background's life are people."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from omnijax import detect, learn_background
from runtime.realtime.perception import PERSON_SEEN_S, BackgroundKeeper
from runtime.realtime.targeting import TrustRule
from runtime.realtime.tracker import Track
from tests.omnijax.test_detection import _noisy, _paint_person
from tests.omnijax.test_life import _floor


def test_a_track_seen_with_a_persons_edge_is_a_person_to_the_life(paper_rig, paper_detector):
    """Someone standing since before the tracker started (a track that never moved, so never trusted
    for targeting) whose detection shows a person's edge in every frame is a person to the life after
    PERSON_SEEN_S of frames (counted a frame late: the verdicts are read at the next update)."""
    rng = np.random.default_rng(5)
    base = _floor(rng)
    i = int(np.argmin(np.abs(np.asarray(paper_detector.polar.hyp_R) - 2.0)))
    person = _paint_person(rng, base, paper_detector, i, 0.7)
    fps = 10.0
    floor = learn_background(np.stack([_noisy(rng, base) for _ in range(20)]))
    keeper = BackgroundKeeper(paper_rig, paper_detector, floor, TrustRule(), fps, 20)
    needed = int(PERSON_SEEN_S * fps)
    assert keeper.person_needed == needed
    track = Track(id=7, x=np.zeros(4), P=np.eye(4), t=0.0)
    said = []
    for _ in range(needed + 3):
        x = jnp.asarray(_noisy(rng, person))
        dets, trace = detect(paper_detector, x, keeper.lines)
        valid = np.nonzero(np.asarray(dets.valid))[0]
        assert len(valid) == 1
        trusted = keeper.trusted([track], {track.id: int(valid[0])}, len(dets.valid))
        said.append(bool(trusted[valid[0]]))
        keeper.update(x, dets, trace, trusted)
    assert not track.trusted  # never trusted for targeting: it never moved
    assert said == [False] * (needed + 1) + [True] * 2
    keeper.trusted([], {}, 8)  # the track is gone: its count goes with it
    assert keeper.person_frames == {}
